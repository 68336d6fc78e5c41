"""Configuration: a model, its data and a joint configuration, with kinematics computed once per step."""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
from numba import njit

from ibik_pin.checks import all_finite, as_float_array, require_instance
from ibik_pin.exceptions import InputError

if TYPE_CHECKING:
    from ibik_pin.limits import JointLimits

_WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_KINEMATIC_STATES = itertools.count(1)  # one number per update, unique across all configurations


@njit(cache=True, nogil=True)
def _fill_translation_jacobians(jacobians, positions, joint_jacobians, moved_by, frame_ids, translations):
    """jacobians[f] (3, nv) = J_v - p_f x J_w over the coordinates that move frame f, for each f of
    frame_ids, with p_f = positions[f], first copied from translations[f] when that (nframes, 3)
    view is given (else positions[f] is current already)."""
    nv = joint_jacobians.shape[1]
    for f in frame_ids:
        if translations is not None:
            for axis in range(3):
                positions[f, axis] = translations[f, axis]
        x, y, z = positions[f, 0], positions[f, 1], positions[f, 2]
        for v in range(nv):
            if not moved_by[f, v]:
                jacobians[f, 0, v] = jacobians[f, 1, v] = jacobians[f, 2, v] = 0.0
                continue
            wx, wy, wz = joint_jacobians[3, v], joint_jacobians[4, v], joint_jacobians[5, v]
            jacobians[f, 0, v] = joint_jacobians[0, v] - (y * wz - z * wy)
            jacobians[f, 1, v] = joint_jacobians[1, v] - (z * wx - x * wz)
            jacobians[f, 2, v] = joint_jacobians[2, v] - (x * wy - y * wx)


@njit(cache=True, nogil=True)
def _pulled_back(frame_gradient, jacobians, frame_ids, count, out):
    """out (nv,) = sum over k of (frame_gradient[k] / count) . jacobians[frame_ids[k]] (3, nv)."""
    out[:] = 0.0
    for k in range(frame_ids.shape[0]):
        frame = frame_ids[k]
        for axis in range(3):
            pull = frame_gradient[k, axis] / count
            for v in range(out.shape[0]):
                out[v] += pull * jacobians[frame, axis, v]


def _strided_translations(placements: list) -> np.ndarray | None:
    """Every frame's translation (nframes, 3) [m] as one read-only view into Pinocchio's data, or
    None.

    Each placement's `translation` is a view into data.oMf, which keeps its SE3s at equal
    distances in memory: one strided view then reads all frames at once. Measured on the human's 21
    keypoint frames: 5 us a read through the view against 113 us through Pinocchio's API
    (`data.oMf[frame].translation`, frame by frame), a quarter of a whole-body step's median. This
    depends on Pinocchio's layout, so the view is built only where the addresses show it, and
    tests/test_configuration.py fails the day Pinocchio's layout changes (no view, or a view that
    reads other values than the API). The view lives as long as `data`, whose vector is never resized.
    """
    translations = [placement.translation for placement in placements]
    if not translations or any(t.dtype != np.float64 or t.shape != (3,) or t.strides != (8,) for t in translations):
        return None
    addresses = np.array([t.__array_interface__["data"][0] for t in translations], dtype=np.int64)
    spacing = np.diff(addresses)
    if len(translations) > 1 and not (spacing[0] >= 24 and (spacing == spacing[0]).all()):
        return None
    stride = int(spacing[0]) if len(translations) > 1 else 24
    return np.lib.stride_tricks.as_strided(translations[0], shape=(len(translations), 3), strides=(stride, 8),
                                           writeable=False)


