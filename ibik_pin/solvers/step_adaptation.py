"""The image step's norm: Rprop on the direction the solver actually takes, kept by the solver.

A gradient level steps along its unit direction projected into what the higher levels leave free
(docs/method.md, "The image step"). Its norm starts at the task's `max_step_size` at every solve,
is halved (never below `min_step_size`) when the direction taken reverses from the previous step's,
and grows by 1.2 (up to `max_step_size`) while it holds.

This state belongs to the solver that takes the steps, not to the task: a task only says what it
measures and how far one step may go, so the same task object can run through several solvers,
each adapting its own step. The rule itself (`adapt_step_size`, with Rprop's factors 0.5 and 1.2 of
Riedmiller & Braun 1993) is compiled in :mod:`ibik_pin.solvers.kernels`: the level loop applies it
inside its one compiled call.
"""

from __future__ import annotations

import numpy as np

from ibik_pin.solvers.kernels import STEP_SIZE, adapt_step_size
from ibik_pin.tasks.base import GradientTask

__all__ = ["StepAdaptation"]


class StepAdaptation:
    """The adapted step norm of every gradient task a solver steps along, forgotten by `reset`."""

    def __init__(self) -> None:
        # Keyed by id(task), with the task kept alive so that its id cannot be reused meanwhile.
        self._steps: dict[int, tuple[GradientTask, np.ndarray, np.ndarray]] = {}

    def reset(self) -> None:
        """Forget every task's adaptation: the next step of each starts at its max_step_size."""
        self._steps.clear()

    def state(self, task: GradientTask, nv: int) -> tuple[np.ndarray, np.ndarray]:
        """The task's state row (4,) and previous direction (nv,) that `adapt_step_size` updates."""
        entry = self._steps.get(id(task))
        if entry is None or entry[2].size != nv:  # (a task stepped on another model starts afresh)
            state = np.array([task.max_step_size, task.min_step_size, task.max_step_size, 0.0])
            entry = (task, state, np.zeros(nv))
            self._steps[id(task)] = entry
        return entry[1], entry[2]

    def hold(self, task: GradientTask, state: np.ndarray, previous: np.ndarray) -> None:
        """Keep the task's state in these arrays (its row (4,) and previous direction (nv,)) from now
        on, its current state copied in: the level loop's packed arrays, which the compiled loop then
        updates in place, with nothing copied back and forth at every step."""
        current_state, current_previous = self.state(task, previous.size)
        state[:], previous[:] = current_state, current_previous
        self._steps[id(task)] = (task, state, previous)

    def step_size(self, task: GradientTask) -> float:
        """The task's current step norm [rad, or the units of v]: max_step_size before its first step."""
        entry = self._steps.get(id(task))
        return task.max_step_size if entry is None else float(entry[1][STEP_SIZE])

    def adapt(self, task: GradientTask, taken: np.ndarray) -> float:
        """The step norm along `taken` for this iteration, adapted to the previous iteration's.

        Args:
            task: the gradient task of the level.
            taken: (nv,) the unit direction the solver steps along this iteration: the task's
                gradient projected into the null space of the higher levels.

        Returns:
            The step norm [rad, or the units of v].

        Adapting on the projected direction rather than on the raw gradient matters: when most of
        the gradient pulls against a higher level (a forearm on a dilated silhouette pulling the
        wrist off its target), the small remainder left in the null space flips from one
        iteration to the next. Rprop on the raw gradient never sees the flips and keeps taking
        full steps back and forth; here they halve the step, so noise cannot walk the limb away.
        """
        taken = np.ascontiguousarray(taken, dtype=np.float64)
        state, previous = self.state(task, taken.size)
        return float(adapt_step_size(state, previous, taken))
