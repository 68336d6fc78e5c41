"""Synthetic calibrated views of real motion, as in HumanEva, written as the files `ibik track` reads.

Real motion capture (CMU ASF/AMC, CMU BVH, the boxing BVH) gives the ground truth: its joints are
mapped onto Pose2Sim keypoints (:func:`keypoints_from_motion`), the scaled human model is fitted to
all of them every frame (:func:`pose_model_to_keypoints`: elbows and knees included, so the model's
pose is the truth the tracker must recover), a few cameras are placed around the subject
(:func:`humaneva_rig`), the posed model's capsules are rendered into silhouettes
(:func:`render_silhouettes`), optionally degraded like a real segmentation (:func:`apply_defects`),
and everything is written to a folder (:func:`write_dataset`): the calibration, the end-effector
targets, the truth and the masks.

Frames: the "model frame" is the human model's world: Y up, metres; a subject facing +X has its left
at -Z (ISB). TRC files are written in it. The calibration TOML follows Pose2Sim's Z-up world, in
which a TRC point p is the point ``POSE2SIM_TRC_TO_WORLD @ p``.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np
import pinocchio as pin

from .cameras import POSE2SIM_TRC_TO_WORLD, PinholeCamera, look_at_camera, write_calibration
from .configuration import Configuration
from .exceptions import InputError, UnknownNameError
from .io.motion import SkeletonMotion
from .io.trc import TrcData, write_trc
from .limits import JointLimits
from .model import BodyModel
from .render import render_capsules
from .solvers import make_solver
from .tasks import FramePositionTask, PostureTask

__all__ = [
    "DatasetPaths",
    "KEYPOINT_SOURCES",
    "MISSING_LIMB_SEGMENTS",
    "SilhouetteDefects",
    "apply_defects",
    "facing_directions",
    "humaneva_rig",
    "keypoints_from_motion",
    "pose_model_to_keypoints",
    "render_limb_masks",
    "render_silhouettes",
    "write_dataset",
]

UP = np.array([0.0, 1.0, 0.0])

# Pose2Sim keypoint -> joint of each source, left side; the right side swaps the prefixes.
# CMU ASF/AMC: a joint is the END point of the bone of that name (ibik_pin.io.asf_amc), so
# "lfemur" is the knee. The forearm is two bones, lradius then lwrist: the wrist is lwrist's end.
# The neck is the end of lowerneck (4 cm above the shoulders for subject 35); thorax's end, at the
# base of the neck, lies below the shoulders, far from the model's Neck (0.15 m above them).
# "head" ends at the top of the head. CMU has no heel.
_ASF = {
    "Hip": "root",
    "LHip": "lhipjoint",
    "LKnee": "lfemur",
    "LAnkle": "ltibia",
    "LBigToe": "ltoes",
    "Neck": "lowerneck",
    "Head": "head",
    "LShoulder": "lclavicle",
    "LElbow": "lhumerus",
    "LWrist": "lwrist",
}
# CMU BVH (cgspeed): a joint is the START of its bone. Two namings exist; 131_01.bvh's:
_CMU_BVH_131 = {
    "Hip": "Hips",
    "LHip": "LeftHip",
    "LKnee": "LeftKnee",
    "LAnkle": "LeftAnkle",
    "LBigToe": "LeftToe_end",
    "Neck": "Neck",  # lowerneck's end ("lowerneck" is the base of the neck, thorax's end)
    "Head": "Head_end",
    "LShoulder": "LeftShoulder",  # the clavicle's end ("LeftCollar" is its start)
    "LElbow": "LeftElbow",
    "LWrist": "LeftWrist",
}
# ... and 01_01.bvh's (MotionBuilder names):
_CMU_BVH_01 = {
    "Hip": "Hips",
    "LHip": "LeftUpLeg",
    "LKnee": "LeftLeg",
    "LAnkle": "LeftFoot",
    "LBigToe": "LeftToeBase_end",
    "Neck": "Neck1",  # lowerneck's end ("Neck" is the base of the neck)
    "Head": "Head_end",
    "LShoulder": "LeftArm",  # the clavicle's end ("LeftShoulder" is its start)
    "LElbow": "LeftForeArm",
    "LWrist": "LeftHand",
}
# Boxing_Toes.bvh (assimp test model): Hips is at the hip joints' level; Neck at the shoulders'.
_BOXING = {
    "Hip": "Hips",
    "LHip": "LeftHip",
    "LKnee": "LeftKnee",
    "LAnkle": "LeftAnkle",
    "LBigToe": "LeftToes_end",
    "Neck": "Neck",
    "Head": "Head_end",
    "LShoulder": "LeftShoulder",
    "LElbow": "LeftElbow",
    "LWrist": "LeftWrist",
}

#: The sources :func:`keypoints_from_motion` knows.
KEYPOINT_SOURCES = ("asf", "cmu_bvh", "boxing")

#: Keypoints a forearm or shank capsule ends on: the limbs a segmentation may lose.
MISSING_LIMB_SEGMENTS = (("LElbow", "LWrist"), ("RElbow", "RWrist"), ("LKnee", "LAnkle"), ("RKnee", "RAnkle"))


def _both_sides(left_table: dict[str, str], left: str, right: str) -> dict[str, str]:
    table = {}
    for keypoint, joint in left_table.items():
        table[keypoint] = joint
        if keypoint.startswith("L"):
            table["R" + keypoint[1:]] = right + joint[len(left):] if joint.startswith(left) else joint
    return table


def _source_table(motion: SkeletonMotion, source: str) -> dict[str, str]:
    if source == "asf":
        return _both_sides(_ASF, "l", "r")
    if source == "cmu_bvh":
        table = _CMU_BVH_01 if "LeftUpLeg" in motion.names else _CMU_BVH_131
        return _both_sides(table, "Left", "Right")
    if source == "boxing":
        return _both_sides(_BOXING, "Left", "Right")
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


def _kabsch(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (3, 3) and translation t (3,) minimising |R source + t - target| (rows)."""
    source_mean, target_mean = source.mean(axis=0), target.mean(axis=0)
    covariance = (target - target_mean).T @ (source - source_mean)
    u, _, vt = np.linalg.svd(covariance)
    sign = np.sign(np.linalg.det(u @ vt))
    rotation = u @ np.diag([1.0, 1.0, sign]) @ vt
    return rotation, target_mean - rotation @ source_mean


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
    levels = [tasks, [posture]]
    solver = make_solver("qp", limits=JointLimits(model))

    configuration = Configuration(model)
    present = np.all(np.isfinite(positions[0]), axis=1)
    if present.sum() < 3:
        raise InputError(f"positions: expected at least 3 keypoints in the first frame, got {int(present.sum())}")
    neutral_points = configuration.frame_positions(frame_ids)[present]
    rotation, translation = _kabsch(neutral_points, positions[0, present])
    q = pin.neutral(model)
    placement = pin.SE3(rotation, translation)
    if model.joints[1].shortname() == "JointModelFreeFlyer":
        q[:7] = pin.SE3ToXYZQUAT(placement)
    configuration.update(q)

    q_all = np.empty((positions.shape[0], model.nq))
    residuals = np.empty(positions.shape[0])
    for frame, targets in enumerate(positions):
        for task, target in zip(tasks, targets):
            task.set_target(target if np.all(np.isfinite(target)) else None)
        solver.solve(configuration, levels, iterations=first_iterations if frame == 0 else iterations)
        q_all[frame] = configuration.q
        fitted = configuration.frame_positions(frame_ids)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a frame with no keypoint
            residuals[frame] = np.nanmean(np.linalg.norm(fitted - targets, axis=1))
    return q_all, residuals


