"""The two kinds of task every solver accepts.

- `Task`: a least-squares task with an error e(q) and its Jacobian J(q). A step asks for
  J dq = -gain * e (first-order convergence of e to zero), weighted by `weight` within its level.
- `GradientTask`: a scalar criterion h(q) to maximise (the image overlap of eq. 5-6). A step moves
  along its unit gradient with a norm of at most `max_step_size`: a normalised secondary step
  converges where the raw gradient, in pixels per radian, does not. The solver adapts the norm
  between `min_step_size` and `max_step_size` (Rprop on the direction it takes,
  :mod:`ibik_pin.solvers.step_adaptation`); a task holds no solver state. Why both:
  docs/method.md, "The image step".
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError


def _check_positive(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise InputError(f"{name} must be a positive finite number, got {value}")
    return value


class Task(ABC):
    """A least-squares task: drive e(q) to zero; a step asks J dq = -gain * e.

    Attributes:
        gain: fraction of the error corrected per step, in (0, 1].
        weight: weight of this task's rows within its priority level.
        enabled: a disabled task (e.g. an occluded target) is skipped by every solver.
    """

    def __init__(self, gain: float = 1.0, weight: float = 1.0) -> None:
        self.gain = _check_positive("gain", gain)
        if self.gain > 1.0:
            raise InputError(f"gain must be in (0, 1], got {gain}")
        self.weight = _check_positive("weight", weight)
        self.enabled = True

    @abstractmethod
    def compute_error(self, configuration: Configuration) -> np.ndarray:
        """Task error e(q), shape (m,)."""

    @abstractmethod
    def compute_jacobian(self, configuration: Configuration) -> np.ndarray:
        """Task Jacobian de/dv, shape (m, nv)."""

    def compute_linear_system(self, configuration: Configuration) -> tuple[np.ndarray, np.ndarray]:
        """Weighted rows (A, b) of the step's least-squares problem A dq ~= b.

        Returns:
            A = sqrt(weight) J, shape (m, nv); b = -sqrt(weight) gain e, shape (m,).
        """
        scale = math.sqrt(self.weight)  # np.sqrt's value, as a Python float: a step builds many tasks' rows
        return (
            scale * self.compute_jacobian(configuration),
            -scale * self.gain * self.compute_error(configuration),
        )

    @classmethod
    def stacked_linear_system(cls, tasks: Sequence[Task], configuration: Configuration,
                              memo: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The rows (A, b) of several tasks of this class, stacked in order: each task's
        compute_linear_system, in one (m, nv) and one (m,). A class whose tasks' rows come faster
        together (FramePositionTask: one read of every frame's Jacobian) overrides this.

        `memo`: a dict the solver keeps for the steps of one solve, in which an override may keep
        what does not change during a solve (the tasks' frames, targets, weights and gains)."""
        if len(tasks) == 1:  # no copy into a stack of one
            return tasks[0].compute_linear_system(configuration)
        rows = [task.compute_linear_system(configuration) for task in tasks]
        return np.vstack([A for A, _ in rows]), np.concatenate([b for _, b in rows])


class GradientTask(ABC):
    """A scalar criterion h(q) to maximise by steps of bounded norm along its gradient.

    Attributes:
        max_step_size: largest step norm [rad, or the units of v]; each solve starts there.
        min_step_size: the solver's adapted step never shrinks below this.
        enabled: a disabled criterion (e.g. no usable silhouette) is skipped by every solver.
    """

    def __init__(self, max_step_size: float = 0.05, min_step_size: float = 1e-4) -> None:
        self.max_step_size = _check_positive("max_step_size", max_step_size)
        self.min_step_size = _check_positive("min_step_size", min_step_size)
        self.enabled = True

    @abstractmethod
    def compute_value(self, configuration: Configuration) -> float:
        """The criterion h(q)."""

    @abstractmethod
    def compute_gradient(self, configuration: Configuration) -> np.ndarray:
        """dh/dv, shape (nv,)."""

    def compute_direction(self, configuration: Configuration) -> np.ndarray:
        """Unit ascent direction gradient / |gradient|, shape (nv,) (zeros if it vanishes)."""
        gradient = self.compute_gradient(configuration)
        norm = math.sqrt(gradient @ gradient)  # np.linalg.norm's value, without its wrapper
        if norm == 0.0 or not math.isfinite(norm):
            return np.zeros_like(gradient)
        return gradient / norm
