"""What tracking a sequence gives: every frame's pose, keypoints, residuals, image overlap and levels.

`Tracker.track` (:mod:`ibik_pin.tracking.tracker`) fills it; :mod:`ibik_pin.app.report` turns it
into report.json, :mod:`ibik_pin.app.outputs` into the output files.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ibik_pin.solvers import LevelReport
from ibik_pin.tracking.outcomes import LevelOutcome

__all__ = ["TrackingResult"]


@dataclass
class TrackingResult:
    """The motion and what happened while solving it.

    Attributes:
        q: (F, nq) configurations [m, rad].
        keypoint_names: every keypoint of the body.
        keypoints: (F, K, 3) world positions of those keypoints [m].
        target_residuals: (F,) mean distance of the present targets to their keypoints [m].
        target_names: the T target keypoints, in the order of the targets given to track().
        target_distances: (F, T) distance of each target keypoint of the model to its target [m],
            NaN where the target is absent that frame.
        overlap: (F, V) the criterion of each view at the solution (NaN where disabled): the mean
            over the skeleton's sample points of the capped signed-distance support [px].
        inside_fraction: (F, V) the fraction of those sample points that project inside the
            silhouette (support > 0) [0-1], NaN where disabled.
        camera_names: the cameras whose images were read, in the order of overlap's columns
            (empty when blind).
        limit_hits: per frame, the joints at a limit.
        dropped_targets: per frame, the targets absent (NaN) in that frame.
        disabled_views: per frame, the cameras whose silhouette was empty.
        solve_seconds: wall time of the solves alone [s], Numba's compilation included.
        compile_seconds: wall time this process spent compiling kernels during the frame loop [s]
            (a first run on a machine; 0 once they are cached on disk); solve_compile_seconds:
            its part inside the solves.
        loop_seconds: wall time of the whole frame loop [s]: the solves, reading the silhouettes,
            building the support images and medial axes, and each frame's checks.
        level_names: the L levels of the stack, highest first (the default stack's: "lower-body
            targets", "upper-body targets", "image" (when the image is used), "posture").
        level_reports: per frame, per level handed to the solver (one per strict stack level, one
            per run of weighted ones), the solver's report of the frame solve's last step: status
            ("solved", "relaxed", "failed", "empty") and residual (NaN for the image level, which
            reports its criterion instead). With `swivel_search`, the frame's main solve, before
            the swivel pass.
        level_outcomes: per frame, per stack level (L), its status, residual, criterion and how
            much of it the levels above sacrificed, at the frame's solution (tracking.outcomes).
        iterations: per frame, the steps of its main solve (fewer than the settings' with
            `step_tolerance`; the first frame's are its search's).
        swivel_smoothing: what the swivel smoothing did (Tracker.track's `frame_rate_hz`): its
            cutoff, the frames moved, per elbow and knee how far it moved and how far it ended from
            its smoothed place [mm]; None when it did not run.
    """

    q: np.ndarray
    keypoint_names: list[str]
    keypoints: np.ndarray
    target_residuals: np.ndarray
    overlap: np.ndarray
    limit_hits: list[list[str]] = field(default_factory=list)
    dropped_targets: list[list[str]] = field(default_factory=list)
    disabled_views: list[list[str]] = field(default_factory=list)
    solve_seconds: float = 0.0
    loop_seconds: float = 0.0
    compile_seconds: float = 0.0
    solve_compile_seconds: float = 0.0
    target_names: list[str] = field(default_factory=list)
    target_distances: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    level_names: list[str] = field(default_factory=list)
    level_reports: list[list[LevelReport]] = field(default_factory=list)
    level_outcomes: list[list[LevelOutcome]] = field(default_factory=list)
    inside_fraction: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    camera_names: list[str] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    swivel_smoothing: dict | None = None

    @property
    def solve_frames_per_second(self) -> float:
        """Frames per second of the solves alone, compilation left out [Hz]; NaN if unmeasured."""
        seconds = self.solve_seconds - self.solve_compile_seconds
        return len(self.q) / seconds if seconds > 0 else float("nan")

    @property
    def frames_per_second(self) -> float:
        """Frames per second of the whole frame loop, compilation left out [Hz]; NaN if unmeasured."""
        seconds = self.loop_seconds - self.compile_seconds
        return len(self.q) / seconds if seconds > 0 else float("nan")
