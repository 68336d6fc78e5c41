"""What every solver shares: levels of tasks in, one step out, and the iteration loop.

`levels` is a list of priority levels, highest first; each level is a list of tasks. A level holds
either least-squares tasks (`Task`, rows stacked with their weights) or exactly one `GradientTask`
(the image criterion). Priority is an argument of the solver, never a property of a task: the same
task objects run through every solver.

Every solver is built the same way, with keyword arguments only:
``Scheme(limits=None, damping=DEFAULT_DAMPING)`` (the QP adds its backend settings); a solver owns
the adaptation of its image steps (:class:`~ibik_pin.solvers.step_adaptation.StepAdaptation`).
"""

from __future__ import annotations

import itertools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ibik_pin.checks import all_finite
from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError, SolverError
from ibik_pin.limits import JointLimits
from ibik_pin.solvers.status import LevelStatus
from ibik_pin.solvers.step_adaptation import StepAdaptation
from ibik_pin.tasks.base import GradientTask, Task

Levels = Sequence[Sequence[Task | GradientTask]]

# Damping lambda of every scheme [units of the task Jacobians, m/rad], one rule for all: a
# positive finite number, the weight of |dq|^2 being lambda^2 in each level's least squares
# (the damped pseudo-inverse J^T (J J^T + lambda^2 I)^-1 of the projection schemes, the QP's
# regulariser). The standing human at its neutral pose is singular (straight knees and elbows) and
# 1e-3 lets the first steps blow up to tens of radians; 3e-2 converges on whole-body targets in a
# few steps.
DEFAULT_DAMPING = 3e-2


def vector_norm(vector: np.ndarray) -> float:
    """|v|, the same float as np.linalg.norm (the square root of v.v) without its wrapper's
    microseconds, which add up over the several norms of every step."""
    return math.sqrt(vector.dot(vector))


@dataclass
class LeastSquaresLevel:
    """Rows A dq ~= b of the enabled least-squares tasks of one level."""

    A: np.ndarray  # (m, nv)
    b: np.ndarray  # (m,)


@dataclass
class GradientLevel:
    """Ascent along a unit direction with a step norm the solver adapts to the direction taken
    (its StepAdaptation, once per step, on the direction projected into the higher levels' null
    space)."""

    direction: np.ndarray  # (nv,) unit gradient, zeros when it vanishes
    value: float  # the criterion h(q) before the step
    task: GradientTask
    step_size: float = 0.0  # the norm the step took (0: none)


@dataclass
class LevelReport:
    """What one level got at a step.

    Attributes:
        kind: "tasks" (least squares) or "gradient".
        residual: |A dq - b| of a least-squares level after the step (NaN for a gradient level).
        value: the criterion h(q) of a gradient level before the step (NaN otherwise).
        status: the level's LevelStatus (each member's `definition` says what it means).
        detail: the QP backend's own status when the level failed (e.g. "proxsuite:
            PROXQP_MAX_ITER_REACHED"), else "".
    """

    kind: str
    residual: float
    value: float
    status: LevelStatus
    detail: str = ""


class StepResult:
    """One step: dq (nv,), the report of every level, and `criterion`: the first gradient level's
    h(q) before the step (NaN without one), which `Solver.solve` watches with `stop_at_peak`.

    The reports may be given as a function that computes them, called when they are first read: a
    solve reads its last step's only, and a report costs a residual per level.
    """

    def __init__(self, dq: np.ndarray, levels: list[LevelReport] | Callable[[], list[LevelReport]],
                 criterion: float = float("nan")) -> None:
        self.dq = dq
        self._levels = levels
        self.criterion = criterion

    @property
    def levels(self) -> list[LevelReport]:
        if callable(self._levels):
            self._levels = self._levels()
        return self._levels


@dataclass
class SolveResult:
    """The outcome of `Solver.solve`.

    Attributes:
        q: final configuration, shape (nq,).
        iterations: steps taken.
        levels: the reports of the last step, one per level.
        step_norms: |dq| of every step, shape (iterations,).
        limit_violation: how far [rad] the final q leaves the joint limits (0 inside, NaN without).
    """

    q: np.ndarray
    iterations: int
    levels: list[LevelReport]
    step_norms: np.ndarray
    limit_violation: float = float("nan")
    failed_levels: int = field(default=0)


