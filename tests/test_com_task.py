"""Tests of ibik_pin.tasks.com: the centre of mass over the feet."""

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.tasks.com import CenterOfMassTask
from tests.conftest import random_human_configuration
from tests.test_tasks import finite_difference_jacobian, relative_error


def test_the_error_is_the_horizontal_offset_of_the_centre_of_mass_from_the_feet(human, rng):
    q = random_human_configuration(human, rng)
    configuration = Configuration(human.model, q)
    task = CenterOfMassTask(human, ["LAnkle", "RAnkle"])
    com = pin.centerOfMass(human.model, human.model.createData(), q)
    feet = configuration.frame_positions(human.frame_ids(["LAnkle", "RAnkle"])).mean(axis=0)
    np.testing.assert_allclose(task.compute_error(configuration), (com - feet)[[0, 2]], atol=1e-12)


def test_the_jacobian_matches_finite_differences(human, rng):
    q = random_human_configuration(human, rng)
    task = CenterOfMassTask(human)
    analytic = task.compute_jacobian(Configuration(human.model, q))
    assert analytic.shape == (2, human.model.nv)
    assert relative_error(finite_difference_jacobian(task, human.model, q), analytic) < 1e-4


def test_the_task_leaves_the_configuration_s_kinematics_alone(human, rng):
    configuration = Configuration(human.model, random_human_configuration(human, rng))
    before = configuration.frame_position(human.frame_id("RWrist")).copy()
    jacobian = configuration.frame_translation_jacobian(human.frame_id("RWrist")).copy()
    task = CenterOfMassTask(human)
    task.compute_jacobian(Configuration(human.model, random_human_configuration(human, rng)))  # another q
    task.compute_error(configuration)
    assert np.array_equal(configuration.frame_position(human.frame_id("RWrist")), before)
    assert np.array_equal(configuration.frame_translation_jacobian(human.frame_id("RWrist")), jacobian)


def test_unknown_feet_are_refused_with_the_known_keypoints(human):
    with pytest.raises(InputError, match=r"feet: expected keypoints of the body, found .*'LPaw'.*known keypoints: Hip"):
        CenterOfMassTask(human, ["LAnkle", "LPaw"])
