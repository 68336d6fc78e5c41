"""Frames left unsolved (a whole-body jump of their targets, app.input_checks.frame_jumps): the tracker
solves the other frames only, and each left-out frame gets the pose interpolated in time between the
solved frames on either side (pinocchio.interpolate: along the configuration space's geodesic, the
free-flyer's orientation included); at an end, the nearest solved frame's pose.

Solving such a frame from its leapt targets would pull the body metres away and spoil the frames
after it (the solver's start is the previous frame's pose); solving it without targets would leave
it wherever the image term drags it. Its figures say so: residuals, image criterion and inside
fractions NaN (null in report.json), every target listed as dropped, every level "empty".
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import pinocchio as pin

from ibik_pin.configuration import Configuration
from ibik_pin.model import BodyModel
from ibik_pin.tracking.outcomes import LevelOutcome
from ibik_pin.tracking.result import TrackingResult

__all__ = ["SolvedFramesSource", "expand_to_frames"]


class SolvedFramesSource:
    """The silhouettes of the solved frames only: the tracker's frame i is the trial's frame
    solved[i]."""

    def __init__(self, source: Callable[[int], Sequence[np.ndarray]], solved: np.ndarray) -> None:
        self._source = source
        self._solved = np.asarray(solved, dtype=int)

    def __call__(self, frame: int) -> Sequence[np.ndarray]:
        return self._source(int(self._solved[frame]))


def expand_to_frames(result: TrackingResult, body: BodyModel, solved: np.ndarray,
                     times_s: np.ndarray) -> TrackingResult:
    """The tracking of the frames `solved` (indices into the trial's F frames, increasing) spread
    over all F frames, the others' poses interpolated (see the module docstring).

    Args:
        result: the tracker's result over len(solved) frames.
        solved: the trial's indices of those frames.
        times_s: (F,) the trial's times [s].
    """
    times = np.asarray(times_s, dtype=float)
    frame_count = len(times)
    solved = np.asarray(solved, dtype=int)
    left_out = np.setdiff1d(np.arange(frame_count), solved)

    def spread(values: np.ndarray, fill: float) -> np.ndarray:
        out = np.full((frame_count, *values.shape[1:]), fill, dtype=float)
        out[solved] = values
        return out

    def listed(values: list, fill: Callable[[], object]) -> list:
        out = [fill() for _ in range(frame_count)]
        for index, frame in enumerate(solved):
            out[frame] = values[index]
        return out

    q = spread(result.q, np.nan)
    keypoints = spread(result.keypoints, np.nan)
    keypoint_ids = body.frame_ids(list(result.keypoint_names))
    for frame in left_out:
        after = int(np.searchsorted(solved, frame))
        if after == 0 or after == len(solved):
            q[frame] = q[solved[min(after, len(solved) - 1)]]
        else:
            before_frame, after_frame = solved[after - 1], solved[after]
            weight = (times[frame] - times[before_frame]) / (times[after_frame] - times[before_frame])
            q[frame] = pin.interpolate(body.model, q[before_frame], q[after_frame], float(weight))
        keypoints[frame] = Configuration(body.model, q[frame]).frame_positions(keypoint_ids)
    level_count = len(result.level_names)
    return TrackingResult(
        q=q, keypoint_names=list(result.keypoint_names), keypoints=keypoints,
        target_residuals=spread(result.target_residuals, np.nan),
        overlap=spread(result.overlap, np.nan),
        limit_hits=listed(result.limit_hits, list),
        dropped_targets=listed(result.dropped_targets, lambda: list(result.target_names)),
        disabled_views=listed(result.disabled_views, list),
        solve_seconds=result.solve_seconds, loop_seconds=result.loop_seconds,
        compile_seconds=result.compile_seconds, solve_compile_seconds=result.solve_compile_seconds,
        target_names=list(result.target_names),
        target_distances=spread(result.target_distances, np.nan),
        level_names=list(result.level_names),
        level_reports=listed(result.level_reports, list),
        level_outcomes=listed(result.level_outcomes, lambda: [LevelOutcome("empty", np.nan, np.nan, np.nan)
                                                              for _ in range(level_count)]),
        inside_fraction=(spread(result.inside_fraction, np.nan) if len(result.inside_fraction) == len(solved)
                         else result.inside_fraction),
        camera_names=list(result.camera_names),
        iterations=listed(result.iterations, int),
        swivel_smoothing=result.swivel_smoothing,
    )