@dataclass(frozen=True)
class LevelPlan:
    """What each level evaluates, fixed for the steps of one solve (tasks are switched on and off,
    and given their targets, between solves, not during one): per level None (no enabled task), its
    gradient task, or its enabled least-squares tasks in runs of one class (each run's rows stacked
    in one call, with a memo of what stays the same over the solve: Task.stacked_linear_system).

    Attributes:
        levels: the levels planned (the scheme's arranged levels).
        entries: per level, None, a GradientTask, or a tuple of runs, each (tasks of one class, memo).
        criterion_level: the first gradient level (None without one), whose h(q) a step reports.
    """

    levels: Levels
    entries: tuple
    criterion_level: int | None = None

    @classmethod
    def of(cls, levels: Levels) -> LevelPlan:
        """The plan of the levels as their tasks are enabled now.

        Raises:
            InputError: a gradient task shares its level with other tasks.
        """
        entries: list = []
        for index, level in enumerate(levels):
            tasks = [task for task in level if task.enabled]
            gradient_tasks = [task for task in tasks if isinstance(task, GradientTask)]
            if gradient_tasks:
                if len(tasks) != 1:
                    raise InputError(
                        f"level {index} mixes a gradient task with other tasks: a gradient task "
                        "(the image criterion) must be alone in its level"
                    )
                entries.append(gradient_tasks[0])
            elif tasks:
                entries.append(tuple((list(run), {}) for _, run in itertools.groupby(tasks, key=type)))
            else:
                entries.append(None)
        gradients = [index for index, entry in enumerate(entries) if isinstance(entry, GradientTask)]
        return cls(levels, tuple(entries), gradients[0] if gradients else None)

    def criterion(self, built: list) -> float:
        """h(q) of the first gradient level of `built` (build_levels on this plan), NaN without one."""
        return float("nan") if self.criterion_level is None else built[self.criterion_level].value


def build_levels(configuration: Configuration, levels: Levels, plan: LevelPlan | None = None) -> list:
    """Evaluate the levels at the configuration: LeastSquaresLevel / GradientLevel / None (empty).

    Args:
        configuration: the state the step starts from.
        levels: priority levels, highest first.
        plan: the levels' LevelPlan, when one solve's steps share it (made here otherwise).

    Raises:
        InputError: a gradient task shares its level with other tasks.
        SolverError: a least-squares task gives a non-finite error or Jacobian: no step exists.
    """
    built: list[LeastSquaresLevel | GradientLevel | None] = []
    for entry in (plan or LevelPlan.of(levels)).entries:
        if entry is None:
            built.append(None)
        elif type(entry) is not tuple:  # a gradient task (not isinstance: GradientTask's ABC check is slower)
            built.append(GradientLevel(entry.compute_direction(configuration), entry.compute_value(configuration),
                                       entry))
        else:
            blocks = [type(run[0]).stacked_linear_system(run, configuration, memo) for run, memo in entry]
            level_rows = (LeastSquaresLevel(*blocks[0]) if len(blocks) == 1 else
                          LeastSquaresLevel(np.vstack([A for A, _ in blocks]), np.concatenate([b for _, b in blocks])))
            # NaN rows would turn the whole step, then q, into NaN without a word. One check of the
            # level's rows (tasks are many, each check a few numpy calls), then the culprit named.
            if not (all_finite(level_rows.A) and all_finite(level_rows.b)):
                culprit = next(task for run, _ in entry for task in run if not all(
                    np.isfinite(rows).all() for rows in task.compute_linear_system(configuration)))
                raise SolverError(
                    f"{type(culprit).__name__} gave a non-finite error or Jacobian (NaN or infinity); "
                    "no step can be computed"
                )
            built.append(level_rows)
    return built


def least_squares_status(residual: float, b: np.ndarray) -> LevelStatus:
    """SOLVED when the residual is small next to the requested change (damping alone leaves
    lambda^2 / (sigma^2 + lambda^2) of it), else RELAXED."""
    return LevelStatus.SOLVED if residual <= 1e-6 + 0.05 * vector_norm(b) else LevelStatus.RELAXED


def report_levels(built: list, dq: np.ndarray, failed: Mapping[int, str] | None = None) -> list[LevelReport]:
    """Reports of every level for the step dq; `failed`: the levels whose QP failed, each with its
    backend's status."""
    failed = failed or {}
    reports = []
    for index, level in enumerate(built):
        if level is None:
            reports.append(LevelReport("tasks", float("nan"), float("nan"), LevelStatus.EMPTY))
        elif isinstance(level, GradientLevel):
            status = (LevelStatus.FAILED if index in failed else
                      LevelStatus.EMPTY if level.step_size == 0 else LevelStatus.SOLVED)
            reports.append(LevelReport("gradient", float("nan"), level.value, status, failed.get(index, "")))
        else:
            residual = vector_norm(level.A @ dq - level.b)
            status = LevelStatus.FAILED if index in failed else least_squares_status(residual, level.b)
            reports.append(LevelReport("tasks", residual, float("nan"), status, failed.get(index, "")))
    return reports


