"""The centre of mass over the feet: a balance task from Pinocchio's centre-of-mass Jacobian."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.tasks.base import Task

__all__ = ["DEFAULT_FEET", "CenterOfMassTask"]

# The support the centre of mass is kept over when no feet are named: the ankles and, where the
# model has them, the heels and big toes (the mean of a foot's points lies mid-foot).
DEFAULT_FEET = ("LAnkle", "RAnkle", "LHeel", "RHeel", "LBigToe", "RBigToe")


class CenterOfMassTask(Task):
    """Keep the horizontal position of the centre of mass over the mean of the feet keypoints.

    e = S (c(q) - mean_k p_k(q)) [m], shape (2,), where c is the centre of mass (Pinocchio's
    segment masses), p_k the feet keypoints and S keeps the two horizontal axes of the model's
    frame (Y up). Its Jacobian is S (J_com - mean_k J_k).

    Args:
        body: the body model (its masses and keypoints).
        feet: keypoints whose mean is the support point (None: DEFAULT_FEET present in the body).
        gain, weight: as every Task.

    Raises:
        InputError: an unknown keypoint among the feet, or a body without mass.
    """

    def __init__(self, body: BodyModel, feet: Sequence[str] | None = None, gain: float = 1.0,
                 weight: float = 1.0) -> None:
        super().__init__(gain, weight)
        if feet is None:
            feet = [name for name in DEFAULT_FEET if name in body.keypoints]
        unknown = [name for name in feet if name not in body.keypoints]
        if unknown or not feet:
            raise InputError(f"feet: expected keypoints of the body, found {list(feet)!r}; "
                             f"known keypoints: {', '.join(body.keypoints)}")
        if pin.computeTotalMass(body.model) <= 0.0:
            raise InputError("the centre-of-mass task needs a body with mass; this model's segments have none")
        self.model = body.model
        self.feet = list(feet)
        self.feet_frame_ids = body.frame_ids(self.feet)
        self._data = body.model.createData()  # its own: the COM algorithms must not touch the configuration's
        self._horizontal = np.array([0, 2])
        self._cache_version = -1
        self._com = np.zeros(3)
        self._com_jacobian = np.zeros((3, body.model.nv))

    def _update(self, configuration: Configuration) -> None:
        if self._cache_version != configuration.version:
            self._com_jacobian = pin.jacobianCenterOfMass(self.model, self._data, configuration.q).copy()
            self._com = self._data.com[0].copy()
            self._cache_version = configuration.version

    def center_of_mass(self, configuration: Configuration) -> np.ndarray:
        """World position of the centre of mass [m], shape (3,)."""
        self._update(configuration)
        return self._com

    def compute_error(self, configuration: Configuration) -> np.ndarray:
        support = configuration.frame_positions(self.feet_frame_ids).mean(axis=0)
        return (self.center_of_mass(configuration) - support)[self._horizontal]

    def compute_jacobian(self, configuration: Configuration) -> np.ndarray:
        self._update(configuration)
        support = configuration.frame_translation_jacobians(self.feet_frame_ids).mean(axis=0)
        return (self._com_jacobian - support)[self._horizontal]
