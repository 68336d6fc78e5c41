"""Levenberg-Marquardt on the static fit of subject calibration.

The fit, a :class:`~ibik_pin.subject.static_fit.StaticFit`, is solved in place in the two stages
:func:`~ibik_pin.subject.calibration.calibrate_subject` runs: the poses alone (:func:`solve_poses`),
then poses, placements and joint groups together (:func:`solve_all`). Each step uses the analytic
Jacobians of :meth:`~ibik_pin.subject.static_fit.StaticFit.frame_terms` and eliminates the model
unknowns through the per-frame pose blocks, so a step costs F small solves.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ibik_pin.exceptions import SolverError
from ibik_pin.subject.static_fit import StaticFit

__all__ = ["solve_all", "solve_poses"]


def solve_poses(fit: StaticFit) -> None:
    """Each frame's pose on the current model (placements and scales fixed), set in ``fit.q``.

    Raises:
        SolverError: a Levenberg-Marquardt step failed.
    """
    _levenberg_marquardt(fit, fit_model=False, iterations=fit.settings.pose_iterations)


def solve_all(fit: StaticFit) -> None:
    """Poses, placements and segment groups together, set in ``fit``.

    Raises:
        SolverError: a Levenberg-Marquardt step failed.
    """
    _levenberg_marquardt(fit, fit_model=True, iterations=fit.settings.iterations)


def _levenberg_marquardt(fit: StaticFit, fit_model: bool, iterations: int) -> None:
    """Levenberg-Marquardt on every frame's pose, and the placements if `fit_model`.

    Each step linearises at the current poses (tangent v, q <- integrate(q, v)); the
    placements' unknowns are eliminated through the per-frame blocks (Schur complement), so a
    step costs F small solves. Joint limits and placement bounds are kept by clipping, with the
    coordinates at a bound that the gradient pushes outward frozen for the step.
    """
    model = fit.model
    nv, frame_count = model.nv, fit.points.shape[0]
    theta = fit.model_vector()
    theta_count = theta.size if fit_model else 0
    theta_lower, theta_upper = fit.model_bounds()
    q = np.array([fit.clip(configuration) for configuration in fit.q])
    cost = fit.cost(q, theta)
    damping = 1e-3
    posture = fit.posture_weights ** 2
    for _ in range(iterations):
        fit.set_model_vector(theta)
        terms = [fit.frame_terms(frame, q[frame], fit_model) for frame in range(frame_count)]
        residual = np.array([term[0] for term in terms])  # (F, 3K)
        row_weights = np.repeat(np.array([term[1] for term in terms]), 3, axis=1)  # (F, 3K)
        pose_jacobian = np.array([term[2] for term in terms])  # (F, 3K, nv)
        weighted = pose_jacobian * row_weights[..., None]
        hessian = np.matmul(weighted.transpose(0, 2, 1), pose_jacobian)  # (F, nv, nv)
        gradient = np.matmul(weighted.transpose(0, 2, 1), residual[..., None])[..., 0]
        hessian[:, fit.revolute_v, fit.revolute_v] += posture
        gradient[:, fit.revolute_v] += posture * q[:, fit.revolute_q]
        if fit_model:
            model_jacobian = np.array([term[3] for term in terms])  # (F, 3K, T)
            coupling = np.matmul(weighted.transpose(0, 2, 1), model_jacobian)  # (F, nv, T)
            weighted_model = (model_jacobian * row_weights[..., None]).reshape(-1, model_jacobian.shape[2])
            hessian_model = weighted_model.T @ model_jacobian.reshape(weighted_model.shape)
            gradient_model = weighted_model.T @ residual.reshape(-1)
        else:
            coupling = np.zeros((frame_count, nv, 0))
            hessian_model, gradient_model = np.zeros((0, 0)), np.zeros(0)
        # Coordinates at a limit that the gradient pushes outward are frozen for the step.
        at_lower = q[:, fit.revolute_q] <= fit.lower + 1e-10
        at_upper = q[:, fit.revolute_q] >= fit.upper - 1e-10
        revolute_gradient = gradient[:, fit.revolute_v]
        pushed = np.zeros((frame_count, nv), dtype=bool)
        pushed[:, fit.revolute_v] = (at_lower & (revolute_gradient > 0.0)) | (at_upper & (revolute_gradient < 0.0))
        blocks = (hessian, gradient, coupling, pushed)
        frozen_model = np.zeros(theta_count, dtype=bool)
        if fit_model:
            prior, prior_weights = fit.model_prior(theta)
            hessian_model[np.diag_indices(theta_count)] += prior_weights ** 2
            gradient_model += prior_weights * prior
            frozen_model = ((theta <= theta_lower + 1e-12) & (gradient_model > 0.0)) | (
                (theta >= theta_upper - 1e-12) & (gradient_model < 0.0))
            if not fit.settings.fit_scales:
                frozen_model[3 * len(fit.names):] = True
        accepted = False
        for _ in range(12):
            try:
                steps, step_model = _damped_step(blocks, hessian_model, gradient_model, frozen_model, damping)
            except np.linalg.LinAlgError as error:
                raise SolverError(f"calibration: a Levenberg-Marquardt step failed: {error}") from error
            q_new = np.array([fit.clip(pin.integrate(model, q[f], steps[f])) for f in range(frame_count)])
            theta_new = np.clip(theta + step_model, theta_lower, theta_upper) if fit_model else theta
            new_cost = fit.cost(q_new, theta_new)
            if new_cost < cost:
                accepted = True
                break
            damping *= 4.0
        if not accepted:
            break
        decrease = cost - new_cost
        q, theta, cost = q_new, theta_new, new_cost
        damping = max(damping / 3.0, 1e-9)
        if decrease <= 1e-12 * max(cost, 1e-12) + 1e-16:
            break
    fit.q = q
    fit.set_model_vector(theta)


def _damped_step(blocks, hessian_model, gradient_model, frozen_model, damping):
    """The LM step: per-frame pose steps (F, nv) and the placements' step, by Schur complement.

    `blocks`: the frames' Hessians (F, nv, nv), gradients (F, nv), couplings to the model unknowns
    (F, nv, T) and frozen coordinates (F, nv) bool, solved for every frame at once."""
    hessian, gradient, coupling, pushed = blocks
    theta_count = gradient_model.size
    damped = hessian + damping * _diagonal(_damping_scale(hessian))
    frozen = pushed[:, :, None] | pushed[:, None, :]
    damped[frozen] = 0.0
    damped += _diagonal(pushed.astype(float))
    gradient = np.where(pushed, 0.0, gradient)
    coupling = np.where(pushed[..., None], 0.0, coupling)
    solved = np.linalg.solve(damped, np.concatenate([gradient[..., None], coupling], axis=2))  # (F, nv, 1 + T)
    step_model = np.zeros(theta_count)
    if theta_count:
        schur = hessian_model + damping * np.diag(_damping_scale(hessian_model))
        stacked = coupling.reshape(-1, theta_count)  # (F nv, T): the frames' sums as one product
        schur -= stacked.T @ solved[:, :, 1:].reshape(stacked.shape)
        rhs = -gradient_model + stacked.T @ solved[:, :, 0].reshape(-1)
        free = ~frozen_model
        step_model[free] = np.linalg.solve(schur[np.ix_(free, free)], rhs[free])
    steps = -(solved[:, :, 0] + np.matmul(solved[:, :, 1:], step_model))
    return steps, step_model


def _diagonal(values: np.ndarray) -> np.ndarray:
    """Diagonal matrices (..., n, n) of the rows of `values` (..., n)."""
    out = np.zeros((*values.shape, values.shape[-1]))
    index = np.arange(values.shape[-1])
    out[..., index, index] = values
    return out


def _damping_scale(hessian: np.ndarray) -> np.ndarray:
    """Levenberg-Marquardt damping per unknown: the Hessian's diagonal, floored at 1e-3 of its
    largest entry so that an unknown the data barely sees (a wrist turn no keypoint follows) cannot
    take a huge step. `hessian` (n, n), or (F, n, n) for F frames at once."""
    diagonal = np.diagonal(hessian, axis1=-2, axis2=-1).copy()
    largest = np.max(diagonal, axis=-1, keepdims=True, initial=0.0)
    return np.maximum(diagonal, 1e-3 * np.maximum(largest, 1e-12))
