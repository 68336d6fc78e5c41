"""Joint position limits (from the URDF) and per-step bounds, as box constraints on dq."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

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
        self.q_index = np.array(q_index, dtype=int)
        self.v_index = np.array(v_index, dtype=int)
        self.lower = np.asarray(model.lowerPositionLimit)[self.q_index].copy()
        self.upper = np.asarray(model.upperPositionLimit)[self.q_index].copy()
        self.step = step

    def step_bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds on dq for a step from q, each shape (nv,)."""
        lower_step = -self.step
        upper_step = self.step.copy()
        q_limited = q[self.q_index]
        lower = np.maximum(lower_step[self.v_index], self.lower - q_limited)
        upper = np.minimum(upper_step[self.v_index], self.upper - q_limited)
        # Outside the limits by more than one step the box would be empty: land on the limit.
        empty = lower > upper
        if empty.any():
            below = empty & (q_limited < self.lower)
            above = empty & (q_limited > self.upper)
            upper = np.where(below, lower, upper)
            lower = np.where(above, upper, lower)
        lower_step[self.v_index] = lower
        upper_step[self.v_index] = upper
        return lower_step, upper_step

    def clamp(self, q: np.ndarray) -> np.ndarray:
        """q with its limited coordinates clipped into [lower, upper], shape (nq,)."""
        q = q.copy()
        q[self.q_index] = np.clip(q[self.q_index], self.lower, self.upper)
        return q

    def violation(self, q: np.ndarray) -> float:
        """Largest distance [rad or m] by which q leaves its limits (0 inside)."""
        q_limited = q[self.q_index]
        return float(max(0.0, np.max(self.lower - q_limited, initial=0.0),
                         np.max(q_limited - self.upper, initial=0.0)))

    def at_limit(self, q: np.ndarray, tolerance: float = 1e-6) -> list[str]:
        """Names of the joints within `tolerance` of a limit."""
        q_limited = q[self.q_index]
        hit = (q_limited - self.lower < tolerance) | (self.upper - q_limited < tolerance)
        return [name for name, is_hit in zip(self.joint_names, hit, strict=True) if is_hit]
