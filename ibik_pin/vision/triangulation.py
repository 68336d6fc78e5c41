"""3D keypoints from 2D detections in several calibrated views.

Three steps, each a physical argument rather than a tuned constant:

1. **Left and right across views.** A 2D detector names the person's left and right from one
   image, and in a frontal view it may swap them for a frame. In each frame, the labelling of every
   view but the first is swapped or not so that the left and right keypoints triangulate with the
   smallest reprojection error (2^(V-1) labellings, V <= 8 views); then the whole frame's labelling
   is checked against the face: the person's left is on the side of forward x down, forward from
   the ears to the nose, down from the ears to the shoulders (midpoints, which a swap leaves alone).
2. **Robust triangulation.** Weighted linear triangulation (DLT) on undistorted rays; a view whose
   reprojection lies farther than `outlier_m` from the point, measured at the point's depth (a
   metric distance: a hand's width, whatever the camera's resolution), is dropped and the point
   triangulated again, as long as two views remain; a point whose last two views still miss it
   by more is left out (NaN): one of them is wrong, and nothing says which.
3. **Pose2Sim's names.** BlazePose's landmarks map to the keypoints Pose2Sim writes (HALPE_26
   names); its Neck is the shoulders' midpoint and its Head (the top of the head) is placed from
   the ears, the nose and the shoulders (:func:`head_top`).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.vision.learned_pose import LANDMARKS
from ibik_pin.vision.pinhole import PinholeCamera

__all__ = ["POSE2SIM_FROM_LANDMARKS", "Triangulation", "head_top", "labelled_landmarks", "triangulate",
           "triangulate_landmarks"]

# Pose2Sim (HALPE_26) keypoint -> the BlazePose landmark it is read from.
POSE2SIM_FROM_LANDMARKS = {
    "RHip": "right_hip", "RKnee": "right_knee", "RAnkle": "right_ankle", "RBigToe": "right_foot_index",
    "RHeel": "right_heel", "LHip": "left_hip", "LKnee": "left_knee", "LAnkle": "left_ankle",
    "LBigToe": "left_foot_index", "LHeel": "left_heel", "Nose": "nose", "RShoulder": "right_shoulder",
    "RElbow": "right_elbow", "RWrist": "right_wrist", "LShoulder": "left_shoulder", "LElbow": "left_elbow",
    "LWrist": "left_wrist",
}
# The order of the written TRC: Pose2Sim's own, less the small toes BlazePose does not detect.
POSE2SIM_ORDER = ("RHip", "RKnee", "RAnkle", "RBigToe", "RHeel", "LHip", "LKnee", "LAnkle", "LBigToe", "LHeel",
                  "Neck", "Head", "Nose", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist")
# Ear to the top of the head along the head's vertical [m]: about 0.13 m in adults (tragion to
# vertex, anthropometric surveys such as ANSUR II's "tragion-top of head").
EAR_TO_VERTEX_M = 0.13
_LEFT = [i for i, name in enumerate(LANDMARKS) if name.startswith("left")]
_RIGHT = [LANDMARKS.index("right" + LANDMARKS[i][4:]) for i in _LEFT]


def _swap_sides(landmarks: np.ndarray) -> np.ndarray:
    """The landmarks (..., 33, k) with every left/right pair exchanged."""
    swapped = landmarks.copy()
    swapped[..., _LEFT, :], swapped[..., _RIGHT, :] = landmarks[..., _RIGHT, :], landmarks[..., _LEFT, :]
    return swapped


def labelled_landmarks(landmarks: np.ndarray, swapped: np.ndarray) -> np.ndarray:
    """Landmarks (V, F, 33, k) with each view's left and right exchanged where `swapped` (F, V)
    says (triangulate_landmarks' "views_swapped"): every view then names the same side alike."""
    labelled = np.array(landmarks, dtype=np.float64, copy=True)
    views, frames = np.nonzero(np.asarray(swapped).T)
    labelled[views, frames] = _swap_sides(labelled[views, frames])
    return labelled


def _projection_rows(cameras: Sequence[PinholeCamera], pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undistorted normalised coordinates (V, N, 2) of pixels (V, N, 2), and the cameras' [R | t] (V, 3, 4)."""
    normalised = np.full(pixels.shape, np.nan)
    for view, camera in enumerate(cameras):
        finite = np.isfinite(pixels[view]).all(axis=1)
        if finite.any():
            normalised[view, finite] = cv2.undistortPoints(
                pixels[view, finite].reshape(-1, 1, 2).astype(np.float64), camera.intrinsics,
                camera.distortion).reshape(-1, 2)
    extrinsics = np.array([np.hstack((camera.rotation, camera.translation[:, None])) for camera in cameras])
    return normalised, extrinsics


def _dlt(normalised: np.ndarray, extrinsics: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Points (N, 3) from normalised coordinates (V, N, 2) weighted (V, N); NaN with fewer than two views."""
    usable = np.isfinite(normalised).all(axis=2) & (weights > 0)
    w = np.where(usable, weights, 0.0)
    coordinates = np.nan_to_num(normalised)
    # Each view gives x P3 - P1 = 0 and y P3 - P2 = 0 (P = [R | t]); rows (N, 2V, 4).
    rows_x = coordinates[..., 0, None] * extrinsics[:, None, 2] - extrinsics[:, None, 0]
    rows_y = coordinates[..., 1, None] * extrinsics[:, None, 2] - extrinsics[:, None, 1]
    system = np.concatenate((rows_x * w[..., None], rows_y * w[..., None]), axis=0).transpose(1, 0, 2)
    _, _, vt = np.linalg.svd(system)
    homogeneous = vt[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):  # a point no view sees: NaN just below
        points = homogeneous[:, :3] / homogeneous[:, 3:4]
    points[usable.sum(axis=0) < 2] = np.nan
    return points


def _reprojection_m(cameras: Sequence[PinholeCamera], points: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """(V, N) distance between each view's pixel and the point's projection, at the point's depth [m]."""
    errors = np.full(pixels.shape[:2], np.nan)
    finite = np.isfinite(points).all(axis=1)
    for view, camera in enumerate(cameras):
        if not finite.any():
            break
        projected = camera.project(points[finite])
        depth = camera.points_camera(points[finite])[:, 2]
        errors[view, finite] = np.linalg.norm(projected - pixels[view, finite], axis=1) * depth / camera.focal_px
    return errors


@dataclass
class Triangulation:
    """Points triangulated from V views.

    Attributes:
        points: (N, 3) [m], NaN where fewer than two views agree.
        views_used: (V, N) bool, the views each point was triangulated from.
        reprojection_m: (V, N) each view's reprojection error at the point's depth [m] (NaN
            where the point or the pixel is missing), dropped views included.
    """

    points: np.ndarray
    views_used: np.ndarray
    reprojection_m: np.ndarray


def triangulate(cameras: Sequence[PinholeCamera], pixels: np.ndarray, weights: np.ndarray | None = None,
                outlier_m: float = 0.10) -> Triangulation:
    """Points seen in several calibrated views, robust to one wrong view per point.

    Args:
        cameras: V calibrated cameras (their world is the points' frame).
        pixels: (V, N, 2) [px]; NaN where a view has no detection.
        weights: (V, N) confidence of each detection (0 drops it); None: all 1.
        outlier_m: a view that misses the point by more than this at the point's depth [m] is
            dropped (worst first) while more than two views remain.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim != 3 or pixels.shape[0] != len(cameras) or pixels.shape[2] != 2:
        raise InputError(f"pixels: expected ({len(cameras)}, N, 2), found {pixels.shape}")
    weights = np.ones(pixels.shape[:2]) if weights is None else np.asarray(weights, dtype=np.float64)
    normalised, extrinsics = _projection_rows(cameras, pixels)
    used = np.isfinite(normalised).all(axis=2) & (weights > 0)
    while True:
        points = _dlt(normalised, extrinsics, np.where(used, weights, 0.0))
        errors = _reprojection_m(cameras, points, pixels)
        masked = np.where(used, np.nan_to_num(errors, nan=np.inf), -np.inf)
        worst = np.argmax(masked, axis=0)
        worst_error = masked[worst, np.arange(pixels.shape[1])]
        drop = (worst_error > outlier_m) & (used.sum(axis=0) > 2)
        if not drop.any():
            return Triangulation(points, used, errors)
        used[worst[drop], np.flatnonzero(drop)] = False


def _labelling_errors(cameras: Sequence[PinholeCamera], landmarks: np.ndarray, weights: np.ndarray,
                      labellings: Sequence[tuple[bool, ...]], cap_m: float) -> np.ndarray:
    """(F, L) per frame and labelling (per view, whether its left and right are exchanged) the sum
    over the left and right landmarks of their capped reprojection errors [m], from landmarks
    (V, F, 33, 2) weighted (V, F, 33). Every frame and labelling in one triangulation (the DLT and
    the reprojection are per point, the rays undistorted once per view and side): each sum is the
    one a triangulation of that frame alone gives, to the bit."""
    views, frames = landmarks.shape[:2]
    sides = _LEFT + _RIGHT
    both = np.stack([landmarks[:, :, sides], _swap_sides(landmarks)[:, :, sides]], axis=1)  # (V, 2, F, S, 2)
    both_weights = np.stack([weights[:, :, sides], _swap_sides(weights[..., None])[:, :, sides, 0]], axis=1)
    normalised, extrinsics = _projection_rows(cameras, both.reshape(views, -1, 2))
    normalised = normalised.reshape(both.shape)
    chosen = np.array(labellings, dtype=np.int64).T  # (V, L): 1 where the view's sides are exchanged
    picked = np.arange(views)[:, None]
    count = len(labellings) * frames * len(sides)
    rays = normalised[picked, chosen].reshape(views, count, 2)
    pixels = both[picked, chosen].reshape(views, count, 2)
    rows_weights = both_weights[picked, chosen].reshape(views, count)
    points = _dlt(rays, extrinsics, rows_weights)
    errors = _reprojection_m(cameras, points, pixels).reshape(views, len(labellings), frames, len(sides))
    missing = np.isnan(points[:, 0]).reshape(len(labellings), frames, len(sides)).sum(axis=2)
    totals = np.empty((frames, len(labellings)))
    for labelling in range(len(labellings)):
        for frame in range(frames):  # each (V, S) summed as one frame's own array would be
            view_errors = np.ascontiguousarray(errors[:, labelling, frame])
            totals[frame, labelling] = float(np.nansum(np.minimum(view_errors, cap_m))
                                             + cap_m * missing[labelling, frame])
    return totals


def _face_says_swapped(points: np.ndarray) -> bool:
    """Whether 3D landmarks (33, 3) have the person's left and right exchanged, judged from the face."""
    index = LANDMARKS.index
    ears = 0.5 * (points[index("left_ear")] + points[index("right_ear")])
    shoulders = 0.5 * (points[index("left_shoulder")] + points[index("right_shoulder")])
    left = np.cross(points[index("nose")] - ears, shoulders - ears)  # forward x down
    sides = sum(points[index(f"left_{part}")] - points[index(f"right_{part}")] for part in ("ear", "shoulder", "hip"))
    return bool(np.dot(left, sides) < 0.0)


def head_top(ears_left: np.ndarray, ears_right: np.ndarray, nose: np.ndarray, shoulders_mid: np.ndarray) -> np.ndarray:
    """The top of the head (N, 3): EAR_TO_VERTEX_M above the ears' midpoint along the head's vertical.

    The vertical is orthogonal to the ear-to-ear axis and to the face's forward direction (ears to
    nose), turned away from the shoulders."""
    ears = 0.5 * (ears_left + ears_right)
    lateral = ears_left - ears_right
    forward = nose - ears
    up = np.cross(lateral, forward)
    up /= np.linalg.norm(up, axis=-1, keepdims=True)
    up *= np.sign(np.sum(up * (ears - shoulders_mid), axis=-1, keepdims=True))
    return ears + EAR_TO_VERTEX_M * up


def triangulate_landmarks(cameras: Sequence[PinholeCamera], landmarks: np.ndarray, visibility: np.ndarray,
                          *, min_visibility: float = 0.3, outlier_m: float = 0.10,
                          side_error_cap_m: float = 0.5) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Pose2Sim keypoints over frames from BlazePose landmarks in V synchronised views.

    Args:
        cameras: V calibrated cameras; their world is the frame of the returned points.
        landmarks: (V, F, 33, 2) pixels of LANDMARKS (NaN where a view found no person).
        visibility: (V, F, 33) detector confidence; below `min_visibility` a landmark is not used.
        outlier_m: see triangulate.
        side_error_cap_m: one landmark's reprojection error counts at most this much when choosing
            each view's left and right.

    Returns:
        (keypoints, quality): keypoint name -> (F, 3) [m] (NaN where not triangulated), in
        POSE2SIM_ORDER; and per frame "views_swapped" (F, V) bool, "views_used" (F, V) mean share
        of the landmarks each view contributed, "reprojection_m" (F,) median reprojection error.
    """
    landmarks = np.asarray(landmarks, dtype=np.float64)
    visibility = np.asarray(visibility, dtype=np.float64)
    views, frames = landmarks.shape[:2]
    if landmarks.shape[2:] != (len(LANDMARKS), 2) or visibility.shape != landmarks.shape[:3] or views != len(cameras):
        raise InputError(f"landmarks: expected ({len(cameras)}, F, {len(LANDMARKS)}, 2) with visibility "
                         f"(V, F, {len(LANDMARKS)}), found {landmarks.shape} and {visibility.shape}")
    weights = np.where(visibility >= min_visibility, visibility, 0.0)
    points = np.full((frames, len(LANDMARKS), 3), np.nan)
    swapped = np.zeros((frames, views), bool)
    used_share = np.zeros((frames, views))
    median_error = np.full(frames, np.nan)
    labellings = [(False, *flips) for flips in itertools.product((False, True), repeat=views - 1)]
    best_labelling = np.argmin(_labelling_errors(cameras, landmarks, weights, labellings, side_error_cap_m), axis=1)
    chosen = np.array(labellings)[best_labelling]  # (F, V)
    labelled_all = labelled_landmarks(landmarks, chosen)
    weighted_all = labelled_landmarks(weights[..., None], chosen)[..., 0]
    for frame in range(frames):
        flags = labellings[best_labelling[frame]]
        result = triangulate(cameras, labelled_all[:, frame], weighted_all[:, frame], outlier_m)
        frame_points = result.points
        # Two views left that still miss each other: no point rather than a wrong one (a limb the
        # detector guessed in one view, another person's in the other).
        kept_errors = np.where(result.views_used, result.reprojection_m, 0.0)
        frame_points[np.nan_to_num(kept_errors, nan=0.0).max(axis=0) > outlier_m] = np.nan
        flags_array = np.array(flags)
        if np.isfinite(frame_points).all(axis=1).sum() >= 7 and _face_says_swapped(frame_points):
            frame_points = _swap_sides(frame_points)
            flags_array = ~flags_array
        points[frame], swapped[frame] = frame_points, flags_array
        used_share[frame] = result.views_used.mean(axis=1)
        kept = np.where(result.views_used, result.reprojection_m, np.nan)
        median_error[frame] = np.nanmedian(kept) if np.isfinite(kept).any() else np.nan
    index = LANDMARKS.index
    keypoints = {name: points[:, index(landmark)] for name, landmark in POSE2SIM_FROM_LANDMARKS.items()}
    keypoints["Neck"] = 0.5 * (keypoints["LShoulder"] + keypoints["RShoulder"])
    keypoints["Head"] = head_top(points[:, index("left_ear")], points[:, index("right_ear")], keypoints["Nose"],
                                 keypoints["Neck"])
    quality = {"views_swapped": swapped, "views_used": used_share, "reprojection_m": median_error}
    return {name: keypoints[name] for name in POSE2SIM_ORDER}, quality
