import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.model import load_arm
from tests.conftest import random_human_configuration


def test_frame_jacobians_match_finite_differences_on_the_human(human, rng):
    q = random_human_configuration(human, rng)
    configuration = Configuration(human.model, q)
    frame_ids = human.frame_ids(["LWrist", "Head", "RBigToe"])
    jacobians = configuration.frame_translation_jacobians(frame_ids)
    positions = configuration.frame_positions(frame_ids)
    eps = 1e-7
    numeric = np.zeros_like(jacobians)
    for k in range(human.model.nv):
        dv = np.zeros(human.model.nv)
        dv[k] = eps
        shifted = Configuration(human.model, pin.integrate(human.model, q, dv))
        numeric[:, :, k] = (shifted.frame_positions(frame_ids) - positions) / eps
    assert np.linalg.norm(numeric - jacobians) / np.linalg.norm(jacobians) < 1e-4


def test_update_gives_a_new_version_and_refreshes_positions(human, rng):
    configuration = Configuration(human.model)
    other = Configuration(human.model)
    version = configuration.version
    frame = human.frame_id("LWrist")
    before = configuration.frame_position(frame).copy()
    configuration.update(random_human_configuration(human, rng))
    assert configuration.version not in (version, other.version)
    assert not np.allclose(before, configuration.frame_position(frame))


def test_a_configuration_of_the_wrong_size_is_refused(human):
    with pytest.raises(InputError, match=r"shape \(45,\)"):
        Configuration(human.model, np.zeros(38))


def test_a_non_finite_configuration_is_refused(human):
    q = pin.neutral(human.model)
    q[10] = np.nan
    with pytest.raises(InputError, match="finite"):
        Configuration(human.model, q)


def test_a_move_is_the_integrated_step_clamped_into_the_limits_and_updated(human, rng):
    """Configuration.move(dq, limits): the q of integrate + clamp + update, to the bit, with the
    kinematics updated; a step of the wrong size or not finite is refused, q left as it was."""
    from ibik_pin.limits import JointLimits

    limits = JointLimits(human.model)
    start = random_human_configuration(human, rng)
    dq = rng.normal(0.0, 1.0, human.model.nv)  # large enough to leave some limits
    for bound in (None, limits):
        moved, updated = Configuration(human.model, start), Configuration(human.model, start)
        version = moved.version
        moved.move(dq, bound)
        q = updated.integrate(dq)
        updated.update(q if bound is None else bound.clamp(q))
        np.testing.assert_array_equal(moved.q, updated.q)
        assert moved.version != version
        frame_ids = human.frame_ids(["LWrist", "RAnkle"])
        np.testing.assert_array_equal(moved.frame_positions(frame_ids), updated.frame_positions(frame_ids))
        np.testing.assert_array_equal(moved.frame_translation_jacobians(frame_ids),
                                      updated.frame_translation_jacobians(frame_ids))
    assert limits.violation(Configuration(human.model, start).integrate(dq)) > 0.1  # the clamp did work
    configuration = Configuration(human.model, start)
    for bad, message in ((np.zeros(human.model.nv - 1), r"of shape \(44,\), got shape \(43,\)"),
                         (np.full(human.model.nv, np.nan), "NaN or infinity")):
        with pytest.raises(InputError, match=message):
            configuration.move(bad, limits)
        np.testing.assert_array_equal(configuration.q, start)


def test_frame_positions_follow_every_update_as_pinocchio_gives_them(human, rng):
    configuration = Configuration(human.model)
    data = human.model.createData()
    frames = np.arange(human.model.nframes)
    for _ in range(5):
        q = random_human_configuration(human, rng)
        configuration.update(q)
        pin.framesForwardKinematics(human.model, data, q)
        expected = np.array([data.oMf[int(frame)].translation for frame in frames])
        assert np.array_equal(configuration.frame_positions(frames), expected)
        assert np.array_equal(configuration.frame_position(int(frames[-1])), expected[-1])


def test_frames_asked_in_turn_read_pinocchios_positions_by_the_strided_view_and_without_it(human, rng):
    """The one view over data.oMf's translations (and the frame-by-frame read where it is not
    used) give Pinocchio's positions, for sets of frames that grow as the tasks ask."""
    data = human.model.createData()
    for strided in (True, False):
        configuration = Configuration(human.model)
        assert (configuration._translations is not None) is True  # the layout the view needs, seen
        if not strided:
            configuration._translations = None
        for frames in (np.array([3, 8]), np.array([8, 20, 5]), np.arange(human.model.nframes)[::-1]):
            q = random_human_configuration(human, rng)
            configuration.update(q)
            pin.framesForwardKinematics(human.model, data, q)
            expected = np.array([data.oMf[int(frame)].translation for frame in frames])
            assert np.array_equal(configuration.frame_positions(frames), expected)


