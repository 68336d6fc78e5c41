"""Real motion capture as Pose2Sim keypoints, and the human model posed to them.

The joints of a motion read by :mod:`ibik_pin.io` (CMU ASF/AMC, CMU's BVH conversions,
Boxing_Toes.bvh) are mapped to the Pose2Sim keypoints the model carries and turned to face +X;
the model is then fitted to them frame by frame by the hierarchical QP. The fitted configurations
are the ground truth of a synthetic data set (:mod:`ibik_pin.synthetic.dataset`).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError, UnknownNameError
from ibik_pin.io.skeleton import SkeletonMotion
from ibik_pin.limits import JointLimits
from ibik_pin.model import BodyModel
from ibik_pin.solvers import make_solver
from ibik_pin.tasks import FramePositionTask, PostureTask, Task

__all__ = ["KEYPOINT_SOURCES", "UP", "facing_directions", "keypoints_from_motion", "pose_model_to_keypoints"]

#: The vertical axis of the model frame and of the motion capture sources: Y up.
UP = np.array([0.0, 1.0, 0.0])

#: The sources :func:`keypoints_from_motion` knows.
KEYPOINT_SOURCES = ("asf", "cmu_bvh", "boxing")

# Pose2Sim keypoint -> joint of each source, left side; the right side swaps the prefixes.
# Columns: CMU ASF/AMC; CMU BVH (cgspeed), which comes in two namings, 131_01.bvh's and
# 01_01.bvh's (MotionBuilder names); Boxing_Toes.bvh (assimp test model).
# - CMU ASF/AMC: a joint is the END point of the bone of that name (ibik_pin.io.asf_amc), so
#   "lfemur" is the knee. The forearm is two bones, lradius then lwrist: the wrist is lwrist's
#   end. The neck is the end of lowerneck (4 cm above the shoulders for subject 35); thorax's end,
#   at the base of the neck, lies below the shoulders, far from the model's Neck (0.15 m above
#   them). "head" ends at the top of the head. CMU has no heel.
# - CMU BVH: a joint is the START of its bone. The Neck is lowerneck's end (131_01's "Neck",
#   01_01's "Neck1": 01_01's "Neck" is the base of the neck); the shoulder is the clavicle's end
#   (131_01's "LeftShoulder", 01_01's "LeftArm"; "LeftCollar" and "LeftShoulder" are its start).
# - Boxing_Toes.bvh: Hips is at the hip joints' level; Neck at the shoulders'.
_LEFT_JOINTS = {
    # keypoint: (asf, cmu_bvh 131_01, cmu_bvh 01_01, boxing)
    "Hip": ("root", "Hips", "Hips", "Hips"),
    "LHip": ("lhipjoint", "LeftHip", "LeftUpLeg", "LeftHip"),
    "LKnee": ("lfemur", "LeftKnee", "LeftLeg", "LeftKnee"),
    "LAnkle": ("ltibia", "LeftAnkle", "LeftFoot", "LeftAnkle"),
    "LBigToe": ("ltoes", "LeftToe_end", "LeftToeBase_end", "LeftToes_end"),
    "Neck": ("lowerneck", "Neck", "Neck1", "Neck"),
    "Head": ("head", "Head_end", "Head_end", "Head_end"),
    "LShoulder": ("lclavicle", "LeftShoulder", "LeftArm", "LeftShoulder"),
    "LElbow": ("lhumerus", "LeftElbow", "LeftForeArm", "LeftElbow"),
    "LWrist": ("lwrist", "LeftWrist", "LeftHand", "LeftWrist"),
}


def _both_sides(column: int, left: str, right: str) -> dict[str, str]:
    """Keypoint -> joint of one column of :data:`_LEFT_JOINTS`, the right side added."""
    table = {}
    for keypoint, joints in _LEFT_JOINTS.items():
        joint = joints[column]
        table[keypoint] = joint
        if keypoint.startswith("L"):
            table["R" + keypoint[1:]] = right + joint[len(left):] if joint.startswith(left) else joint
    return table


def _source_table(motion: SkeletonMotion, source: str) -> dict[str, str]:
    if source == "asf":
        return _both_sides(0, "l", "r")
    if source == "cmu_bvh":
        return _both_sides(2 if "LeftUpLeg" in motion.names else 1, "Left", "Right")
    if source == "boxing":
        return _both_sides(3, "Left", "Right")
    raise UnknownNameError(f"source: unknown source {source!r}; known: {', '.join(KEYPOINT_SOURCES)}")


def keypoints_from_motion(motion: SkeletonMotion, source: str) -> tuple[list[str], np.ndarray]:
    """Pose2Sim keypoints from the joints of a motion capture skeleton, in the model frame.

    The three sources are Y up and right-handed, their subjects facing +Z with the left at +X in
    the rest pose. The motion is rotated about the vertical so that at the first frame the subject
    faces +X (left at -Z, as the model at its neutral pose); no translation is applied.

    Keypoints per source (left side; the right side likewise): Hip (pelvis centre: the root),
    LHip, LKnee, LAnkle, LBigToe (toe tip), Neck, Head (top of the head), LShoulder, LElbow,
    LWrist. None of the sources has a heel, a small toe or a nose.

    Args:
        motion: joint positions [m], e.g. from ``read_asf_amc`` or ``read_bvh(...).to_skeleton_motion()``.
        source: "asf" (CMU ASF/AMC), "cmu_bvh" (CMU BVH conversions, either the naming of
            131_01.bvh or that of 01_01.bvh) or "boxing" (Boxing_Toes.bvh).

    Returns:
        names: the K keypoint names.
        positions: shape (F, K, 3) [m], model frame.

    Raises:
        UnknownNameError: an unknown source, or a joint the source needs is absent (the message
            lists the motion's joints).
    """
    table = _source_table(motion, source)
    missing = sorted({joint for joint in table.values() if joint not in motion.names})
    if missing:
        raise UnknownNameError(
            f"motion: joint(s) {missing} of source {source!r} are absent; the motion's joints: "
            + ", ".join(motion.names)
        )
    names = list(table)
    positions = motion.positions[:, [motion.index(table[name]) for name in names]]
    forward = facing_directions(names, positions[:1])[0]
    yaw = np.arctan2(forward[2], forward[0])  # the rotation about Y taking forward to +X
    rotation = pin.exp3(UP * yaw)
    return names, positions @ rotation.T


def facing_directions(names: Sequence[str], positions: np.ndarray) -> np.ndarray:
    """Horizontal unit direction the subject faces, from its left-right axis, per frame.

    With Y up the subject's left is ``up x forward``, so forward = left x up, where left is the
    horizontal part of (LHip - RHip) + (LShoulder - RShoulder) (the pairs present).

    Args:
        names: the K keypoint names.
        positions: shape (F, K, 3) [m], Y up.

    Returns:
        Shape (F, 3), unit vectors with zero Y (NaN in frames where those keypoints are missing).

    Raises:
        InputError: neither pair of keypoints is among the names.
    """
    names = list(names)
    positions = np.asarray(positions, dtype=float)
    left = np.zeros((positions.shape[0], 3))
    pairs = [(a, b) for a, b in (("LHip", "RHip"), ("LShoulder", "RShoulder")) if a in names and b in names]
    if not pairs:
        raise InputError(f"names: expected LHip and RHip or LShoulder and RShoulder, got {names}")
    for a, b in pairs:
        left += positions[:, names.index(a)] - positions[:, names.index(b)]
    forward = np.cross(left, UP)
    forward[:, 1] = 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        return forward / np.linalg.norm(forward, axis=1, keepdims=True)


def pose_model_to_keypoints(
    body: BodyModel,
    names: Sequence[str],
    positions: np.ndarray,
    iterations: int = 20,
    first_iterations: int = 200,
    posture_weight: float = 0.1,
) -> tuple[np.ndarray, np.ndarray]:
    """Fit the model to every keypoint of every frame: the ground-truth pose of a synthetic set.

    One priority level holds a position task per keypoint (the elbows and knees too), the level
    below a light posture task toward the neutral pose (it only settles the joints no keypoint
    sees, e.g. the wrists). The project's hierarchical QP solves it with the model's joint limits,
    warm-started frame to frame. The first frame starts from the neutral pose moved rigidly onto
    the keypoints (the best rotation and translation of the neutral keypoints, which also turns a
    subject facing away) and gets ``first_iterations`` steps.

    Args:
        body: the (scaled) model; scale it first (:func:`ibik_pin.scaling.scale_human`).
        names: the K keypoint names, all known to the body.
        positions: shape (F, K, 3) [m], model frame; NaN marks a missing keypoint in a frame.
        iterations: solver steps per frame after the first.
        first_iterations: solver steps for the first frame.
        posture_weight: weight of the posture task; in its own level below the keypoints it never
            competes with them, only with the solver's damping (0.1: the joints no keypoint sees
            return to neutral within a few steps).

    Returns:
        q: shape (F, nq), the fitted configurations.
        residuals: shape (F,), mean distance between the model's keypoints and the given ones [m].

    Raises:
        InputError: shapes, names or iteration counts that do not fit.
    """
    names = list(names)
    positions = np.asarray(positions, dtype=float)
    if positions.ndim != 3 or positions.shape[1:] != (len(names), 3) or positions.shape[0] == 0:
        raise InputError(f"positions: expected shape (F, {len(names)}, 3) [m] with F >= 1, got {positions.shape}")
    if int(iterations) < 1 or int(first_iterations) < 1:
        raise InputError(f"iterations, first_iterations: expected >= 1, got {iterations}, {first_iterations}")
    frame_ids = body.frame_ids(names)
    model = body.model
    tasks = [FramePositionTask(model, body.keypoints[name]) for name in names]
    posture = PostureTask(model, weight=posture_weight)
    levels: list[list[Task]] = [list(tasks), [posture]]
    solver = make_solver("qp", limits=JointLimits(model))

    configuration = Configuration(model)
    present = np.all(np.isfinite(positions[0]), axis=1)
    if present.sum() < 3:
        raise InputError(f"positions: expected at least 3 keypoints in the first frame, got {int(present.sum())}")
    neutral_points = configuration.frame_positions(frame_ids)[present]
    # The rigid motion best moving the neutral keypoints onto the first frame's (Kabsch).
    neutral_mean, target_mean = neutral_points.mean(axis=0), positions[0, present].mean(axis=0)
    rotation = Rotation.align_vectors(positions[0, present] - target_mean, neutral_points - neutral_mean)[0]
    q = pin.neutral(model)
    placement = pin.SE3(rotation.as_matrix(), target_mean - rotation.apply(neutral_mean))
    if model.joints[1].shortname() == "JointModelFreeFlyer":
        q[:7] = pin.SE3ToXYZQUAT(placement)
    configuration.update(q)

    q_all = np.empty((positions.shape[0], model.nq))
    residuals = np.empty(positions.shape[0])
    for frame, targets in enumerate(positions):
        for task, target in zip(tasks, targets, strict=True):
            task.set_target(target if np.all(np.isfinite(target)) else None)
        solver.solve(configuration, levels, iterations=first_iterations if frame == 0 else iterations)
        q_all[frame] = configuration.q
        fitted = configuration.frame_positions(frame_ids)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a frame with no keypoint
            residuals[frame] = np.nanmean(np.linalg.norm(fitted - targets, axis=1))
    return q_all, residuals
