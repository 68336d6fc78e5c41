"""Each camera's disagreement with the others' detections, and the turn of a camera that slipped
(vision.extrinsics_refit), on projections of Pose2Sim's own triangulation of its demo into the
demo's four calibrated cameras (1/4 size), with seeded pixel noise: the "detections" come from the
true cameras, the calibration given is wrong for one of them."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from ibik_pin.exceptions import InputError
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.trc import read_trc
from ibik_pin.vision.camera import cameras_in_frame
from ibik_pin.vision.extrinsics_refit import in_calibration_world, refit_extrinsics
from ibik_pin.vision.pinhole import PinholeCamera
from ibik_pin.vision.triangulation import _swap_sides, labelled_landmarks
from tests.paths import TEST_DATA

CALIBRATION = TEST_DATA / "pose2sim_video" / "calibration.toml"
REFERENCE = TEST_DATA / "pose2sim_balancing_excerpt.trc"
NOISE_PX = 0.5  # the 1/4-size detector's noise is a few pixels; small here so the tolerances are tight


@pytest.fixture(scope="module")
def cameras():
    return cameras_in_frame(read_calibration(CALIBRATION), POSE2SIM_TRC_TO_WORLD)


@pytest.fixture(scope="module")
def detections(cameras):
    """(V, F, K, 2) noisy projections of the reference's keypoints into the true cameras, and (V, F, K) weights."""
    points = read_trc(REFERENCE).positions
    rng = np.random.default_rng(7)
    pixels = np.array([[camera.project(frame) for frame in points] for camera in cameras])
    return pixels + rng.normal(0.0, NOISE_PX, pixels.shape), np.ones(pixels.shape[:3])


def turned(camera: PinholeCamera, turn_deg: float) -> PinholeCamera:
    """The camera turned about its centre, about a fixed oblique axis (a bumped camera)."""
    axis = np.array([0.3, -0.8, 0.5]) / np.linalg.norm([0.3, -0.8, 0.5])
    rotation = cv2.Rodrigues(np.radians(turn_deg) * axis)[0] @ camera.rotation
    return PinholeCamera(camera.name, camera.size, camera.intrinsics, camera.distortion, rotation,
                         -rotation @ camera.center_world)


def test_a_slipped_camera_stands_out_and_is_turned_back(cameras, detections):
    pixels, weights = detections
    given = list(cameras)
    given[2] = turned(cameras[2], turn_deg=1.5)
    refitted, found = refit_extrinsics(given, pixels, weights, refit=[cameras[2].name])
    assert found.refitted == [cameras[2].name]
    # The slip is seen before the turn, in its camera most; after it every camera is at the noise.
    errors = found.reprojection_px
    assert errors[cameras[2].name] > 5.0 and errors[cameras[2].name] == max(errors.values())
    assert max(found.reprojection_after_px.values()) < 2.0 * NOISE_PX
    # The true pose comes back (the others hold the world frame); the other cameras are untouched.
    turn = np.degrees(np.linalg.norm(cv2.Rodrigues(refitted[2].rotation @ cameras[2].rotation.T)[0]))
    assert turn < 0.02
    np.testing.assert_allclose(refitted[2].center_world, cameras[2].center_world, atol=1e-9)
    assert all(refitted[v] is given[v] for v in (0, 1, 3))
    assert found.turn_deg[cameras[2].name] == pytest.approx(1.5, abs=0.1)


def test_without_names_the_cameras_are_measured_not_moved(cameras, detections):
    given = list(cameras)
    given[2] = turned(cameras[2], turn_deg=1.5)
    refitted, found = refit_extrinsics(given, *detections)
    assert found.refitted == [] and found.reprojection_after_px == found.reprojection_px
    assert all(new is old for new, old in zip(refitted, given, strict=True))
    _, calibrated = refit_extrinsics(cameras, *detections)
    assert max(calibrated.reprojection_px.values()) < 2.0 * NOISE_PX


@pytest.mark.parametrize("view", range(4))
def test_turning_a_good_camera_changes_little(cameras, detections, view):
    """Within what the pixel noise allows: 0.5 px at the 1/4-size focal length of 420 px is 0.07 deg."""
    _, found = refit_extrinsics(cameras, *detections, refit=[cameras[view].name])
    assert found.turn_deg[cameras[view].name] < 0.07


@pytest.mark.parametrize(("views", "refit", "pattern"), [
    ([0, 1], [], "from three cameras"),
    ([0, 1, 2], ["cam_09"], "cam_09 not among the cameras cam_01, cam_02, cam_03"),
])
def test_what_cannot_be_checked_is_refused(cameras, detections, views, refit, pattern):
    pixels, weights = detections
    with pytest.raises(InputError, match=pattern):
        refit_extrinsics([cameras[v] for v in views], pixels[views], weights[views], refit=refit)


def test_a_camera_far_from_its_calibration_is_refused(cameras, detections):
    given = list(cameras)
    given[1] = turned(cameras[1], turn_deg=12.0)
    with pytest.raises(InputError, match=f"refit {cameras[1].name}: .* turn it 12.0 deg .* calibrate again") as raised:
        refit_extrinsics(given, *detections, refit=[cameras[1].name])
    assert raised.value.parameter == "refit"


def test_unused_detections_do_not_count(cameras, detections):
    """Zero weights (a detector's low confidence) keep a wild detection out of the fit."""
    pixels, weights = detections
    pixels, weights = pixels.copy(), weights.copy()
    given = list(cameras)
    given[2] = turned(cameras[2], 1.5)
    pixels[2, :, :3] += 200.0
    weights[2, :, :3] = 0.0
    refitted, found = refit_extrinsics(given, pixels, weights, refit=[cameras[2].name])
    assert found.refitted == [cameras[2].name]
    assert np.degrees(np.linalg.norm(cv2.Rodrigues(refitted[2].rotation @ cameras[2].rotation.T)[0])) < 0.02


def test_refitted_cameras_go_back_to_the_calibration_world(cameras):
    back = in_calibration_world(cameras, POSE2SIM_TRC_TO_WORLD)
    for original, camera in zip(read_calibration(CALIBRATION), back, strict=True):
        np.testing.assert_allclose(camera.rotation, original.rotation, atol=1e-12)


def test_labelled_landmarks_swap_the_flagged_views_only():
    rng = np.random.default_rng(3)
    landmarks = rng.normal(size=(3, 4, 33, 2))
    swapped = np.zeros((4, 3), bool)
    swapped[1, 2] = swapped[3, 0] = True
    labelled = labelled_landmarks(landmarks, swapped)
    np.testing.assert_array_equal(labelled[2, 1], _swap_sides(landmarks[2, 1]))
    np.testing.assert_array_equal(labelled[0, 3], _swap_sides(landmarks[0, 3]))
    untouched = np.ones((3, 4), bool)
    untouched[2, 1] = untouched[0, 3] = False
    np.testing.assert_array_equal(labelled[untouched], landmarks[untouched])