def test_frame_jacobians_are_pinocchios_for_every_frame_and_follow_updates(human, rng):
    """All at once from the joint Jacobians, as getFrameJacobian (LOCAL_WORLD_ALIGNED) gives them one
    frame at a time, on the free-flyer human and the fixed-base arm; a single frame's too."""
    arm = load_arm()
    for body in (human, arm):
        configuration = Configuration(body.model)
        frames = np.arange(body.model.nframes)
        for _ in range(5):
            q = random_human_configuration(body, rng) if body is human else rng.uniform(-2.0, 2.0, arm.model.nq)
            configuration.update(q)
            expected = np.stack([pin.getFrameJacobian(body.model, configuration.data, int(frame),
                                                      pin.LOCAL_WORLD_ALIGNED)[:3] for frame in frames])
            np.testing.assert_allclose(configuration.frame_translation_jacobians(frames), expected, rtol=0, atol=1e-13)
            np.testing.assert_allclose(configuration.frame_translation_jacobian(int(frames[-1])), expected[-1],
                                       rtol=0, atol=1e-13)


def test_a_gradient_on_frame_positions_pulls_back_through_pinocchios_jacobians(human, rng):
    """velocity_gradient: sum over frames of g_k . J_k / count, J_k from getFrameJacobian, for frames
    asked in any order (repeated too) and read before or not; the positions' view stays Pinocchio's."""
    configuration = Configuration(human.model)
    for frames in (np.array([3, 8, 20]), np.array([20, 3, 3, 11]), np.arange(human.model.nframes)[::-1].copy()):
        q = random_human_configuration(human, rng)
        configuration.update(q)
        frame_gradient = rng.normal(size=(len(frames), 3))
        expected = sum(frame_gradient[k] @ pin.getFrameJacobian(human.model, configuration.data, int(frame),
                                                               pin.LOCAL_WORLD_ALIGNED)[:3]
                       for k, frame in enumerate(frames)) / 7.0
        np.testing.assert_allclose(configuration.velocity_gradient(frames, frame_gradient, 7.0), expected,
                                   rtol=0, atol=1e-12)
        positions, _ = configuration.frame_arrays(frames)
        data = human.model.createData()
        pin.framesForwardKinematics(human.model, data, q)
        assert np.array_equal(positions[frames], [data.oMf[int(frame)].translation for frame in frames])


def test_frame_reads_are_kept_read_only_until_the_next_update(human, rng):
    """A set of frames asked again gives the same array, which no caller can change; an update
    gives new positions."""
    configuration = Configuration(human.model, random_human_configuration(human, rng))
    frames = human.frame_ids(["LWrist", "Head"])
    for read in (configuration.frame_positions, configuration.frame_translation_jacobians):
        first = read(frames)
        assert read(frames) is first
        with pytest.raises(ValueError, match="read-only"):
            first[0, 0] = 1.0
    before = configuration.frame_positions(frames)
    configuration.update(random_human_configuration(human, rng))
    assert not np.allclose(configuration.frame_positions(frames), before)


@pytest.mark.parametrize("model_name", ["human", "arm"])
def test_the_fast_read_of_frame_translations_matches_pinocchios_api(human, rng, model_name):
    """The strided view over data.oMf (Configuration's fast read, measured 20x faster than the API's
    frame-by-frame read) relies on Pinocchio's memory layout: this fails the day that layout changes,
    rather than the code falling back silently to the slow read."""
    import gc

    model = human.model if model_name == "human" else load_arm().model
    configuration = Configuration(model)
    view = configuration._translations
    assert view is not None, "data.oMf no longer keeps its SE3s at equal distances in memory"
    for _ in range(3):
        q = (random_human_configuration(human, rng) if model_name == "human"
             else rng.uniform(model.lowerPositionLimit, model.upperPositionLimit))
        configuration.update(q)
        gc.collect()
        expected = np.array([configuration.data.oMf[frame].translation for frame in range(model.nframes)])
        np.testing.assert_array_equal(view, expected)
        ids = np.arange(model.nframes, dtype=np.int64)
        np.testing.assert_array_equal(configuration.frame_positions(ids), expected)
