"""Tests of ibik_pin.tracking.outcomes: each level's residual and what the levels above cost it."""

import numpy as np
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.tasks import FramePositionTask
from ibik_pin.tasks.base import GradientTask
from ibik_pin.tracking.levels import StackPlan
from ibik_pin.tracking.outcomes import level_outcomes
from tests.conftest import random_human_configuration


class Fixed(GradientTask):
    """A criterion whose gradient is a given direction (nv,)."""

    def __init__(self, direction):
        super().__init__()
        self.direction = np.asarray(direction, dtype=float)

    def compute_value(self, configuration):
        return 0.5

    def compute_gradient(self, configuration):
        return self.direction


def outcomes_of(levels, names, configuration):
    image = next((level[0] for level in levels if isinstance(level[0], GradientTask)), None)
    plan = StackPlan(names, levels, levels, list(range(len(levels))),
                     None if image is None else [level[0] for level in levels].index(image), image)
    statuses = ["solved", "relaxed", "relaxed", "solved"]
    return level_outcomes(plan, configuration, statuses[:len(levels)], list(range(len(levels))), damping=3e-2)


def test_a_target_fighting_a_higher_one_for_the_same_point_is_wholly_sacrificed(human, rng):
    configuration = Configuration(human.model, random_human_configuration(human, rng, spread=0.3))
    wrist = configuration.frame_position(human.frame_id("RWrist")).copy()
    first = FramePositionTask(human.model, human.keypoints["RWrist"], wrist + [0.02, 0.0, 0.0])
    second = FramePositionTask(human.model, human.keypoints["RWrist"], wrist + [0.0, 0.05, 0.0], weight=4.0)
    ankle = configuration.frame_position(human.frame_id("LAnkle")) + [0.0, 0.0, 0.03]
    third = FramePositionTask(human.model, human.keypoints["LAnkle"], ankle)
    outcomes = outcomes_of([[first], [second], [third]], ["one", "two", "three"], configuration)
    assert [outcome.status for outcome in outcomes] == ["solved", "relaxed", "relaxed"]
    assert outcomes[0].residual == pytest.approx(0.02, abs=1e-12)
    assert outcomes[0].sacrificed == 0.0  # nothing above it
    assert outcomes[1].residual == pytest.approx(2.0 * 0.05, abs=1e-12)  # sqrt(weight) |e|
    assert outcomes[1].sacrificed == pytest.approx(outcomes[1].residual, rel=1e-9)  # the first level holds its point
    assert outcomes[2].residual == pytest.approx(0.03, abs=1e-12)
    assert outcomes[2].sacrificed < 1e-9  # the leg is free of the wrist


def test_an_image_gradient_is_sacrificed_by_the_share_the_levels_above_take(human, rng):
    configuration = Configuration(human.model, random_human_configuration(human, rng, spread=0.3))
    wrist = FramePositionTask(human.model, human.keypoints["RWrist"], configuration.frame_position(
        human.frame_id("RWrist")) + [0.01, 0.0, 0.0])
    along_the_wrist = wrist.compute_jacobian(configuration)[0]
    free = np.zeros(human.model.nv)
    free[human.model.joints[human.model.getJointId("left_wrist_X")].idx_v] = 1.0  # moves no wrist target
    taken = outcomes_of([[wrist], [Fixed(along_the_wrist)]], ["wrist", "image"], configuration)[1]
    untouched = outcomes_of([[wrist], [Fixed(free)]], ["wrist", "image"], configuration)[1]
    assert taken.sacrificed == pytest.approx(1.0, abs=1e-9)
    assert untouched.sacrificed == pytest.approx(0.0, abs=1e-9)
    assert np.isnan(taken.residual) and taken.criterion == 0.5


def test_a_level_with_no_enabled_task_has_no_residual(human):
    configuration = Configuration(human.model)
    absent = FramePositionTask(human.model, human.keypoints["RWrist"], None)
    outcome = outcomes_of([[absent]], ["absent"], configuration)[0]
    assert np.isnan(outcome.residual) and np.isnan(outcome.sacrificed)