def humaneva_rig(
    n_views: int,
    subject_center: np.ndarray,
    distance_m: float = 4.0,
    size: tuple[int, int] = (640, 480),
    focal_px: float = 700.0,
    height_m: float = 1.5,
    seed: int = 0,
    jitter_deg: float = 15.0,
) -> list[PinholeCamera]:
    """Cameras around the subject like HumanEva's: on a horizontal circle, looking at its centre.

    HumanEva's colour cameras stand 3-5 m from the capture volume's centre at about 1.5 m, 640 x 480
    px. Here the azimuths are spread evenly (360 deg / n_views apart) from a seeded random start,
    each with a seeded jitter of up to ``jitter_deg``; distortion is zero.

    Args:
        n_views: number of cameras (HumanEva: 3 or 4).
        subject_center: shape (3,) [m], model frame (Y up): the point every camera looks at, e.g.
            the mean Hip position over the sequence.
        distance_m: horizontal distance of each camera from the subject's centre [m].
        size: (width, height) [px].
        focal_px: focal length [px].
        height_m: height of the camera centres, model-frame Y [m] (the motion data's floor is 0).
        seed: seeds the start azimuth and the jitter.
        jitter_deg: largest deviation of an azimuth from the even spread [deg].

    Returns:
        Cameras named cam1 .. camN, extrinsics mapping model-frame points.

    Raises:
        InputError: n_views < 1, a non-positive distance, a centre that is not (3,).
    """
    if int(n_views) != n_views or n_views < 1:
        raise InputError(f"n_views: expected a positive integer, got {n_views!r}")
    distance_m = float(distance_m)
    if not (np.isfinite(distance_m) and distance_m > 0.0):
        raise InputError(f"distance_m: expected a positive distance [m], got {distance_m}")
    center = np.asarray(subject_center, dtype=float)
    if center.shape != (3,) or not np.all(np.isfinite(center)):
        raise InputError(f"subject_center: expected a finite point of shape (3,) [m], got {subject_center!r}")
    rng = np.random.default_rng(seed)
    start = rng.uniform(0.0, 2.0 * np.pi)
    jitter = np.deg2rad(float(jitter_deg)) * rng.uniform(-1.0, 1.0, int(n_views))
    azimuths = start + 2.0 * np.pi * np.arange(int(n_views)) / n_views + jitter
    cameras = []
    for index, azimuth in enumerate(azimuths, start=1):
        eye = center + distance_m * np.array([np.cos(azimuth), 0.0, np.sin(azimuth)])
        eye[1] = height_m
        cameras.append(look_at_camera(f"cam{index}", size, focal_px, eye, center, UP))
    return cameras


