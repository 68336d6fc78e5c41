"""Position of a model frame in the world: the end-effector task of eq. (1)-(3)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import numpy as np
import pinocchio as pin
from numba import njit

from ibik_pin.checks import all_finite
from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.model import frame_id
from ibik_pin.tasks.base import Task


@njit(cache=True, nogil=True)
def _position_rows(positions, jacobians, frame_ids, column_scales, targets, error_scales, A, b):
    """Writes the rows (3K, nv) and right-hand sides (3K,) of K position tasks: task k's rows are
    its frame's translation Jacobian times its column scales, its right-hand side its error times
    -sqrt(weight) gain (its error_scales[k])."""
    for k in range(frame_ids.shape[0]):
        frame = frame_ids[k]
        for axis in range(3):
            row = 3 * k + axis
            b[row] = error_scales[k] * (positions[frame, axis] - targets[k, axis])
            for v in range(A.shape[1]):
                A[row, v] = jacobians[frame, axis, v] * column_scales[k, v]


class FramePositionTask(Task):
    """Bring the origin of a frame to a world target: e = p_frame(q) - p_target [m].

    Attributes:
        frame_name: the model frame.
        target: world target [m], shape (3,), or None (task disabled, e.g. occluded this frame).
        driven: (nv,) bool, the velocity coordinates allowed to move toward the target (the
            Jacobian's other columns are zero), or None for all of them.
    """

    def __init__(
        self,
        model: pin.Model,
        frame_name: str,
        target: np.ndarray | None = None,
        gain: float = 1.0,
        weight: float = 1.0,
        driven: np.ndarray | None = None,
    ) -> None:
        super().__init__(gain, weight)
        self.frame_name = frame_name
        self.frame_id = frame_id(model, frame_name)
        self.driven = None
        if driven is not None:
            self.driven = np.array(driven, dtype=bool)
            if self.driven.shape != (model.nv,):
                raise InputError(f"driven: expected a bool mask of shape ({model.nv},), got {self.driven.shape}")
            self.driven.setflags(write=False)  # its column scales are kept (column_scales)
        self._nv = model.nv
        self._column_scales: tuple[float, np.ndarray | None, np.ndarray] | None = None
        self.set_target(target)

    def set_target(self, target: np.ndarray | None) -> None:
        """Set the world target [m], shape (3,); None disables the task."""
        if target is None:
            self.target = None
            self.enabled = False
            return
        target = np.array(target, dtype=float)
        if target.shape != (3,):
            raise InputError(
                f"target of frame {self.frame_name!r} must have shape (3,), got {target.shape}"
            )
        if not all_finite(target):  # compiled: a frame sets every target, each call counts
            raise InputError(
                f"target of frame {self.frame_name!r} must be finite, got {target.tolist()}"
            )
        self.target = target
        self.enabled = True

    def compute_error(self, configuration: Configuration) -> np.ndarray:
        return configuration.frame_position(self.frame_id) - self.target

    def compute_jacobian(self, configuration: Configuration) -> np.ndarray:
        jacobian = configuration.frame_translation_jacobian(self.frame_id)
        if self.driven is None:
            return jacobian
        return np.where(self.driven, jacobian, 0.0)

    @classmethod
    def stacked_linear_system(cls, tasks: Sequence[Task], configuration: Configuration,
                              memo: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The tasks' rows from one read of their frames' positions and Jacobians: the rows
        compute_linear_system gives each, to the bit. A subclass (which may change the error or the
        Jacobian) gets the rows task by task. With `memo`, the frames, column scales, targets and
        error scales are gathered at a solve's first step only (they change between solves)."""
        if cls is not FramePositionTask:
            return super().stacked_linear_system(tasks, configuration, memo)
        constants = memo.get("position rows") if memo is not None else None
        if constants is None:
            chosen = cast(Sequence[FramePositionTask], tasks)
            constants = (np.array([task.frame_id for task in chosen]),
                         np.array([task.column_scales() for task in chosen]),
                         np.array([task.target for task in chosen]),
                         np.array([-math.sqrt(task.weight) * task.gain for task in chosen]))
            if memo is not None:
                memo["position rows"] = constants
        frame_ids, column_scales, targets, error_scales = constants
        positions, jacobians = configuration.frame_arrays(frame_ids)
        A, b = np.empty((3 * len(frame_ids), configuration.nv)), np.empty(3 * len(frame_ids))
        _position_rows(positions, jacobians, frame_ids, column_scales, targets, error_scales, A, b)
        return A, b

    def column_scales(self) -> np.ndarray:
        """What each Jacobian column of the task's rows is multiplied by, shape (nv,):
        sqrt(weight) on the driven coordinates, 0 on the others (read-only; kept while weight and
        driven stay the same objects)."""
        kept = self._column_scales
        if kept is None or kept[0] != self.weight or kept[1] is not self.driven:
            scales = np.full(self._nv, math.sqrt(self.weight))
            if self.driven is not None:
                scales[~self.driven] = 0.0
            scales.setflags(write=False)
            kept = self._column_scales = (self.weight, self.driven, scales)
        return kept[2]
