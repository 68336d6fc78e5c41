"""Check each camera's pose against the other views' detections, and turn a camera that slipped.

A calibration can be wrong for one camera: bumped after the calibration, a lens re-seated, a video
cropped. Its projections then miss the person by a steady offset and the image term pulls the
skeleton toward where that camera says the body is not. The other views tell: the landmarks they
triangulate, projected into that camera, should land on its own detections. For each camera this
module measures the median distance (leave-one-out reprojection error, report.json's
"extrinsics"); a camera named by the user is then turned about its centre to meet its detections
(trimmed of the worst matches; intrinsics and centre kept: a bumped camera turns, and the small
volume one person fills cannot tell a few centimetres of shift from a small turn, so a full pose
fit is ill-conditioned there). The other views fix the world frame, so the targets keep their
coordinates.

Which camera is wrong is left to the user: a detector's landmarks depend on the view (BlazePose's
hips most), and a wrong camera also raises the others' errors. On the Pose2Sim demo, turning
cam_01 or cam_03 brings the four errors to means within 5 % of each other (15.8 and 15.0 px); Pose2Sim's own
triangulation, from another detector, names cam_03 (docs/method.md, "From video").
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.vision.pinhole import PinholeCamera
from ibik_pin.vision.triangulation import triangulate

__all__ = ["ExtrinsicsRefit", "in_calibration_world", "refit_extrinsics"]

# A re-fit turning the camera more than this is not a slip of the calibration but a wrong one [deg].
MAX_TURN_DEG = 5.0
# Fewer detections seen by the other views than this and a camera's turn is not fitted.
MIN_MATCHES = 50
# Detections kept in the fit: within this multiple of the median residual (drops a wrong side or person).
TRIM_FACTOR = 3.0
FIT_ROUNDS = 3


@dataclass
class ExtrinsicsRefit:
    """The cameras' agreement with each other, and the re-fitted ones (report.json's "extrinsics").

    Attributes:
        refitted: names of the re-fitted cameras.
        reprojection_px: per camera, median distance between its detections and the landmarks the
            other views triangulate, projected [px], with the cameras as calibrated.
        reprojection_after_px: the same with the re-fitted cameras.
        turn_deg: per re-fitted camera, how far it turned.
        diagnosis: per camera, "agrees" or why it disagrees: another person, a detector that
            switched people, or the camera itself (vision.camera_diagnosis); empty when not judged.
    """

    refitted: list[str] = field(default_factory=list)
    reprojection_px: dict[str, float] = field(default_factory=dict)
    reprojection_after_px: dict[str, float] = field(default_factory=dict)
    turn_deg: dict[str, float] = field(default_factory=dict)
    diagnosis: dict[str, str] = field(default_factory=dict)


def _matches(cameras: Sequence[PinholeCamera], landmarks: np.ndarray, weights: np.ndarray,
             view: int) -> tuple[np.ndarray, np.ndarray]:
    """Points triangulated without `view` (N, 3) and that view's detections of them (N, 2)."""
    others = [v for v in range(len(cameras)) if v != view]
    flat_pixels = landmarks[others].reshape(len(others), -1, 2)
    flat_weights = weights[others].reshape(len(others), -1)
    points = triangulate([cameras[v] for v in others], flat_pixels, flat_weights).points
    pixels = landmarks[view].reshape(-1, 2)
    usable = np.isfinite(points).all(axis=1) & np.isfinite(pixels).all(axis=1) & (weights[view].reshape(-1) > 0)
    return points[usable], pixels[usable]


