"""A gradient task as one least-squares row, so that it can be weighted against other tasks.

A priority level holds either least-squares tasks or one gradient task (solvers.base). To weigh the
image criterion against targets in one least-squares level, as Pink weighs every task of its single
QP, the criterion asks for a step of `step` along its unit gradient: the row
    sqrt(weight) g^T dq ~= sqrt(weight) step,    g = grad h / |grad h|,
whose residual is how much of that step the other tasks of the level (and the levels above) took
away. Unlike a gradient level, the step is not adapted by the solver.
"""

from __future__ import annotations

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.tasks.base import GradientTask, Task, _check_positive

__all__ = ["CriterionStepTask"]


class CriterionStepTask(Task):
    """One weighted row asking for a step of `step` [rad] up a criterion's unit gradient.

    Attributes:
        criterion: the gradient task followed; the row is enabled when it is.
        step: the step asked for per solver step [rad, or the units of v].
    """

    def __init__(self, criterion: GradientTask, step: float, weight: float = 1.0) -> None:
        super().__init__(gain=1.0, weight=weight)
        self.criterion = criterion
        self.step = _check_positive("step", step)

    @property
    def enabled(self) -> bool:
        return self.criterion.enabled

    @enabled.setter
    def enabled(self, value: bool) -> None:
        """The row follows its criterion; the base class's initial flag is ignored."""

    def compute_error(self, configuration: Configuration) -> np.ndarray:
        """e = -step, shape (1,): J dq = -gain e asks for the step whatever q is."""
        return np.array([-self.step])

    def compute_jacobian(self, configuration: Configuration) -> np.ndarray:
        """The criterion's unit gradient as a row, shape (1, nv) (zeros where it vanishes)."""
        return self.criterion.compute_direction(configuration)[None, :]
