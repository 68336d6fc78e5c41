"""Triangulation of 2D keypoints (vision.triangulation) and the subject's part of a mask
(app.video_inputs.keep_subject), on exact projections of Pose2Sim's own triangulation of its
demo into the demo's four calibrated cameras (no detector involved: these run everywhere)."""

from __future__ import annotations

import numpy as np
import pytest

from ibik_pin.app.video_inputs import keep_subject
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.trc import read_trc
from ibik_pin.vision.camera import cameras_in_frame
from ibik_pin.vision.learned_pose import LANDMARKS
from ibik_pin.vision.triangulation import (
    EAR_TO_VERTEX_M,
    POSE2SIM_FROM_LANDMARKS,
    head_top,
    triangulate,
    triangulate_landmarks,
)
from tests.paths import TEST_DATA

CALIBRATION = TEST_DATA / "pose2sim_video" / "calibration.toml"
REFERENCE = TEST_DATA / "pose2sim_balancing_excerpt.trc"


@pytest.fixture(scope="module")
def cameras():
    return cameras_in_frame(read_calibration(CALIBRATION), POSE2SIM_TRC_TO_WORLD)


@pytest.fixture(scope="module")
def body():
    """(F, 33, 3) landmarks of Pose2Sim's keypoints, with ears placed on the real head (8 cm behind
    the nose, 7.5 cm to each side), the rest NaN; and the reference."""
    reference = read_trc(REFERENCE)
    frames = 10
    points = np.full((frames, len(LANDMARKS), 3), np.nan)
    for name, landmark in POSE2SIM_FROM_LANDMARKS.items():
        points[:, LANDMARKS.index(landmark)] = reference.positions[:frames, reference.marker_names.index(name)]

    def at(name):
        return reference.positions[:frames, reference.marker_names.index(name)]

    left = at("LShoulder") - at("RShoulder")
    left /= np.linalg.norm(left, axis=1, keepdims=True)
    up = np.array([0.0, 1.0, 0.0])  # the TRC is Y up
    forward = np.cross(left, up)  # left = up x forward
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    ears = at("Nose") - 0.08 * forward
    points[:, LANDMARKS.index("left_ear")] = ears + 0.075 * left
    points[:, LANDMARKS.index("right_ear")] = ears - 0.075 * left
    return points, reference


def project_all(cameras, points):
    """(V, F, 33, 2) pixels of (F, 33, 3) points; NaN where the point is NaN."""
    finite = np.isfinite(points).all(axis=2)
    pixels = np.full((len(cameras), *points.shape[:2], 2), np.nan)
    for view, camera in enumerate(cameras):
        pixels[view][finite] = camera.project(points[finite])
    return pixels


def test_exact_projections_triangulate_to_the_points(cameras, body):
    points, _ = body
    frame = points[0][np.isfinite(points[0]).all(axis=1)]
    pixels = np.array([camera.project(frame) for camera in cameras])
    result = triangulate(cameras, pixels)
    np.testing.assert_allclose(result.points, frame, atol=1e-6)
    assert result.views_used.all()
    assert np.nanmax(result.reprojection_m) < 1e-6


def test_a_wrong_view_is_dropped_and_the_point_kept(cameras, body):
    points, _ = body
    frame = points[0][np.isfinite(points[0]).all(axis=1)]
    pixels = np.array([camera.project(frame) for camera in cameras])
    pixels[2, 3] += (25.0, -20.0)  # about 0.3 m off at the subject's distance in the 1/4-size cam_03
    result = triangulate(cameras, pixels)
    assert not result.views_used[2, 3] and result.views_used[:, [0, 1, 2, 4]].all()
    np.testing.assert_allclose(result.points[3], frame[3], atol=1e-6)
    blind = triangulate(cameras, pixels, outlier_m=np.inf)
    assert np.linalg.norm(blind.points[3] - frame[3]) > 0.02  # what keeping the wrong view would cost


def test_a_point_seen_by_fewer_than_two_views_is_not_triangulated(cameras, body):
    points, _ = body
    frame = points[0][np.isfinite(points[0]).all(axis=1)][:2]
    pixels = np.array([camera.project(frame) for camera in cameras])
    pixels[1:, 0] = np.nan
    result = triangulate(cameras, pixels)
    assert np.isnan(result.points[0]).all() and np.isfinite(result.points[1]).all()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_left_and_right_swapped_in_some_views_are_resolved(cameras, body, seed):
    points, reference = body
    pixels = project_all(cameras, points)
    visibility = np.where(np.isfinite(pixels[..., 0]), 0.9, 0.0)
    swapped = np.random.default_rng(seed).random((len(cameras), len(points))) < 0.4
    left = [i for i, name in enumerate(LANDMARKS) if name.startswith("left")]
    right = [LANDMARKS.index("right" + LANDMARKS[i][4:]) for i in left]
    for view, frame in zip(*np.nonzero(swapped), strict=True):
        pixels[view, frame, left + right] = pixels[view, frame, right + left]
    keypoints, quality = triangulate_landmarks(cameras, pixels, visibility)
    for name in ("LWrist", "RWrist", "LAnkle", "RAnkle", "LHip", "RHip", "LKnee", "RElbow"):
        np.testing.assert_allclose(keypoints[name], reference.positions[:10, reference.marker_names.index(name)],
                                   atol=1e-5, err_msg=name)
    np.testing.assert_array_equal(quality["views_swapped"], swapped.T)


