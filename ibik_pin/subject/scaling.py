"""Scale the human model to a subject: segment lengths measured on keypoints, set on the model.

Lengths 1-2 cm off doubled the elbow error of the image criterion (docs/method.md, "Scaling the
model to the subject"), so the model is scaled to the subject before tracking. The lengths are distances between
Pose2Sim keypoints (median over the frames of a static or moving trial), and `scale_human` edits the
joint placements (and keypoint frame placements) of a copy of the model until the same keypoint
distances, measured on the model at its neutral pose, equal them.

Lengths [m] that `segment_lengths_from_keypoints` measures and `scale_human` sets (``MID_HIP`` is
the midpoint of LHip and RHip):

============== ========================== =====================================================
name           keypoints                  what of the model changes
============== ========================== =====================================================
left_thigh     LHip -> LKnee              knee joint placement (along its offset)
left_shank     LKnee -> LAnkle            ankle joint placement (ankle_Y, the first of three)
left_foot      LAnkle -> LBigToe          forward (X) offsets of the foot keypoint frames (toes,
                                          heel): a longer foot, the same ankle height
left_upper_arm LShoulder -> LElbow        elbow joint placement
left_forearm   LElbow -> LWrist           wrist joint placement
right_...      the same on the right
pelvis_width   LHip -> RHip               lateral (Z) offsets of the hip joints
shoulder_width LShoulder -> RShoulder     lateral (Z) offsets of the shoulder joints
trunk          MID_HIP -> Neck            spine placements (lumbar to cervical; the clavicles and
                                          the shoulders' forward and vertical offsets follow)
neck_head      Neck -> Head               head keypoint frames (Head, Nose)
pelvis_height  Hip -> MID_HIP             the Hip keypoint frame, along the root -> MID_HIP line
neck_shoulder  Neck -> L/RShoulder (mean) vertical (Y) offsets of the shoulder joints
============== ========================== =====================================================

The last two are not body segments but where a data set puts its keypoints: Pose2Sim's or a BVH
file's Hip may be at the hip joints' level (pelvis_height 0) while the model's Hip is its root,
0.10 m higher; a Neck may be at the shoulders' level while the model's is 0.15 m above them. Setting
them lets the model's keypoints coincide with the data's, which a fit cannot do otherwise.

This module is long because its one concept, the table of lengths and the model edits that set each, is
one table read by one fitting loop; split, each half would need the other.
"""

from __future__ import annotations

import copy
import dataclasses
import warnings
from collections.abc import Callable, Mapping, Sequence

import numpy as np
import pinocchio as pin

from ibik_pin.exceptions import IbikWarning, InputError, UnknownNameError
from ibik_pin.human import neutral_stature
from ibik_pin.model import BodyModel

__all__ = [
    "LENGTH_KEYPOINTS",
    "MID_HIP",
    "keypoint_lengths",
    "scale_from_stature",
    "scale_human",
    "scale_uniformly",
    "segment_lengths_from_keypoints",
]

#: Pseudo keypoint: the midpoint of LHip and RHip.
MID_HIP = "MidHip"

#: Length name -> (first keypoint, second keypoint); see the module docstring.
LENGTH_KEYPOINTS: dict[str, tuple[str, str]] = {
    "left_thigh": ("LHip", "LKnee"),
    "right_thigh": ("RHip", "RKnee"),
    "left_shank": ("LKnee", "LAnkle"),
    "right_shank": ("RKnee", "RAnkle"),
    "left_foot": ("LAnkle", "LBigToe"),
    "right_foot": ("RAnkle", "RBigToe"),
    "left_upper_arm": ("LShoulder", "LElbow"),
    "right_upper_arm": ("RShoulder", "RElbow"),
    "left_forearm": ("LElbow", "LWrist"),
    "right_forearm": ("RElbow", "RWrist"),
    "pelvis_width": ("LHip", "RHip"),
    "shoulder_width": ("LShoulder", "RShoulder"),
    "trunk": (MID_HIP, "Neck"),
    "neck_head": ("Neck", "Head"),
    "pelvis_height": ("Hip", MID_HIP),
    "neck_shoulder": ("Neck", "LShoulder"),  # and Neck -> RShoulder: the mean of both sides
}

# Lengths that say where a data set puts a keypoint rather than how big the subject is: they do
# not enter the mean ratio that scales the segments nobody measured.
_OFFSET_LENGTHS = frozenset({"pelvis_height", "neck_shoulder"})

