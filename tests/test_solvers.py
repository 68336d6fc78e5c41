import dataclasses

import numpy as np
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError, QPBackendError, SolverError, UnknownNameError
from ibik_pin.limits import JointLimits
from ibik_pin.model import load_arm
from ibik_pin.solvers import (
    DEFAULT_DAMPING,
    SOLVERS,
    DampedLeastSquaresSolver,
    HierarchicalQPSolver,
    LiegeoisSolver,
    PriorityStackSolver,
    StepAdaptation,
    available_qp_solvers,
    make_solver,
)
from ibik_pin.solvers.base import build_levels, report_levels, vector_norm
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
    worst, failed = 0.0, 0
    for _ in range(200):
        levels = human_levels(human, random_human_configuration(human, rng))
        configuration = Configuration(human.model, random_human_configuration(human, rng))
        solver = make_solver(solver_name, limits=limits)
        reports = [solver.compute_step(configuration, levels[:count]).levels for count in (1, 2, 3)]
        if any(report.status == "failed" for step in reports for report in step):
            failed += 1  # a level without a step leaves its null space to the levels below it
            continue
        residuals = [[report.residual for report in step] for step in reports]
        worst = max(worst, residuals[1][0] - residuals[0][0], residuals[2][0] - residuals[0][0],
                    residuals[2][1] - residuals[1][1])
    assert worst <= 1e-8
    # The compiled active-set method (the default backend) stops on held bounds whose rows are
    # nearly dependent, which these random starts reach in 5 of the 200 (reported "failed").
    assert failed <= 10


def test_qp_and_projection_stack_give_the_same_step_when_no_limit_is_active(human):
    rng = np.random.default_rng(11)
    for _ in range(20):
        levels = human_levels(human, random_human_configuration(human, rng))
        levels.insert(2, [FrameHeight(human, "RElbow")])
        configuration = Configuration(human.model, random_human_configuration(human, rng))
        # Each solver adapts its own image step: the stack's step leaves the QP's untouched.
        stack_step = PriorityStackSolver().compute_step(configuration, levels).dq
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


@pytest.mark.parametrize("qp_solver", available_qp_solvers())
def test_qp_keeps_every_step_inside_the_joint_limits(human, monkeypatch, qp_solver):
    """Seeded episodes of four kinds, two of each: reachable targets, unreachable targets, starts
    on the limits, starts beyond them; on every backend every step must end inside the limits, and
    the bounds must actually reach the QP (not only the unconstrained shortcut) in every kind. Levels
    whose bounds hold implicit equalities (two near-parallel rows, one at its upper bound and one at
    its lower) defeat some solves of every backend here: each is reported with its backend's status."""
    rng = np.random.default_rng(2024)
    limits = JointLimits(human.model)
    solver = HierarchicalQPSolver(limits=limits, qp_solver=qp_solver)
    kinds = ["reachable", "unreachable", "on the limits", "beyond the limits"]
    qp_solves = dict.fromkeys(kinds, 0)
    solve = solver.backend.solve

    def counting_solve(problem):
        qp_solves[kind] += 1
        return solve(problem)

    monkeypatch.setattr(solver.backend, "solve", counting_solve)
    # The compiled active-set method runs inside the compiled level loop: its QPs counted there.
    monkeypatch.setattr(solver.backend, "in_loop", False)
    relaxed_seen = 0
    for episode in range(8):
        kind = kinds[episode % 4]
        levels = human_levels(human, random_human_configuration(human, rng, spread=1.0))
        if kind == "unreachable":  # hands and head 2-3 m away
            for task in levels[1]:
                task.set_target(task.target + rng.uniform(2.0, 3.0, 3) * rng.choice([-1, 1], 3))
        q = random_human_configuration(human, rng, spread=1.0)
        if kind == "on the limits":  # exactly at a limit on half of the joints
            at = rng.random(limits.q_index.size) < 0.5
            q[limits.q_index[at]] = np.where(rng.random(at.sum()) < 0.5, limits.lower[at], limits.upper[at])
        if kind == "beyond the limits":  # outside by up to 1 rad on 30 % of the joints
            out = rng.random(limits.q_index.size) < 0.3
            q[limits.q_index[out]] = np.where(
                rng.random(out.sum()) < 0.5,
                limits.lower[out] - rng.uniform(0, 1, out.sum()),
                limits.upper[out] + rng.uniform(0, 1, out.sum()),
            )
            assert limits.violation(q) > 0.1
        configuration = Configuration(human.model, q)
        for _ in range(12):
            step = solver.compute_step(configuration, levels)
            q_next = configuration.integrate(step.dq)
            # Inside stays inside; a start outside is brought back by the first step.
            assert limits.violation(q_next) <= 1e-9, kind
            relaxed_seen += kind == "unreachable" and step.levels[1].status == "relaxed"
            for report in step.levels:
                assert (report.status == "failed") == report.detail.startswith(f"{qp_solver}: "), report
            configuration.update(q_next)
    assert relaxed_seen > 0
    assert min(qp_solves.values()) > 0, qp_solves


