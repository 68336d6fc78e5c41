"""Joint position limits (from the URDF) and per-step bounds, as box constraints on dq."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numba import njit

from ibik_pin.checks import require_instance
from ibik_pin.exceptions import InputError


class JointLimits:
    """Box bounds lower <= dq <= upper for one step from configuration q.

    Joints with one coordinate (revolute, prismatic) are bounded by their URDF position limits and
    by `max_step` per step. A free-flyer root is bounded by `max_root_translation` [m] and
    `max_step` [rad] per step only. Other joints (spherical, continuous) get the step bound only.

    A coordinate already outside its limits is brought back at once: its bounds are set so that the
    step lands on the limit (never an empty box).
    """

    def __init__(
        self,
        model: pin.Model,
        max_step: float = 0.5,
        max_root_translation: float = 0.5,
    ) -> None:
        require_instance(model, pin.Model, "model", "a Pinocchio model (pinocchio.Model)")
        if not (max_step > 0 and max_root_translation > 0):
            raise InputError(
                f"max_step and max_root_translation must be positive, got {max_step}, "
                f"{max_root_translation}"
            )
        self.model = model
        q_index, v_index, names = [], [], []
        step = np.full(model.nv, float(max_step))
        for joint, name in zip(model.joints[1:], model.names[1:], strict=True):
            if joint.shortname() == "JointModelFreeFlyer":
                step[joint.idx_v : joint.idx_v + 3] = max_root_translation
            elif joint.nq == 1 and joint.nv == 1:
                q_index.append(joint.idx_q)
                v_index.append(joint.idx_v)
                names.append(name)
        self.joint_names = names
        self.q_index = np.array(q_index, dtype=np.int64)
        self.v_index = np.array(v_index, dtype=np.int64)
        self.lower = np.asarray(model.lowerPositionLimit)[self.q_index].copy()
        self.upper = np.asarray(model.upperPositionLimit)[self.q_index].copy()
        self.step = step

    def step_bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds on dq for a step from q, each shape (nv,)."""
        lower, upper = np.empty(self.step.shape[0]), np.empty(self.step.shape[0])
        _step_bounds(np.ascontiguousarray(q, dtype=np.float64), self.q_index, self.v_index, self.lower, self.upper,
                     self.step, lower, upper)
        return lower, upper

    def clamp(self, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """q with its limited coordinates clipped into [lower, upper], shape (nq,); written into
        `out` (a contiguous float64 array of q's shape, q itself for in place) when given."""
        if out is None:
            out = np.array(q, dtype=np.float64)
        elif out is not q:
            out[:] = q
        _clamp(out, self.q_index, self.lower, self.upper)
        return out

    def violation(self, q: np.ndarray) -> float:
        """Largest distance [rad or m] by which q leaves its limits (0 inside)."""
        return float(_violation(np.ascontiguousarray(q, dtype=np.float64), self.q_index, self.lower, self.upper))

    def at_limit(self, q: np.ndarray, tolerance: float = 1e-6) -> list[str]:
        """Names of the joints within `tolerance` of a limit."""
        q_limited = q[self.q_index]
        hit = (q_limited - self.lower < tolerance) | (self.upper - q_limited < tolerance)
        return [name for name, is_hit in zip(self.joint_names, hit, strict=True) if is_hit]


# Compiled: they run at every solver step or solve, where their dozen numpy calls cost more than
# the arithmetic.
@njit(cache=True, nogil=True)
def _step_bounds(q, q_index, v_index, lower_limit, upper_limit, step, lower, upper):
    """lower, upper (nv,) of JointLimits.step_bounds, written in place."""
    for v in range(step.shape[0]):
        lower[v], upper[v] = -step[v], step[v]
    for i in range(q_index.shape[0]):
        v, value = v_index[i], q[q_index[i]]
        low = max(-step[v], lower_limit[i] - value)
        high = min(step[v], upper_limit[i] - value)
        # Outside the limits by more than one step the box would be empty: land on the limit.
        if low > high:
            if value < lower_limit[i]:
                high = low
            elif value > upper_limit[i]:
                low = high
        lower[v], upper[v] = low, high


@njit(cache=True, nogil=True)
def _clamp(q, q_index, lower_limit, upper_limit):
    """q's limited coordinates clipped into their limits, in place."""
    for i in range(q_index.shape[0]):
        q[q_index[i]] = min(max(q[q_index[i]], lower_limit[i]), upper_limit[i])


@njit(cache=True, nogil=True)
def _violation(q, q_index, lower_limit, upper_limit):
    """JointLimits.violation: the largest distance by which q's limited coordinates leave their limits."""
    worst = 0.0
    for i in range(q_index.shape[0]):
        value = q[q_index[i]]
        worst = max(worst, lower_limit[i] - value, value - upper_limit[i])
    return worst
