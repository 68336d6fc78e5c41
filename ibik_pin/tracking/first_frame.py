"""The first frame of a sequence: solved from the neutral pose, blind first, then with the image."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.solvers import SolveResult
from ibik_pin.tasks.base import GradientTask

__all__ = ["solve_first_frame"]

# The blind solve from the neutral pose stops once a step is this small [rad]: on a body a metre
# long it then moves no keypoint by a micrometre. It converges in about 20 of its 100 steps on
# real boxing; the steps with the image, which keep moving with the silhouettes, run in full.
BLIND_CONVERGED = 1e-6


def solve_first_frame(
    solver,
    configuration: Configuration,
    levels: list[list],
    image_task: GradientTask | None,
    iterations: int,
    starts: int = 1,
    spread: float = 0.5,
    seed: int = 0,
    solve: Callable[..., SolveResult] | None = None,
    blind_levels: list[list] | None = None,
) -> SolveResult:
    """The first frame, from configuration.q: blind IK (at most `iterations` steps, fewer once it
    has converged), then every level (`iterations` steps); with `starts` > 1 also
    from random joint angles (a fraction `spread` of each range around the middle, root kept),
    keeping the solution whose image criterion is highest. Returns the kept solution's last solve.
    The blind solve takes `blind_levels` (default: the levels without the one holding image_task).

    Later frames warm-start from this one and follow the criterion's local maximum, so a wrong
    basin on the first frame (an elbow 20 cm off with its forearm still on the silhouette) lasts;
    several starts make that much rarer. `solve(configuration, levels, iterations=)` solves with
    the image (default solver.solve; the tracker passes its frame solve).
    """
    solve = solver.solve if solve is None else solve
    blind = [level for level in levels if image_task not in level] if blind_levels is None else blind_levels
    limits = solver.limits
    rng = np.random.default_rng(seed)
    initial = configuration.q.copy()
    solutions: list[tuple[float, np.ndarray, SolveResult]] = []  # criterion, q, last solve
    for start in range(max(int(starts), 1) if image_task is not None else 1):
        q = initial.copy()
        if start > 0 and limits is not None:
            middle = 0.5 * (limits.lower + limits.upper)
            half = 0.5 * spread * (limits.upper - limits.lower)
            q[limits.q_index] = middle + rng.uniform(-1.0, 1.0, middle.size) * half
        configuration.update(q)
        blind_result = solver.solve(configuration, blind, iterations=iterations, tolerance=BLIND_CONVERGED)
        if image_task is None:
            return blind_result
        solved = solve(configuration, levels, iterations=iterations)
        solutions.append((image_task.compute_value(configuration), configuration.q.copy(), solved))
    # The first of the highest criteria, as max() keeps the earliest of equal keys.
    _, best_q, best_result = max(solutions, key=lambda solution: solution[0])
    configuration.update(best_q)
    return best_result
