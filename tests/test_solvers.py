import numpy as np
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError, UnknownNameError
from ibik_pin.limits import JointLimits
from ibik_pin.model import load_arm
from ibik_pin.solvers import (
    DampedLeastSquaresSolver,
    HierarchicalQPSolver,
    LiegeoisSolver,
    PriorityStackSolver,
    make_solver,
)
from ibik_pin.tasks import FramePositionTask, GradientTask, PostureTask
from tests.conftest import random_human_configuration


class FrameHeight(GradientTask):
    """A real scalar criterion for solver tests: the height (world Y) of a frame, to maximise."""

    def __init__(self, body, keypoint, max_step_size=0.05):
        super().__init__(max_step_size)
        self.frame_id = body.frame_id(keypoint)

    def compute_value(self, configuration):
        return float(configuration.frame_position(self.frame_id)[1])

    def compute_gradient(self, configuration):
        return configuration.frame_translation_jacobian(self.frame_id)[1].copy()


def human_levels(body, targets_q, posture_weight=1e-2):
    """1: pelvis and feet, 2: hands and head, 3: posture; targets from the configuration."""
    configuration = Configuration(body.model, targets_q)

    def task(name):
        return FramePositionTask(body.model, name, configuration.frame_position(body.frame_id(name)).copy())

    return [
        [task("Hip"), task("LAnkle"), task("RAnkle")],
        [task("LWrist"), task("RWrist"), task("Head")],
        [PostureTask(body.model, weight=posture_weight)],
    ]


@pytest.mark.parametrize("solver_name", ["stack", "qp"])
def test_lower_levels_never_raise_a_higher_levels_residual(human, solver_name):
    rng = np.random.default_rng(7)
    limits = JointLimits(human.model) if solver_name == "qp" else None
    worst = 0.0
    for _ in range(200):
        levels = human_levels(human, random_human_configuration(human, rng))
        configuration = Configuration(human.model, random_human_configuration(human, rng))
        solver = make_solver(solver_name, limits=limits)
        residuals = [
            [report.residual for report in solver.compute_step(configuration, levels[:count]).levels]
            for count in (1, 2, 3)
        ]
        worst = max(worst, residuals[1][0] - residuals[0][0], residuals[2][0] - residuals[0][0],
                    residuals[2][1] - residuals[1][1])
    assert worst <= 1e-8


def test_qp_and_projection_stack_give_the_same_step_when_no_limit_is_active(human):
    rng = np.random.default_rng(11)
    for _ in range(20):
        levels = human_levels(human, random_human_configuration(human, rng))
        levels.insert(2, [FrameHeight(human, "RElbow")])
        configuration = Configuration(human.model, random_human_configuration(human, rng))
        stack_step = PriorityStackSolver().compute_step(configuration, levels).dq
        for level in levels:
            for task in level:
                if isinstance(task, GradientTask):
                    task.reset()
        qp_step = HierarchicalQPSolver().compute_step(configuration, levels).dq
        assert np.max(np.abs(stack_step - qp_step)) < 1e-6


def test_every_scheme_reaches_reachable_targets(human):
    rng = np.random.default_rng(3)
    levels = human_levels(human, random_human_configuration(human, rng, spread=0.4))
    for name in ["ik", "liegeois", "stack", "qp"]:
        configuration = Configuration(human.model, random_human_configuration(human, rng, spread=0.4))
        result = make_solver(name, limits=JointLimits(human.model)).solve(
            configuration, levels[:2], iterations=60
        )
        errors = [np.linalg.norm(task.compute_error(configuration)) for task in levels[0] + levels[1]]
        assert max(errors) < 1e-3, name
        assert result.iterations == 60


def test_qp_keeps_every_step_inside_the_joint_limits(human):
    """10,000 seeded steps: reachable and unreachable targets, starts at and beyond the limits."""
    rng = np.random.default_rng(2024)
    limits = JointLimits(human.model)
    solver = HierarchicalQPSolver(limits=limits)
    relaxed_seen = 0
    for episode in range(100):
        kind = episode % 4
        levels = human_levels(human, random_human_configuration(human, rng, spread=1.0))
        if kind == 1:  # unreachable: hands and head 2-3 m away
            for task in levels[1]:
                task.set_target(task.target + rng.uniform(2.0, 3.0, 3) * rng.choice([-1, 1], 3))
        q = random_human_configuration(human, rng, spread=1.0)
        if kind == 2:  # exactly at a limit on half of the joints
            at = rng.random(limits.q_index.size) < 0.5
            q[limits.q_index[at]] = np.where(rng.random(at.sum()) < 0.5, limits.lower[at], limits.upper[at])
        if kind == 3:  # outside the limits by up to 1 rad
            out = rng.random(limits.q_index.size) < 0.3
            q[limits.q_index[out]] = np.where(
                rng.random(out.sum()) < 0.5,
                limits.lower[out] - rng.uniform(0, 1, out.sum()),
                limits.upper[out] + rng.uniform(0, 1, out.sum()),
            )
        configuration = Configuration(human.model, q)
        for _ in range(100):
            was_inside = limits.violation(configuration.q) <= 1e-9
            step = solver.compute_step(configuration, levels)
            q_next = configuration.integrate(step.dq)
            if was_inside:
                assert limits.violation(q_next) <= 1e-9
            else:  # a start outside the limits is brought back by the first step
                assert limits.violation(q_next) <= 1e-9
            relaxed_seen += kind == 1 and step.levels[1].status == "relaxed"
            configuration.update(q_next)
    assert relaxed_seen > 0