def _keypoint_positions(body: BodyModel, q: np.ndarray) -> dict[str, np.ndarray]:
    """World position [m] of every keypoint of the body at q."""
    q = np.asarray(q, dtype=float)
    if q.shape != (body.model.nq,):
        raise InputError(f"q: expected shape ({body.model.nq},), got {q.shape}")
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, q)
    return {name: data.oMf[body.frame_id(name)].translation.copy() for name in body.keypoints}


def _head_sphere(points: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Centre (1, 3) [m] and radius (1,) [m] of the head: 60 % of the way from Neck to Head, with a
    radius of 42 % of that length, so that its top reaches the Head keypoint (the top of the head)."""
    if "Neck" not in points or "Head" not in points:
        return np.zeros((0, 3)), np.zeros(0)
    neck_to_head = points["Head"] - points["Neck"]
    centre = points["Neck"] + 0.6 * neck_to_head
    return centre[np.newaxis], np.array([0.42 * np.linalg.norm(neck_to_head)])


def render_silhouettes(body: BodyModel, q: np.ndarray, cameras: Sequence) -> list[np.ndarray]:
    """Silhouettes of the posed model: its segment capsules (``body.segments``,
    ``body.segment_radii``) and a head sphere, one mask per camera.

    Args:
        body: the model.
        q: configuration, shape (nq,).
        cameras: cameras whose extrinsics map model-frame points.

    Returns:
        One (H, W) bool mask per camera.
    """
    points = _keypoint_positions(body, q)
    starts = np.array([points[a] for a, _ in body.segments]).reshape(-1, 3)
    ends = np.array([points[b] for _, b in body.segments]).reshape(-1, 3)
    spheres, sphere_radii = _head_sphere(points)
    return [
        render_capsules(camera, starts, ends, body.segment_radii, spheres, sphere_radii)
        for camera in cameras
    ]


def render_limb_masks(body: BodyModel, q: np.ndarray, camera) -> list[np.ndarray]:
    """Pixels that only a forearm or a shank covers, per limb of :data:`MISSING_LIMB_SEGMENTS`.

    A segmentation that loses a limb loses those pixels; where the limb is in front of the trunk
    the trunk's pixels stay.

    Returns:
        One (H, W) bool mask per limb segment the body has.
    """
    points = _keypoint_positions(body, q)
    spheres, sphere_radii = _head_sphere(points)
    masks = []
    for limb in MISSING_LIMB_SEGMENTS:
        if limb not in body.segments:
            continue
        index = body.segments.index(limb)
        others = [i for i in range(len(body.segments)) if i != index]
        limb_mask = render_capsules(
            camera, points[limb[0]][np.newaxis], points[limb[1]][np.newaxis], body.segment_radii[index]
        )
        rest = render_capsules(
            camera,
            np.array([points[body.segments[i][0]] for i in others]).reshape(-1, 3),
            np.array([points[body.segments[i][1]] for i in others]).reshape(-1, 3),
            body.segment_radii[others],
            spheres,
            sphere_radii,
        )
        masks.append(limb_mask & ~rest)
    return masks


@dataclass(frozen=True)
class SilhouetteDefects:
    """How a synthetic silhouette is degraded to look like a real segmentation.

    Applied in this order by :func:`apply_defects`: a missing limb, erosion, dilation, holes, blobs.

    Attributes:
        erode_px: erosion radius [px] (elliptic structuring element of 2 r + 1 px): a tight mask.
        dilate_px: dilation radius [px]: a loose mask.
        holes: number of discs removed inside the silhouette (a colour like the background's).
        hole_radius_px: their radius [px].
        blobs: number of elliptic blobs added (shadows, clutter).
        blob_radius_px: their semi-major axis [px]; the semi-minor axis is 50-100 % of it.
        attached_blob_probability: chance that a blob is centred on the silhouette's border
            (a shadow, attached) rather than anywhere in the image (clutter, detached).
        missing_limb_probability: chance, per mask, that the pixels of one random forearm or
            shank are lost.
    """

    erode_px: int = 0
    dilate_px: int = 0
    holes: int = 0
    hole_radius_px: float = 4.0
    blobs: int = 0
    blob_radius_px: float = 12.0
    attached_blob_probability: float = 0.5
    missing_limb_probability: float = 0.0

    def __post_init__(self) -> None:
        for name in ("erode_px", "dilate_px", "holes", "blobs"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < 0:
                raise InputError(f"{name}: expected a non-negative integer, got {value!r}")
            object.__setattr__(self, name, int(value))
        for name in ("hole_radius_px", "blob_radius_px"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0.0):
                raise InputError(f"{name}: expected a positive radius [px], got {value}")
        for name in ("attached_blob_probability", "missing_limb_probability"):
            value = float(getattr(self, name))
            if not 0.0 <= value <= 1.0:
                raise InputError(f"{name}: expected a probability in [0, 1], got {value}")


def _disc_kernel(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def apply_defects(
    mask: np.ndarray,
    defects: SilhouetteDefects,
    rng: np.random.Generator,
    limb_masks: Sequence[np.ndarray] | None = None,
) -> np.ndarray:
    """A degraded copy of a silhouette (the input is not modified).

    Args:
        mask: (H, W) bool silhouette.
        defects: what to apply.
        rng: the random generator (seed it for a reproducible data set).
        limb_masks: the pixels of each forearm and shank (:func:`render_limb_masks`), needed for a
            missing limb; without them no limb goes missing.

    Returns:
        (H, W) bool mask.
    """
    mask = np.asarray(mask)
    if mask.ndim != 2 or mask.dtype != np.bool_:
        raise InputError(f"mask: expected an (H, W) bool array, got shape {mask.shape} and dtype {mask.dtype}")
    image = mask.astype(np.uint8)
    if limb_masks and rng.random() < defects.missing_limb_probability:
        lost = np.asarray(limb_masks[int(rng.integers(len(limb_masks)))], dtype=bool)
        if lost.shape != mask.shape:
            raise InputError(f"limb_masks: expected masks of shape {mask.shape}, got {lost.shape}")
        image[lost] = 0
    if defects.erode_px:
        image = cv2.erode(image, _disc_kernel(defects.erode_px))
    if defects.dilate_px:
        image = cv2.dilate(image, _disc_kernel(defects.dilate_px))
    height, width = image.shape
    for _ in range(defects.holes):
        rows, columns = np.nonzero(image)
        if rows.size == 0:
            break
        pick = int(rng.integers(rows.size))
        radius = int(round(defects.hole_radius_px))
        cv2.circle(image, (int(columns[pick]), int(rows[pick])), radius, 0, thickness=-1)
    for _ in range(defects.blobs):
        border = image.astype(bool) & ~cv2.erode(image, _disc_kernel(1)).astype(bool)
        rows, columns = np.nonzero(border)
        if rows.size and rng.random() < defects.attached_blob_probability:
            pick = int(rng.integers(rows.size))
            centre = (int(columns[pick]), int(rows[pick]))
        else:
            centre = (int(rng.integers(width)), int(rng.integers(height)))
        semi_major = max(int(round(defects.blob_radius_px)), 1)
        semi_minor = max(int(round(semi_major * rng.uniform(0.5, 1.0))), 1)
        angle = float(rng.uniform(0.0, 180.0))
        cv2.ellipse(image, centre, (semi_major, semi_minor), angle, 0.0, 360.0, 1, thickness=-1)
    return image.astype(bool)


@dataclass(frozen=True)
class DatasetPaths:
    """The files :func:`write_dataset` wrote.

    Attributes:
        folder: the data set's folder.
        calibration: Pose2Sim calibration TOML (Z-up world, see the module docstring).
        targets: TRC of the target keypoints, model frame (Y up), metres, with noise.
        truth: TRC of every keypoint of the posed model, no noise.
        truth_q: .npy of the true configurations, shape (F, nq).
        masks: folder with one sub-folder of masks per camera (``<camera>/000000.png``, 0/255).
        metadata: JSON of the parameters (frame rate, cameras, noise, defects, seed).
    """

    folder: Path
    calibration: Path
    targets: Path
    truth: Path
    truth_q: Path
    masks: Path
    metadata: Path


def write_dataset(
    out_dir: str | Path,
    body: BodyModel,
    q: np.ndarray,
    cameras: Sequence[PinholeCamera],
    frame_rate: float,
    target_keypoints: Sequence[str],
    noise_mm: float = 0.0,
    defects: SilhouetteDefects | None = None,
    seed: int = 0,
) -> DatasetPaths:
    """Write a synthetic sequence as the files `ibik track` reads.

    ``ibik track --targets targets.trc --calibration calibration.toml --masks masks`` runs on it;
    truth.trc and truth_q.npy are what the estimate is compared with.

    Args:
        out_dir: the folder (created if needed; files of the same names are replaced).
        body: the model the truth was posed with.
        q: true configurations, shape (F, nq).
        cameras: pinhole cameras mapping model-frame points (e.g. :func:`humaneva_rig`).
        frame_rate: frames per second [Hz].
        target_keypoints: the keypoints written to targets.trc (the known end-effectors).
        noise_mm: standard deviation of the Gaussian noise added to each target coordinate [mm].
        defects: silhouette defects, or None for the clean rendered masks.
        seed: seeds the noise and the defects (two independent streams).

    Returns:
        The paths written.

    Raises:
        InputError: shapes, names or values that do not fit.
        UnknownNameError: a target keypoint the body does not have.
    """
    model = body.model
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != model.nq or q.shape[0] == 0:
        raise InputError(f"q: expected shape (F, {model.nq}) with F >= 1, got {q.shape}")
    frame_rate = float(frame_rate)
    if not (np.isfinite(frame_rate) and frame_rate > 0.0):
        raise InputError(f"frame_rate: expected a positive number [Hz], got {frame_rate}")
    noise_mm = float(noise_mm)
    if not (np.isfinite(noise_mm) and noise_mm >= 0.0):
        raise InputError(f"noise_mm: expected a non-negative standard deviation [mm], got {noise_mm}")
    if isinstance(target_keypoints, str) or not list(target_keypoints):
        raise InputError(f"target_keypoints: expected a non-empty list of keypoint names, got {target_keypoints!r}")
    target_keypoints = list(target_keypoints)
    unknown = [name for name in target_keypoints if name not in body.keypoints]
    if unknown:
        raise UnknownNameError(
            f"target_keypoints: unknown keypoint(s) {unknown}; known: {', '.join(body.keypoints)}"
        )
    if len(set(target_keypoints)) != len(target_keypoints):
        raise InputError(f"target_keypoints: expected each name once, got {target_keypoints}")
    cameras = list(cameras)
    if not cameras:
        raise InputError("cameras: expected at least one camera, got none")
    if defects is not None and not isinstance(defects, SilhouetteDefects):
        raise InputError(f"defects: expected a SilhouetteDefects or None, got {type(defects).__name__}")

    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    paths = DatasetPaths(
        folder=folder,
        calibration=folder / "calibration.toml",
        targets=folder / "targets.trc",
        truth=folder / "truth.trc",
        truth_q=folder / "truth_q.npy",
        masks=folder / "masks",
        metadata=folder / "dataset.json",
    )
    # Pose2Sim's calibration world is Z up: world = M @ model frame, so R_world = R_model @ M^T.
    write_calibration(
        paths.calibration,
        [_replace_rotation(camera, camera.rotation @ POSE2SIM_TRC_TO_WORLD.T) for camera in cameras],
    )

    keypoints = list(body.keypoints)
    truth = np.array([[points[name] for name in keypoints]
                      for points in (_keypoint_positions(body, q_frame) for q_frame in q)])
    frame_count = q.shape[0]
    times = np.arange(frame_count) / frame_rate
    frame_numbers = np.arange(1, frame_count + 1)
    write_trc(paths.truth, TrcData(keypoints, times, truth, "m", frame_rate, frame_numbers))
    noise_rng = np.random.default_rng([seed, 0])
    defect_rng = np.random.default_rng([seed, 1])
    target_indices = [keypoints.index(name) for name in target_keypoints]
    targets = truth[:, target_indices] + noise_rng.normal(0.0, noise_mm * 1e-3, (frame_count, len(target_indices), 3))
    write_trc(paths.targets, TrcData(target_keypoints, times, targets, "m", frame_rate, frame_numbers))
    np.save(paths.truth_q, q)

    folders = [paths.masks / camera.name for camera in cameras]
    for camera_folder in folders:
        camera_folder.mkdir(parents=True, exist_ok=True)
    lose_limbs = defects is not None and defects.missing_limb_probability > 0.0
    for frame, q_frame in enumerate(q):
        masks = render_silhouettes(body, q_frame, cameras)
        for camera, camera_folder, mask in zip(cameras, folders, masks):
            if defects is not None:
                limbs = render_limb_masks(body, q_frame, camera) if lose_limbs else None
                mask = apply_defects(mask, defects, defect_rng, limbs)
            path = camera_folder / f"{frame:06d}.png"
            if not cv2.imwrite(str(path), mask.astype(np.uint8) * 255):
                raise InputError(f"{path}: OpenCV cannot write this mask")

    metadata = {
        "frames": frame_count,
        "frame_rate": frame_rate,
        "cameras": [camera.name for camera in cameras],
        "target_keypoints": target_keypoints,
        "truth_keypoints": keypoints,
        "noise_mm": noise_mm,
        "defects": None if defects is None else asdict(defects),
        "seed": seed,
        "model": model.name,
        "nq": model.nq,
    }
    paths.metadata.write_text(json.dumps(metadata, indent=2) + "\n")
    return paths


def _replace_rotation(camera: PinholeCamera, rotation: np.ndarray) -> PinholeCamera:
    if not isinstance(camera, PinholeCamera):
        raise InputError(
            f"cameras: expected PinholeCamera (a calibration TOML holds no other kind), got {type(camera).__name__}"
        )
    return PinholeCamera(camera.name, camera.size, camera.intrinsics, camera.distortion, rotation, camera.translation)