class Solver(ABC):
    """A scheme that turns levels into a step dq; `solve` iterates it.

    Args:
        limits: joint limits, or None.
        damping: lambda [m/rad], a positive finite number (see DEFAULT_DAMPING).

    Attributes:
        limits: joint limits, or None. The QP enforces them as constraints at every level; the
            projection schemes lock a coordinate that would leave them and solve again.
        damping: lambda of every level's damped least squares.
        step_adaptation: the adapted step norm of each gradient task, reset by `solve`; a loop of
            `compute_step` calls outside `solve` resets it itself.

    Raises:
        InputError: a damping that is not a positive finite number.
    """

    name = "solver"

    def __init__(self, *, limits: JointLimits | None = None, damping: float = DEFAULT_DAMPING) -> None:
        try:
            valid = bool(np.isfinite(damping) and damping > 0.0)
        except TypeError:
            valid = False
        if not valid:
            raise InputError(f"damping: expected a positive finite number [m/rad], got {damping!r}")
        if limits is not None and not isinstance(limits, JointLimits):
            raise InputError(f"limits: expected a JointLimits (ibik_pin.limits) or None, found {type(limits).__name__}",
                             parameter="limits")
        self.limits = limits
        self.damping = float(damping)
        self.step_adaptation = StepAdaptation()

    def arrange(self, levels: Levels) -> Levels:
        """The levels this scheme actually solves (IK and Liegeois regroup them)."""
        return levels

    @abstractmethod
    def compute_step(self, configuration: Configuration, levels: Levels, plan: LevelPlan | None = None) -> StepResult:
        """One step from the configuration's current (already updated) kinematics; `plan`: the
        LevelPlan of self.arrange(levels) when a solve's steps share it (made here otherwise)."""

    def solve(
        self,
        configuration: Configuration,
        levels: Levels,
        iterations: int = 15,
        tolerance: float | None = None,
        stop_at_peak: bool = False,
    ) -> SolveResult:
        """Iterate steps from configuration.q; the configuration ends updated at the result.

        Args:
            configuration: start state; updated in place.
            levels: priority levels, highest first.
            iterations: maximum number of steps (the paper uses 15 per frame).
            tolerance: stop early once |dq| < tolerance.
            stop_at_peak: stop once the first gradient level's criterion no longer rises: when the
                criterion after a step (from the second on) is not above its value after the step
                before, that step is undone and the solve ends there, at the best of the two. The
                first step is not judged: it also carries the higher levels' move to their new
                targets, which may lower the criterion. A step of bounded norm along a gradient
                rarely lands on a maximum; past it, steps go back and forth around it (on real
                motion, whole-body steps kept a norm near 0.1 rad to the fifteenth), and a climb
                that is still gaining keeps going (docs/method.md, "Where the image steps stop").

        Raises:
            InputError: iterations below 1, or a gradient task sharing its level.
            SolverError: a task gives non-finite rows, so no step can be computed.
        """
        if int(iterations) < 1:
            raise InputError(f"iterations must be >= 1, got {iterations}")
        self.step_adaptation.reset()
        step_norms: list[float] = []
        step = StepResult(np.zeros(configuration.nv), [])
        plan = LevelPlan.of(self.arrange(levels))  # the same for every step of this solve
        # With stop_at_peak: q before the last step and the criterion there; `taken`, the step
        # before the last (whose reports the solve returns if the last is undone).
        previous_q, previous_value, taken = configuration.q, float("nan"), step
        # The criterion alone, to judge the last step before the next is computed (the same value
        # the step would report): the step past the peak costs no QP. None: no gradient level.
        criterion = plan.entries[plan.criterion_level] if stop_at_peak and plan.criterion_level is not None else None
        for index in range(int(iterations)):
            if criterion is not None and index >= 2 and criterion.compute_value(configuration) <= previous_value:
                # h after `index` steps is not above h after the step before; NaN never stops.
                configuration.update(previous_q)  # the last step undone
                step_norms.pop()
                step = taken
                break
            taken, step = step, self.compute_step(configuration, levels, plan)
            if stop_at_peak:
                previous_q, previous_value = configuration.q.copy(), step.criterion
            configuration.move(step.dq, self.limits)
            step_norms.append(vector_norm(step.dq))
            if tolerance is not None and step_norms[-1] < tolerance:
                break
        violation = float("nan") if self.limits is None else self.limits.violation(configuration.q)
        return SolveResult(
            q=configuration.q.copy(),
            iterations=len(step_norms),
            levels=step.levels,
            step_norms=np.array(step_norms),
            limit_violation=violation,
            failed_levels=sum(report.status is LevelStatus.FAILED for report in step.levels),
        )
