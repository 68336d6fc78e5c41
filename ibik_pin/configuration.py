"""Configuration: a model, its data and a joint configuration, with kinematics computed once per step."""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin

from ibik_pin.exceptions import InputError

_WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_KINEMATIC_STATES = itertools.count(1)  # one number per update, unique across all configurations


class Configuration:
    """Model + data + configuration q; forward kinematics and joint Jacobians run once per `update`.

    Frame positions and translation Jacobians are read from the cached data and memoised until the
    next update, so several tasks asking for the same frame cost one Pinocchio call.

    Attributes:
        model: the Pinocchio model.
        data: its data, kept alive between steps.
        q: current configuration, shape (nq,).
    """

    def __init__(self, model: pin.Model, q: np.ndarray | None = None) -> None:
        self.model = model
        self.data = model.createData()
        # The frames' placements in data, by reference (they follow every update): reading them
        # spares Pinocchio's vector wrapper, a third of the time of a frame's position.
        self._placements = [self.data.oMf[frame] for frame in range(model.nframes)]
        self._jacobian_cache: dict[int, np.ndarray] = {}
        self._stacked_jacobians: dict[bytes, np.ndarray] = {}  # by the frame ids' bytes
        self.version = 0  # a new unique number at every update, so tasks can memoise per state
        self.q = pin.neutral(model) if q is None else self._checked(q)
        self.update()

    def _checked(self, q: np.ndarray) -> np.ndarray:
        q = np.array(q, dtype=float).reshape(-1)
        if q.shape != (self.model.nq,):
            raise InputError(f"configuration q must have shape ({self.model.nq},), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise InputError("configuration q must be finite, got NaN or infinity")
        return q

    def update(self, q: np.ndarray | None = None) -> None:
        """Set q (if given) and run forward kinematics, joint Jacobians and frame placements once."""
        if q is not None:
            self.q = self._checked(q)
        pin.computeJointJacobians(self.model, self.data, self.q)
        pin.updateFramePlacements(self.model, self.data)
        self._jacobian_cache.clear()
        self._stacked_jacobians.clear()
        self.version = next(_KINEMATIC_STATES)

    @property
    def nv(self) -> int:
        return self.model.nv

    def frame_position(self, frame_id: int) -> np.ndarray:
        """World position [m] of a frame origin, shape (3,)."""
        return self._placements[frame_id].translation

    def frame_positions(self, frame_ids: np.ndarray) -> np.ndarray:
        """World positions [m] of several frame origins, shape (K, 3)."""
        placements = self._placements
        return np.array([placements[i].translation for i in frame_ids]).reshape(-1, 3)

    def frame_translation_jacobian(self, frame_id: int) -> np.ndarray:
        """d(frame origin in world)/dv, world-aligned, shape (3, nv) [m per unit of v]."""
        jacobian = self._jacobian_cache.get(frame_id)
        if jacobian is None:
            jacobian = pin.getFrameJacobian(self.model, self.data, frame_id, _WORLD_ALIGNED)[:3]
            self._jacobian_cache[frame_id] = jacobian
        return jacobian

    def frame_translation_jacobians(self, frame_ids: np.ndarray) -> np.ndarray:
        """Translation Jacobians of several frames, shape (K, 3, nv), read-only (memoised: the image
        terms ask for the same frames at every step)."""
        frame_ids = np.asarray(frame_ids)
        key = frame_ids.tobytes() + frame_ids.dtype.str.encode()
        stacked = self._stacked_jacobians.get(key)
        if stacked is None:
            stacked = np.stack([self.frame_translation_jacobian(int(i)) for i in frame_ids.reshape(-1)])
            stacked.setflags(write=False)
            self._stacked_jacobians[key] = stacked
        return stacked

    def integrate(self, dq: np.ndarray) -> np.ndarray:
        """q (+) dq on the configuration manifold (free-flyer quaternion included), shape (nq,)."""
        return pin.integrate(self.model, self.q, dq)
