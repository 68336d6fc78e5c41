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

One module per piece: the joint groups and weights (:mod:`~ibik_pin.subject.calibration_settings`),
the unknowns, cost and Jacobians (:mod:`~ibik_pin.subject.static_fit`), their minimisation
(:mod:`~ibik_pin.subject.static_fit_solver`), the result and its report
(:mod:`~ibik_pin.subject.calibration_result`). This module checks the static trial, builds the
start and runs the two stages.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from ibik_pin.checks import as_float_array, require_instance
from ibik_pin.exceptions import InputError, UnknownNameError
from ibik_pin.human import neutral_stature
from ibik_pin.io.keypoints import read_keypoints
from ibik_pin.model import BodyModel
from ibik_pin.subject.calibration_result import CalibrationResult
from ibik_pin.subject.calibration_settings import (
    JOINT_CENTRE_KEYPOINTS,
    SCALE_GROUPS,
    SHIFT_GROUPS,
    SHOULDER_KEYPOINTS,
    CalibrationSettings,
)
from ibik_pin.subject.scaling import keypoint_lengths, scale_human, segment_lengths_from_keypoints
from ibik_pin.subject.static_fit import StaticFit
from ibik_pin.subject.static_fit_solver import solve_all, solve_poses

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
    "select_frames",
]

#: Fewest distinct keypoints a static trial must hold.
MIN_KEYPOINTS = 6

# Lengths that place keypoints rather than size segments: not a subject's size.
_PLACEMENT_LENGTHS = frozenset({"pelvis_height", "neck_shoulder"})
# A subject's segments are between 0.4 and 2.5 times the model's (a small child to a giant):
# outside, the static trial's units are wrong.
_PLAUSIBLE_RATIO = (0.4, 2.5)


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
        body: the human (:func:`~ibik_pin.human.load_human`), not modified and not a calibrated
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
    require_instance(body, BodyModel, "body", "a BodyModel (ibik_pin.human.load_human)")
    settings = settings or CalibrationSettings()
    if body.calibrated:
        # Its keypoints are placed on the segments they were fitted with: scaling its segments again
        # would leave them behind. The model it was made from is the one to calibrate.
        raise InputError(f"body: {body.urdf_path or 'the model'} is already a calibrated subject; calibrate the "
                         "model it was made from (e.g. the default human) on the new static trial")
    names = list(names)
    points = as_float_array(positions, "positions")
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
    baseline = StaticFit(scaled, names, points, present, settings)
    solve_poses(baseline)
    before = baseline.keypoint_residuals()
    # The start: the same with the pelvis in the spine's proportion, from the baseline's poses.
    problem = StaticFit(_pelvis_as_spine(dataclasses.replace(scaled, model=copy.deepcopy(scaled.model)), body),
                        names, points, present, settings)
    problem.q = baseline.q.copy()
    solve_poses(problem)
    solve_all(problem)
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
    trunk_axes = dict(SCALE_GROUPS["trunk"])
    for hip in joints[1:]:
        sagittal = np.asarray(trunk_axes[hip])
        index = model.getJointId(hip)
        translation = (1.0 - sagittal) * model.jointPlacements[index].translation + sagittal * ratio * (
            before.jointPlacements[before.getJointId(hip)].translation)
        model.jointPlacements[index] = pin.SE3(model.jointPlacements[index].rotation, translation)
    return start


def calibrate_static_trial(
    path: str | Path,
    body: BodyModel,
    frame_range: tuple[int | None, int | None] = (None, None),
    settings: CalibrationSettings | None = None,
) -> CalibrationResult:
    """:func:`calibrate_subject` on a static trial's TRC file (m, cm or mm as its header says), or a
    C3D file (io.keypoints: its markers mapped to keypoints by io.c3d's default mapping).

    Args:
        path: the TRC or C3D file; its keypoints are Pose2Sim names, every one known to the body.
        body: the human to calibrate (not modified).
        frame_range: (first, last) TRC frame numbers (``Frame#``) to use, both included; None for
            the file's first or last frame.
        settings: the calibration's weights.

    Raises:
        FileFormatError: the file cannot be read.
        InputError, UnknownNameError: see :func:`calibrate_subject`; no frame in the range.
    """
    trc = read_keypoints(path).in_metres()
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
