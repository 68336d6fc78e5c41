"""Limb lengths refined on a trial: the reach bound and the search over the silhouettes' evidence."""

import numpy as np
import pytest

from ibik_pin.exceptions import InputError
from ibik_pin.human import load_human
from ibik_pin.subject.scaling import keypoint_lengths
from ibik_pin.subject.trial_lengths import (
    MIN_GAIN,
    apply_lengths,
    reach_bounds,
    refine_from_images,
    refine_from_reach,
)
from ibik_pin.tracking.trunk import TRUNK_SECTION, inside_trunk

NAMES = ["LHip", "LKnee", "LAnkle"]
THIGH, SHANK = 0.42, 0.40


class _Body:
    """The little of a BodyModel the refinement reads: keypoint names and their frame ids."""

    def __init__(self):
        self.keypoints = {name: 10 + k for k, name in enumerate(NAMES)}

    def frame_ids(self, names):
        return np.array([self.keypoints[name] for name in names])


class _PeakAt:
    """A criterion whose value is highest where the knee is at `truth[frame]`: -distance^2."""

    enabled = True

    def __init__(self, truth: np.ndarray | None):
        self.truth = truth
        self.frame_ids = np.array([10, 11, 12])

    def at_pose(self, current):
        return None

    def values_at_moves(self, current, pose, moves):
        if self.truth is None:  # flat: every candidate alike
            return [np.zeros(len(points)) for _, points in moves]
        return [-np.sum((points - self.truth) ** 2, axis=1) for _, points in moves]


def _leg(frames: int, bend_deg: np.ndarray, thigh: float = THIGH, shank: float = SHANK, seed: int = 0):
    """Hip, knee, ankle (F, 3, 3) [m] of a leg bent by `bend_deg` at the knee, swivelled at random."""
    rng = np.random.default_rng(seed)
    legs = np.zeros((frames, 3, 3))
    for frame in range(frames):
        bend = np.radians(bend_deg[frame])
        swivel = rng.uniform(-0.5, 0.5)
        hip = np.array([0.0, 0.9, 0.1])
        thigh_direction = np.array([np.sin(0.3 * bend) * np.cos(swivel), -np.cos(0.3 * bend),
                                    np.sin(0.3 * bend) * np.sin(swivel)])
        knee = hip + thigh * thigh_direction
        shank_direction = np.array([-np.sin(0.7 * bend) * np.cos(swivel), -np.cos(0.7 * bend),
                                    -np.sin(0.7 * bend) * np.sin(swivel)])
        legs[frame] = hip, knee, knee + shank * shank_direction
    return legs


def test_the_reach_bound_is_a_high_quantile_of_the_end_to_end_distance():
    legs = _leg(50, np.linspace(5.0, 60.0, 50))
    reach = np.linalg.norm(legs[:, 2] - legs[:, 0], axis=1)
    bounds = reach_bounds(NAMES, legs, quantile=1.0, smoothing_frames=1)
    assert bounds["left_leg"] == pytest.approx(reach.max(), abs=1e-12)
    assert bounds["left_leg"] <= THIGH + SHANK
    assert "right_leg" not in bounds


def test_smoothing_the_reach_keeps_noise_from_inflating_the_bound():
    legs = _leg(200, np.full(200, 10.0))
    true_reach = np.linalg.norm(legs[:, 2] - legs[:, 0], axis=1).max()
    noisy = legs + np.random.default_rng(1).normal(0.0, 0.01, legs.shape)
    raw = reach_bounds(NAMES, noisy, smoothing_frames=1)["left_leg"]
    smoothed = reach_bounds(NAMES, noisy, smoothing_frames=5)["left_leg"]
    assert raw > true_reach + 0.01
    assert smoothed < raw - 0.005
    with pytest.raises(InputError, match="smoothing_frames"):
        reach_bounds(NAMES, noisy, smoothing_frames=0)