_ALL = (1.0, 1.0, 1.0)
_FORWARD = (1.0, 0.0, 0.0)
_LATERAL = (0.0, 0.0, 1.0)
_SAGITTAL = (1.0, 1.0, 0.0)


def segment_lengths_from_keypoints(
    keypoints: Mapping[str, np.ndarray] | Sequence[str],
    positions: np.ndarray | None = None,
) -> dict[str, float]:
    """Median over frames of the keypoint distances that :func:`scale_human` sets.

    Frames where a keypoint is missing (NaN) are left out of that length's median; a length whose
    keypoints are absent or never present together is left out of the result.

    Args:
        keypoints: either a mapping keypoint name -> position, shape (3,) or (F, 3) [m]; or the K
            keypoint names, with ``positions``.
        positions: with a list of names, shape (F, K, 3) or (K, 3) [m].

    Returns:
        Length name (see :data:`LENGTH_KEYPOINTS`) -> length [m]; empty if nothing is measurable.

    Raises:
        InputError: shapes that do not match, names repeated.
    """
    names, points = _keypoint_array(keypoints, positions)
    index = {name: k for k, name in enumerate(names)}

    def position(name: str) -> np.ndarray | None:
        if name == MID_HIP:
            if "LHip" not in index or "RHip" not in index:
                return None
            return 0.5 * (points[:, index["LHip"]] + points[:, index["RHip"]])
        return points[:, index[name]] if name in index else None

    lengths: dict[str, float] = {}
    for length_name, (first, second) in LENGTH_KEYPOINTS.items():
        seconds = ("LShoulder", "RShoulder") if length_name == "neck_shoulder" else (second,)
        start = position(first)
        ends = [end for end in (position(name) for name in seconds) if end is not None]
        if start is None or not ends:
            continue
        distances = np.stack([np.linalg.norm(end - start, axis=-1) for end in ends])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN frames
            per_frame = np.nanmean(distances, axis=0)
        if np.all(np.isnan(per_frame)):
            continue
        lengths[length_name] = float(np.nanmedian(per_frame))
    return lengths


def _keypoint_array(keypoints, positions) -> tuple[list[str], np.ndarray]:
    """Names (K) and positions (F, K, 3) [m] from either calling form."""
    if isinstance(keypoints, Mapping):
        if positions is not None:
            raise InputError("positions: expected None when keypoints is a mapping name -> position")
        names = list(keypoints)
        arrays = []
        for name in names:
            array = np.asarray(keypoints[name], dtype=float)
            if array.shape[-1:] != (3,) or array.ndim not in (1, 2):
                raise InputError(f"keypoints[{name!r}]: expected shape (3,) or (F, 3) [m], got {array.shape}")
            arrays.append(np.atleast_2d(array))
        frame_counts = {array.shape[0] for array in arrays}
        if len(frame_counts) > 1:
            raise InputError("keypoints: expected the same number of frames for every keypoint, got "
                             f"{sorted(frame_counts)}")
        points = np.stack(arrays, axis=1) if arrays else np.zeros((1, 0, 3))
    else:
        if isinstance(keypoints, str):
            raise InputError(f"keypoints: expected a list of names, got the string {keypoints!r}")
        names = list(keypoints)
        if positions is None:
            raise InputError("positions: expected an array (F, K, 3) [m] with a list of keypoint names, got None")
        points = np.asarray(positions, dtype=float)
        if points.ndim == 2:
            points = points[np.newaxis]
        if points.ndim != 3 or points.shape[1:] != (len(names), 3):
            raise InputError(
                f"positions: expected shape (F, {len(names)}, 3) [m] for {len(names)} names, got {points.shape}"
            )
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise InputError(f"keypoints: expected unique names, got {repeated} more than once")
    return names, points


def keypoint_lengths(body: BodyModel, q: np.ndarray | None = None) -> dict[str, float]:
    """The lengths of :data:`LENGTH_KEYPOINTS` measured on the model (at ``q``, default neutral) [m]."""
    model = body.model
    q = pin.neutral(model) if q is None else np.asarray(q, dtype=float)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    present = [name for name in body.keypoints if model.existFrame(body.keypoints[name])]
    positions = np.array([data.oMf[body.frame_id(name)].translation for name in present]).reshape(-1, 3)
    return segment_lengths_from_keypoints(present, positions)


