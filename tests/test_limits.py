import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.exceptions import InputError
from ibik_pin.limits import JointLimits
from tests.conftest import random_human_configuration


def test_limits_come_from_the_urdf(human):
    limits = JointLimits(human.model)
    assert limits.q_index.size == 38
    knee = limits.joint_names.index("left_knee_Z")
    assert limits.lower[knee] == 0.0
    assert np.isclose(limits.upper[knee], 3.14159)


def test_step_bounds_stop_at_the_limit(human):
    limits = JointLimits(human.model, max_step=0.5)
    q = pin.neutral(human.model)
    lower, upper = limits.step_bounds(q)
    knee_v = limits.v_index[limits.joint_names.index("left_knee_Z")]
    assert lower[knee_v] == 0.0  # already at the lower limit
    assert upper[knee_v] == 0.5
    assert np.all(upper[:3] == 0.5)  # root translation, step bound only


def test_a_coordinate_outside_the_limits_is_brought_back_onto_them(human):
    limits = JointLimits(human.model, max_step=0.1)
    q = pin.neutral(human.model)
    knee = limits.joint_names.index("left_knee_Z")
    q[limits.q_index[knee]] = -1.0
    lower, upper = limits.step_bounds(q)
    v = limits.v_index[knee]
    assert lower[v] == upper[v] == pytest.approx(1.0)
    assert limits.violation(q) == pytest.approx(1.0)


def test_clamp_puts_every_coordinate_inside(human, rng):
    limits = JointLimits(human.model)
    q = pin.neutral(human.model)
    q[7:] = rng.uniform(-5, 5, 38)
    clamped = limits.clamp(q)
    assert limits.violation(clamped) == 0.0
    assert limits.violation(q) > 0.0  # q itself untouched
    into = np.empty_like(q)
    assert limits.clamp(q, out=into) is into
    np.testing.assert_array_equal(into, clamped)
    assert limits.clamp(q, out=q) is q  # in place
    np.testing.assert_array_equal(q, clamped)


def test_violation_is_the_largest_distance_outside_the_limits(human, rng):
    """The compiled violation equals a plain numpy reading of the limits, inside and outside."""
    limits = JointLimits(human.model)
    for _ in range(20):
        q = pin.neutral(human.model)
        q[7:] = rng.uniform(-3, 3, 38)
        limited = q[limits.q_index]
        expected = max(0.0, float(np.max(limits.lower - limited)), float(np.max(limited - limits.upper)))
        assert limits.violation(q) == expected
    assert limits.violation(limits.clamp(q)) == 0.0


def test_at_limit_names_the_joints(human):
    limits = JointLimits(human.model)
    names = limits.at_limit(pin.neutral(human.model))
    assert "left_knee_Z" in names and "left_shoulder_Z" not in names


def test_a_non_positive_step_is_refused(human):
    with pytest.raises(InputError, match="max_step"):
        JointLimits(human.model, max_step=0.0)


def test_a_coordinate_above_its_upper_limit_is_brought_back_onto_it(human):
    limits = JointLimits(human.model, max_step=0.1)
    q = pin.neutral(human.model)
    joint = limits.joint_names.index("left_hip_X")
    q[limits.q_index[joint]] = limits.upper[joint] + 0.8
    lower, upper = limits.step_bounds(q)
    v = limits.v_index[joint]
    assert lower[v] == upper[v] == pytest.approx(-0.8)


def test_step_bounds_equal_a_plain_reading_of_the_rule(human, rng):
    """Seeded configurations inside, at and beyond the limits, against the rule coordinate by coordinate."""
    limits = JointLimits(human.model, max_step=0.3)
    for _ in range(50):
        q = random_human_configuration(human, rng)
        q[limits.q_index] = rng.uniform(limits.lower - 1.0, limits.upper + 1.0)
        lower, upper = limits.step_bounds(q)
        expected_lower, expected_upper = -limits.step.copy(), limits.step.copy()
        for k, (qi, vi) in enumerate(zip(limits.q_index, limits.v_index, strict=True)):
            low = max(-limits.step[vi], limits.lower[k] - q[qi])
            high = min(limits.step[vi], limits.upper[k] - q[qi])
            if low > high:
                low, high = (low, low) if q[qi] < limits.lower[k] else (high, high)
            expected_lower[vi], expected_upper[vi] = low, high
        assert np.array_equal(lower, expected_lower) and np.array_equal(upper, expected_upper)
