"""Several criteria followed as one: h(q) = sum of w_k h_k(q).

A priority level holds at most one gradient task; this one lets a level follow, for example, the
paper's overlap and the silhouette-axis term together, each with its weight.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.tasks.base import GradientTask

__all__ = ["WeightedSum"]


class WeightedSum(GradientTask):
    """The weighted sum of gradient tasks; disabled terms count as zero.

    Attributes:
        terms: the criteria; weights: their weights (>= 0), shape (T,).
    """

    def __init__(
        self,
        terms: Sequence[GradientTask],
        weights: Sequence[float],
        max_step_size: float = 0.05,
        min_step_size: float = 1e-4,
    ) -> None:
        super().__init__(max_step_size, min_step_size)
        self.terms = list(terms)
        self.weights = np.asarray(weights, dtype=float)
        if not self.terms or self.weights.shape != (len(self.terms),):
            raise InputError(f"weights: expected one weight per term ({len(self.terms)}), found {self.weights.shape}")
        if not (np.isfinite(self.weights).all() and (self.weights >= 0.0).all()):
            raise InputError(f"weights: expected finite non-negative weights, found {self.weights.tolist()}")

    @property
    def enabled(self) -> bool:
        return any(term.enabled for term in getattr(self, "terms", ()))

    @enabled.setter
    def enabled(self, value: bool) -> None:
        """The sum follows its terms; the base class's initial flag is ignored."""

    def compute_value(self, configuration: Configuration) -> float:
        return float(sum(weight * term.compute_value(configuration)
                         for term, weight in zip(self.terms, self.weights, strict=True) if term.enabled))

    def compute_gradient(self, configuration: Configuration) -> np.ndarray:
        gradient = np.zeros(configuration.model.nv)
        for term, weight in zip(self.terms, self.weights, strict=True):
            if term.enabled and weight > 0.0:
                gradient += weight * term.compute_gradient(configuration)
        return gradient
