"""The centre-line cue for a leg's split (subject.split_cue): on silhouettes of a thick thigh and a
thin shank it moves a wrong split toward the truth, where the widths would pull an overlap criterion."""

import cv2
import numpy as np
import pytest

from ibik_pin.exceptions import InputError
from ibik_pin.human import load_human
from ibik_pin.subject.split_cue import CLEARANCE_M, FLAT_BEYOND, MIN_RADIUS, ROBUST_SCALE_M, AxisDistanceCue
from ibik_pin.subject.trial_lengths import refine_from_images
from ibik_pin.vision.camera import OrthographicCamera
from ibik_pin.vision.medial_axis import axis_distance_image

THIGH, SHANK = 0.42, 0.40
THIGH_RADIUS, SHANK_RADIUS = 0.08, 0.035  # the sweep's silhouette body at the hip and the knee [m]
SCALE = 200.0  # px / m


def _cameras() -> list[OrthographicCamera]:
    """A front view (image u = world x) and a side view (u = world z), v = -world y."""
    front = np.diag([1.0, -1.0, -1.0])
    side = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
    return [OrthographicCamera(name, (400, 400), rotation, np.array([0.0, 0.5, 5.0]), SCALE, np.array([200.0, 200.0]))
            for name, rotation in (("front", front), ("side", side))]


def _legs(frames: int) -> np.ndarray:
    """Hip, knee, ankle (F, 3, 3) [m] of a leg bent 40-80 degrees, its knee forward (-z) and swivelled."""
    legs = np.zeros((frames, 3, 3))
    for frame, (bend, swivel) in enumerate(zip(np.radians(np.linspace(40.0, 80.0, frames)),
                                               np.linspace(-0.6, 0.6, frames), strict=True)):
        hip = np.array([0.1, 0.9, 0.0])
        half = 0.5 * bend
        thigh = np.array([np.sin(swivel) * np.sin(half), -np.cos(half), -np.cos(swivel) * np.sin(half)])
        shank = np.array([-np.sin(swivel) * np.sin(half), -np.cos(half), np.cos(swivel) * np.sin(half)])
        knee = hip + THIGH * thigh
        legs[frame] = hip, knee, knee + SHANK * shank
    return legs


def _silhouette(camera: OrthographicCamera, leg: np.ndarray) -> np.ndarray:
    """The leg as two capsules, the thigh more than twice as thick as the shank."""
    mask = np.zeros((400, 400), np.uint8)
    hip, knee, ankle = camera.project(leg)
    for start, end, radius in ((hip, knee, THIGH_RADIUS), (knee, ankle, SHANK_RADIUS)):
        pixels = round(radius * SCALE)
        a, b = tuple(int(round(v)) for v in start), tuple(int(round(v)) for v in end)
        cv2.line(mask, a, b, 255, 2 * pixels)
        cv2.circle(mask, a, pixels, 255, -1)
        cv2.circle(mask, b, pixels, 255, -1)
    return mask > 0


def test_the_cue_moves_a_wrong_split_toward_the_truth_whatever_the_widths():
    body = load_human()
    cameras = _cameras()
    cue = AxisDistanceCue(body, ["left_leg"])
    # Every other keypoint far above the leg in both views: no other segment near its samples.
    far = {name: np.array([-1.0, 2.0 + 0.01 * k, 1.0]) for k, name in enumerate(body.keypoints)}

    def frames():
        for leg in _legs(12):
            cue.set_views(cameras, [axis_distance_image(_silhouette(camera, leg)) for camera in cameras],
                          [ROBUST_SCALE_M * SCALE] * 2, [CLEARANCE_M * SCALE] * 2)
            yield dict(far, LHip=leg[0], LKnee=leg[1], LAnkle=leg[2]), [(cue, 1.0)]

    wrong = {"left_thigh": THIGH - 0.017, "left_shank": SHANK + 0.017}  # 4 % of the thigh the wrong way
    # A wider grid than the default's +-3 %: the cue's own bias, not the grid, is under test.
    refined = refine_from_images(body, wrong, frames(), factors=np.linspace(0.92, 1.08, 17), limbs=["left_leg"],
                                 keep_sum=True, min_radius=MIN_RADIUS)
    assert refined.lengths["left_thigh"] + refined.lengths["left_shank"] == pytest.approx(THIGH + SHANK, abs=1e-12)
    # The grid's step is 1 % of the thigh (4.1 mm): within one step of the truth.
    assert refined.lengths["left_thigh"] == pytest.approx(THIGH, abs=0.0045)
    assert refined.evidence["left_leg"]["scored_frames"] == 12


def test_the_centre_line_image_is_the_distance_to_a_band_s_middle():
    band = np.zeros((60, 100), bool)
    band[20:41, 10:90] = True  # rows 20-40: the middle row is 30
    distance = axis_distance_image(band)
    assert distance[30, 50] == 0.0 and distance[25, 50] == 5.0 and distance[0, 50] == 30.0
    assert np.isinf(axis_distance_image(np.zeros((5, 5), bool))).all()
    with pytest.raises(InputError, match="2D"):
        axis_distance_image(np.zeros(5))


def test_within_a_margin_the_centre_line_image_is_the_whole_image_s_and_beyond_it_the_cost_is_flat():
    rng = np.random.default_rng(4)
    for _ in range(20):
        mask = np.zeros((160, 220), np.uint8)
        for _ in range(int(rng.integers(1, 4))):
            cv2.ellipse(mask, (int(rng.integers(20, 200)), int(rng.integers(20, 140))),
                        (int(rng.integers(4, 30)), int(rng.integers(4, 50))), float(rng.uniform(0, 180)), 0, 360, 1, -1)
        whole = axis_distance_image(mask)
        for margin in (0.0, 6.5, 25.0):
            windowed = axis_distance_image(mask, within_px=margin)
            computed = np.isfinite(windowed)
            assert np.array_equal(windowed[computed], whole[computed])
            assert (whole[~computed] >= margin).all()
    # The cue reads 1 - exp(-(d / c)^2): beyond FLAT_BEYOND robust scales it is 1.0 to the bit, as at +inf.
    assert 1.0 - np.exp(-(FLAT_BEYOND ** 2)) == 1.0
