import warnings

import numpy as np
import pytest

from ibik_pin.exceptions import IbikWarning, InputError, UnknownNameError
from ibik_pin.human import HUMAN_NEUTRAL_STATURE_M, neutral_stature
from ibik_pin.io.asf_amc import read_asf_amc
from ibik_pin.model import load_arm
from ibik_pin.subject.scaling import (
    LENGTH_KEYPOINTS,
    keypoint_lengths,
    scale_from_stature,
    scale_human,
    segment_lengths_from_keypoints,
)
from ibik_pin.synthetic.mocap import keypoints_from_motion
from tests.paths import TEST_DATA

MILLIMETRE = 1e-3


def placements(body):
    """Every joint and frame placement translation of the model, for comparisons."""
    model = body.model
    joints = np.array([model.jointPlacements[i].translation for i in range(model.njoints)])
    frames = np.array([frame.placement.translation for frame in model.frames])
    return joints, frames


def requested_lengths(human, rng):
    """Lengths 80-120 % of the model's, each its own factor, with keypoint conventions changed."""
    lengths = {name: value * rng.uniform(0.8, 1.2) for name, value in keypoint_lengths(human).items()}
    lengths["pelvis_height"] = rng.uniform(0.0, 0.12)
    lengths["neck_shoulder"] = 0.5 * lengths["shoulder_width"] + rng.uniform(0.01, 0.1)
    return lengths


def test_the_scaled_human_has_every_requested_length_within_a_millimetre(human, rng):
    for _ in range(3):
        lengths = requested_lengths(human, rng)
        scaled = scale_human(human, lengths)
        achieved = keypoint_lengths(scaled)
        for name, value in lengths.items():
            assert abs(achieved[name] - value) < MILLIMETRE, name


def test_scaling_leaves_the_input_model_untouched(human, rng):
    joints, frames = placements(human)
    radii = human.segment_radii.copy()
    scaled = scale_human(human, requested_lengths(human, rng))
    scaled_joints, _ = placements(scaled)
    assert scaled.model is not human.model
    assert not np.allclose(scaled_joints, joints)
    assert np.array_equal(placements(human)[0], joints)
    assert np.array_equal(placements(human)[1], frames)
    assert np.array_equal(human.segment_radii, radii)


def test_the_model_s_own_lengths_give_the_model_back(human):
    scaled = scale_human(human, keypoint_lengths(human))
    for before, after in zip(placements(human), placements(scaled), strict=True):
        assert np.allclose(before, after, atol=1e-12)


def test_segments_nobody_measured_keep_the_mean_ratio_of_the_measured_ones(human):
    model_lengths = keypoint_lengths(human)
    scaled = scale_human(human, {"left_thigh": 1.1 * model_lengths["left_thigh"],
                                 "right_thigh": 1.3 * model_lengths["right_thigh"]})
    achieved = keypoint_lengths(scaled)
    assert achieved["left_forearm"] == pytest.approx(1.2 * model_lengths["left_forearm"], abs=1e-9)
    assert achieved["trunk"] == pytest.approx(1.2 * model_lengths["trunk"], abs=1e-9)
    assert np.allclose(scaled.segment_radii, 1.2 * human.segment_radii)


def test_keypoint_offsets_do_not_change_the_body_s_size(human):
    scaled = scale_human(human, {"pelvis_height": 0.0})
    achieved = keypoint_lengths(scaled)
    assert achieved["pelvis_height"] < MILLIMETRE
    assert achieved["trunk"] == pytest.approx(keypoint_lengths(human)["trunk"], abs=1e-12)


def test_lengths_are_medians_over_frames_that_skip_missing_keypoints(rng):
    frames = 9
    hip = rng.normal(0.0, 0.1, (frames, 3))
    knee = hip + np.array([0.0, -0.4, 0.0])
    knee[0] = hip[0] + [0.0, -5.0, 0.0]  # one outlier frame: the median ignores it
    knee[1] = np.nan  # one missing frame
    lengths = segment_lengths_from_keypoints(["LHip", "LKnee"], np.stack([hip, knee], axis=1))
    assert lengths == {"left_thigh": pytest.approx(0.4, abs=1e-12)}


