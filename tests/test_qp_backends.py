"""Tests of ibik_pin.solvers.qp_backends: the level QP as a LevelProblem, and its backends.

The trial: the first frames of the demo's real walking (CMU 35_01, ibik_pin/data) rendered into 2
calibrated cameras and read back from the files `ibik track` reads (tests/test_levels.py's Walk),
tracked with the default stack by every installed backend.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import qpsolvers

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import QPBackendError, UnknownNameError
from ibik_pin.limits import JointLimits
from ibik_pin.model import load_arm
from ibik_pin.solvers import DEFAULT_DAMPING, HierarchicalQPSolver, LevelProblem, available_qp_solvers, make_solver
from ibik_pin.solvers.qp_backends import UNBOUNDED, make_qp_backend
from ibik_pin.tasks import FramePositionTask, PostureTask
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.stack import Stack, StackError
from ibik_pin.tracking.tracker import Tracker
from tests.test_levels import Walk

# The backends every installation has: the compiled method, proxsuite's objects, and DAQP (a
# dual active-set method) through qpsolvers (the `test` extra installs it).
REQUIRED = ("active_set", "proxsuite", "daqp")
# Agreement of the tracked frames (joint angles [rad], keypoints [m]) with the default backend's.
# The active-set methods solve each level exactly: their trials agree to rounding (DAQP: 7e-13 rad
# here). proxsuite meets the bounds to its tolerance (eps_abs 1e-11 on the dual residual): 1e-10 rad
# here, through 15 steps a frame. Over longer trials a difference this small can flip where a
# frame's image steps stop (the peak rule), which moves that frame by up to a step (0.07 rad once in
# the demo's 30 frames): the agreement of whole trials is in docs/method.md.
EXACT_RAD, EXACT_M = 1e-9, 1e-9
PROXSUITE_RAD, PROXSUITE_M = 1e-7, 1e-7


@pytest.fixture(scope="module")
def walk(tmp_path_factory) -> Walk:
    return Walk(tmp_path_factory.mktemp("walk"))


@pytest.fixture(scope="module")
def trials(walk):
    """Per backend, the tracked walk and its tracker (read-ahead off: one thread, the same order)."""
    runs = {}
    for name in available_qp_solvers():
        tracker = Tracker(walk.body, walk.cameras, TrackingSettings(qp_solver=name, read_ahead="off"))
        runs[name] = tracker, tracker.track(walk.names, walk.targets, walk.silhouettes.frame)
    return runs


def test_the_backends_every_installation_needs_are_available():
    assert set(REQUIRED) <= set(available_qp_solvers())


@pytest.mark.parametrize("name", [name for name in available_qp_solvers() if name != "active_set"])
def test_every_backend_tracks_the_real_walk_as_the_default_one(walk, trials, name):
    reference = trials["active_set"][1]
    tracker, result = trials[name]
    assert tracker.solver.backend.name == name
    model = walk.body.model
    angles = np.array([pin.difference(model, q_ref, q) for q_ref, q in zip(reference.q, result.q, strict=True)])
    positions = np.linalg.norm(result.keypoints - reference.keypoints, axis=2)
    radians, metres = (PROXSUITE_RAD, PROXSUITE_M) if name in ("proxsuite", "proxqp") else (EXACT_RAD, EXACT_M)
    assert np.abs(angles).max() <= radians, name
    assert positions.max() <= metres, name
    assert all(report.status != "failed" for reports in result.level_reports for report in reports)


def _arm_level():
    body = load_arm()
    configuration = Configuration(body.model, np.array([0.3, 0.4, 0.2, 0.9, 0.1, 0.5]))
    wrist = FramePositionTask(body.model, body.keypoints["Wrist"], np.array([0.2, 0.1, 0.3]))
    return body, configuration, wrist


def test_a_level_problem_is_the_damped_least_squares_qp_of_its_rows_under_the_step_bounds():
    """Level 0 of one position task, built by hand: Z = I, H = J^T J + lambda^2 I,
    g = -J^T (-gain e), bounds the limits' step bounds."""
    body, configuration, wrist = _arm_level()
    limits = JointLimits(body.model, max_step=0.05)
    solver = HierarchicalQPSolver(limits=limits)
    (problem,) = solver.level_problems(configuration, [[wrist]])
    jacobian = wrist.compute_jacobian(configuration)
    target_change = -wrist.gain * wrist.compute_error(configuration)
    lower, upper = limits.step_bounds(configuration.q)
    np.testing.assert_allclose(problem.H, jacobian.T @ jacobian + DEFAULT_DAMPING**2 * np.eye(6), rtol=0, atol=1e-12)
    np.testing.assert_allclose(problem.g, -jacobian.T @ target_change, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(problem.C, np.eye(6))
    np.testing.assert_array_equal(problem.lower, lower)
    np.testing.assert_array_equal(problem.upper, upper)
    np.testing.assert_array_equal(problem.dq_above, np.zeros(6))
    assert problem.level == 0


def test_a_lower_levels_problem_lives_in_the_null_space_the_higher_level_leaves():
    body, configuration, wrist = _arm_level()
    posture = PostureTask(body.model, reference=np.zeros(6), coordinates=np.ones(6, dtype=bool))
    solver = HierarchicalQPSolver(limits=JointLimits(body.model, max_step=0.05))
    top, below = solver.level_problems(configuration, [[wrist], [posture]])
    jacobian = wrist.compute_jacobian(configuration)
    assert below.C.shape == (6, 3)  # the wrist's 3 rows leave 3 directions
    np.testing.assert_allclose(jacobian @ below.C, 0.0, atol=1e-10)
    np.testing.assert_allclose(below.C.T @ below.C, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(below.lower, top.lower - below.dq_above, rtol=0, atol=1e-15)
    # The step above is the top level's answer, which every backend finds.
    w = make_qp_backend("daqp").solve(top)
    np.testing.assert_allclose(below.dq_above, top.step(w), atol=1e-9)


def test_to_qpsolvers_gives_the_same_qp():
    """P and q are H and g; G w <= h holds exactly the two-sided rows, unbounded sides left out;
    qpsolvers' answer is the backend's."""
    body, configuration, wrist = _arm_level()
    (problem,) = HierarchicalQPSolver(limits=JointLimits(body.model, max_step=0.05)).level_problems(
        configuration, [[wrist]])
    converted = problem.to_qpsolvers()
    assert isinstance(converted, qpsolvers.Problem)
    np.testing.assert_array_equal(converted.P, problem.H)
    np.testing.assert_array_equal(converted.q, problem.g)
    np.testing.assert_array_equal(converted.G, np.vstack([problem.C, -problem.C]))
    np.testing.assert_array_equal(converted.h, np.concatenate([problem.upper, -problem.lower]))
    answer = qpsolvers.solve_problem(converted, solver="daqp").x
    np.testing.assert_allclose(answer, make_qp_backend("active_set").solve(problem), atol=1e-10)
    # A side at UNBOUNDED is no row.
    free = LevelProblem(0, problem.H, problem.g, problem.C, np.full(6, -UNBOUNDED), problem.upper, problem.dq_above)
    assert free.to_qpsolvers().G.shape == (6, 6)
    assert LevelProblem(0, problem.H, problem.g, problem.C, np.full(6, -UNBOUNDED), np.full(6, UNBOUNDED),
                        problem.dq_above).to_qpsolvers().G is None


@pytest.mark.parametrize("name", ["daqp", "proxsuite"])
def test_a_backend_failure_carries_its_own_status(name):
    """Bounds no w meets (lower above upper): no foreign exception, the backend's own status."""
    problem = LevelProblem(3, np.eye(2), np.ones(2), np.eye(2), np.array([1.0, 1.0]), np.array([-1.0, -1.0]),
                           np.zeros(2))
    with pytest.raises(QPBackendError) as raised:
        make_qp_backend(name).solve(problem)
    assert (raised.value.backend, raised.value.level) == (name, 3)
    assert raised.value.status
    assert str(raised.value).startswith(f"QP backend {name!r} found no answer to level 3: ")


def test_unknown_backend_names_are_refused_with_the_available_ones(walk):
    available = ", ".join(available_qp_solvers())
    with pytest.raises(UnknownNameError, match=f"unknown QP solver 'osqpp'; available: {available}$"):
        HierarchicalQPSolver(qp_solver="osqpp")
    with pytest.raises(UnknownNameError, match="available: active_set, proxsuite, "):
        make_solver("stack", qp_solver="osqpp")
    with pytest.raises(UnknownNameError, match="unknown QP solver 'osqpp'"):
        Tracker(walk.body, walk.cameras, TrackingSettings(qp_solver="osqpp"))
    with pytest.raises(StackError, match=f"test stack: key 'qp_solver': expected one of {available}, found 'osqpp'"):
        Stack.from_dict({"qp_solver": "osqpp", "level": [{"name": "targets", "tasks": [{"kind": "position"}]}]},
                        source="test stack")


def test_the_stack_files_qp_solver_key_picks_the_trackers_backend(walk):
    stack = Stack.from_dict({"qp_solver": "daqp", "level": [
        {"name": "targets", "tasks": [{"kind": "position", "keypoints": "present"}]}]}, source="test stack")
    tracker = Tracker(walk.body, walk.cameras, TrackingSettings(stack=stack))
    assert tracker.settings.qp_solver == "daqp" and tracker.solver.backend.name == "daqp"
