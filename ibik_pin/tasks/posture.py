"""Posture: stay near a reference configuration (the usual lowest level of a stack)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.tasks.base import Task


class PostureTask(Task):
    """e = q (-) q_ref on chosen velocity coordinates: by default the actuated joints (the
    free-flyer root, if any, is left free).

    The Jacobian is the identity on those velocity coordinates, exact for revolute and prismatic
    joints, and for a free-flyer root at the reference (where a hold keeps it). Holding
    coordinates where they are (`coordinates` a mask, reference the current q) at the top of a
    stack freezes them for the levels below, which is how the tracker keeps the trunk out of the
    image level's reach.
    """

    def __init__(
        self,
        model: pin.Model,
        reference: np.ndarray | None = None,
        gain: float = 1.0,
        weight: float = 1.0,
        coordinates: np.ndarray | None = None,
    ) -> None:
        """
        Args:
            coordinates: (nv,) bool mask of the velocity coordinates the task holds; None: every
                coordinate but a free-flyer root's six.
        """
        super().__init__(gain, weight)
        self.model = model
        if coordinates is None:
            root_is_free = model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer"
            self._rows = np.arange(6 if root_is_free else 0, model.nv)
        else:
            mask = np.asarray(coordinates, dtype=bool)
            if mask.shape != (model.nv,):
                raise InputError(f"coordinates: expected a bool mask of shape ({model.nv},), got {mask.shape}")
            self._rows = np.flatnonzero(mask)
        self._jacobian = np.eye(model.nv)[self._rows]
        self.set_reference(pin.neutral(model) if reference is None else reference)

    def set_reference(self, reference: np.ndarray) -> None:
        """Set the reference configuration, shape (nq,)."""
        reference = np.array(reference, dtype=float)
        if reference.shape != (self.model.nq,) or not np.all(np.isfinite(reference)):
            raise InputError(
                f"posture reference must be a finite array of shape ({self.model.nq},), "
                f"got shape {reference.shape}"
            )
        self.reference = reference

    def compute_error(self, configuration: Configuration) -> np.ndarray:
        return pin.difference(self.model, self.reference, configuration.q)[self._rows]

    def compute_jacobian(self, configuration: Configuration) -> np.ndarray:
        return self._jacobian
