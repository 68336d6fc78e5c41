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
    assert analytic.shape == (38, 44)
    assert relative_error(finite_difference_jacobian(task, human.model, q), analytic) < 1e-4


def test_a_posture_task_on_chosen_coordinates_includes_the_root(human, rng):
    held = ~human.limb_coordinates  # root, spine, clavicles, neck
    q = random_human_configuration(human, rng)
    # Held where it is, as the tracker holds the trunk: the identity is the root's exact Jacobian there.
    task = PostureTask(human.model, q, coordinates=held)
    analytic = task.compute_jacobian(Configuration(human.model, q))
    assert analytic.shape == (int(held.sum()), 44)
    assert np.allclose(analytic[:6, :6], np.eye(6))  # the free flyer's six are held too
    assert relative_error(finite_difference_jacobian(task, human.model, q), analytic) < 1e-4
    with pytest.raises(InputError, match=r"coordinates: expected a bool mask of shape \(44,\)"):
        PostureTask(human.model, coordinates=held[:-1])


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


def test_stacked_position_rows_are_each_tasks_rows_to_the_bit(human, rng):
    """One read of every frame for a level's position tasks gives what each task gives alone: mixed
    gains and weights, a task driven by some joints, a repeated frame; a subclass, which may change
    the error, gets its rows task by task."""
    configuration = Configuration(human.model, random_human_configuration(human, rng))
    driven = np.zeros(human.model.nv, dtype=bool)
    driven[10:20] = True
    tasks = [FramePositionTask(human.model, name, target=rng.normal(0.0, 0.5, 3), gain=gain, weight=weight,
                               driven=mask)
             for name, gain, weight, mask in [("LWrist", 1.0, 1.0, None), ("Head", 0.5, 4.0, None),
                                              ("RBigToe", 0.8, 0.3, driven), ("LWrist", 0.2, 2.0, None)]]
    A, b = FramePositionTask.stacked_linear_system(tasks, configuration)
    rows = [task.compute_linear_system(configuration) for task in tasks]
    assert np.array_equal(A, np.vstack([rows_A for rows_A, _ in rows]))
    assert np.array_equal(b, np.concatenate([rows_b for _, rows_b in rows]))

    class Shifted(FramePositionTask):
        def compute_error(self, configuration):
            return super().compute_error(configuration) + 1.0

    # A solve's memo keeps the tasks' constants: the rows stay each task's at another configuration.
    memo: dict = {}
    moved = Configuration(human.model, random_human_configuration(human, rng))
    for state in (configuration, moved, configuration):
        A, b = FramePositionTask.stacked_linear_system(tasks, state, memo)
        rows = [task.compute_linear_system(state) for task in tasks]
        assert np.array_equal(A, np.vstack([rows_A for rows_A, _ in rows]))
        assert np.array_equal(b, np.concatenate([rows_b for _, rows_b in rows]))
    assert "position rows" in memo

    shifted = [Shifted(human.model, "Head", target=[0.0, 0.0, 1.0])]
    assert np.array_equal(Shifted.stacked_linear_system(shifted, configuration)[1],
                          shifted[0].compute_linear_system(configuration)[1])


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


def test_a_position_task_driven_by_some_joints_moves_only_those(human):
    import pinocchio as pin

    from ibik_pin.configuration import Configuration
    from ibik_pin.tasks import FramePositionTask

    model = human.model
    driven = np.zeros(model.nv, dtype=bool)
    joint = model.joints[model.getJointId("left_ankle_Z")]
    driven[joint.idx_v:joint.idx_v + joint.nv] = True
    task = FramePositionTask(model, human.keypoints["LBigToe"], np.zeros(3), driven=driven)
    full = FramePositionTask(model, human.keypoints["LBigToe"], np.zeros(3))
    configuration = Configuration(model, pin.neutral(model))
    jacobian = task.compute_jacobian(configuration)
    np.testing.assert_array_equal(jacobian[:, ~driven], 0.0)
    np.testing.assert_array_equal(jacobian[:, driven], full.compute_jacobian(configuration)[:, driven])
    with pytest.raises(InputError, match="driven"):
        FramePositionTask(model, human.keypoints["LBigToe"], driven=np.ones(3, dtype=bool))


def test_the_tracker_drives_toes_and_heels_by_the_joints_that_do_not_move_the_ankle(human):
    from ibik_pin.tracking.tracker import Tracker

    tracker = Tracker(human)
    model = human.model
    for point, side in [("LBigToe", "left"), ("RHeel", "right")]:
        driven = tracker._foot_point_joints(point)
        names = {model.names[j] for j in range(1, model.njoints)
                 if driven[model.joints[j].idx_v:model.joints[j].idx_v + model.joints[j].nv].any()}
        # The ankle's three axes only: the hip's axial rotation would swivel a bent knee.
        assert names == {f"{side}_ankle_Y", f"{side}_ankle_Z", f"{side}_ankle_X"}
    assert tracker._foot_point_joints("LWrist") is None
