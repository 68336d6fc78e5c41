"""Tests of ibik_pin.app.axes: the TRC's axis convention told from the cameras."""

from __future__ import annotations

import numpy as np
import pytest

from ibik_pin.app.axes import (
    TRC_TO_MODEL,
    AxesChoice,
    choose_axes,
    sample_frames,
    score_axes,
)
from ibik_pin.exceptions import IbikWarning, InputError
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD
from ibik_pin.synthetic.rig import humaneva_rig

NAMES = ["Head", "Hip", "LAnkle", "RAnkle"]


def standing_targets(frame_count: int = 4) -> np.ndarray:
    """(F, 4, 3) a standing body in the model's frame (Y up) [m], walking along X."""
    body = np.array([[0.0, 1.7, 0.0], [0.0, 1.0, 0.0], [0.0, 0.1, -0.1], [0.0, 0.1, 0.1]])
    return np.stack([body + [0.1 * frame, 0.0, 0.0] for frame in range(frame_count)])


def disc_masks(cameras, points_model: np.ndarray, radius_px: int = 12) -> list[np.ndarray]:
    """One mask per camera: discs around the projected points, as a silhouette would cover them."""
    masks = []
    for camera in cameras:
        mask = np.zeros((camera.height, camera.width), bool)
        rows, columns = np.mgrid[: camera.height, : camera.width]
        for u, v in camera.project(points_model):
            mask |= (columns - u) ** 2 + (rows - v) ** 2 <= radius_px**2
        masks.append(mask)
    return masks


@pytest.fixture
def cameras():
    return humaneva_rig(3, np.array([0.15, 1.0, 0.0]), seed=4)


def test_the_two_conventions_permute_the_axes_so_that_z_up_becomes_y_up():
    up_in_z_up_trc = np.array([0.0, 0.0, 1.0])
    assert np.allclose(TRC_TO_MODEL["z-up"] @ up_in_z_up_trc, [0.0, 1.0, 0.0], atol=0.0)
    choice = AxesChoice("z-up", "forced")
    points = np.random.default_rng(0).normal(size=(5, 3))
    assert np.array_equal(choice.to_trc(choice.to_model(points)), points)
    assert np.array_equal(choice.to_model(points @ POSE2SIM_TRC_TO_WORLD.T), points)


def test_sampled_frames_spread_over_the_frames_that_hold_a_target():
    targets = np.zeros((40, 2, 3))
    targets[:5] = np.nan
    frames = sample_frames(targets, count=10)
    assert len(frames) == 10 and frames[0] == 5 and frames[-1] == 39
    assert sample_frames(np.full((3, 2, 3), np.nan)) == []


def test_silhouettes_decide_between_conventions_that_both_fit_the_images(cameras):
    targets = standing_targets()
    z_up = targets @ POSE2SIM_TRC_TO_WORLD.T
    scores = score_axes(NAMES, z_up, cameras, [0, 3], lambda f: disc_masks(cameras, targets[f]))
    by_axes = {score.axes: score for score in scores}
    assert by_axes["y-up"].inside_images > 0.8  # the wrong convention alone would pass the images
    assert by_axes["z-up"].inside_silhouettes == pytest.approx(1.0)
    assert by_axes["y-up"].inside_silhouettes < 0.3
    choice = choose_axes("auto", NAMES, z_up, cameras, lambda f: disc_masks(cameras, targets[f]))
    assert (choice.axes, choice.how, choice.decided_by) == ("z-up", "detected", "silhouettes")


def test_the_upright_body_decides_when_the_images_cannot(cameras):
    targets = standing_targets()
    choice = choose_axes("auto", NAMES, targets, cameras)
    scores = {score.axes: score for score in choice.scores}
    assert abs(scores["y-up"].inside_images - scores["z-up"].inside_images) < 0.1
    assert (choice.axes, choice.decided_by) == ("y-up", "upright body")
    assert scores["y-up"].upright == pytest.approx(1.0, abs=0.02) and abs(scores["z-up"].upright) < 0.1


def test_nothing_to_tell_the_conventions_apart_is_refused():
    # Cameras 30 m away see the targets in both readings, and hips alone give no up direction.
    cameras = humaneva_rig(2, np.array([0.0, 1.0, 0.0]), distance_m=30.0, seed=0)
    targets = np.array([[[0.0, 1.0, 0.0], [0.0, 1.0, 0.2]]])
    with pytest.raises(InputError, match="neither the cameras nor the body's posture tell"):
        choose_axes("auto", ["LHip", "RHip"], targets, cameras)


def test_targets_outside_every_image_are_refused(cameras):
    with pytest.raises(InputError, match="no axis convention puts the targets inside the cameras' images"):
        choose_axes("auto", NAMES, standing_targets() + 100.0, cameras)


def test_a_forced_convention_is_kept_and_warned_about_when_it_misses_the_images(cameras):
    with pytest.warns(IbikWarning, match="--trc-axes z-up keeps the targets out"):
        choice = choose_axes("z-up", NAMES, standing_targets() + 100.0, cameras)
    assert (choice.axes, choice.how) == ("z-up", "forced")


def test_without_cameras_y_up_is_the_default_and_a_z_up_body_is_warned_about():
    choice = choose_axes("auto", NAMES, standing_targets(), [])
    assert (choice.axes, choice.how) == ("y-up", "default")
    with pytest.warns(IbikWarning, match="stands upright only if they are z-up"):
        choice = choose_axes("auto", NAMES, standing_targets() @ POSE2SIM_TRC_TO_WORLD.T, [])
    assert choice.axes == "y-up"


def test_an_unknown_convention_is_refused():
    with pytest.raises(InputError, match="--trc-axes: expected one of auto, y-up, z-up, got 'x-up'"):
        choose_axes("x-up", NAMES, standing_targets(), [])