def scale_uniformly(body: BodyModel, factor: float) -> BodyModel:
    """A copy of the body with every length (placements, centres of mass, radii) times ``factor``.

    Masses and rotational inertias are kept: the model is used for kinematics.
    """
    factor = float(factor)
    if not (np.isfinite(factor) and factor > 0.0):
        raise InputError(f"factor: expected a positive finite scale, got {factor}")
    model = copy.deepcopy(body.model)
    _scale_model(model, factor)
    return _with_model(body, model, body.segment_radii * factor)


def scale_from_stature(body: BodyModel, stature_m: float) -> BodyModel:
    """A copy of the body scaled uniformly so that its neutral stature is ``stature_m``.

    Args:
        body: the human (not modified); its neutral stature is measured by :func:`~ibik_pin.human.neutral_stature`
            (1.742 m for example-robot-data's human, :data:`~ibik_pin.human.HUMAN_NEUTRAL_STATURE_M`).
        stature_m: the subject's Head height above the lowest foot keypoint, standing [m].

    Raises:
        InputError: the stature is not a positive number, or the body has no Head or foot keypoint.
    """
    if isinstance(stature_m, bool) or not isinstance(stature_m, (int, float, np.integer, np.floating)):
        raise InputError(f"stature_m: expected a number of metres, found {stature_m!r}", parameter="stature_m")
    stature_m = float(stature_m)
    if not (np.isfinite(stature_m) and stature_m > 0.0):
        raise InputError(f"stature_m: expected a positive height [m], got {stature_m}")
    return scale_uniformly(body, stature_m / neutral_stature(body))


def scale_human(body: BodyModel, lengths: Mapping[str, float]) -> BodyModel:
    """A copy of the human whose keypoint distances at the neutral pose are the given lengths.

    First every length of the model is multiplied by the mean ratio requested / model over the
    measured segments (not over pelvis_height and neck_shoulder), so that the segments nobody
    measured keep the model's proportion to the measured ones; then each measured length is set
    exactly by moving the placements of the module docstring's table along one direction (a
    quadratic in the move, solved in closed form). The segment radii are scaled by the mean ratio.

    Args:
        body: example-robot-data's human from :func:`~ibik_pin.human.load_human` (or a URDF with
            the same joint names); not modified (its Pinocchio model is deep-copied).
        lengths: length name -> length [m], names from :data:`LENGTH_KEYPOINTS`; e.g. the output of
            :func:`segment_lengths_from_keypoints`.

    Returns:
        The scaled body. A length that no placement can give (e.g. a Neck -> shoulder distance
        shorter than half the shoulder width) is brought as close as it can be, with an
        :class:`~ibik_pin.exceptions.IbikWarning`.

    Raises:
        UnknownNameError: a length name is not in :data:`LENGTH_KEYPOINTS`.
        InputError: a length is not finite or not positive (pelvis_height may be 0), or the body
            lacks a joint or keypoint the length needs.
    """
    requested = _checked_lengths(lengths)
    model_lengths = keypoint_lengths(body)
    unmeasurable = [name for name in requested if name not in model_lengths]
    if unmeasurable:
        raise InputError(
            f"lengths: the model {body.model.name!r} lacks the keypoints of {unmeasurable}; scale_human "
            "expects example-robot-data's human (load_human)"
        )
    degenerate = [name for name in requested if name not in _OFFSET_LENGTHS and not model_lengths[name] > 1e-6]
    if degenerate:
        source = f"URDF file {str(body.urdf_path)!r}" if body.urdf_path is not None else f"model {body.model.name!r}"
        raise InputError(f"{source}: the segment(s) {', '.join(degenerate)} have no length (their joints' "
                         "origins coincide), so the model cannot be scaled to the subject")
    ratios = [requested[name] / model_lengths[name] for name in requested if name not in _OFFSET_LENGTHS]
    mean_ratio = float(np.mean(ratios)) if ratios else 1.0
    model = copy.deepcopy(body.model)
    _scale_model(model, mean_ratio)
    scaled = _with_model(body, model, body.segment_radii * mean_ratio)
    for name in LENGTH_KEYPOINTS:  # the table's order: a later edit never moves an earlier length
        if name in requested:
            _set_length(scaled, name, requested[name])
    return scaled


