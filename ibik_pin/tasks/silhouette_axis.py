"""The silhouette explained by the skeleton: its medial axis drawn to the nearest projected segment.

The paper's criterion (eq. 5-6, :mod:`ibik_pin.tasks.image`) is one-way: it rewards a skeleton for
lying inside the silhouette, never for accounting for all of it. Inside a capped support it is flat:
a nearly straight leg whose knee swivels, or an arm held over the trunk, scores the same wherever it
lies within the silhouette. This term is the other way round: every sample x_i of the silhouette's
medial axis (:func:`ibik_pin.vision.medial_axis.medial_axis_pixels`) asks that some projected
segment pass through it:

    h_axis(q) = - mean over views and samples of  c/2 (1 - exp(-(d_i / c)^2))

with d_i [px] the distance from x_i to the nearest projected segment (the segment between the
projections of its two end keypoints) and c [px] a robust scale: a sample much farther than c from
every segment (a spur of the axis, clutter, a limb the model lacks) weighs almost nothing. The term
asks for centre lines on centre lines, so it needs no body widths.

Gradient (the nearest segment and the closest point's parameter s held, which is exact for the
minimum over s and almost everywhere for the minimum over segments):

    dh/dq = mean of  exp(-(d_i/c)^2) / c  r_i^T ((1 - s) dpi/dX J_a + s dpi/dX J_b)

with r_i = x_i - p_i the residual from the closest point p_i to the sample [px], J_a and J_b the
translation Jacobians of the segment's end frames and dpi/dX the projection Jacobian.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from ibik_pin.checks import all_finite
from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.tasks.segments import SegmentCriterion, segment_ends
from ibik_pin.vision.camera import CameraLike
from ibik_pin.vision.candidate_kernels import (
    candidate_axis_values,
    moved_axis_values,
    nearest_of_rows,
    segment_squared_distances,
)
from ibik_pin.vision.kernels import MIN_DEPTH, axis_value_and_frame_gradient

__all__ = ["AxisView", "SilhouetteAxisTask"]


@dataclass
class AxisView:
    """One camera and the medial-axis samples of its silhouette.

    Attributes:
        camera: the camera (vision.camera.CameraLike); its ``project_with_jacobian(points_world
            (K, 3))`` gives pixels (K, 2), d pixels / d X_world (K, 2, 3) and depth (K,).
        pixels: (N, 2) medial-axis samples (u, v) [px]; N = 0 disables the view.
        robust_scale_px: c, the distance [px] beyond which a sample stops pulling.
    """

    camera: CameraLike
    pixels: np.ndarray
    robust_scale_px: float

    def __post_init__(self) -> None:
        self.pixels = np.asarray(self.pixels, dtype=np.float64).reshape(-1, 2)
        if not all_finite(self.pixels):  # compiled: every frame's views are checked
            raise InputError("pixels: the medial-axis samples must be finite [px]")
        if not (np.isfinite(self.robust_scale_px) and self.robust_scale_px > 0.0):
            raise InputError(f"robust_scale_px: expected a positive distance [px], found {self.robust_scale_px}")


class SilhouetteAxisTask(SegmentCriterion):
    """Maximise h_axis: every medial-axis sample of every view near some projected segment.

    Attributes:
        body: the body model (keypoints and segments).
        segments: the keypoint pairs that can explain an axis sample.
        views: the views; replace with `set_views` per frame.
    """

    def __init__(
        self,
        body: BodyModel,
        views: Sequence[AxisView] = (),
        segments: Sequence[tuple[str, str]] | None = None,
        max_step_size: float = 0.05,
        min_step_size: float = 1e-4,
    ) -> None:
        super().__init__(max_step_size, min_step_size)
        self.body = body
        # Unique end frames: each projection and Jacobian is computed once per step.
        self.segments, self._frame_ids, self._start_index, self._end_index = segment_ends(
            body, segments, "the silhouette-axis task"
        )
        self.views: list[AxisView] = []
        self._changing: dict[bytes | None, tuple[np.ndarray, np.ndarray]] = {}
        self.set_views(views)

    def set_views(self, views: Sequence[AxisView]) -> None:
        """Replace the views (the next frame's axis samples); views without samples are skipped."""
        self.views = list(views)
        self._active_views = [view for view in self.views if len(view.pixels)]
        _, self._project, self._pixels = self._projections([view.camera for view in self._active_views])
        self.enabled = bool(self._active_views)
        self._cache_version = -1
        self._cache: tuple[float, np.ndarray] | None = None

    def _evaluate(self, configuration: Configuration) -> tuple[float, np.ndarray]:
        if self._cache_version == configuration.version and self._cache is not None:
            return self._cache
        positions = configuration.frame_positions(self._frame_ids)  # (K, 3)
        value = 0.0
        gradient_frames = np.zeros_like(positions)  # dh/dX of each end frame, (K, 3)
        views = 0
        for view, projection in zip(self._active_views, self._project(positions), strict=True):
            # A view with a segment end behind the camera is skipped: its projection means nothing.
            view_value, in_front = axis_value_and_frame_gradient(
                view.pixels, *projection, self._start_index, self._end_index, view.robust_scale_px, gradient_frames)
            value += view_value
            views += in_front
        if views == 0:
            self._cache = (0.0, np.zeros(configuration.model.nv))
        else:
            self._cache = (value / views, configuration.velocity_gradient(self._frame_ids, gradient_frames, views))
        self._cache_version = configuration.version
        return self._cache

    def at_pose(self, frame_positions: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per view: the ends' pixels (K, 2), whether each is in front (K,), and the squared distance
        of every axis sample to every segment (S, N) [px^2]."""
        known = []
        for view, (pixels, depth) in zip(self._active_views, self._pixels(frame_positions), strict=True):
            distances = np.empty((len(self.segments), len(view.pixels)))
            segment_squared_distances(view.pixels, pixels[self._start_index], pixels[self._end_index], distances)
            known.append((pixels, depth > MIN_DEPTH, distances))
        return known

    def values_at(self, frame_positions: np.ndarray, moved: np.ndarray | None = None,
                  pose: object | None = None) -> np.ndarray:
        """h_axis for (C, K, 3) placements of the segment ends, shape (C,) (see SegmentCriterion.values_at).

        The distances to the segments that no `moved` row ends are computed once, not per
        candidate (read in `pose` when given); a view with an end behind the camera is skipped for
        that candidate.
        """
        known = cast(list | None, pose) if moved is not None else None
        placed = _project_candidates(self._pixels, frame_positions, moved,
                                     None if known is None else [at_pose[:2] for at_pose in known])
        return self._placed_values(placed, frame_positions.shape[0], moved, known)

    def values_at_moves(self, positions: np.ndarray, pose: object | None,
                        moves: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[np.ndarray]:
        """values_at for each move (SegmentCriterion.values_at_moves), every move's candidates
        projected in one call and read in one compiled call per view: the same values, to the bit."""
        if pose is None or not moves:
            return super().values_at_moves(positions, pose, moves)
        known = cast(list, pose)
        placed = np.concatenate([np.asarray(points, dtype=float).reshape(-1, 3) for _, points in moves])
        bounds, placed_rows, changing, slices = self._kept_for_moves(moves, self._move_layout)
        values, counts = np.zeros(len(placed)), np.zeros(len(placed))
        view_values, visible = np.empty(len(placed)), np.empty(len(placed), dtype=bool)
        for view, (pose_pixels, pose_in_front, distances), (pixels, depth) in zip(
                self._active_views, known, self._pixels(placed), strict=True):
            moved_axis_values(view.pixels, distances, pose_pixels, pose_in_front, placed_rows, changing, bounds,
                              pixels, depth, self._start_index, self._end_index, view.robust_scale_px,
                              view_values, visible)
            values += np.where(visible, view_values, 0.0)
            counts += visible
        values /= np.maximum(counts, 1)
        return [values[start:stop] for start, stop in slices]

    def _move_layout(self, moves: Sequence[tuple[np.ndarray, np.ndarray]]) -> tuple:
        """values_at_moves' arrays for these moves (built once per set: SegmentCriterion._kept_for_moves):
        where each move's candidates start, the row each places, the segments each changes, and
        each move's (start, stop) among the candidates."""
        bounds = np.cumsum([0] + [len(points) for _, points in moves]).astype(np.int64)
        return (bounds, np.array([rows[0] for rows, _ in moves], dtype=np.int64),
                np.array([self._changing_mask(rows) for rows, _ in moves]), list(itertools.pairwise(bounds.tolist())))

    def _placed_values(self, placed: list[tuple[np.ndarray, np.ndarray]], candidates: int,
                       moved: np.ndarray | None, known: list | None) -> np.ndarray:
        """h_axis of C candidates placed in every view (_project_candidates), shape (C,)."""
        changing, still = self._changing_segments(moved)
        values = np.zeros(candidates)
        counts = np.zeros(candidates)
        for index, (view, (pixels, visible)) in enumerate(zip(self._active_views, placed, strict=True)):
            fixed = np.empty(len(view.pixels))  # the squared distance to the segments every candidate shares
            if known is not None:
                nearest_of_rows(known[index][2], still, fixed)
            else:
                distances = np.empty((len(still), len(view.pixels)))
                segment_squared_distances(view.pixels, pixels[0, self._start_index[still]],
                                          pixels[0, self._end_index[still]], distances)
                nearest_of_rows(distances, np.arange(len(still)), fixed)
            view_values = np.empty(candidates)
            candidate_axis_values(view.pixels, pixels[:, self._start_index[changing]],
                                  pixels[:, self._end_index[changing]], fixed, view.robust_scale_px, view_values)
            values += np.where(visible, view_values, 0.0)
            counts += visible
        return values / np.maximum(counts, 1)

    def _changing_segments(self, moved: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The segments that a `moved` row ends and the others, as index arrays (kept per set of
        rows; without `moved`, every segment changes)."""
        key = None if moved is None else np.asarray(moved).tobytes()
        kept = self._changing.get(key)
        if kept is None:
            changing = np.ones(len(self.segments), dtype=bool)
            if moved is not None:
                # np.isin's sorting costs a hundred microseconds; the moved rows are one or two.
                changing = ((self._start_index[:, None] == moved) | (self._end_index[:, None] == moved)).any(axis=1)
            kept = self._changing[key] = (np.flatnonzero(changing), np.flatnonzero(~changing))
        return kept

    def _changing_mask(self, moved: np.ndarray) -> np.ndarray:
        """(S,) bool: the segments that a `moved` row ends (_changing_segments as a mask)."""
        mask = np.zeros(len(self.segments), dtype=bool)
        mask[self._changing_segments(moved)[0]] = True
        return mask

    def compute_value(self, configuration: Configuration) -> float:
        return self._evaluate(configuration)[0]

    def compute_gradient(self, configuration: Configuration) -> np.ndarray:
        return self._evaluate(configuration)[1]


def _project_candidates(project: Callable[[np.ndarray], list[tuple[np.ndarray, np.ndarray]]],
                        frame_positions: np.ndarray, moved: np.ndarray | None,
                        shared: list[tuple[np.ndarray, np.ndarray]] | None = None
                        ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per view (`project`: points -> each view's pixels and depth), pixels (C, K, 2) of (C, K, 3)
    placements and whether each candidate has every end in front of the camera (C,); the rows not
    `moved` are the same in every candidate, so projected once (or taken from `shared`: per view,
    pixels (K, 2) and in front (K,) of a pose with those rows)."""
    candidates, frames = frame_positions.shape[:2]
    if moved is None:
        return [(pixels.reshape(candidates, frames, 2), np.all(depth.reshape(candidates, frames) > MIN_DEPTH, axis=1))
                for pixels, depth in project(frame_positions.reshape(-1, 3))]
    if shared is None:
        shared = [(pixels, depth > MIN_DEPTH) for pixels, depth in project(frame_positions[0])]
    return _place_candidates(shared, project(frame_positions[:, moved].reshape(-1, 3)), candidates, moved)


def _place_candidates(shared: list[tuple[np.ndarray, np.ndarray]], moving: list[tuple[np.ndarray, np.ndarray]],
                      candidates: int, moved: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """_project_candidates from the pose's projection (`shared`) and that of the moved rows
    (`moving`: per view, pixels (C * r, 2) and depth (C * r,), candidate by candidate)."""
    placed = []
    for (shared_pixels, shared_in_front), (moving_pixels, moving_depth) in zip(shared, moving, strict=True):
        pixels = np.repeat(shared_pixels[None], candidates, axis=0)
        pixels[:, moved] = moving_pixels.reshape(candidates, len(moved), 2)
        in_front = np.repeat(shared_in_front[None], candidates, axis=0)
        in_front[:, moved] = moving_depth.reshape(candidates, len(moved)) > MIN_DEPTH
        placed.append((pixels, np.all(in_front, axis=1)))
    return placed