def test_an_unreachable_level_is_reported_relaxed_and_the_higher_one_solved(human):
    rng = np.random.default_rng(5)
    levels = human_levels(human, random_human_configuration(human, rng, spread=0.4))
    levels[1][0].set_target(levels[1][0].target + np.array([3.0, 0.0, 0.0]))
    configuration = Configuration(human.model, random_human_configuration(human, rng, spread=0.4))
    result = HierarchicalQPSolver(limits=JointLimits(human.model)).solve(configuration, levels, iterations=40)
    assert [report.status for report in result.levels[:2]] == ["solved", "relaxed"]
    assert result.failed_levels == 0


def test_ik_ignores_the_gradient_level_and_liegeois_uses_it(human):
    # Gradient steps in the null space end at another solution of the targets than plain IK's, not
    # always a higher one (on about 1 start in 10 the path ends lower), so the test takes 8 starts.
    rng = np.random.default_rng(9)
    gains = []
    for _ in range(8):
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
        gains.append(heights["liegeois"] - heights["ik"])
    assert np.median(gains) > 0.02
    assert sum(gain > 0.005 for gain in gains) >= 6


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
    solver = HierarchicalQPSolver(limits=JointLimits(human.model, max_step=1e-3, max_root_translation=1e-3),
                                  qp_solver="proxsuite")
    configuration = Configuration(human.model)
    solver.compute_step(configuration, levels)
    first = dict(solver.backend.qps)
    solver.compute_step(configuration, levels)
    assert len(first) == 3
    assert all(solver.backend.qps[key] is qp for key, qp in first.items())
    # A stack of another shape solved in between (the tracker's targets-only steps) keeps its own
    # objects and leaves these in place.
    solver.compute_step(configuration, levels[:1])
    solver.compute_step(configuration, levels)
    assert all(solver.backend.qps[key] is qp for key, qp in first.items())


@pytest.mark.parametrize("qp_solver", available_qp_solvers())
def test_every_backend_solves_a_level_to_the_damped_least_squares_step_without_active_bounds(qp_solver):
    """The QP path itself (not the shortcut taken when no bound is active) matches the stack."""
    from ibik_pin.solvers.nullspace import damped_solve
    from ibik_pin.solvers.qp_backends import LevelProblem, make_qp_backend

    rng = np.random.default_rng(4)
    backend = make_qp_backend(qp_solver)
    for _ in range(20):
        A, b = rng.normal(size=(9, 42)), rng.normal(size=9)
        null_basis = np.linalg.qr(rng.normal(size=(42, 30)))[0]
        projected = A @ null_basis
        hessian = projected.T @ projected + DEFAULT_DAMPING**2 * np.eye(30)
        problem = LevelProblem(0, hessian, -projected.T @ b, null_basis, np.full(42, -1e20), np.full(42, 1e20),
                               np.zeros(42))
        w_stack, _ = damped_solve(projected, b, DEFAULT_DAMPING)
        assert np.max(np.abs(backend.solve(problem) - w_stack)) < 1e-6


def _bounded_level(rng, n, nv, damping):
    """A least-squares level as the QP poses it: H = P'P + damping^2 I, g, an orthonormal null basis
    as the constraint and a box around w = 0 that the unconstrained optimum breaks."""
    projected = rng.normal(size=(3, n))
    hessian = projected.T @ projected + damping**2 * np.eye(n)
    linear = -projected.T @ rng.normal(size=3)
    constraint = np.linalg.qr(rng.normal(size=(nv, n)))[0]
    lower, upper = -rng.uniform(0.0, 0.3, nv), rng.uniform(0.0, 0.3, nv)
    return hessian, linear, constraint, lower, upper


def _enumerated_optimum(hessian, linear, constraint, lower, upper):
    """The QP's optimum by trying every set of active bounds (each row at its lower or upper bound,
    or free) and keeping the feasible KKT point of least cost: a plain reference for small sizes."""
    import itertools

    n, rows = hessian.shape[0], constraint.shape[0]
    best, best_cost = None, np.inf
    for sides in itertools.product((None, "lower", "upper"), repeat=rows):
        active = [i for i in range(rows) if sides[i] is not None]
        if len(active) > n:
            continue
        held = constraint[active]
        kkt = np.block([[hessian, held.T], [held, np.zeros((len(active), len(active)))]])
        targets = [lower[i] if sides[i] == "lower" else upper[i] for i in active]
        try:
            w = np.linalg.solve(kkt, np.concatenate([-linear, targets]))[:n]
        except np.linalg.LinAlgError:
            continue
        values = constraint @ w
        cost = 0.5 * w @ hessian @ w + linear @ w
        if np.all(values >= lower - 1e-12) and np.all(values <= upper + 1e-12) and cost < best_cost:
            best, best_cost = w, cost
    return best