def _checked_lengths(lengths: Mapping[str, float]) -> dict[str, float]:
    if not isinstance(lengths, Mapping):
        raise InputError(f"lengths: expected a mapping name -> length [m], got {type(lengths).__name__}")
    unknown = [name for name in lengths if name not in LENGTH_KEYPOINTS]
    if unknown:
        raise UnknownNameError(f"lengths: unknown length name(s) {unknown}; known: {', '.join(LENGTH_KEYPOINTS)}")
    checked = {}
    for name, value in lengths.items():
        value = float(value)
        smallest_allowed_is_zero = name == "pelvis_height"
        if not np.isfinite(value) or value < 0.0 or (value == 0.0 and not smallest_allowed_is_zero):
            expected = "a non-negative" if smallest_allowed_is_zero else "a positive"
            raise InputError(f"lengths[{name!r}]: expected {expected} finite length [m], got {value}")
        checked[name] = value
    return checked


def _with_model(body: BodyModel, model: pin.Model, radii: np.ndarray) -> BodyModel:
    return dataclasses.replace(
        body,
        model=model,
        keypoints=dict(body.keypoints),
        segments=list(body.segments),
        segment_radii=np.array(radii, dtype=float),
        end_effectors=list(body.end_effectors),
    )


def _scale_model(model: pin.Model, factor: float) -> None:
    """Every joint and frame placement translation, and every centre of mass, times factor."""
    for index in range(1, model.njoints):
        placement = model.jointPlacements[index].copy()
        placement.translation = placement.translation * factor
        model.jointPlacements[index] = placement
        inertia = model.inertias[index].copy()
        inertia.lever = inertia.lever * factor
        model.inertias[index] = inertia
    for index in range(model.nframes):
        frame = model.frames[index]
        frame.placement = pin.SE3(frame.placement.rotation, frame.placement.translation * factor)
        model.frames[index] = frame


# --- Setting one length -----------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class _Edit:
    """Move a joint's placement (kind "joint") or a frame's placement (kind "frame") in its parent
    by theta * direction; direction = mask * current translation (``additive`` None) or the given
    vector."""

    kind: str
    name: str | None  # None: the body lacks the keypoint (_check_edits reports it)
    mask: tuple[float, float, float] = _ALL
    additive: tuple[float, float, float] | None = None


def _edits(body: BodyModel, name: str) -> list[_Edit]:
    frame = body.keypoints.get
    side = name.split("_")[0]  # "left" or "right" for the paired lengths
    if name.endswith(("_thigh", "_shank", "_upper_arm", "_forearm")):
        joint = {"thigh": "knee_Z", "shank": "ankle_Y", "upper_arm": "elbow_Z", "forearm": "wrist_Z"}
        return [_Edit("joint", f"{side}_{joint[name.split('_', 1)[1]]}")]
    if name.endswith("_foot"):
        prefix = side[0].upper()
        return [_Edit("frame", frame(f"{prefix}{point}"), _FORWARD) for point in ("BigToe", "SmallToe", "Heel")
                if f"{prefix}{point}" in body.keypoints]
    if name == "pelvis_width":
        return [_Edit("joint", "left_hip_Z", _LATERAL), _Edit("joint", "right_hip_Z", _LATERAL)]
    if name == "shoulder_width":
        return [_Edit("joint", "left_shoulder_Z", _LATERAL), _Edit("joint", "right_shoulder_Z", _LATERAL)]
    if name == "trunk":
        return [
            _Edit("joint", "middle_thoracic_Z"),
            _Edit("joint", "middle_cervical_Z"),
            _Edit("joint", "left_clavicle_joint_X"),
            _Edit("joint", "right_clavicle_joint_X"),
            _Edit("joint", "left_shoulder_Z", _SAGITTAL),
            _Edit("joint", "right_shoulder_Z", _SAGITTAL),
        ]
    if name == "neck_head":
        return [_Edit("frame", frame(point)) for point in ("Head", "Nose") if point in body.keypoints]
    if name == "pelvis_height":
        model = body.model
        hips = [model.jointPlacements[model.getJointId(j)].translation for j in ("left_hip_Z", "right_hip_Z")
                if model.existJointName(j)]
        towards_mid_hip = np.mean(hips, axis=0) if hips else np.zeros(3)
        norm = np.linalg.norm(towards_mid_hip)
        direction = tuple(towards_mid_hip / norm) if norm > 0 else (0.0, 1.0, 0.0)
        return [_Edit("frame", frame("Hip"), additive=direction)]
    if name == "neck_shoulder":
        up = (0.0, 1.0, 0.0)
        return [_Edit("joint", "left_shoulder_Z", additive=up), _Edit("joint", "right_shoulder_Z", additive=up)]
    raise UnknownNameError(f"length {name!r} has no edit; known: {', '.join(LENGTH_KEYPOINTS)}")