def test_the_reach_lengthens_a_limb_too_short_for_its_targets_and_never_shortens_one():
    legs = _leg(50, np.full(50, 3.0))
    short = refine_from_reach({"left_thigh": 0.95 * THIGH, "left_shank": 0.95 * SHANK}, NAMES, legs, slack=0.0)
    total = short.lengths["left_thigh"] + short.lengths["left_shank"]
    assert total == pytest.approx(reach_bounds(NAMES, legs)["left_leg"], abs=1e-9)
    assert short.lengths["left_thigh"] / short.lengths["left_shank"] == pytest.approx(THIGH / SHANK, rel=1e-12)
    long = refine_from_reach({"left_thigh": 1.05 * THIGH, "left_shank": 1.05 * SHANK}, NAMES, legs)
    assert long.changes == {}


def test_the_image_search_finds_the_lengths_whose_knee_the_criterion_prefers():
    legs = _leg(30, np.linspace(20.0, 70.0, 30))
    calibrated = {"left_thigh": THIGH / 1.03, "left_shank": SHANK / 0.97}
    # The first pass's knee: on the circle of the calibrated lengths, which the criterion will not prefer.
    frames = [({"LHip": leg[0], "LKnee": leg[1], "LAnkle": leg[2]}, [(_PeakAt(leg[1]), 1.0)]) for leg in legs]
    refined = refine_from_images(_Body(), calibrated, frames, factors=np.linspace(0.94, 1.06, 9), swivels=72)
    assert refined.lengths["left_thigh"] == pytest.approx(THIGH, rel=0.004)
    assert refined.lengths["left_shank"] == pytest.approx(SHANK, rel=0.004)
    assert refined.evidence["left_leg"]["frames"] == 30
    assert set(refined.report()["segments_mm"]) == {"left_thigh", "left_shank"}


def test_a_flat_criterion_keeps_the_calibrated_lengths_unless_they_cannot_reach():
    legs = _leg(20, np.linspace(20.0, 60.0, 20))
    frames = [({"LHip": leg[0], "LKnee": leg[1], "LAnkle": leg[2]}, [(_PeakAt(None), 1.0)]) for leg in legs]
    kept = refine_from_images(_Body(), {"left_thigh": THIGH, "left_shank": SHANK}, frames)
    assert kept.changes == {}
    straight = _leg(20, np.full(20, 2.0))
    frames = [({"LHip": leg[0], "LKnee": leg[1], "LAnkle": leg[2]}, [(_PeakAt(None), 1.0)]) for leg in straight]
    short = refine_from_images(_Body(), {"left_thigh": 0.95 * THIGH, "left_shank": 0.95 * SHANK}, frames)
    reach = np.linalg.norm(straight[:, 2] - straight[:, 0], axis=1).max()
    assert short.lengths["left_thigh"] + short.lengths["left_shank"] >= reach - 0.005
    assert short.evidence["left_leg"]["calibrated_reaches"] is False


def test_keeping_the_sum_moves_the_knee_along_the_leg_and_keeps_thigh_plus_shank():
    legs = _leg(30, np.linspace(20.0, 70.0, 30))
    # The right sum, split 12 mm the wrong way: only the split is to be found.
    calibrated = {"left_thigh": THIGH - 0.012, "left_shank": SHANK + 0.012}
    frames = [({"LHip": leg[0], "LKnee": leg[1], "LAnkle": leg[2]}, [(_PeakAt(leg[1]), 1.0)]) for leg in legs]
    refined = refine_from_images(_Body(), calibrated, frames, factors=np.linspace(0.94, 1.06, 49), swivels=72,
                                 keep_sum=True)
    assert refined.lengths["left_thigh"] + refined.lengths["left_shank"] == pytest.approx(THIGH + SHANK, abs=1e-12)
    assert refined.lengths["left_thigh"] == pytest.approx(THIGH, abs=0.002)
    assert refined.evidence["left_leg"]["factors"][1] == pytest.approx(refined.lengths["left_shank"]
                                                                        / calibrated["left_shank"], rel=1e-12)
    with pytest.raises(InputError, match="choose one"):
        refine_from_images(_Body(), calibrated, frames, keep_sum=True, keep_ratio=True)