def test_every_view_swapped_is_put_right_by_the_face(cameras, body):
    points, reference = body
    left = [i for i, name in enumerate(LANDMARKS) if name.startswith("left")]
    right = [LANDMARKS.index("right" + LANDMARKS[i][4:]) for i in left]
    mirrored = points.copy()
    mirrored[:, left + right] = points[:, right + left]  # a detector that swaps in every view
    pixels = project_all(cameras, mirrored)
    keypoints, quality = triangulate_landmarks(cameras, pixels, np.where(np.isfinite(pixels[..., 0]), 0.9, 0.0))
    np.testing.assert_allclose(keypoints["LWrist"], reference.positions[:10, reference.marker_names.index("LWrist")],
                               atol=1e-5)
    assert quality["views_swapped"].all()


def test_neck_and_head_are_built_from_the_shoulders_and_the_face(cameras, body):
    points, reference = body
    pixels = project_all(cameras, points)
    keypoints, _ = triangulate_landmarks(cameras, pixels, np.where(np.isfinite(pixels[..., 0]), 0.9, 0.0))
    shoulders = 0.5 * (keypoints["LShoulder"] + keypoints["RShoulder"])
    np.testing.assert_allclose(keypoints["Neck"], shoulders, atol=1e-12)
    ears = 0.5 * (points[:, LANDMARKS.index("left_ear")] + points[:, LANDMARKS.index("right_ear")])
    np.testing.assert_allclose(np.linalg.norm(keypoints["Head"] - ears, axis=1), EAR_TO_VERTEX_M, atol=1e-6)
    assert (keypoints["Head"][:, 1] > ears[:, 1] + 0.1).all()  # above the ears in the Y-up TRC
    assert "Head" in reference.marker_names


def test_head_top_is_above_the_ears_away_from_the_shoulders():
    ears_left, ears_right = np.array([[0.07, 1.6, 0.0]]), np.array([[-0.07, 1.6, 0.0]])
    nose = np.array([[0.0, 1.6, 0.1]])  # level with the ears: the head is upright
    shoulders = np.array([[0.0, 1.4, 0.0]])
    np.testing.assert_allclose(head_top(ears_left, ears_right, nose, shoulders), [[0.0, 1.6 + EAR_TO_VERTEX_M, 0.0]],
                               atol=1e-12)
    # Upside down (shoulders above the ears), the top of the head is below them.
    assert head_top(ears_left, ears_right, nose, shoulders + [0.0, 0.4, 0.0])[0, 1] < 1.6


def test_keep_subject_keeps_the_parts_holding_a_target():
    mask = np.zeros((60, 80), bool)
    mask[10:30, 5:15] = True  # the subject
    mask[10:30, 50:60] = True  # someone else
    mask[40:45, 20:24] = True  # a blob just beside a target
    kept = keep_subject(mask, np.array([[10.0, 20.0], [26.0, 46.0]]), np.array([3.0, 3.0]))
    assert kept[10:30, 5:15].all() and kept[40:45, 20:24].all()
    assert not kept[:, 40:].any()
    assert not keep_subject(mask, np.array([[40.0, 55.0]]), np.array([2.0])).any()
    assert not keep_subject(mask, np.full((1, 2), np.nan), np.array([2.0])).any()


def test_every_frame_and_labelling_at_once_scores_as_each_frame_triangulated_alone(cameras, body):
    """The left/right choice scores all frames and labellings in one triangulation: each score is
    the one the frame's own triangulation of its left and right landmarks gives, to the bit (noisy
    pixels, a missing view, low weights)."""
    from ibik_pin.vision.triangulation import _LEFT, _RIGHT, _labelling_errors, _swap_sides

    points, _ = body
    rng = np.random.default_rng(7)
    pixels = project_all(cameras, points) + rng.normal(0.0, 3.0, (len(cameras), *points.shape[:2], 2))
    pixels[1, 3] = np.nan  # a view without the person in one frame
    weights = np.where(np.isfinite(pixels[..., 0]), rng.uniform(0.0, 1.0, pixels.shape[:3]), 0.0)
    labellings = [(False, a, b, c) for a in (False, True) for b in (False, True) for c in (False, True)]
    cap, sides = 0.5, _LEFT + _RIGHT
    batched = _labelling_errors(cameras, pixels, weights, labellings, cap)
    for frame in range(points.shape[0]):
        for index, flags in enumerate(labellings):
            labelled = np.array([_swap_sides(pixels[v, frame]) if flags[v] else pixels[v, frame]
                                 for v in range(len(cameras))])
            weighted = np.array([_swap_sides(weights[v, frame, :, None])[:, 0] if flags[v] else weights[v, frame]
                                 for v in range(len(cameras))])
            alone = triangulate(cameras, labelled[:, sides], weighted[:, sides], outlier_m=np.inf)
            expected = float(np.nansum(np.minimum(alone.reprojection_m, cap))
                             + cap * np.isnan(alone.points[:, 0]).sum())
            assert batched[frame, index] == expected, (frame, flags)
