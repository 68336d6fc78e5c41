"""Shared fixtures: real Pinocchio models, seeded random generators, reachable targets."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see ibik_pin/cli.py

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.human import load_human
from ibik_pin.limits import JointLimits


@pytest.fixture(scope="session")
def human():
    return load_human()


@pytest.fixture
def rng():
    return np.random.default_rng(20101)


def random_human_configuration(body, rng, spread: float = 0.6) -> np.ndarray:
    """A configuration inside the limits (a fraction `spread` of each range around its middle),
    with a random root position and orientation, shape (nq,)."""
    model = body.model
    limits = JointLimits(model)
    middle = 0.5 * (limits.lower + limits.upper)
    half = 0.5 * (limits.upper - limits.lower) * spread
    q = pin.neutral(model)
    q[limits.q_index] = middle + rng.uniform(-1.0, 1.0, middle.size) * half
    q[:3] = rng.normal(0.0, 0.3, 3)
    q[3:7] = pin.Quaternion(pin.exp3(rng.normal(0.0, 0.3, 3))).coeffs()
    return q


def central_difference_gradient(task, model, q, eps=1e-6):
    """d task.compute_value / dv at q by central differences (steps of `eps` through pin.integrate),
    shape (nv,): the reference every analytic gradient is checked against."""
    gradient = np.zeros(model.nv)
    for k in range(model.nv):
        dv = np.zeros(model.nv)
        dv[k] = eps
        plus = task.compute_value(Configuration(model, pin.integrate(model, q, dv)))
        minus = task.compute_value(Configuration(model, pin.integrate(model, q, -dv)))
        gradient[k] = (plus - minus) / (2 * eps)
    return gradient
