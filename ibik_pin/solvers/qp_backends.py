"""One level of the hierarchical QP as an inspectable problem, and the backends that solve it.

Level k of :class:`~ibik_pin.solvers.hqp.HierarchicalQPSolver` searches its increment w (r,) in the
null space Z (nv, r) that the higher levels leave, dq = dq_above + Z w, and solves
    min 1/2 w^T H w + g^T w   subject to   lower <= Z w <= upper,
with lower, upper (nv,) the joint limits' per-step bounds minus dq_above. :class:`LevelProblem`
holds these arrays; :meth:`LevelProblem.to_qpsolvers` gives the same problem as a
`qpsolvers.Problem`.

A backend (:class:`QPBackend`) turns a LevelProblem into w or raises :class:`QPBackendError` with its
own status:
- "active_set": the primal active-set method, compiled (:mod:`ibik_pin.solvers.active_set`), run
  inside the compiled level loop;
- "proxsuite": ProxSuite's dense QP objects, one per level and size, kept alive, updated and
  warm-started from their previous answer across iterations and frames;
- any solver that `qpsolvers` finds installed (e.g. "daqp", "proxqp", "quadprog"), through
  `qpsolvers.solve_problem`, one call per level.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import proxsuite

from ibik_pin.exceptions import QPBackendError, UnknownNameError
from ibik_pin.solvers.active_set import primal_active_set

if TYPE_CHECKING:
    import qpsolvers

__all__ = ["LevelProblem", "QPBackend", "ActiveSetBackend", "ProxsuiteBackend", "QpsolversBackend",
           "available_qp_solvers", "make_qp_backend", "qp_solver_available", "UNBOUNDED", "FEASIBILITY"]

UNBOUNDED = 1e20  # the stand-in for an infinite bound; rows bounded by it on a side are unbounded there
# How far [rad, m] the active-set answer may leave a bound: a bound on a coordinate that the higher
# levels have all but frozen (a null-space row of norm 1e-17..1e-12) must not block.
FEASIBILITY = 1e-10


@dataclass(frozen=True)
class LevelProblem:
    """The QP of one level at one step: min 1/2 w^T H w + g^T w s.t. lower <= C w <= upper.

    Attributes:
        level: the level's index in the solver's (arranged) levels, highest first.
        H: (r, r) Hessian, positive definite: A_k^T A_k projected on C plus damping^2 I for a
            least-squares level, I / step_size for a gradient level.
        g: (r,) linear term: -(A_k C)^T (b_k - A_k dq_above), or minus the unit projected gradient.
        C: (nv, r) the orthonormal null-space basis Z of the higher levels (w's coordinates).
        lower, upper: (nv,) bounds on C w [rad, m]: the step bounds minus dq_above; +-UNBOUNDED
            where a coordinate has none.
        dq_above: (nv,) the higher levels' step; the level's step is dq_above + C w.
    """

    level: int
    H: np.ndarray
    g: np.ndarray
    C: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    dq_above: np.ndarray

    def step(self, w: np.ndarray) -> np.ndarray:
        """dq (nv,) after this level: dq_above + C w."""
        return self.dq_above + self.C @ w

    def to_qpsolvers(self) -> qpsolvers.Problem:
        """The same QP as a `qpsolvers.Problem` (P = H, q = g, G w <= h), the two-sided rows split
        into G = [C; -C] and h = [upper; -lower], rows with an UNBOUNDED side left out."""
        qpsolvers = _qpsolvers()
        has_upper = self.upper < UNBOUNDED
        has_lower = self.lower > -UNBOUNDED
        if not (has_upper.any() or has_lower.any()):
            return qpsolvers.Problem(self.H, self.g)
        G = np.vstack([self.C[has_upper], -self.C[has_lower]])
        h = np.concatenate([self.upper[has_upper], -self.lower[has_lower]])
        return qpsolvers.Problem(self.H, self.g, G, h)


class QPBackend(ABC):
    """Solves LevelProblems; raises QPBackendError with its own status when it finds no answer.

    Attributes:
        name: the name it is chosen by (`make_qp_backend`).
        in_loop: True for the compiled active-set method, which the compiled level loop runs itself.
    """

    name = "backend"
    in_loop = False

    @abstractmethod
    def solve(self, problem: LevelProblem) -> np.ndarray:
        """w (r,) of the problem.

        Raises:
            QPBackendError: the backend found no answer (its status in `status`).
        """


class ActiveSetBackend(QPBackend):
    """The primal active-set method (:func:`ibik_pin.solvers.active_set.primal_active_set`): from
    w = 0 (feasible), one Schur-complement KKT solve per bound held or released, compiled. The level
    loop runs it in its compiled code; `solve` is the same method on one LevelProblem."""

    name = "active_set"
    in_loop = True

    def solve(self, problem: LevelProblem) -> np.ndarray:
        w = primal_active_set(problem.H, problem.g, problem.C, problem.lower, problem.upper, FEASIBILITY)
        if w is None:
            raise QPBackendError(self.name, "did not end within 2 (variables + bounds) iterations", problem.level)
        return w


class ProxsuiteBackend(QPBackend):
    """ProxSuite's dense solver: one `proxsuite.proxqp.dense.QP` per (level, variables, rows), created
    once, then updated and warm-started from its previous result.

    A QP object whose solve failed is dropped, so the level's next solve starts from a new one.

    Args:
        accuracy: eps_abs (eps_rel is 0).
        max_iterations: max_iter of each solve.
    """

    name = "proxsuite"
    _SOLVED = frozenset({
        proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED,
        proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE,
    })

    def __init__(self, accuracy: float = 1e-11, max_iterations: int = 1000) -> None:
        self.accuracy = float(accuracy)
        self.max_iterations = int(max_iterations)
        self.qps: dict[tuple[int, int, int], proxsuite.proxqp.dense.QP] = {}  # (level, n, n_in) -> QP

    def _qp(self, key: tuple[int, int, int]):
        """The QP object of this key, created once; returns it and whether it is new."""
        cached = self.qps.get(key)
        if cached is not None:
            return cached, False
        qp = proxsuite.proxqp.dense.QP(key[1], 0, key[2])
        qp.settings.eps_abs = self.accuracy
        qp.settings.eps_rel = 0.0
        qp.settings.max_iter = self.max_iterations
        # Set here, at creation and before init: this order works on proxsuite 0.8, which crashed
        # (segmentation fault) with this guess set otherwise before a QP's first solve.
        qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        qp.settings.verbose = False
        # Bounds active on coordinates that the level's rows barely move make proxsuite declare a
        # feasible problem "primal infeasible"; this mode returns the closest feasible point instead.
        qp.settings.primal_infeasibility_solving = True
        self.qps[key] = qp
        return qp, True

    def solve(self, problem: LevelProblem) -> np.ndarray:
        key = (problem.level, problem.H.shape[0], problem.C.shape[0])
        arguments = (problem.H, problem.g, None, None, problem.C, problem.lower, problem.upper)
        try:
            qp, is_new = self._qp(key)
            if is_new:
                qp.init(*arguments)
            else:
                qp.update(*arguments)
            qp.solve()
        except (RuntimeError, ValueError) as error:
            self.qps.pop(key, None)
            raise QPBackendError(self.name, f"{type(error).__name__}: {error}", problem.level) from error
        status = qp.results.info.status
        w = qp.results.x.copy()
        if status not in self._SOLVED or not np.all(np.isfinite(w)):
            self.qps.pop(key, None)
            raise QPBackendError(self.name, f"{status.name} after {qp.results.info.iter} iterations",
                                 problem.level)
        return w


class QpsolversBackend(QPBackend):
    """A solver through `qpsolvers.solve_problem` (LevelProblem.to_qpsolvers), one call per level.

    Args:
        name: a name in `qpsolvers.available_solvers`.
        options: keyword arguments passed to the solver through solve_problem.
    """

    def __init__(self, name: str, **options) -> None:
        self.name = name
        self.options = options

    def solve(self, problem: LevelProblem) -> np.ndarray:
        try:
            solution = _qpsolvers().solve_problem(problem.to_qpsolvers(), solver=self.name, **self.options)
        except Exception as error:  # qpsolvers' and its backends' own errors, re-raised as ours
            raise QPBackendError(self.name, f"{type(error).__name__}: {error}", problem.level) from error
        if not solution.found or solution.x is None or not np.all(np.isfinite(solution.x)):
            # qpsolvers keeps some solvers' own result in extras (proxqp's Info and its status).
            status = getattr(getattr(solution.extras.get("info"), "status", None), "name", None)
            raise QPBackendError(self.name, status or "no solution found (qpsolvers Solution.found is False)",
                                 problem.level)
        return np.asarray(solution.x, dtype=float)


#: The backends of the package itself; the others are qpsolvers'.
BUILT_IN_QP_SOLVERS = ("active_set", "proxsuite")


def _qpsolvers():
    """qpsolvers, imported when a name or backend of its is needed: its import (scipy.sparse's with
    it) took 0.2 s of every command's, which the built-in backends never use."""
    import qpsolvers

    return qpsolvers


def available_qp_solvers() -> list[str]:
    """The backend names `make_qp_backend` accepts here: "active_set", "proxsuite", then qpsolvers'
    installed solvers."""
    return [*BUILT_IN_QP_SOLVERS, *sorted(_qpsolvers().available_solvers)]


def qp_solver_available(name: str) -> bool:
    """Whether `make_qp_backend` accepts `name` here (qpsolvers is imported only for a name not built in)."""
    return name in BUILT_IN_QP_SOLVERS or name in _qpsolvers().available_solvers


def make_qp_backend(name: str, *, accuracy: float = 1e-11, max_iterations: int = 1000) -> QPBackend:
    """The backend of this name.

    Args:
        name: one of `available_qp_solvers()`.
        accuracy: the absolute tolerance given to proxsuite (both "proxsuite" and qpsolvers' "proxqp").
        max_iterations: proxsuite's iteration cap per level.

    Raises:
        UnknownNameError: a name that is not available here (the message lists those that are).
    """
    if name == "active_set":
        return ActiveSetBackend()
    if name == "proxsuite":
        return ProxsuiteBackend(accuracy, max_iterations)
    if name in _qpsolvers().available_solvers:
        options = {"eps_abs": accuracy, "eps_rel": 0.0, "max_iter": max_iterations} if name == "proxqp" else {}
        return QpsolversBackend(name, **options)
    raise UnknownNameError(f"unknown QP solver {name!r}; available: {', '.join(available_qp_solvers())}")