def _all_matches(cameras: Sequence[PinholeCamera], landmarks: np.ndarray,
                 weights: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    return [_matches(cameras, landmarks, weights, view) for view in range(len(cameras))]


def _errors(cameras: Sequence[PinholeCamera], matches: Sequence[tuple[np.ndarray, np.ndarray]]) -> dict[str, float]:
    """Per camera, the median distance between its detections and the others' points, projected [px]."""
    return {camera.name: _median_px(camera, *match) for camera, match in zip(cameras, matches, strict=True)}


def _median_px(camera: PinholeCamera, points: np.ndarray, pixels: np.ndarray) -> float:
    return float(np.median(np.linalg.norm(camera.project(points) - pixels, axis=1))) if len(points) else np.nan


def _fit_rotation(camera: PinholeCamera, points: np.ndarray, pixels: np.ndarray) -> PinholeCamera:
    """The camera turned about its centre so that the rays to the points meet its detections: the
    rotation taking the unit directions centre -> point onto the detections' undistorted rays in
    the least-squares sense (Kabsch), trimmed of the worst matches."""
    normalised = cv2.undistortPoints(pixels.reshape(-1, 1, 2), camera.intrinsics, camera.distortion).reshape(-1, 2)
    rays = np.column_stack((normalised, np.ones(len(normalised))))
    rays = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    directions = points - camera.center_world
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    fitted = camera
    residual = np.linalg.norm(camera.project(points) - pixels, axis=1)
    for _ in range(FIT_ROUNDS):
        kept = residual <= TRIM_FACTOR * np.median(residual)
        u, _, vt = np.linalg.svd(rays[kept].T @ directions[kept])
        rotation = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
        fitted = PinholeCamera(camera.name, camera.size, camera.intrinsics, camera.distortion, rotation,
                               -rotation @ camera.center_world)
        residual = np.linalg.norm(fitted.project(points) - pixels, axis=1)
    return fitted


def refit_extrinsics(cameras: Sequence[PinholeCamera], landmarks: np.ndarray, weights: np.ndarray,
                     refit: Sequence[str] = ()) -> tuple[list[PinholeCamera], ExtrinsicsRefit]:
    """Measure how far each camera's detections lie from the landmarks the other views triangulate,
    and turn the cameras named in `refit` to meet them (see the module's docstring); returns the
    cameras (re-fitted ones replaced) and the figures.

    Args:
        cameras: V >= 3 calibrated cameras.
        landmarks: (V, F, L, 2) detections [px] with the person's left and right already agreed
            across views (triangulation.labelled_landmarks); NaN where missing.
        weights: (V, F, L) confidence, 0 where a detection is not to be used.
        refit: names of the cameras to turn, each against all the others, in this order.

    Raises:
        InputError: fewer than three cameras, a name in `refit` is not a camera, a camera to turn
            has fewer than MIN_MATCHES detections the others see, or its fit turns it more than
            MAX_TURN_DEG (a wrong calibration, not a slip).
    """
    cameras = list(cameras)
    names = [camera.name for camera in cameras]
    if len(cameras) < 3:
        raise InputError(f"the cameras' extrinsics are checked against each other from three cameras, found {names}")
    unknown = [name for name in refit if name not in names]
    if unknown:
        raise InputError(f"refit: {', '.join(unknown)} not among the cameras {', '.join(names)}", parameter="refit")
    matches = _all_matches(cameras, landmarks, weights)
    result = ExtrinsicsRefit(reprojection_px=_errors(cameras, matches))
    for name in refit:
        view = names.index(name)
        if len(matches[view][0]) < MIN_MATCHES:
            raise InputError(f"refit {name}: {len(matches[view][0])} detections seen by the other views as well, "
                             f"{MIN_MATCHES} needed", parameter="refit")
        fitted = _fit_rotation(cameras[view], *matches[view])
        turn = float(np.degrees(np.linalg.norm(cv2.Rodrigues(fitted.rotation @ cameras[view].rotation.T)[0])))
        if turn > MAX_TURN_DEG:
            raise InputError(f"refit {name}: its detections turn it {turn:.1f} deg from its calibration, more than a "
                             f"slip ({MAX_TURN_DEG:g} deg): the calibration is wrong, calibrate again",
                             parameter="refit")
        cameras[view] = fitted
        result.refitted.append(name)
        result.turn_deg[name] = turn
        # The turned camera now triangulates with the others: their matches change.
        matches = _all_matches(cameras, landmarks, weights)
    result.reprojection_after_px = _errors(cameras, matches)
    return cameras, result


def in_calibration_world(cameras: Sequence[PinholeCamera], frame_to_world: np.ndarray) -> list[PinholeCamera]:
    """Cameras made by vision.camera.cameras_in_frame(…, frame_to_world), back in the calibration's world."""
    return [dataclasses.replace(camera, rotation=camera.rotation @ np.asarray(frame_to_world).T) for camera in cameras]