def test_the_active_set_method_finds_the_qp_optimum_of_every_seeded_level():
    """Against every active set tried in turn (3 variables, 6 bounds), and against DAQP's dual
    active-set method on larger levels; each level's unconstrained optimum breaks a bound."""
    from ibik_pin.solvers.active_set import primal_active_set
    from ibik_pin.solvers.qp_backends import FEASIBILITY, LevelProblem, make_qp_backend

    rng = np.random.default_rng(11)
    daqp = make_qp_backend("daqp")
    solved = 0
    for n, nv, reference in [(3, 6, "enumeration")] * 30 + [(12, 44, "daqp")] * 30:
        hessian, linear, constraint, lower, upper = _bounded_level(rng, n, nv, DEFAULT_DAMPING)
        unconstrained = np.linalg.solve(hessian, -linear)
        values = constraint @ unconstrained
        if np.all((values >= lower) & (values <= upper)):
            continue
        w = primal_active_set(hessian, linear, constraint, lower, upper, FEASIBILITY)
        assert w is not None
        solved += 1
        if reference == "enumeration":
            np.testing.assert_allclose(w, _enumerated_optimum(hessian, linear, constraint, lower, upper),
                                       atol=1e-10)
        else:
            expected = daqp.solve(LevelProblem(0, hessian, linear, constraint, lower, upper, np.zeros(nv)))
            np.testing.assert_allclose(w, expected, atol=1e-8)
    assert solved >= 40


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
    solver = make_solver(solver_name, limits=JointLimits(body.model))
    solver.solve(configuration, [[wrist], [criterion]], iterations=12)
    # The raw gradient never reverses; the direction actually taken does, so the step halves at
    # every iteration (down to its floor) and the arm moves less than two first steps in all.
    assert solver.step_adaptation.step_size(criterion) == pytest.approx(criterion.min_step_size)
    assert np.linalg.norm(configuration.q - start) < 2 * 0.05


@pytest.mark.parametrize("name", list(SOLVERS))
def test_every_solver_is_built_with_the_same_keyword_only_arguments(human, name):
    limits = JointLimits(human.model)
    solver = SOLVERS[name](limits=limits, damping=0.1)
    assert (solver.limits, solver.damping) == (limits, 0.1)
    assert SOLVERS[name]().damping == DEFAULT_DAMPING
    assert make_solver(name, damping=0.2).damping == 0.2
    with pytest.raises(TypeError):
        SOLVERS[name](limits)
    with pytest.raises(TypeError):
        make_solver(name, limits)


@pytest.mark.parametrize("name", list(SOLVERS))
@pytest.mark.parametrize("damping", [0.0, -0.1, float("nan"), float("inf"), "a lot"])
def test_every_solver_refuses_a_damping_that_is_not_positive_and_finite(name, damping):
    with pytest.raises(InputError, match="damping: expected a positive finite number"):
        make_solver(name, damping=damping)


class NotANumber(FramePositionTask):
    """A position task whose Jacobian went wrong: one NaN entry."""

    def compute_jacobian(self, configuration):
        jacobian = super().compute_jacobian(configuration).copy()
        jacobian[0, 0] = np.nan
        return jacobian


@pytest.mark.parametrize("name", list(SOLVERS))
def test_a_task_with_nan_rows_raises_a_solver_error_instead_of_a_nan_step(human, name):
    levels = [[FramePositionTask(human.model, "Hip", [0.0, 0.9, 0.0])],
              [NotANumber(human.model, "LWrist", [0.3, 1.0, 0.2])]]
    configuration = Configuration(human.model)
    with pytest.raises(SolverError, match="NotANumber gave a non-finite error or Jacobian"):
        make_solver(name, limits=JointLimits(human.model)).solve(configuration, levels, iterations=3)
    assert np.isfinite(configuration.q).all()


def test_a_factorisation_of_a_non_finite_matrix_is_raised_as_a_solver_error():
    from ibik_pin.solvers import nullspace

    broken = np.ones((3, 6))
    broken[1, 2] = np.nan
    with pytest.raises(SolverError, match=r"the factors of a level's projected Jacobian \(3, 6\) failed"):
        nullspace.damped_solve(broken, np.ones(3), DEFAULT_DAMPING)
    with pytest.raises(SolverError, match=r"projected Jacobian \(3, 6\) are not positive definite"):
        nullspace.damped_step(broken, np.ones(3), DEFAULT_DAMPING)


def _svd_damped_solve(projected, residual, damping):
    """The damped least squares and null space by the SVD, the textbook reference."""
    u, sigma, vt = np.linalg.svd(projected)
    rank = int(np.count_nonzero(sigma > 1e-10 * max(1.0, sigma[0] if sigma.size else 0.0)))
    w = vt[:rank].T @ (sigma[:rank] / (sigma[:rank] ** 2 + damping**2) * (u[:, :rank].T @ residual))
    return w, vt[rank:].T