def _knee_with_lengths(leg: np.ndarray, factor: float) -> np.ndarray:
    """Where the knee of a leg whose segments are `factor` times THIGH and SHANK lies between the
    leg's hip and ankle, on the side of its own knee."""
    hip, knee, ankle = leg
    axis = (ankle - hip) / np.linalg.norm(ankle - hip)
    distance = float(np.linalg.norm(ankle - hip))
    radial = (knee - hip) - ((knee - hip) @ axis) * axis
    radial /= np.linalg.norm(radial)
    thigh, shank = factor * THIGH, factor * SHANK
    along = (distance**2 + thigh**2 - shank**2) / (2.0 * distance)
    return hip + along * axis + np.sqrt(thigh**2 - along**2) * radial


@pytest.mark.parametrize(("truth", "moves"), [(1.003, False), (1.004, True)])
def test_a_preference_below_the_minimum_gain_keeps_the_calibrated_lengths(truth, moves):
    legs = _leg(30, np.linspace(20.0, 70.0, 30))
    # The knees of legs 0.3 % (0.4 %) longer: nearest the grid's 1.005, but 1.0 scores almost as well.
    frames = [({"LHip": leg[0], "LKnee": leg[1], "LAnkle": leg[2]}, [(_PeakAt(_knee_with_lengths(leg, truth)), 1.0)])
              for leg in legs]
    calibrated = {"left_thigh": THIGH, "left_shank": SHANK}
    refined = refine_from_images(_Body(), calibrated, frames, keep_ratio=True, swivels=360)
    gain = refined.evidence["left_leg"]["gain"]
    assert (gain > MIN_GAIN) is moves
    assert refined.evidence["left_leg"]["factors"][0] == pytest.approx(1.005 if moves else 1.0)
    anyway = refine_from_images(_Body(), calibrated, frames, keep_ratio=True, swivels=360, min_gain=0.0)
    assert anyway.evidence["left_leg"]["factors"][0] == pytest.approx(1.005)


def test_bad_arguments_are_refused_with_what_was_expected():
    with pytest.raises(InputError, match="targets: expected shape"):
        reach_bounds(NAMES, np.zeros((4, 2, 3)))
    with pytest.raises(InputError, match="limbs: unknown"):
        reach_bounds(NAMES, np.zeros((4, 3, 3)), limbs=["tail"])
    with pytest.raises(InputError, match="factors"):
        refine_from_images(_Body(), {}, [], factors=np.array([0.0, 1.0]))


def test_applying_refined_lengths_changes_those_segments_of_the_model_and_no_other():
    body = load_human()
    lengths = keypoint_lengths(body)
    legs = _leg(10, np.full(10, 2.0), thigh=1.04 * lengths["left_thigh"], shank=1.04 * lengths["left_shank"])
    refined = refine_from_reach(lengths, NAMES, legs, slack=0.0)
    assert set(refined.changes) == {"left_thigh", "left_shank"}
    after = keypoint_lengths(apply_lengths(body, refined))
    for name, value in lengths.items():
        expected = refined.lengths[name] if name in refined.changes else value
        assert after[name] == pytest.approx(expected, abs=1e-6), name
    assert apply_lengths(body, refine_from_reach(lengths, NAMES, legs[:, :, :] * 0.5)) is body