def _translation(model: pin.Model, edit: _Edit) -> np.ndarray:
    if edit.kind == "joint":
        return model.jointPlacements[model.getJointId(edit.name)].translation.copy()
    return model.frames[model.getFrameId(edit.name)].placement.translation.copy()


def _set_translation(model: pin.Model, edit: _Edit, translation: np.ndarray) -> None:
    if edit.kind == "joint":
        index = model.getJointId(edit.name)
        placement = model.jointPlacements[index].copy()
        placement.translation = translation
        model.jointPlacements[index] = placement
    else:
        index = model.getFrameId(edit.name)
        frame = model.frames[index]
        frame.placement = pin.SE3(frame.placement.rotation, translation)
        model.frames[index] = frame


def _check_edits(body: BodyModel, name: str, edits: list[_Edit]) -> None:
    model = body.model
    first, second = LENGTH_KEYPOINTS[name]
    needed = [k for k in (first, second) if k != MID_HIP] + (["LHip", "RHip"] if MID_HIP in (first, second) else [])
    missing = [k for k in needed if k not in body.keypoints or not model.existFrame(body.keypoints[k])]
    missing += [
        str(edit.name) for edit in edits
        if edit.name is None
        or (edit.kind == "joint" and not model.existJointName(edit.name))
        or (edit.kind == "frame" and not model.existFrame(edit.name))
    ]
    if missing or not edits:
        raise InputError(
            f"lengths[{name!r}]: the model {model.name!r} lacks {missing or 'the placements'} this length "
            "needs; scale_human expects example-robot-data's human (load_human)"
        )


def _length_vector(body: BodyModel, name: str) -> Callable[[pin.Model], np.ndarray]:
    """A function of the model: the vector whose norm is the length `name` at the neutral pose."""
    first, second = LENGTH_KEYPOINTS[name]

    def measure(model: pin.Model) -> np.ndarray:
        data = model.createData()
        pin.framesForwardKinematics(model, data, pin.neutral(model))

        def position(keypoint: str) -> np.ndarray:
            if keypoint == MID_HIP:
                return 0.5 * (position("LHip") + position("RHip"))
            return data.oMf[model.getFrameId(body.keypoints[keypoint])].translation

        return position(second) - position(first)

    return measure


def _set_length(body: BodyModel, name: str, length: float) -> None:
    """Move the length's placements by theta * direction so that |a + theta b| = length."""
    model = body.model
    edits = _edits(body, name)
    _check_edits(body, name, edits)
    measure = _length_vector(body, name)
    starts = [_translation(model, edit) for edit in edits]
    directions = [
        np.asarray(edit.additive) if edit.additive is not None else np.asarray(edit.mask) * start
        for edit, start in zip(edits, starts, strict=True)
    ]
    a = measure(model)
    for edit, start, direction in zip(edits, starts, directions, strict=True):
        _set_translation(model, edit, start + direction)
    b = measure(model) - a  # the length vector is affine in theta: every rotation is fixed
    quadratic, half_linear, constant = b @ b, a @ b, a @ a - length**2
    discriminant = half_linear**2 - quadratic * constant
    if quadratic < 1e-18:
        theta = 0.0
    elif discriminant < 0.0:
        theta = -half_linear / quadratic  # the closest the placements can come
    else:
        roots = (-half_linear + np.array([-1.0, 1.0]) * np.sqrt(discriminant)) / quadratic
        theta = float(roots[np.argmin(np.abs(roots))])  # the smaller move keeps the model's layout
    for edit, start, direction in zip(edits, starts, directions, strict=True):
        _set_translation(model, edit, start + theta * direction)
    achieved = float(np.linalg.norm(a + theta * b))
    if abs(achieved - length) > 1e-3:
        warnings.warn(
            f"lengths[{name!r}]: requested {length:.4f} m, but the model's placements reach at best "
            f"{achieved:.4f} m (the other lengths constrain it)",
            IbikWarning,
            stacklevel=3,
        )