def test_only_lengths_whose_keypoints_are_present_are_measured():
    lengths = segment_lengths_from_keypoints(
        {"LShoulder": [0.0, 1.4, -0.2], "RShoulder": [0.0, 1.4, 0.2], "LElbow": [0.0, 1.1, -0.2]}
    )
    assert lengths == {"shoulder_width": pytest.approx(0.4), "left_upper_arm": pytest.approx(0.3)}
    assert segment_lengths_from_keypoints(["Hip", "LWrist"], np.zeros((3, 2, 3))) == {}


def test_a_keypoint_never_seen_measures_nothing():
    positions = np.array([[[0.0, 1.0, 0.0], [np.nan, np.nan, np.nan]]])
    assert segment_lengths_from_keypoints(["LHip", "LKnee"], positions) == {}


def test_lengths_measured_on_real_walking_scale_the_model_within_a_millimetre(human):
    motion = read_asf_amc(TEST_DATA / "35.asf", TEST_DATA / "35_01_excerpt.amc")
    names, positions = keypoints_from_motion(motion, "asf")
    lengths = segment_lengths_from_keypoints(names, positions)
    assert set(lengths) == set(LENGTH_KEYPOINTS)
    achieved = keypoint_lengths(scale_human(human, lengths))
    for name, value in lengths.items():
        assert abs(achieved[name] - value) < MILLIMETRE, name


def test_scaling_from_stature_is_uniform(human):
    scaled = scale_from_stature(human, 1.60)
    assert neutral_stature(scaled) == pytest.approx(1.60, abs=1e-9)
    factor = 1.60 / neutral_stature(human)
    model_lengths = keypoint_lengths(human)
    for name, value in keypoint_lengths(scaled).items():
        assert value == pytest.approx(factor * model_lengths[name], abs=1e-9), name
    assert neutral_stature(human) == pytest.approx(HUMAN_NEUTRAL_STATURE_M, abs=5e-4)


def test_the_scaled_model_keeps_its_joint_axes_and_limits(human, rng):
    scaled = scale_human(human, requested_lengths(human, rng))
    assert np.array_equal(scaled.model.lowerPositionLimit, human.model.lowerPositionLimit)
    for index in range(1, human.model.njoints):
        assert np.allclose(scaled.model.jointPlacements[index].rotation, human.model.jointPlacements[index].rotation)


def test_an_unknown_length_name_lists_the_known_ones(human):
    with pytest.raises(UnknownNameError, match=r"unknown length name.*'femur'.*known: left_thigh"):
        scale_human(human, {"femur": 0.4})


@pytest.mark.parametrize("value", [0.0, -0.3, float("nan")])
def test_a_segment_length_must_be_positive_and_finite(human, value):
    with pytest.raises(InputError, match=r"lengths\['left_thigh'\]: expected a positive finite length"):
        scale_human(human, {"left_thigh": value})


def test_a_model_without_the_human_s_keypoints_is_refused():
    with pytest.raises(InputError, match="scale_human expects example-robot-data's human"):
        scale_human(load_arm(), {"left_thigh": 0.4})


def test_a_length_the_placements_cannot_reach_warns(human):
    with pytest.warns(IbikWarning, match=r"lengths\['neck_shoulder'\]: requested 0.1000 m"):
        scale_human(human, {"shoulder_width": 0.4, "neck_shoulder": 0.1})


def test_reachable_lengths_do_not_warn(human, rng):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scale_human(human, requested_lengths(human, rng))


def test_positions_must_match_the_names():
    with pytest.raises(InputError, match=r"positions: expected shape \(F, 2, 3\)"):
        segment_lengths_from_keypoints(["LHip", "LKnee"], np.zeros((4, 3, 3)))
    with pytest.raises(InputError, match="expected unique names"):
        segment_lengths_from_keypoints(["LHip", "LHip"], np.zeros((4, 2, 3)))