class Configuration:
    """Model + data + configuration q; forward kinematics and joint Jacobians run once per `update`.

    The frames asked for are remembered: at the first request after an update, the positions and
    translation Jacobians of all of them are read at once and kept until the next update, as is
    each set of frames handed out (read-only). The tasks and image terms of a step, asking for
    overlapping sets of the same frames at every step, then cost one read of each frame.

    Attributes:
        model: the Pinocchio model.
        data: its data, kept alive between steps.
        q: current configuration, shape (nq,).
    """

    def __init__(self, model: pin.Model, q: np.ndarray | None = None) -> None:
        require_instance(model, pin.Model, "model", "a Pinocchio model (pinocchio.Model)")
        self.model = model
        self.data = model.createData()
        # The frames' placements in data, by reference (they follow every update): reading them
        # spares Pinocchio's vector wrapper, a third of the time of a frame's position.
        self._placements = [self.data.oMf[frame] for frame in range(model.nframes)]
        self._translations = _strided_translations(self._placements)
        # Per frame, the velocity coordinates that move it: those of its parent joint's supports.
        self._moved_by = np.zeros((model.nframes, model.nv), dtype=np.bool_)
        for frame in range(model.nframes):
            for joint in model.supports[int(model.frames[frame].parentJoint)][1:]:
                start = model.joints[joint].idx_v
                self._moved_by[frame, start:start + model.joints[joint].nv] = True
        # The frames ever asked for, and their positions and Jacobians, read at the version given.
        self._asked = np.zeros(model.nframes, dtype=bool)
        self._asked_ids = np.zeros(0, dtype=np.int64)
        self._asked_sets: set[bytes] = set()  # the frame-id arrays (bytes) known to be among them
        self._positions = np.zeros((model.nframes, 3))
        self._jacobians = np.zeros((model.nframes, 3, model.nv))
        self._read_version = -1
        self._all_positions, self._all_jacobians = self._positions.view(), self._jacobians.view()
        self._all_positions.setflags(write=False)
        self._all_jacobians.setflags(write=False)
        # The arrays handed out since the last update, by the frame ids' bytes (int64).
        self._position_sets: dict[bytes, np.ndarray] = {}
        self._jacobian_sets: dict[bytes, np.ndarray] = {}
        self.version = 0  # a new unique number at every update, so tasks can memoise per state
        self.q = pin.neutral(model) if q is None else self._checked(q)
        self.update()

    def _checked(self, q: np.ndarray) -> np.ndarray:
        q = as_float_array(q, "q").reshape(-1)
        if q.shape != (self.model.nq,):
            raise InputError(f"configuration q must have shape ({self.model.nq},), got {q.shape}")
        if not all_finite(q):
            raise InputError("configuration q must be finite, got NaN or infinity")
        return q

    def update(self, q: np.ndarray | None = None) -> None:
        """Set q (if given) and run forward kinematics, joint Jacobians and frame placements once."""
        if q is not None:
            self.q = self._checked(q)
        pin.computeJointJacobians(self.model, self.data, self.q)
        pin.updateFramePlacements(self.model, self.data)
        self._position_sets.clear()
        self._jacobian_sets.clear()
        self.version = next(_KINEMATIC_STATES)

    @property
    def nv(self) -> int:
        return self.model.nv

    def frame_position(self, frame_id: int) -> np.ndarray:
        """World position [m] of a frame origin, shape (3,)."""
        return self._placements[frame_id].translation

    def _read(self, frame_ids: np.ndarray) -> None:
        """Make the positions and Jacobians of frame_ids, and of every frame asked for before,
        current."""
        key = frame_ids.tobytes()
        if key not in self._asked_sets:
            self._asked_sets.add(key)
            if not self._asked[frame_ids].all():
                self._asked[frame_ids] = True
                self._asked_ids = np.flatnonzero(self._asked)
                self._read_version = -1
        if self._read_version != self.version:
            if self._translations is None:
                placements = self._placements
                self._positions[self._asked_ids] = [placements[frame].translation for frame in self._asked_ids]
            # The positions copied from Pinocchio's data in the compiled loop (numpy's gather of the
            # strided view cost 5 us a step).
            _fill_translation_jacobians(self._jacobians, self._positions, self.data.J, self._moved_by,
                                        self._asked_ids, self._translations)
            self._read_version = self.version

    def _handed_out(self, kept: dict[bytes, np.ndarray], values: np.ndarray, frame_ids: np.ndarray) -> np.ndarray:
        """values[frame_ids], read-only, kept in `kept` until the next update."""
        frame_ids = np.asarray(frame_ids).reshape(-1)
        key = frame_ids.tobytes()
        rows = kept.get(key)
        if rows is None:
            self._read(frame_ids)
            rows = kept[key] = values[frame_ids]
            rows.setflags(write=False)
        return rows

    def frame_arrays(self, frame_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every frame's position (nframes, 3) [m] and translation Jacobian (nframes, 3, nv), current
        on the rows of frame_ids (other rows may be stale), read-only: for compiled readers that
        pick their rows themselves, without a copy of them."""
        self._read(np.asarray(frame_ids).reshape(-1))
        return self._all_positions, self._all_jacobians

    def velocity_gradient(self, frame_ids: np.ndarray, frame_gradient: np.ndarray, count: float = 1.0) -> np.ndarray:
        """(nv,) d f / dv of a function f whose derivative with respect to each frame's origin
        (frame_ids (K,) int64) is frame_gradient (K, 3) / count: the frames' translation Jacobians
        pulled back in one compiled loop, without a copy of them."""
        self._read(frame_ids)
        gradient = np.empty(self.model.nv)
        _pulled_back(frame_gradient, self._jacobians, frame_ids, float(count), gradient)
        return gradient

    def frame_positions(self, frame_ids: np.ndarray) -> np.ndarray:
        """World positions [m] of several frame origins, shape (K, 3), read-only."""
        return self._handed_out(self._position_sets, self._positions, frame_ids)

    def frame_translation_jacobian(self, frame_id: int) -> np.ndarray:
        """d(frame origin in world)/dv, world-aligned, shape (3, nv) [m per unit of v], read-only."""
        return self.frame_translation_jacobians(np.array([frame_id]))[0]

    def frame_translation_jacobians(self, frame_ids: np.ndarray) -> np.ndarray:
        """Translation Jacobians of several frames, world-aligned, shape (K, 3, nv), read-only.

        From the joint Jacobians (computeJointJacobians' data.J: each joint's twist at the world
        origin, J = [J_v; J_w]), in one compiled loop: a frame at p moves at J_v - p x J_w over the
        coordinates of its supporting joints. Pinocchio's getFrameJacobian (LOCAL_WORLD_ALIGNED)
        computes the same, one frame per call.
        """
        return self._handed_out(self._jacobian_sets, self._jacobians, frame_ids)

    def integrate(self, dq: np.ndarray) -> np.ndarray:
        """q (+) dq on the configuration manifold (free-flyer quaternion included), shape (nq,)."""
        return pin.integrate(self.model, self.q, dq)

    def move(self, dq: np.ndarray, limits: JointLimits | None = None) -> None:
        """A solver's step: q becomes q (+) dq, clamped into the joint limits when given, and the
        kinematics are updated (as update(q), without copying and checking the q made here).

        Raises:
            InputError: dq is not a finite (nv,) vector.
        """
        dq = np.asarray(dq, dtype=float)
        if dq.shape != (self.model.nv,):
            raise InputError(f"a step dq must be a finite vector of shape ({self.model.nv},), got shape {dq.shape}")
        if not all_finite(dq):
            raise InputError("a step dq must be a finite vector, got NaN or infinity")
        q = pin.integrate(self.model, self.q, dq)
        if limits is not None:
            limits.clamp(q, out=q)
        self.q = q
        self.update()