def test_the_chosen_lengths_say_where_each_frame_put_the_middle_joint():
    legs = _leg(30, np.linspace(20.0, 70.0, 30))
    calibrated = {"left_thigh": THIGH / 1.03, "left_shank": SHANK / 0.97}
    frames = [({"LHip": leg[0], "LKnee": leg[1], "LAnkle": leg[2]}, [(_PeakAt(leg[1]), 1.0)]) for leg in legs]
    refined = refine_from_images(_Body(), calibrated, frames, factors=np.linspace(0.94, 1.06, 9), swivels=72)
    middles = refined.middles["left_leg"]
    assert middles.shape == (30, 3)
    # At the chosen lengths (within 0.4 % of the truth) and the best of 72 swivels (5 degrees apart).
    assert np.max(np.linalg.norm(middles - legs[:, 1], axis=1)) < 0.012


def test_nearly_straight_frames_do_not_score_a_limb_when_a_radius_is_asked():
    bends = np.concatenate((np.full(10, 2.0), np.linspace(40.0, 70.0, 20)))
    legs = _leg(30, bends)
    calibrated = {"left_thigh": THIGH - 0.012, "left_shank": SHANK + 0.012}
    frames = [({"LHip": leg[0], "LKnee": leg[1], "LAnkle": leg[2]}, [(_PeakAt(leg[1]), 1.0)]) for leg in legs]
    radii = np.linalg.norm(np.cross(legs[:, 1] - legs[:, 0], legs[:, 2] - legs[:, 0]), axis=1) / np.linalg.norm(
        legs[:, 2] - legs[:, 0], axis=1)
    refined = refine_from_images(_Body(), calibrated, frames, factors=np.linspace(0.94, 1.06, 49), swivels=72,
                                 keep_sum=True, min_radius=0.08)
    assert refined.evidence["left_leg"]["scored_frames"] == np.count_nonzero(radii >= 0.08) == 20
    assert refined.lengths["left_thigh"] == pytest.approx(THIGH, abs=0.002)
    assert refine_from_images(_Body(), calibrated, frames, keep_sum=True,
                              min_radius=1.0).evidence["left_leg"]["scored_frames"] == 0


class _Arm:
    """An arm and the trunk keypoints (BodyModel's names and frame ids, as _Body)."""

    def __init__(self):
        names = ["Hip", "Neck", "LShoulder", "RShoulder", "LElbow", "LWrist"]
        self.keypoints = {name: 10 + k for k, name in enumerate(names)}

    def frame_ids(self, names):
        return np.array([self.keypoints[name] for name in names])


def test_an_elbow_is_never_placed_inside_the_trunk_when_a_section_is_given():
    # Trunk along y, shoulders 0.36 m apart along x (left at +x), the front is -z (left x up).
    pose = {"Hip": np.array([0.0, 1.0, 0.0]), "Neck": np.array([0.0, 1.5, 0.0]),
            "LShoulder": np.array([0.18, 1.45, 0.0]), "RShoulder": np.array([-0.18, 1.45, 0.0]),
            "LWrist": np.array([0.16, 1.0, -0.1])}
    # The wrist hangs in front of the hip: the elbow's circle passes through the trunk.
    upper, lower = 0.30, 0.27
    criterion = _PeakAt(np.array([0.0, 1.2, 0.0]))  # the trunk's axis: the criterion prefers it there
    criterion.frame_ids = np.array([12, 14, 15])
    frames = [(dict(pose, LElbow=np.array([0.25, 1.2, 0.0])), [(criterion, 1.0)])] * 3
    lengths = {"left_upper_arm": upper, "left_forearm": lower}
    free = refine_from_images(_Arm(), lengths, frames, factors=np.array([1.0]), limbs=["left_arm"])
    kept_out = refine_from_images(_Arm(), lengths, frames, factors=np.array([1.0]), limbs=["left_arm"],
                                  trunk_section=TRUNK_SECTION)
    trunk = [pose[name] for name in ("Hip", "Neck", "LShoulder", "RShoulder")]
    assert inside_trunk(free.middles["left_arm"], *trunk).all()
    assert not inside_trunk(kept_out.middles["left_arm"], *trunk).any()