def test_the_qr_factorisation_gives_the_svds_step_and_null_space(rng):
    """Wide, square and tall levels, full rank and rank-deficient (repeated and zero rows, a zero
    column): the same step and the same null space (as a projector) as the SVD, and the last
    level's Cholesky step the same step."""
    from ibik_pin.solvers.nullspace import damped_solve, damped_step

    checked = 0
    for rows, size in [(21, 28), (18, 18), (38, 7), (9, 12), (1, 8), (44, 44), (3, 40)]:
        for deficiency in range(3):
            matrix = rng.normal(size=(rows, size))
            if deficiency == 1 and rows > 2:
                matrix[-1] = matrix[0] - 2.0 * matrix[1]
            if deficiency == 2:
                matrix[0] = 0.0
                matrix[:, -1] = 0.0
            residual = rng.normal(size=rows)
            w, remaining = damped_solve(matrix, residual, DEFAULT_DAMPING)
            w_svd, remaining_svd = _svd_damped_solve(matrix, residual, DEFAULT_DAMPING)
            np.testing.assert_allclose(w, w_svd, rtol=0, atol=1e-9 * (1 + np.abs(w_svd).max()))
            assert remaining.shape == remaining_svd.shape
            np.testing.assert_allclose(remaining.T @ remaining, np.eye(remaining.shape[1]), atol=1e-12)
            np.testing.assert_allclose(remaining @ remaining.T, remaining_svd @ remaining_svd.T, atol=1e-10)
            np.testing.assert_allclose(damped_step(matrix, residual, DEFAULT_DAMPING), w_svd, rtol=0,
                                       atol=1e-9 * (1 + np.abs(w_svd).max()))
            checked += 1
    assert checked == 21
    for zero in (np.zeros((3, 6)), np.zeros((5, 2))):  # no direction at all: no step, every direction free
        w, remaining = damped_solve(zero, np.ones(zero.shape[0]), DEFAULT_DAMPING)
        assert not w.any() and not damped_step(zero, np.ones(zero.shape[0]), DEFAULT_DAMPING).any()
        np.testing.assert_allclose(remaining @ remaining.T, np.eye(zero.shape[1]), atol=1e-12)


def test_the_residual_outside_a_range_is_the_svds(rng):
    """|r - P r| with P the projector on a matrix's range, wide, square and tall, full rank and
    rank-deficient (a dependent column, a zero row and column), against the SVD's; and nothing
    outside the range of a full-row-rank matrix, everything outside that of a zero one."""
    from ibik_pin.solvers.nullspace import range_residual

    for rows, size in [(21, 44), (18, 23), (44, 44), (44, 5), (1, 8), (7, 1)]:
        for deficiency in range(3):
            matrix = rng.normal(size=(rows, size))
            if deficiency == 1 and size > 2:
                matrix[:, -1] = matrix[:, 0] - 2.0 * matrix[:, 1]
            if deficiency == 2:
                matrix[0] = 0.0
                matrix[:, -1] = 0.0
            request = rng.normal(size=rows)
            u, sigma, _ = np.linalg.svd(matrix, full_matrices=False)
            basis = u[:, sigma > 1e-10 * max(1.0, sigma[0])]
            expected = np.linalg.norm(request - basis @ (basis.T @ request))
            assert range_residual(matrix, request) == pytest.approx(expected, abs=1e-10)
    assert range_residual(rng.normal(size=(5, 9)), rng.normal(size=5)) == pytest.approx(0.0, abs=1e-12)
    request = rng.normal(size=4)
    assert range_residual(np.zeros((4, 3)), request) == pytest.approx(np.linalg.norm(request), rel=1e-15)