def test_an_unreachable_level_is_reported_relaxed_and_the_higher_one_solved(human):
    rng = np.random.default_rng(5)
    levels = human_levels(human, random_human_configuration(human, rng, spread=0.4))
    levels[1][0].set_target(levels[1][0].target + np.array([3.0, 0.0, 0.0]))
    configuration = Configuration(human.model, random_human_configuration(human, rng, spread=0.4))
    result = HierarchicalQPSolver(limits=JointLimits(human.model)).solve(configuration, levels, iterations=40)
    assert [report.status for report in result.levels[:2]] == ["solved", "relaxed"]
    assert result.failed_levels == 0


def test_ik_ignores_the_gradient_level_and_liegeois_uses_it(human):
    rng = np.random.default_rng(9)
    levels = human_levels(human, random_human_configuration(human, rng, spread=0.4))
    levels = [levels[0] + levels[1], [FrameHeight(human, "RElbow")]]
    start = random_human_configuration(human, rng, spread=0.4)
    heights = {}
    for solver in [DampedLeastSquaresSolver(), LiegeoisSolver()]:
        configuration = Configuration(human.model, start)
        solver.solve(configuration, levels, iterations=40)
        heights[solver.name] = configuration.frame_position(human.frame_id("RElbow"))[1]
        errors = [np.linalg.norm(task.compute_error(configuration)) for task in levels[0]]
        assert max(errors) < 1e-3
    assert heights["liegeois"] > heights["ik"] + 0.005


def test_a_gradient_task_must_be_alone_in_its_level(human):
    levels = [[FramePositionTask(human.model, "Hip", [0, 0, 0]), FrameHeight(human, "RElbow")]]
    with pytest.raises(InputError, match="level 0 mixes a gradient task"):
        PriorityStackSolver().compute_step(Configuration(human.model), levels)


def test_an_unknown_solver_name_lists_the_available_ones():
    with pytest.raises(UnknownNameError, match="available: ik, liegeois, stack, qp"):
        make_solver("pink")


def test_qp_objects_are_kept_between_steps(human):
    levels = human_levels(human, random_human_configuration(human, np.random.default_rng(1)))
    # Per-step bounds so small that every level's unconstrained step violates them: QP each time.
    solver = HierarchicalQPSolver(limits=JointLimits(human.model, max_step=1e-3, max_root_translation=1e-3))
    configuration = Configuration(human.model)
    solver.compute_step(configuration, levels)
    first = {level: entry[1] for level, entry in solver._qps.items()}
    solver.compute_step(configuration, levels)
    assert len(first) == 3
    assert all(solver._qps[level][1] is qp for level, qp in first.items())


def test_proxsuite_level_solution_equals_the_damped_least_squares_step_without_active_bounds():
    """The QP path itself (not the shortcut taken when no bound is active) matches the stack."""
    from ibik_pin.solvers.nullspace import damped_solve

    rng = np.random.default_rng(4)
    solver = HierarchicalQPSolver()
    for _ in range(20):
        A, b = rng.normal(size=(9, 42)), rng.normal(size=9)
        null_basis = np.linalg.qr(rng.normal(size=(42, 30)))[0]
        projected = A @ null_basis
        hessian = projected.T @ projected + solver.damping**2 * np.eye(30)
        w_qp = solver._solve_level(0, hessian, -projected.T @ b, null_basis,
                                   np.full(42, -1e20), np.full(42, 1e20))
        w_stack, _ = damped_solve(projected, b, solver.damping)
        assert np.max(np.abs(w_qp - w_stack)) < 1e-6


class PullingAgainstTheWrist(GradientTask):
    """A criterion whose gradient mostly pulls the wrist off its target (the row space of the
    higher level) while its small null-space remainder reverses at every evaluation."""

    def __init__(self, wrist_task, max_step_size=0.05):
        super().__init__(max_step_size)
        self.wrist_task = wrist_task
        self.evaluations = 0

    def compute_value(self, configuration):
        return 0.0

    def compute_gradient(self, configuration):
        jacobian = self.wrist_task.compute_jacobian(configuration)
        null_direction = np.linalg.svd(jacobian)[2][-1]
        self.evaluations += 1
        return jacobian.T @ np.array([1.0, 0.0, 0.0]) + 0.01 * (-1) ** self.evaluations * null_direction


@pytest.mark.parametrize("solver_name", ["liegeois", "stack", "qp"])
def test_the_image_step_halves_when_its_projected_direction_reverses(solver_name):
    body = load_arm()
    configuration = Configuration(body.model, np.array([0.3, 0.4, 0.2, 0.9, 0.1, 0.5]))
    wrist = FramePositionTask(body.model, body.keypoints["Wrist"])
    wrist.set_target(configuration.frame_position(body.frame_id("Wrist")).copy())
    criterion = PullingAgainstTheWrist(wrist)
    start = configuration.q.copy()
    make_solver(solver_name, limits=JointLimits(body.model)).solve(configuration, [[wrist], [criterion]], iterations=12)
    # The raw gradient never reverses; the direction actually taken does, so the step halves at
    # every iteration (down to its floor) and the arm moves less than two first steps in all.
    assert criterion.step_size == pytest.approx(criterion.min_step_size)
    assert np.linalg.norm(configuration.q - start) < 2 * 0.05
