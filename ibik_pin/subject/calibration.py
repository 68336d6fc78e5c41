"""Subject calibration: segment scales and keypoint placements fitted to a static trial.

What OpenSim's Scale tool does in two steps (scale the segments from marker distances, then the
marker placer moves each marker onto the static trial), done here as one regularised least-squares
fit. Scaling alone leaves a data set's keypoints where the model puts them; when the data's Neck,
Head or shoulders sit elsewhere on the body (DESIGN.md, "Real data": 30-75 mm on real mocap with
segment lengths within 1 cm), tracking spreads that mismatch over the arms. Here every keypoint
present in the static trial gets its own 3D placement on its segment.

The start is lengths-only scaling (:func:`~ibik_pin.subject.scaling.scale_human` with every length
the static trial measures; its pelvis then in the spine's proportion, see :data:`SCALE_GROUPS`).
The unknowns:

* the pose ``q_f`` of each static frame f (free-flyer and joint angles, inside the joint limits);
* the placement ``o_k`` [m] of every keypoint k present, in its parent joint's frame; the start's
  placement ``o_k^0`` is the prior. A keypoint at a joint's centre (hips, knees, ankles,
  shoulders, elbows, wrists, the Neck) is moved first onto the proximal segment, at the same
  place, and its placement counts from that joint's centre: on the joint's own frame any offset
  would make its target hold that joint's rotation during tracking (a hip target 1 mm off the
  hip's axes locks the hip's flexion at the targets' priority, out of the image criterion's reach);
* one parameter per joint group: the scale of each segment of :data:`SCALE_GROUPS` (its joint
  placements times s along the group's axes) and the distance [m] of each shift of
  :data:`SHIFT_GROUPS` (how high the shoulders sit on the trunk).

The cost, every residual in metres::

    sum_f sum_k present rho(|p_k(q_f; o, s) - x_fk|)                     (the static trial)
  + sum_k (offset_weight * stiffness_k * |o_k - o_k^0|)^2                 (the start's placements)
  + sum_g (scale_weight * |joint displacement of group g|)^2              (the measured lengths)
  + sum_f sum_j (posture_weight_j * q_fj)^2                               (the reference posture)

where rho is Huber's loss (quadratic up to ``robust_scale``, linear beyond).

Identifiability, and what the weights decide (defaults in :class:`CalibrationSettings`):

* An offset along a segment trades with that segment's length, and some trades are exact for every
  pose (a hip keypoint's lateral offset and the pelvis width). Both cost per metre moved: a joint
  ``scale_weight`` (0.1), a keypoint ``offset_weight * stiffness`` (0.1 for Neck, Head, Nose, Hip,
  feet and hands; 0.3 for the shoulders; 1.0 for the joint centres). The lengths measured between
  joint-centre keypoints stay unless the data argues; a keypoint away from any joint moves as
  freely as a length.
* The joint-centre keypoints are stiff (``joint_centre_stiffness``): their offsets grow only when
  the data says so consistently, over frames, where no pose can explain it. Their placement
  defines what a tracked knee or elbow means.
* On one frame an offset also trades with the pose (a Head forward or a bowed head). The static
  trial is taken as the reference posture, as OpenSim's marker placer does: the spine, clavicles
  and neck are pulled toward the model's neutral pose (``spine_posture_weight``,
  ``clavicle_posture_weight``, ``neck_posture_weight``), the limbs only lightly
  (``limb_posture_weight``, for the rotations no keypoint sees). The weights only settle what the
  keypoints leave open (a constant angle over every frame against a placement).
* Several frames with different limb poses make placements and lengths identifiable from the
  data alone (a joint centre is what a limb turns about); a single standing frame leaves them to
  the weights. Whatever never moves in the static trial stays a trade: with an upright trunk in
  every frame, the trunk's length and the height of the Neck and Head on it only show together
  (the keypoints' positions are right either way).

The fit runs in two stages: the poses alone, then poses, placements and groups together
(Levenberg-Marquardt with analytic Jacobians; the placements are eliminated through the per-frame
pose blocks, so a step costs F small solves; joint limits and placement bounds are kept by
clipping). The "before" figures are the static fit, poses alike, of lengths-only scaling.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from ibik_pin.exceptions import InputError, SolverError, UnknownNameError
from ibik_pin.io.trc import read_trc
from ibik_pin.model import BodyModel
from ibik_pin.subject.scaling import keypoint_lengths, neutral_stature, scale_human, segment_lengths_from_keypoints

__all__ = [
    "JOINT_CENTRE_KEYPOINTS",
    "MIN_KEYPOINTS",
    "SCALE_GROUPS",
    "SHOULDER_KEYPOINTS",
    "SHIFT_GROUPS",
    "CalibrationResult",
    "CalibrationSettings",
    "calibrate_static_trial",
    "calibrate_subject",
    "check_subject_size",
    "parse_frame_range",
    "select_frames",
]

_ALL = (1.0, 1.0, 1.0)
_SAGITTAL = (1.0, 1.0, 0.0)
_LATERAL = (0.0, 0.0, 1.0)

#: Segment group -> (joint, axes) whose placement translation in its parent the group scales.
#: Together they cover every joint placement of example-robot-data's human; the trunk holds the
#: pelvis (the hip joints' height and depth below the spine base) with the spine and clavicles.
SCALE_GROUPS: dict[str, tuple[tuple[str, tuple[float, float, float]], ...]] = {
    "pelvis_width": (("left_hip_Z", _LATERAL), ("right_hip_Z", _LATERAL)),
    "left_thigh": (("left_knee_Z", _ALL),),
    "right_thigh": (("right_knee_Z", _ALL),),
    "left_shank": (("left_ankle_Z", _ALL),),
    "right_shank": (("right_ankle_Z", _ALL),),
    "trunk": (
        ("left_hip_Z", _SAGITTAL),
        ("right_hip_Z", _SAGITTAL),
        ("middle_thoracic_Z", _ALL),
        ("middle_cervical_Z", _ALL),
        ("left_clavicle_joint_X", _ALL),
        ("right_clavicle_joint_X", _ALL),
        ("left_shoulder_Z", _SAGITTAL),
        ("right_shoulder_Z", _SAGITTAL),
    ),
    "shoulder_width": (("left_shoulder_Z", _LATERAL), ("right_shoulder_Z", _LATERAL)),
    "left_upper_arm": (("left_elbow_Z", _ALL),),
    "right_upper_arm": (("right_elbow_Z", _ALL),),
    "left_forearm": (("left_wrist_Z", _ALL),),
    "right_forearm": (("right_wrist_Z", _ALL),),
}

#: Joint shift -> (joint, unit direction in its parent's frame) moved together by one distance [m]:
#: how high the shoulders sit on the trunk, which no segment's length says.
SHIFT_GROUPS: dict[str, tuple[tuple[str, tuple[float, float, float]], ...]] = {
    "shoulder_height": (("left_shoulder_Z", (0.0, 1.0, 0.0)), ("right_shoulder_Z", (0.0, 1.0, 0.0))),
}

#: Keypoints at a joint centre of the model: their offsets are stiff (see the module docstring).
JOINT_CENTRE_KEYPOINTS = frozenset(
    {"LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle", "LElbow", "RElbow", "LWrist", "RWrist"}
)

#: The shoulders, less stiff: where a data set puts its shoulder (the joint centre, the top of the
#: humeral head, the acromion) varies more, and the joint itself moves with :data:`SHIFT_GROUPS`.
SHOULDER_KEYPOINTS = frozenset({"LShoulder", "RShoulder"})

#: Fewest distinct keypoints a static trial must hold.
MIN_KEYPOINTS = 6

# Joints whose static angle is taken as the model's neutral one (the reference posture).
_SPINE_JOINT_PREFIXES = ("middle_lumbar", "middle_thoracic")
_CLAVICLE_JOINT_PREFIXES = ("left_clavicle", "right_clavicle")
_NECK_JOINT_PREFIXES = ("middle_cervical",)
# Bounds of a segment scale.
_SCALE_BOUNDS = (0.5, 2.0)
# Lengths that place keypoints rather than size segments: not a subject's size.
_PLACEMENT_LENGTHS = frozenset({"pelvis_height", "neck_shoulder"})
# A subject's segments are between 0.4 and 2.5 times the model's (a small child to a giant):
# outside, the static trial's units are wrong.
_PLAUSIBLE_RATIO = (0.4, 2.5)


@dataclasses.dataclass(frozen=True)
class CalibrationSettings:
    """Weights of the calibration cost (module docstring) and how hard to solve it.

    Attributes:
        offset_weight: cost of moving a keypoint from the start's placement, per metre, relative
            to a keypoint missed in one frame (dimensionless). 0.1: a 4 cm move costs what a 4 mm
            miss does in one frame.
        joint_centre_stiffness: factor on ``offset_weight`` for :data:`JOINT_CENTRE_KEYPOINTS`.
        shoulder_stiffness: factor on ``offset_weight`` for :data:`SHOULDER_KEYPOINTS`.
        scale_weight: cost of moving a joint by a segment scale or a shift, per metre of the
            joints' displacement (dimensionless).
        fit_scales: False keeps the start model's segments (scale_human's lengths, no shift) and
            fits only the keypoint placements and poses.
        spine_posture_weight: pull of the lumbar and thoracic angles toward neutral [m/rad].
        clavicle_posture_weight: pull of the clavicles' elevation toward neutral [m/rad].
            Stronger than the shoulder-height shift's cost: shoulders higher than the model's in
            the static trial are the subject's build more often than a shrug.
        neck_posture_weight: pull of the neck's angles toward neutral [m/rad]. Weak: a Head and
            a Nose a few centimetres forward of the model's are a bowed head more often than
            another head shape.
        limb_posture_weight: pull of every other joint angle toward neutral [m/rad].
        max_offset: bound on each coordinate of a keypoint's move from the start's placement [m].
        max_shift: bound on a joint shift of :data:`SHIFT_GROUPS` [m].
        max_frames: at most this many static frames, evenly spread, are fitted.
        robust_scale: keypoint distance [m] beyond which a miss counts linearly, not squared
            (Huber's loss), so that a few inconsistent keypoints of a markerless triangulation
            do not bend the placements of all the others; 0 for plain least squares.
        iterations: Levenberg-Marquardt steps of the joint fit.
        pose_iterations: Levenberg-Marquardt steps of the first stage (poses alone).
    """

    offset_weight: float = 0.1
    joint_centre_stiffness: float = 10.0
    shoulder_stiffness: float = 3.0
    scale_weight: float = 0.1
    fit_scales: bool = True
    spine_posture_weight: float = 0.005
    clavicle_posture_weight: float = 0.05
    neck_posture_weight: float = 0.01
    limb_posture_weight: float = 0.001
    max_offset: float = 0.3
    max_shift: float = 0.15
    max_frames: int = 10
    robust_scale: float = 0.02
    iterations: int = 100
    pose_iterations: int = 60

    def __post_init__(self) -> None:
        for name in ("offset_weight", "joint_centre_stiffness", "shoulder_stiffness", "scale_weight",
                     "spine_posture_weight", "clavicle_posture_weight", "neck_posture_weight",
                     "limb_posture_weight", "max_offset", "max_shift", "robust_scale"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise InputError(f"CalibrationSettings.{name}: expected a finite value >= 0, got {value}")
        for name in ("max_frames", "iterations", "pose_iterations"):
            if int(getattr(self, name)) < 1:
                raise InputError(f"CalibrationSettings.{name}: expected >= 1, got {getattr(self, name)}")


@dataclasses.dataclass
class CalibrationResult:
    """A calibrated subject and how well it explains its static trial.

    Attributes:
        body: the calibrated model (``calibrated`` True); the input body is not modified.
        keypoint_names: the K keypoints present in the static trial (fitted).
        frames: indices of the static frames used, shape (F,).
        q: the static poses of the calibrated model, shape (F, nq).
        residual_before: per keypoint, [mean, max] over frames of the distance to the static
            trial with lengths-only scaling (the start model, poses fitted), shape (K, 2) [m].
        residual_after: the same with the calibrated model, shape (K, 2) [m].
        offsets: per keypoint, the calibrated placement minus the start's (lengths-only scaling),
            in its parent joint's frame (for a keypoint at a joint centre: the proximal segment's
            joint frame, from that centre), shape (K, 3) [m].
        segment_scales: group name of :data:`SCALE_GROUPS` -> length of the calibrated group
            over the input model's (1.0: unchanged).
        joint_shifts: shift name of :data:`SHIFT_GROUPS` -> its distance [m] (0: as scaled).
        frame_numbers: the TRC frame numbers of ``frames``, when read from a file.
    """

    body: BodyModel
    keypoint_names: list[str]
    frames: np.ndarray
    q: np.ndarray
    residual_before: np.ndarray
    residual_after: np.ndarray
    offsets: np.ndarray
    segment_scales: dict[str, float]
    joint_shifts: dict[str, float]
    frame_numbers: np.ndarray | None = None

    def to_json(self) -> dict:
        """The figures as plain JSON types (millimetres for residuals and offsets)."""
        return {
            "frames": [int(frame) for frame in self.frames],
            "trc_frame_numbers": None if self.frame_numbers is None else [int(n) for n in self.frame_numbers],
            "segment_scales": {name: round(value, 5) for name, value in self.segment_scales.items()},
            "joint_shifts_mm": {name: _mm(value) for name, value in self.joint_shifts.items()},
            "keypoints": {
                name: {
                    "before_mm": {"mean": _mm(self.residual_before[k, 0]), "max": _mm(self.residual_before[k, 1])},
                    "after_mm": {"mean": _mm(self.residual_after[k, 0]), "max": _mm(self.residual_after[k, 1])},
                    "offset_mm": [_mm(value) for value in self.offsets[k]],
                }
                for k, name in enumerate(self.keypoint_names)
            },
            "mean_before_mm": _mm(float(np.mean(self.residual_before[:, 0]))),
            "mean_after_mm": _mm(float(np.mean(self.residual_after[:, 0]))),
        }

    def table(self) -> str:
        """The per-keypoint residual table [mm], one line per keypoint, as `ibik calibrate` prints."""
        lines = [f"{'keypoint':<10} {'before mean':>11} {'max':>7} {'after mean':>11} {'max':>7}  "
                 "offset [mm] (x, y, z)"]
        for k, name in enumerate(self.keypoint_names):
            before, after = 1000 * self.residual_before[k], 1000 * self.residual_after[k]
            offset = ", ".join(f"{1000 * value:+.0f}" for value in self.offsets[k])
            lines.append(f"{name:<10} {before[0]:11.1f} {before[1]:7.1f} {after[0]:11.1f} {after[1]:7.1f}  ({offset})")
        mean_before, mean_after = 1000 * self.residual_before[:, 0].mean(), 1000 * self.residual_after[:, 0].mean()
        lines.append(f"{'mean':<10} {mean_before:11.1f} {'':>7} {mean_after:11.1f}")
        return "\n".join(lines)


def _mm(value: float) -> float:
    return round(1000.0 * float(value), 2)


def select_frames(frame_count: int, frames: slice | Sequence[int] | np.ndarray | None, max_frames: int) -> np.ndarray:
    """Indices of the static frames to fit: the given ones (a slice or indices), at most
    ``max_frames`` of them evenly spread.

    Raises:
        InputError: no frame selected, or an index outside the trial.
    """
    if frames is None:
        indices = np.arange(frame_count)
    elif isinstance(frames, slice):
        indices = np.arange(frame_count)[frames]
    else:
        indices = np.asarray(list(frames), dtype=int).reshape(-1)
        outside = indices[(indices < 0) | (indices >= frame_count)]
        if outside.size:
            raise InputError(f"frames: expected indices in [0, {frame_count - 1}], got {outside.tolist()}")
    if indices.size == 0:
        raise InputError(f"frames: no frame selected out of the static trial's {frame_count}")
    if indices.size > max_frames:
        indices = indices[np.round(np.linspace(0, indices.size - 1, max_frames)).astype(int)]
    return indices


def check_subject_size(body: BodyModel, lengths: dict[str, float], source: str) -> float:
    """The median ratio of measured segment lengths to the model's; refuses implausible ones.

    A static trial in millimetres whose header says metres measures segments 1000 times the
    model's: that is a units error, not a subject, and scaling the model to it would be nonsense.

    Args:
        body: the model the lengths are compared with.
        lengths: from :func:`~ibik_pin.subject.scaling.segment_lengths_from_keypoints` [m].
        source: what the lengths come from, for the message (e.g. a file name).

    Returns:
        The median ratio measured / model over the segments both have (1.0 if none).

    Raises:
        InputError: the ratio is outside [0.4, 2.5], with the units the data probably are in.
    """
    model_lengths = keypoint_lengths(body)
    names = [name for name in lengths if name in model_lengths and name not in _PLACEMENT_LENGTHS
             and model_lengths[name] > 0.0]
    if not names:
        return 1.0
    ratios = np.array([lengths[name] / model_lengths[name] for name in names])
    ratio = float(np.median(ratios))
    low, high = _PLAUSIBLE_RATIO
    if not (low <= ratio <= high):
        example = names[int(np.argmin(np.abs(ratios - ratio)))]
        hint = ""
        for factor, units in ((1000.0, "mm"), (100.0, "cm"), (10.0, "mm labelled cm"),
                              (0.001, "m labelled mm"), (0.01, "m labelled cm"), (0.1, "cm labelled mm")):
            if 0.5 * factor <= ratio <= 2.0 * factor:
                hint = f"; the data look like {units}: check the Units in its header"
                break
        raise InputError(
            f"{source}: segment lengths are {ratio:.3g} times the model's (e.g. {example} "
            f"{lengths[example]:.4g} m, the model's {model_lengths[example]:.3f} m); expected "
            f"{low} to {high} times for a person{hint}"
        )
    return ratio


def calibrate_subject(
    body: BodyModel,
    names: Sequence[str],
    positions: np.ndarray,
    settings: CalibrationSettings | None = None,
    frames: slice | Sequence[int] | np.ndarray | None = None,
    source: str = "static trial",
) -> CalibrationResult:
    """Fit segment scales, keypoint placements and poses to a static trial.

    Args:
        body: the human (:func:`~ibik_pin.model.load_human`), not modified and not a calibrated
            subject already; its keypoints must be operational frames.
        names: the K keypoint names of the trial, all known to the body.
        positions: shape (F, K, 3) or (K, 3) [m], in any world frame (the root pose is fitted);
            NaN marks a keypoint missing in a frame.
        settings: the weights (:class:`CalibrationSettings`; defaults documented there).
        frames: which frames to use (a slice or indices; default all, at most
            ``settings.max_frames`` evenly spread).
        source: what the trial is, for error messages (e.g. its file name).

    Returns:
        The calibrated body and the static fit's figures (:class:`CalibrationResult`).

    Raises:
        UnknownNameError: a name is not a keypoint of the body.
        InputError: wrong shapes, fewer than :data:`MIN_KEYPOINTS` keypoints present, no frame
            with 3 keypoints, segments of an implausible size (wrong units), a calibrated body.
        SolverError: the least-squares solver failed.
    """
    settings = settings or CalibrationSettings()
    if body.calibrated:
        # Its keypoints are placed on the segments they were fitted with: scaling its segments again
        # would leave them behind. The model it was made from is the one to calibrate.
        raise InputError(f"body: {body.urdf_path or 'the model'} is already a calibrated subject; calibrate the "
                         "model it was made from (e.g. the default human) on the new static trial")
    names = list(names)
    points = np.asarray(positions, dtype=float)
    if points.ndim == 2:
        points = points[np.newaxis]
    if points.ndim != 3 or points.shape[1:] != (len(names), 3) or points.shape[0] == 0:
        raise InputError(f"{source}: expected positions of shape (F, {len(names)}, 3) [m] with F >= 1, "
                         f"got {points.shape}")
    unknown = [name for name in names if name not in body.keypoints]
    if unknown:
        raise UnknownNameError(f"{source}: unknown keypoint name(s) {', '.join(unknown)}; known keypoints: "
                               + ", ".join(body.keypoints))
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise InputError(f"{source}: keypoint(s) {repeated} appear more than once")
    not_operational = [name for name in names
                       if body.model.frames[body.frame_id(name)].type != pin.FrameType.OP_FRAME]
    if not_operational:
        raise InputError(f"body: calibration moves keypoint frames, expected operational frames for "
                         f"{not_operational} (load_human's)")

    frame_indices = select_frames(points.shape[0], frames, settings.max_frames)
    points = points[frame_indices]
    present = np.all(np.isfinite(points), axis=2)
    usable = present.sum(axis=1) >= 3
    if not np.any(present):
        raise InputError(f"{source}: every cell is empty (NaN): no keypoint to calibrate on")
    if not np.any(usable):
        raise InputError(f"{source}: no frame holds 3 keypoints or more (a pose needs 3)")
    points, frame_indices, present = points[usable], frame_indices[usable], present[usable]
    seen = present.any(axis=0)
    if seen.sum() < MIN_KEYPOINTS:
        raise InputError(f"{source}: expected at least {MIN_KEYPOINTS} keypoints present, got "
                         f"{int(seen.sum())} ({', '.join(n for n, s in zip(names, seen, strict=True) if s)})")
    names = [name for name, s in zip(names, seen, strict=True) if s]
    points, present = points[:, seen], present[:, seen]

    lengths = segment_lengths_from_keypoints(names, points)
    check_subject_size(body, lengths, source)
    # The "before" figures: lengths-only scaling, every length included, the poses fitted.
    scaled = scale_human(body, lengths)
    baseline = _Problem(scaled, names, points, present, settings)
    baseline.solve_poses()
    before = baseline.keypoint_residuals()
    # The start: the same with the pelvis in the spine's proportion, from the baseline's poses.
    problem = _Problem(_pelvis_as_spine(dataclasses.replace(scaled, model=copy.deepcopy(scaled.model)), body),
                       names, points, present, settings)
    problem.q = baseline.q.copy()
    problem.solve_poses()
    problem.solve_all()
    after = problem.keypoint_residuals()
    calibrated = problem.calibrated_body()
    # The radii follow the stature, as load_human sets them for a URDF with keypoint links.
    with contextlib.suppress(InputError):  # a body without Head or feet keeps scale_human's radii
        calibrated.segment_radii = body.segment_radii * (neutral_stature(calibrated) / neutral_stature(body))
    return CalibrationResult(
        body=calibrated,
        keypoint_names=names,
        frames=frame_indices,
        q=problem.q.copy(),
        residual_before=before,
        residual_after=after,
        offsets=problem.offsets - problem.offsets_start,
        segment_scales=_group_lengths_ratio(calibrated, body),
        joint_shifts={name: float(value) for (name, _), value in zip(problem.groups, problem.scales, strict=True)
                      if name in SHIFT_GROUPS},
    )


def _pelvis_as_spine(start: BodyModel, original: BodyModel) -> BodyModel:
    """The scaled body with its pelvis (the hip joints' height and depth below the spine base) in
    the spine's proportion, as the trunk group of :data:`SCALE_GROUPS` moves them; scale_human
    sizes the pelvis by the mean ratio of every length. Modifies and returns ``start``."""
    model, before = start.model, original.model
    joints = ("middle_thoracic_Z", "left_hip_Z", "right_hip_Z")
    if not all(model.existJointName(joint) and before.existJointName(joint) for joint in joints):
        return start
    spine = np.linalg.norm(before.jointPlacements[before.getJointId(joints[0])].translation)
    if spine == 0.0:
        return start
    ratio = np.linalg.norm(model.jointPlacements[model.getJointId(joints[0])].translation) / spine
    sagittal = np.asarray(_SAGITTAL)
    for hip in joints[1:]:
        index = model.getJointId(hip)
        translation = (1.0 - sagittal) * model.jointPlacements[index].translation + sagittal * ratio * (
            before.jointPlacements[before.getJointId(hip)].translation)
        model.jointPlacements[index] = pin.SE3(model.jointPlacements[index].rotation, translation)
    return start


def parse_frame_range(text: str) -> tuple[int | None, int | None]:
    """``FIRST:LAST`` (TRC frame numbers, both included; either may be left out) as a pair.

    Raises:
        InputError: not of that form, or FIRST after LAST.
    """
    first, colon, last = text.partition(":")
    try:
        bounds = (int(first) if first.strip() else None, int(last) if last.strip() else None)
    except ValueError:
        bounds = None
    if not colon or bounds is None:
        raise InputError(f"--frames: expected FIRST:LAST (TRC frame numbers, e.g. 1:30), got {text!r}")
    if bounds[0] is not None and bounds[1] is not None and bounds[0] > bounds[1]:
        raise InputError(f"--frames: FIRST must not be after LAST, got {text!r}")
    return bounds


def calibrate_static_trial(
    path: str | Path,
    body: BodyModel,
    frame_range: tuple[int | None, int | None] = (None, None),
    settings: CalibrationSettings | None = None,
) -> CalibrationResult:
    """:func:`calibrate_subject` on a static trial's TRC file (m, cm or mm as its header says).

    Args:
        path: the TRC file; its markers are Pose2Sim keypoint names, every one known to the body.
        body: the human to calibrate (not modified).
        frame_range: (first, last) TRC frame numbers (``Frame#``) to use, both included; None for
            the file's first or last frame.
        settings: the calibration's weights.

    Raises:
        FileFormatError: the file cannot be read.
        InputError, UnknownNameError: see :func:`calibrate_subject`; no frame in the range.
    """
    trc = read_trc(path).in_metres()
    first, last = frame_range
    numbers = trc.frame_numbers
    if numbers.size == 0:
        raise InputError(f"{path}: no frame")
    selected = np.flatnonzero((numbers >= (numbers.min() if first is None else first))
                              & (numbers <= (numbers.max() if last is None else last)))
    if selected.size == 0:
        raise InputError(f"{path}: no frame numbered {first}:{last} (its frames are "
                         f"{numbers.min()} to {numbers.max()})")
    result = calibrate_subject(body, trc.marker_names, trc.positions, settings, frames=selected, source=str(path))
    result.frame_numbers = numbers[result.frames]
    return result


def _group_length(model: pin.Model, group: str) -> float:
    squares = 0.0
    for joint, axes in SCALE_GROUPS[group]:
        if model.existJointName(joint):
            translation = model.jointPlacements[model.getJointId(joint)].translation
            squares += float(np.sum((np.asarray(axes) * translation) ** 2))
    return float(np.sqrt(squares))


def _group_lengths_ratio(calibrated: BodyModel, original: BodyModel) -> dict[str, float]:
    ratios = {}
    for group in SCALE_GROUPS:
        before = _group_length(original.model, group)
        if before > 0.0:
            ratios[group] = _group_length(calibrated.model, group) / before
    return ratios


class _Problem:
    """The static fit on a working copy of the start model: poses (F, nq), keypoint placements
    (K, 3) [m] and one parameter per joint group (G,), their cost and its minimisation."""

    def __init__(self, start: BodyModel, names: list[str], points: np.ndarray, present: np.ndarray,
                 settings: CalibrationSettings) -> None:
        self.start = start
        self.settings = settings
        self.names = names
        self.points = points
        self.present = present
        self.model = copy.deepcopy(start.model)
        self.data = self.model.createData()
        model = self.model
        self.frame_ids = [int(i) for i in start.frame_ids(names)]
        self.anchors = [_attach_to_proximal_segment(model, frame_id) for frame_id in self.frame_ids]
        self.parent_joints = [int(model.frames[i].parentJoint) for i in self.frame_ids]
        self.frame_rotations = [model.frames[i].placement.rotation.copy() for i in self.frame_ids]
        # The unknown of a keypoint: its frame's translation, less its anchor joint's (if any).
        self.offsets_start = np.array([
            model.frames[i].placement.translation - (model.jointPlacements[anchor].translation if anchor else 0.0)
            for i, anchor in zip(self.frame_ids, self.anchors, strict=True)])
        self.offsets = self.offsets_start.copy()
        stiffness = [settings.joint_centre_stiffness if name in JOINT_CENTRE_KEYPOINTS
                     else settings.shoulder_stiffness if name in SHOULDER_KEYPOINTS else 1.0 for name in names]
        self.offset_weights = settings.offset_weight * np.array(stiffness)

        # Joint groups, each one parameter p: translation = start + (p - p_start) * direction. A
        # scale (p_start 1) moves along the start translation, a shift (p_start 0, [m]) along a unit
        # vector; both cost scale_weight per metre the group's joints move.
        self.groups: list[tuple[str, list[tuple[int, np.ndarray]]]] = []
        starts, weights, bounds = [], [], []
        for kind, table in (("scale", SCALE_GROUPS), ("shift", SHIFT_GROUPS)):
            for group, members in table.items():
                entries = [(model.getJointId(joint), np.asarray(axes, dtype=float)) for joint, axes in members
                           if model.existJointName(joint)]
                if kind == "scale":
                    entries = [(joint, axes * model.jointPlacements[joint].translation) for joint, axes in entries]
                entries = [(joint, direction) for joint, direction in entries if np.linalg.norm(direction) > 0.0]
                if not entries:
                    continue
                self.groups.append((group, entries))
                starts.append(1.0 if kind == "scale" else 0.0)
                weights.append(settings.scale_weight * np.sqrt(sum(d @ d for _, d in entries)))
                bounds.append(_SCALE_BOUNDS if kind == "scale" else (-settings.max_shift, settings.max_shift))
        self.group_starts = np.array(starts)
        self.group_weights = np.array(weights)
        self.group_bounds = np.array(bounds).reshape(-1, 2)
        self.scales = self.group_starts.copy()
        self.joint_start = {joint: model.jointPlacements[joint].copy()
                            for _, entries in self.groups for joint, _ in entries}
        # A keypoint moves with a joint's translation when that joint carries its frame, or is its anchor.
        moved_by = [{*model.supports[joint], anchor} for joint, anchor in zip(self.parent_joints, self.anchors,
                                                                              strict=True)]
        self.group_moves = [[(k, joint, direction) for joint, direction in entries
                             for k in range(len(names)) if joint in moved_by[k]]
                            for _, entries in self.groups]

        # Revolute coordinates: limits and posture weights (the free-flyer is left free).
        revolute = [joint for joint in range(1, model.njoints) if model.nqs[joint] == 1 and model.nvs[joint] == 1]
        self.revolute_q = np.array([model.idx_qs[joint] for joint in revolute], dtype=int)
        self.revolute_v = np.array([model.idx_vs[joint] for joint in revolute], dtype=int)
        posture = [settings.spine_posture_weight if model.names[joint].startswith(_SPINE_JOINT_PREFIXES)
                   else settings.clavicle_posture_weight if model.names[joint].startswith(_CLAVICLE_JOINT_PREFIXES)
                   else settings.neck_posture_weight if model.names[joint].startswith(_NECK_JOINT_PREFIXES)
                   else settings.limb_posture_weight for joint in revolute]
        self.posture_weights = np.array(posture)
        self.lower = model.lowerPositionLimit[self.revolute_q]
        self.upper = model.upperPositionLimit[self.revolute_q]

        self.q = np.array([self._initial_pose(frame) for frame in range(points.shape[0])])

    # --- Model and poses ----------------------------------------------------------------------

    def _initial_pose(self, frame: int) -> np.ndarray:
        """The neutral pose moved rigidly onto the frame's keypoints (best rotation and translation)."""
        model = self.model
        q = pin.neutral(model)
        pin.framesForwardKinematics(model, self.data, q)
        mask = self.present[frame]
        source = np.array([self.data.oMf[i].translation for i in self.frame_ids])[mask]
        target = self.points[frame, mask]
        if model.joints[1].shortname() == "JointModelFreeFlyer":
            rotation, translation = _rigid_fit(source, target)
            q[:7] = pin.SE3ToXYZQUAT(pin.SE3(rotation, translation))
        return q

    def _apply(self, offsets: np.ndarray, scales: np.ndarray) -> None:
        """Set the working model's keypoint frames and joint placements."""
        model = self.model
        translations = {joint: placement.translation.copy() for joint, placement in self.joint_start.items()}
        for (_, entries), value, start in zip(self.groups, scales, self.group_starts, strict=True):
            for joint, direction in entries:
                translations[joint] += (value - start) * direction
        for joint, translation in translations.items():
            model.jointPlacements[joint] = pin.SE3(self.joint_start[joint].rotation, translation)
        for frame_id, rotation, offset, anchor in zip(self.frame_ids, self.frame_rotations, offsets, self.anchors,
                                                      strict=True):
            frame = model.frames[frame_id]
            base = model.jointPlacements[anchor].translation if anchor else 0.0
            frame.placement = pin.SE3(rotation, base + offset)
            model.frames[frame_id] = frame

    def _positions(self, q: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(self.model, self.data, q)
        return np.array([self.data.oMf[i].translation for i in self.frame_ids])

    def keypoint_residuals(self) -> np.ndarray:
        """Per keypoint, [mean, max] distance over frames where present, shape (K, 2) [m]."""
        self._apply(self.offsets, self.scales)
        distances = np.array([np.linalg.norm(self._positions(q) - target, axis=1)
                              for q, target in zip(self.q, self.points, strict=True)])
        distances[~self.present] = np.nan
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.stack([np.nanmean(distances, axis=0), np.nanmax(distances, axis=0)], axis=1)

    # --- Levenberg-Marquardt on poses and placements -------------------------------------------

    def _model_vector(self) -> np.ndarray:
        return np.concatenate([self.offsets.reshape(-1), self.scales])

    def _set_model_vector(self, theta: np.ndarray) -> None:
        count = 3 * len(self.names)
        self.offsets = theta[:count].reshape(-1, 3).copy()
        self.scales = theta[count:].copy()
        self._apply(self.offsets, self.scales)

    def _model_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        box = self.settings.max_offset
        lower = np.concatenate([(self.offsets_start - box).reshape(-1), self.group_bounds[:, 0]])
        upper = np.concatenate([(self.offsets_start + box).reshape(-1), self.group_bounds[:, 1]])
        return lower, upper

    def _model_prior(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual of the placement and segment priors, and its (diagonal) Jacobian weights."""
        weights = np.concatenate([np.repeat(self.offset_weights, 3), self.group_weights])
        centre = np.concatenate([self.offsets_start.reshape(-1), self.group_starts])
        return weights * (theta - centre), weights

    def _frame_terms(self, frame: int, q: np.ndarray, with_model: bool):
        """One frame on the working model at q: data residuals (3K,) (0 where absent), the distance
        weights of the robust loss (K,), d residual / d v (3K, nv) and d residual / d theta
        (3K, 3K + G) or None."""
        model, data = self.model, self.data
        key_count = len(self.names)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        present = self.present[frame]
        residual = np.array([data.oMf[i].translation for i in self.frame_ids]) - self.points[frame]
        residual[~present] = 0.0
        weights = _robust_weights(np.linalg.norm(residual, axis=1), self.settings.robust_scale)
        pose_jacobian = np.zeros((3 * key_count, model.nv))
        observed = [int(k) for k in np.flatnonzero(present)]
        for k in observed:
            pose_jacobian[3 * k:3 * k + 3] = pin.getFrameJacobian(
                model, data, self.frame_ids[k], pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
        model_jacobian = None
        if with_model:
            model_jacobian = np.zeros((3 * key_count, 3 * key_count + len(self.groups)))
            for k in observed:
                model_jacobian[3 * k:3 * k + 3, 3 * k:3 * k + 3] = data.oMi[self.parent_joints[k]].rotation
            for g, moves in enumerate(self.group_moves):
                for moved, joint, direction in moves:
                    if present[moved]:
                        model_jacobian[3 * moved:3 * moved + 3, 3 * key_count + g] += (
                            data.oMi[model.parents[joint]].rotation @ direction)
        return residual.reshape(-1), weights, pose_jacobian, model_jacobian

    def _cost(self, q: np.ndarray, theta: np.ndarray | None) -> float:
        """The calibration cost (module docstring) with the robust loss on the data term."""
        if theta is not None:
            self._set_model_vector(theta)
        total = 0.0
        for frame, configuration in enumerate(q):
            pin.framesForwardKinematics(self.model, self.data, configuration)
            distances = np.linalg.norm(np.array([self.data.oMf[i].translation for i in self.frame_ids])
                                       - self.points[frame], axis=1)[self.present[frame]]
            total += float(np.sum(_robust_loss(distances, self.settings.robust_scale)))
            total += float(np.sum((self.posture_weights * configuration[self.revolute_q]) ** 2))
        prior, _ = self._model_prior(self._model_vector() if theta is None else theta)
        return total + float(prior @ prior)

    def _solve(self, fit_model: bool, iterations: int) -> None:
        """Levenberg-Marquardt on every frame's pose, and the placements if `fit_model`.

        Each step linearises at the current poses (tangent v, q <- integrate(q, v)); the
        placements' unknowns are eliminated through the per-frame blocks (Schur complement), so a
        step costs F small solves. Joint limits and placement bounds are kept by clipping, with the
        coordinates at a bound that the gradient pushes outward frozen for the step.
        """
        model = self.model
        nv, frame_count = model.nv, self.points.shape[0]
        theta = self._model_vector()
        theta_count = theta.size if fit_model else 0
        theta_lower, theta_upper = self._model_bounds()
        q = np.array([self._clip(configuration) for configuration in self.q])
        cost = self._cost(q, theta)
        damping = 1e-3
        for _ in range(iterations):
            self._set_model_vector(theta)
            blocks = []
            hessian_model = np.zeros((theta_count, theta_count))
            gradient_model = np.zeros(theta_count)
            for frame in range(frame_count):
                residual, weights, pose_jacobian, model_jacobian = self._frame_terms(frame, q[frame], fit_model)
                row_weights = np.repeat(weights, 3)
                weighted = pose_jacobian * row_weights[:, None]
                hessian = weighted.T @ pose_jacobian
                gradient = weighted.T @ residual
                posture = self.posture_weights ** 2
                hessian[self.revolute_v, self.revolute_v] += posture
                gradient[self.revolute_v] += posture * q[frame][self.revolute_q]
                coupling = weighted.T @ model_jacobian if fit_model else np.zeros((nv, 0))
                if fit_model:
                    hessian_model += (model_jacobian * row_weights[:, None]).T @ model_jacobian
                    gradient_model += (model_jacobian * row_weights[:, None]).T @ residual
                at_lower = q[frame][self.revolute_q] <= self.lower + 1e-10
                at_upper = q[frame][self.revolute_q] >= self.upper - 1e-10
                pushed = self.revolute_v[(at_lower & (gradient[self.revolute_v] > 0.0))
                                         | (at_upper & (gradient[self.revolute_v] < 0.0))]
                blocks.append((hessian, gradient, coupling, pushed))
            frozen_model = np.zeros(theta_count, dtype=bool)
            if fit_model:
                prior, prior_weights = self._model_prior(theta)
                hessian_model[np.diag_indices(theta_count)] += prior_weights ** 2
                gradient_model += prior_weights * prior
                frozen_model = ((theta <= theta_lower + 1e-12) & (gradient_model > 0.0)) | (
                    (theta >= theta_upper - 1e-12) & (gradient_model < 0.0))
                if not self.settings.fit_scales:
                    frozen_model[3 * len(self.names):] = True
            accepted = False
            for _ in range(12):
                try:
                    steps, step_model = self._damped_step(blocks, hessian_model, gradient_model, frozen_model,
                                                          damping)
                except np.linalg.LinAlgError as error:
                    raise SolverError(f"calibration: a Levenberg-Marquardt step failed: {error}") from error
                q_new = np.array([self._clip(pin.integrate(model, q[f], steps[f])) for f in range(frame_count)])
                theta_new = np.clip(theta + step_model, theta_lower, theta_upper) if fit_model else theta
                new_cost = self._cost(q_new, theta_new)
                if new_cost < cost:
                    accepted = True
                    break
                damping *= 4.0
            if not accepted:
                break
            decrease = cost - new_cost
            q, theta, cost = q_new, theta_new, new_cost
            damping = max(damping / 3.0, 1e-9)
            if decrease <= 1e-12 * max(cost, 1e-12) + 1e-16:
                break
        self.q = q
        self._set_model_vector(theta)

    @staticmethod
    def _damped_step(blocks, hessian_model, gradient_model, frozen_model, damping):
        """The LM step: per-frame pose steps (F, nv) and the placements' step, by Schur complement."""
        theta_count = gradient_model.size
        schur = hessian_model + damping * np.diag(_damping_scale(hessian_model))
        rhs = -gradient_model.copy()
        eliminated = []
        for hessian, gradient, coupling, pushed in blocks:
            damped = hessian + damping * np.diag(_damping_scale(hessian))
            gradient = gradient.copy()
            coupling = coupling.copy()
            damped[pushed, :] = 0.0
            damped[:, pushed] = 0.0
            damped[pushed, pushed] = 1.0
            gradient[pushed] = 0.0
            coupling[pushed, :] = 0.0
            solved = np.linalg.solve(damped, np.column_stack([gradient, coupling]))
            eliminated.append(solved)
            if theta_count:
                schur -= coupling.T @ solved[:, 1:]
                rhs += coupling.T @ solved[:, 0]
        step_model = np.zeros(theta_count)
        if theta_count:
            free = ~frozen_model
            step_model[free] = np.linalg.solve(schur[np.ix_(free, free)], rhs[free])
        steps = np.array([-(solved[:, 0] + solved[:, 1:] @ step_model) for solved in eliminated])
        return steps, step_model

    def _clip(self, q: np.ndarray) -> np.ndarray:
        q = q.copy()
        q[self.revolute_q] = np.clip(q[self.revolute_q], self.lower, self.upper)
        return q

    def solve_poses(self) -> None:
        """Each frame's pose on the current model (placements and scales fixed)."""
        self._solve(fit_model=False, iterations=self.settings.pose_iterations)

    def solve_all(self) -> None:
        """Poses, placements and segment groups together."""
        self._solve(fit_model=True, iterations=self.settings.iterations)

    def calibrated_body(self) -> BodyModel:
        """A copy of the start body with the fitted placements and scales, marked calibrated."""
        self._apply(self.offsets, self.scales)
        return dataclasses.replace(
            self.start,
            model=copy.deepcopy(self.model),
            keypoints=dict(self.start.keypoints),
            segments=list(self.start.segments),
            segment_radii=np.array(self.start.segment_radii, dtype=float),
            end_effectors=list(self.start.end_effectors),
            calibrated=True,
        )


def _attach_to_proximal_segment(model: pin.Model, frame_id: int) -> int:
    """Move a keypoint frame that sits at its joint's origin to the parent joint's frame (same place).

    Such a keypoint (a hip, knee, shoulder, elbow, the Neck) belongs to the proximal segment. Left
    on its joint's own frame, any offset would make its target see that joint's rotation: a hip
    target 1 mm off the hip's axes would hold the hip's flexion at the targets' priority, which
    the image criterion then cannot move. Returns the joint whose origin the keypoint now follows
    (0 if the frame was left where it was: off its joint's origin, or on the root).
    """
    frame = model.frames[frame_id]
    joint = int(frame.parentJoint)
    if joint == 0 or np.linalg.norm(frame.placement.translation) > 1e-12 or \
            model.joints[joint].shortname() == "JointModelFreeFlyer":
        return 0
    parent = int(model.parents[joint])
    frame.placement = model.jointPlacements[joint] * frame.placement
    frame.parentJoint = parent
    frame.parentFrame = model.getFrameId(model.names[parent])
    model.frames[frame_id] = frame
    return joint


def _damping_scale(hessian: np.ndarray) -> np.ndarray:
    """Levenberg-Marquardt damping per unknown: the Hessian's diagonal, floored at 1e-3 of its
    largest entry so that an unknown the data barely sees (a wrist turn no keypoint follows) cannot
    take a huge step."""
    diagonal = np.diag(hessian).copy()
    return np.maximum(diagonal, 1e-3 * max(float(diagonal.max(initial=0.0)), 1e-12))


def _robust_loss(distances: np.ndarray, scale: float) -> np.ndarray:
    """Huber's loss of distances [m]: d^2 up to `scale`, then linear (2 scale d - scale^2)."""
    if scale <= 0.0:
        return distances**2
    return np.where(distances <= scale, distances**2, 2.0 * scale * distances - scale**2)


def _robust_weights(distances: np.ndarray, scale: float) -> np.ndarray:
    """Iteratively reweighted least squares weights of Huber's loss: 1, or scale / d beyond scale."""
    if scale <= 0.0:
        return np.ones_like(distances)
    return np.minimum(1.0, scale / np.maximum(distances, 1e-12))


def _rigid_fit(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (3, 3) and translation t (3,) minimising |R source + t - target| over the rows."""
    source_mean, target_mean = source.mean(axis=0), target.mean(axis=0)
    covariance = (target - target_mean).T @ (source - source_mean)
    u, _, vt = np.linalg.svd(covariance)
    sign = np.sign(np.linalg.det(u @ vt)) or 1.0
    rotation = u @ np.diag([1.0, 1.0, sign]) @ vt
    return rotation, target_mean - rotation @ source_mean