def test_rows_that_each_hold_one_coordinate_take_the_qr_factorisations_step_and_null_space(rng):
    """A posture task on some coordinates (the trunk hold) skips the factorisation: the same step
    and null space as the pivoted QR, a row too weak to count (below the rank tolerance) and a zero
    row included; any other matrix is left to the QR."""
    from ibik_pin.solvers.kernels import coordinate_solve, factor
    from ibik_pin.solvers.nullspace import damped_solve

    matrix = np.zeros((5, 12))
    for row, (column, scale) in enumerate([(3, 1.0), (0, 0.1), (7, 2.5), (9, 1e-12), (5, 0.0)]):
        matrix[row, column] = scale
    residual = rng.normal(size=5)
    w, free, taken = coordinate_solve(matrix, residual, DEFAULT_DAMPING)
    assert taken
    w_qr, remaining_qr = damped_solve(matrix, residual, DEFAULT_DAMPING)
    np.testing.assert_allclose(w, w_qr, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(free, [1, 2, 4, 5, 6, 8, 9, 10, 11])
    np.testing.assert_allclose(np.eye(12)[:, free] @ np.eye(12)[free], remaining_qr @ remaining_qr.T, atol=1e-12)
    assert factor(matrix, DEFAULT_DAMPING)[0].shape[1] == 3  # the QR's rank: the weak row does not count
    shared = matrix.copy()
    shared[4, 3] = 1.0  # two rows on one coordinate
    assert not coordinate_solve(shared, residual, DEFAULT_DAMPING)[2]
    mixed = matrix.copy()
    mixed[0, 4] = 0.5  # a row on two coordinates
    assert not coordinate_solve(mixed, residual, DEFAULT_DAMPING)[2]


def test_a_level_a_backend_solves_hands_on_the_null_space_it_leaves_even_when_none_is_left():
    """A full-rank top level (a posture on every coordinate of the arm) that the bounds reach,
    solved by each backend: the level below it gets no freedom, so the step is the top level's alone."""
    body = load_arm()
    configuration = Configuration(body.model, np.array([0.3, 0.4, 0.2, 0.9, 0.1, 0.5]))
    posture = PostureTask(body.model, reference=np.array([1.0, -0.5, 0.8, 0.1, 0.9, -0.4]),
                          coordinates=np.ones(body.model.nv, dtype=bool))
    wrist = FramePositionTask(body.model, body.keypoints["Wrist"], np.array([0.2, 0.1, 0.3]))
    limits = JointLimits(body.model, max_step=0.05)  # the posture's step leaves this box
    for qp_solver in available_qp_solvers():
        solver = HierarchicalQPSolver(limits=limits, qp_solver=qp_solver, raise_on_failure=True)
        alone = solver.compute_step(configuration, [[posture]]).dq
        stacked = solver.compute_step(configuration, [[posture], [wrist]]).dq
        assert np.abs(alone).max() == pytest.approx(0.05)  # the bounds were reached
        np.testing.assert_allclose(stacked, alone, rtol=0, atol=1e-9)


def test_a_proxsuite_failure_is_reported_with_its_status_or_raised(human, monkeypatch):
    """No foreign exception leaks: the level reads "failed" with proxsuite's own words in its
    detail, or, with raise_on_failure, a QPBackendError carries them."""
    import proxsuite

    class BrokenQP:
        def __init__(self, *arguments):
            raise RuntimeError("proxsuite could not allocate")

    monkeypatch.setattr(proxsuite.proxqp.dense, "QP", BrokenQP)
    levels = human_levels(human, random_human_configuration(human, np.random.default_rng(1)))
    # Per-step bounds so small that every level needs the QP.
    limits = JointLimits(human.model, max_step=1e-3, max_root_translation=1e-3)
    solver = HierarchicalQPSolver(limits=limits, qp_solver="proxsuite")
    result = solver.solve(Configuration(human.model), levels, iterations=2)
    # The posture level, after two skipped levels, fits its bounds without a QP.
    assert [report.status for report in result.levels] == ["failed", "failed", "solved"]
    assert result.levels[0].detail == "proxsuite: RuntimeError: proxsuite could not allocate"
    assert result.failed_levels == 2
    strict = HierarchicalQPSolver(limits=limits, qp_solver="proxsuite", raise_on_failure=True)
    with pytest.raises(QPBackendError, match="could not allocate") as raised:
        strict.solve(Configuration(human.model), levels, iterations=2)
    assert (raised.value.backend, raised.value.level) == ("proxsuite", 0)


def test_a_proxsuite_status_other_than_solved_is_raised_with_its_name():
    """A level proxsuite cannot finish in one iteration: its own status comes out, by name."""
    from ibik_pin.solvers.qp_backends import LevelProblem, ProxsuiteBackend

    rng = np.random.default_rng(3)
    hessian, linear, constraint, lower, upper = _bounded_level(rng, 12, 44, DEFAULT_DAMPING)
    with pytest.raises(QPBackendError, match="PROXQP_MAX_ITER_REACHED after 1 iterations"):
        ProxsuiteBackend(max_iterations=1).solve(LevelProblem(0, hessian, linear, constraint, lower, upper,
                                                              np.zeros(44)))


def test_the_step_adaptation_halves_on_reversal_grows_while_it_holds_and_resets():
    criterion = FrameHeight.__new__(FrameHeight)
    GradientTask.__init__(criterion, max_step_size=0.05, min_step_size=0.01)
    adaptation = StepAdaptation()
    east, west = np.array([1.0, 0.0]), np.array([-1.0, 0.0])
    assert adaptation.step_size(criterion) == 0.05
    assert adaptation.adapt(criterion, east) == 0.05  # the first step: nothing to compare with
    assert adaptation.adapt(criterion, west) == 0.025
    assert adaptation.adapt(criterion, east) == 0.0125
    assert adaptation.adapt(criterion, west) == 0.01  # floor: min_step_size
    assert adaptation.adapt(criterion, west) == pytest.approx(0.012)
    for _ in range(10):
        adaptation.adapt(criterion, west)
    assert adaptation.step_size(criterion) == 0.05  # ceiling: max_step_size
    adaptation.adapt(criterion, east)
    adaptation.reset()
    assert adaptation.step_size(criterion) == 0.05
    assert adaptation.adapt(criterion, west) == 0.05  # a reset forgets the previous direction too


def test_a_gradient_task_holds_no_solver_state_and_each_solver_adapts_its_own_step():
    body = load_arm()
    configuration = Configuration(body.model, np.array([0.3, 0.4, 0.2, 0.9, 0.1, 0.5]))
    wrist = FramePositionTask(body.model, body.keypoints["Wrist"])
    wrist.set_target(configuration.frame_position(body.frame_id("Wrist")).copy())
    criterion = PullingAgainstTheWrist(wrist)
    stack, qp = PriorityStackSolver(), HierarchicalQPSolver()
    before = {key: value for key, value in vars(criterion).items() if key != "evaluations"}
    stack.solve(configuration, [[wrist], [criterion]], iterations=12)
    assert {key: value for key, value in vars(criterion).items() if key != "evaluations"} == before
    assert stack.step_adaptation.step_size(criterion) == pytest.approx(criterion.min_step_size)
    assert qp.step_adaptation.step_size(criterion) == criterion.max_step_size
    stack.solve(configuration, [[wrist], [criterion]], iterations=1)  # a new solve starts afresh
    assert stack.step_adaptation.step_size(criterion) == criterion.max_step_size


def test_the_solvers_vector_norm_is_numpys_to_the_bit():
    rng = np.random.default_rng(12)
    for size in (1, 3, 8, 44, 1000):
        for scale in (1e-12, 1.0, 1e8):
            vector = rng.normal(size=size) * scale
            assert vector_norm(vector) == np.linalg.norm(vector)
    assert vector_norm(np.zeros(5)) == 0.0


@pytest.mark.parametrize("name", ["stack", "qp"])
def test_a_steps_reports_read_later_are_those_of_the_step(human, rng, name):
    """The reports are computed when first read; from the step's own dq and levels, whatever
    happens to the returned dq or the configuration afterwards."""
    solver = make_solver(name, limits=JointLimits(human.model))
    configuration = Configuration(human.model, random_human_configuration(human, rng))
    levels = [[FramePositionTask(human.model, human.keypoints[keypoint], rng.normal(0.0, 0.4, 3) + [0.0, 1.0, 0.0])]
              for keypoint in ("LWrist", "RAnkle")]
    levels.append([PostureTask(human.model)])
    step = solver.compute_step(configuration, levels)
    expected = report_levels(build_levels(configuration, levels), step.dq)
    step.dq[:] = 0.0
    configuration.update(random_human_configuration(human, rng))
    assert step.levels is step.levels
    np.testing.assert_equal([dataclasses.astuple(report) for report in step.levels],  # NaN values equal
                            [dataclasses.astuple(report) for report in expected])


def test_the_compiled_bound_check_is_numpys(rng):
    """Inside, on the bounds, outside by one coordinate, and NaN (never inside)."""
    from ibik_pin.solvers.active_set import within_bounds

    lower, upper = -rng.uniform(0.1, 1.0, 44), rng.uniform(0.1, 1.0, 44)
    cases = [rng.uniform(lower, upper), lower.copy(), upper.copy()]
    for index, value in [(0, 2.0), (43, -2.0), (20, np.nan)]:
        outside = rng.uniform(lower, upper)
        outside[index] = value
        cases.append(outside)
    answers = [within_bounds(values, lower, upper) for values in cases]
    assert answers == [bool((values >= lower).all() and (values <= upper).all()) for values in cases]
    assert answers == [True, True, True, False, False, False]


@pytest.mark.parametrize("solver_name", ["stack", "qp", "liegeois", "ik"])
def test_a_solve_planned_once_equals_its_steps_planned_each_time(human, solver_name):
    """Solver.solve plans its levels once (LevelPlan, with the position rows' constants kept): the
    same motion, to the bit, as steps that each plan the levels afresh, targets changed between."""
    rng = np.random.default_rng(11)
    limits = JointLimits(human.model)
    solver = make_solver(solver_name, limits=limits)
    levels = human_levels(human, random_human_configuration(human, rng))
    levels.insert(2, [FrameHeight(human, "LElbow")])  # a gradient level, as the image's
    start = random_human_configuration(human, rng)
    stepped = Configuration(human.model, start)
    solved = Configuration(human.model, start)
    for _ in range(2):  # two solves, the targets moved between them
        solver.solve(solved, levels, iterations=6)
        solver.step_adaptation.reset()
        for _ in range(6):
            step = solver.compute_step(stepped, levels)
            stepped.update(limits.clamp(stepped.integrate(step.dq)))  # what Configuration.move does
        np.testing.assert_array_equal(solved.q, stepped.q)
        for task in levels[1]:
            task.set_target(task.target + rng.normal(0.0, 0.05, 3))


@pytest.mark.parametrize("solver_name", ["liegeois", "stack", "qp"])
def test_a_solve_stopped_at_the_peak_is_the_counted_solve_cut_at_its_best_step(solver_name):
    """The elbow raised with the wrist held: steps of 0.3 rad overshoot the highest elbow and the
    criterion falls. stop_at_peak ends the solve there: its motion is the counted solve's up to
    that step, to the bit, and so are the level reports; the criterion is the highest of every
    count of steps from one up to it; the step undone does not raise it."""
    body = load_arm()
    start = np.array([0.3, 0.4, 0.2, 0.9, 0.1, 0.5])
    wrist = FramePositionTask(body.model, body.keypoints["Wrist"])
    wrist.set_target(Configuration(body.model, start).frame_position(body.frame_id("Wrist")).copy())
    criterion = FrameHeight(body, "Elbow", max_step_size=0.3)
    levels = [[wrist], [criterion]]
    solver = make_solver(solver_name, limits=JointLimits(body.model))

    def counted(steps):
        configuration = Configuration(body.model, start)
        solver.solve(configuration, levels, iterations=steps)
        return configuration

    peaked = Configuration(body.model, start)
    result = solver.solve(peaked, levels, iterations=40, stop_at_peak=True)
    assert 2 <= result.iterations < 40
    assert result.step_norms.shape == (result.iterations,)
    np.testing.assert_array_equal(peaked.q, counted(result.iterations).q)
    counted_result = solver.solve(Configuration(body.model, start), levels, iterations=result.iterations)
    np.testing.assert_equal([dataclasses.astuple(report) for report in result.levels],
                            [dataclasses.astuple(report) for report in counted_result.levels])
    heights = [criterion.compute_value(counted(steps)) for steps in range(1, result.iterations + 2)]
    assert criterion.compute_value(peaked) == max(heights[:-1])
    assert heights[-1] <= heights[-2]


@pytest.mark.parametrize("solver_name", ["liegeois", "stack", "qp"])
def test_a_solve_stopped_at_the_peak_computes_no_step_past_it(solver_name):
    """The criterion is read before the next step is computed, so a solve stopped at the peak
    computes the steps it keeps and the one it undoes, and none beyond (the criterion's fall used
    to be read off one more whole step: its levels' rows and QPs)."""
    body = load_arm()
    start = np.array([0.3, 0.4, 0.2, 0.9, 0.1, 0.5])
    wrist = FramePositionTask(body.model, body.keypoints["Wrist"])
    wrist.set_target(Configuration(body.model, start).frame_position(body.frame_id("Wrist")).copy())
    levels = [[wrist], [FrameHeight(body, "Elbow", max_step_size=0.3)]]
    solver = make_solver(solver_name, limits=JointLimits(body.model))
    computed = []
    step = solver.compute_step
    solver.compute_step = lambda *arguments: computed.append(1) or step(*arguments)  # type: ignore[method-assign]
    result = solver.solve(Configuration(body.model, start), levels, iterations=40, stop_at_peak=True)
    assert 2 <= result.iterations < 40
    assert len(computed) == result.iterations + 1


@pytest.mark.parametrize("solver_name", ["stack", "qp"])
def test_stopping_at_the_peak_changes_nothing_without_a_gradient_level(human, solver_name):
    rng = np.random.default_rng(5)
    levels = human_levels(human, random_human_configuration(human, rng))
    start = random_human_configuration(human, rng)
    solver = make_solver(solver_name, limits=JointLimits(human.model))
    runs = []
    for stop_at_peak in (False, True):
        configuration = Configuration(human.model, start)
        runs.append((solver.solve(configuration, levels, iterations=8, stop_at_peak=stop_at_peak), configuration.q))
    assert runs[0][0].iterations == runs[1][0].iterations == 8
    np.testing.assert_array_equal(runs[0][1], runs[1][1])


def test_a_plans_packed_levels_are_refilled_step_to_step_and_rebuilt_when_their_layout_changes(human, rng):
    """StepWorkspace: the next step of the same plan reuses the arrays, holding what a fresh packing
    holds; levels of another shape get a new packing, and a later plan (the next solve) the arrays
    kept for its layout, refilled."""
    from ibik_pin.solvers.base import LevelPlan
    from ibik_pin.solvers.level_loop import PackedLevels, StepWorkspace

    levels = human_levels(human, random_human_configuration(human, rng))
    levels.insert(2, [FrameHeight(human, "LElbow")])
    plan = LevelPlan.of(levels)
    adaptation = StepAdaptation()
    workspace = StepWorkspace()
    configuration = Configuration(human.model, random_human_configuration(human, rng))
    first = workspace.packed(build_levels(configuration, levels, plan), plan, adaptation, human.model.nv)
    configuration.update(random_human_configuration(human, rng))
    built = build_levels(configuration, levels, plan)
    again = workspace.packed(built, plan, adaptation, human.model.nv)
    fresh = PackedLevels(built, adaptation, human.model.nv)
    assert again is first
    for name in ("kinds", "rows", "targets", "row_starts", "adaptation", "previous", "steps"):
        np.testing.assert_array_equal(getattr(again, name), getattr(fresh, name))
    # The same plan object with a level of fewer rows (as a task switched off would give).
    shorter = list(built)
    shorter[0] = dataclasses.replace(built[0], A=built[0].A[:3], b=built[0].b[:3])
    rebuilt = workspace.packed(shorter, plan, adaptation, human.model.nv)
    assert rebuilt is not first
    assert rebuilt.rows.shape[0] == fresh.rows.shape[0] - (built[0].A.shape[0] - 3)
    assert workspace.packed(shorter, plan, adaptation, human.model.nv) is rebuilt
    assert workspace.packed(shorter, LevelPlan.of(levels), adaptation, human.model.nv) is rebuilt
    back = workspace.packed(built, LevelPlan.of(levels), adaptation, human.model.nv)
    assert back is first
    for name in ("kinds", "rows", "targets", "row_starts", "adaptation", "previous", "steps"):
        np.testing.assert_array_equal(getattr(back, name), getattr(fresh, name))
    assert workspace.packed(built, LevelPlan.of(levels), StepAdaptation(), human.model.nv) is not first
    # A stack that keeps changing shape: at most a bounded number of layouts kept, each packing right.
    assert built[-1].A.shape[0] > 20  # more layouts than are kept
    for rows in range(1, built[-1].A.shape[0] + 1):
        varied = list(built)
        varied[-1] = dataclasses.replace(built[-1], A=built[-1].A[:rows], b=built[-1].b[:rows])
        packed = workspace.packed(varied, LevelPlan.of(levels), adaptation, human.model.nv)
        np.testing.assert_array_equal(packed.rows, PackedLevels(varied, adaptation, human.model.nv).rows)
    assert len(workspace._by_layout) <= 16
    assert workspace.identity(human.model.nv) is workspace.identity(human.model.nv)
    np.testing.assert_array_equal(workspace.identity(5), np.eye(5))


def test_a_packing_holds_its_gradient_levels_adaptation_where_the_solver_reads_it(human, rng):
    """PackedLevels keeps a gradient task's step adaptation in its own arrays (StepAdaptation.hold):
    what the compiled loop adapts is the solver's state, read back without a copy; a second packing
    of another layout takes the state over where the first left it, and the first takes it back;
    after a reset every packing starts again from max_step_size."""
    from ibik_pin.solvers.base import LevelPlan
    from ibik_pin.solvers.kernels import HAS_PREVIOUS, STEP_SIZE
    from ibik_pin.solvers.level_loop import PackedLevels

    criterion = FrameHeight(human, "LElbow")
    levels = human_levels(human, random_human_configuration(human, rng))
    levels.insert(2, [criterion])
    configuration = Configuration(human.model, random_human_configuration(human, rng))
    adaptation = StepAdaptation()
    nv = human.model.nv
    built = build_levels(configuration, levels, LevelPlan.of(levels))
    shorter = list(built)
    shorter[0] = dataclasses.replace(built[0], A=built[0].A[:3], b=built[0].b[:3])
    first = PackedLevels(built, adaptation, nv)
    state, previous = adaptation.state(criterion, nv)
    assert np.shares_memory(state, first.adaptation) and np.shares_memory(previous, first.previous)
    direction = rng.normal(size=nv)
    adaptation.adapt(criterion, direction)
    adaptation.adapt(criterion, -direction)  # a reversal halves the step
    assert first.adaptation[2, STEP_SIZE] == criterion.max_step_size / 2
    second = PackedLevels(shorter, adaptation, nv)
    np.testing.assert_array_equal(second.adaptation[2], first.adaptation[2])
    np.testing.assert_array_equal(second.previous[2], -direction)
    assert adaptation.step_size(criterion) == criterion.max_step_size / 2
    adaptation.adapt(criterion, -direction)  # held by the second packing now: grows there
    assert second.adaptation[2, STEP_SIZE] == pytest.approx(0.6 * criterion.max_step_size)
    assert first.load(built)
    np.testing.assert_array_equal(first.adaptation[2], second.adaptation[2])
    adaptation.reset()
    assert second.load(shorter)
    assert second.adaptation[2, STEP_SIZE] == criterion.max_step_size and second.adaptation[2, HAS_PREVIOUS] == 0.0
    np.testing.assert_array_equal(second.previous[2], np.zeros(nv))
