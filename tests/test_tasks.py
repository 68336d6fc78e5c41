import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError, UnknownNameError
from ibik_pin.tasks import FramePositionTask, PostureTask
from tests.conftest import random_human_configuration


def finite_difference_jacobian(task, model, q, eps=1e-7):
    error = task.compute_error(Configuration(model, q))
    columns = []
    for k in range(model.nv):
        dv = np.zeros(model.nv)
        dv[k] = eps
        shifted = task.compute_error(Configuration(model, pin.integrate(model, q, dv)))
        columns.append((shifted - error) / eps)
    return np.stack(columns, axis=1)


def relative_error(numeric, analytic):
    return np.linalg.norm(numeric - analytic) / np.linalg.norm(analytic)


def test_position_task_jacobian_matches_finite_differences(human, rng):
    q = random_human_configuration(human, rng)
    task = FramePositionTask(human.model, "RWrist", target=[0.3, 0.2, 0.1])
    analytic = task.compute_jacobian(Configuration(human.model, q))
    assert relative_error(finite_difference_jacobian(task, human.model, q), analytic) < 1e-4


def test_posture_task_jacobian_matches_finite_differences(human, rng):
    reference = random_human_configuration(human, rng)
    q = random_human_configuration(human, rng)
    task = PostureTask(human.model, reference)
    analytic = task.compute_jacobian(Configuration(human.model, q))
    assert analytic.shape == (36, 42)
    assert relative_error(finite_difference_jacobian(task, human.model, q), analytic) < 1e-4


def test_position_task_error_is_frame_minus_target(human):
    configuration = Configuration(human.model)
    task = FramePositionTask(human.model, "Hip", target=[0.0, 0.0, 0.5])
    assert np.allclose(task.compute_error(configuration), [0.0, 0.0, -0.5])


def test_linear_system_asks_for_minus_gain_times_error(human):
    configuration = Configuration(human.model)
    task = FramePositionTask(human.model, "Hip", target=[0.0, 0.0, 0.5], gain=0.5, weight=4.0)
    A, b = task.compute_linear_system(configuration)
    assert np.allclose(b, [0.0, 0.0, 0.5])  # sqrt(4) * 0.5 * 0.5
    assert np.allclose(A, 2.0 * task.compute_jacobian(configuration))


def test_an_unknown_frame_lists_the_available_frames(human):
    with pytest.raises(UnknownNameError, match="available frames: universe, root_joint"):
        FramePositionTask(human.model, "left_hand_tip")


def test_a_non_finite_target_is_refused(human):
    with pytest.raises(InputError, match="target of frame 'LWrist' must be finite"):
        FramePositionTask(human.model, "LWrist", target=[0.0, np.nan, 0.0])


def test_a_target_of_the_wrong_shape_is_refused(human):
    with pytest.raises(InputError, match=r"must have shape \(3,\)"):
        FramePositionTask(human.model, "LWrist", target=[0.0, 1.0])


def test_a_none_target_disables_the_task(human):
    task = FramePositionTask(human.model, "LWrist", target=[0.0, 1.0, 0.0])
    task.set_target(None)
    assert not task.enabled


@pytest.mark.parametrize("gain", [0.0, 1.5, np.inf])
def test_a_gain_outside_0_1_is_refused(human, gain):
    with pytest.raises(InputError, match="gain"):
        FramePositionTask(human.model, "LWrist", gain=gain)
