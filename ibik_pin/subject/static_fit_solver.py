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
    for _ in range(iterations):
        fit.set_model_vector(theta)
        blocks = []
        hessian_model = np.zeros((theta_count, theta_count))
        gradient_model = np.zeros(theta_count)
        for frame in range(frame_count):
            residual, weights, pose_jacobian, model_jacobian = fit.frame_terms(frame, q[frame], fit_model)
            row_weights = np.repeat(weights, 3)
            weighted = pose_jacobian * row_weights[:, None]
            hessian = weighted.T @ pose_jacobian
            gradient = weighted.T @ residual
            posture = fit.posture_weights ** 2
            hessian[fit.revolute_v, fit.revolute_v] += posture
            gradient[fit.revolute_v] += posture * q[frame][fit.revolute_q]
            coupling = weighted.T @ model_jacobian if fit_model else np.zeros((nv, 0))
            if fit_model:
                hessian_model += (model_jacobian * row_weights[:, None]).T @ model_jacobian
                gradient_model += (model_jacobian * row_weights[:, None]).T @ residual
            at_lower = q[frame][fit.revolute_q] <= fit.lower + 1e-10
            at_upper = q[frame][fit.revolute_q] >= fit.upper - 1e-10
            pushed = fit.revolute_v[(at_lower & (gradient[fit.revolute_v] > 0.0))
                                    | (at_upper & (gradient[fit.revolute_v] < 0.0))]
            blocks.append((hessian, gradient, coupling, pushed))
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
    """The LM step: per-frame pose steps (F, nv) and the placements' step, by Schur complement."""
    theta_count = gradient_model.size
    schur = hessian_model + damping * np.diag(_damping_scale(hessian_model))
    rhs = -gradient_model.copy()
    eliminated = []
    for hessian, gradient, coupling, pushed in blocks:
        damped = hessian + damping * np.diag(_damping_scale(hessian))
        gradient = gradient.copy()
        coupling = coupling.copy()
        damped[pushed, :] = 0.0
        damped[:, pushed] = 0.0
        damped[pushed, pushed] = 1.0
        gradient[pushed] = 0.0
        coupling[pushed, :] = 0.0
        solved = np.linalg.solve(damped, np.column_stack([gradient, coupling]))
        eliminated.append(solved)
        if theta_count:
            schur -= coupling.T @ solved[:, 1:]
            rhs += coupling.T @ solved[:, 0]
    step_model = np.zeros(theta_count)
    if theta_count:
        free = ~frozen_model
        step_model[free] = np.linalg.solve(schur[np.ix_(free, free)], rhs[free])
    steps = np.array([-(solved[:, 0] + solved[:, 1:] @ step_model) for solved in eliminated])
    return steps, step_model


def _damping_scale(hessian: np.ndarray) -> np.ndarray:
    """Levenberg-Marquardt damping per unknown: the Hessian's diagonal, floored at 1e-3 of its
    largest entry so that an unknown the data barely sees (a wrist turn no keypoint follows) cannot
    take a huge step."""
    diagonal = np.diag(hessian).copy()
    return np.maximum(diagonal, 1e-3 * max(float(diagonal.max(initial=0.0)), 1e-12))
