"""The image criterion h(q) of eq. (5)-(8): overlap of the projected skeleton with a support image.

Each segment between two keypoints is sampled at n points p = (1 - s) p_a + s p_b (s at the
centres of n equal parts), every sample is projected into every enabled view and read from that
view's support image with bilinear interpolation; h is the mean over views and samples (the 1/n
of eq. 5, averaged over views for eq. 6). Convention: h is an overlap, to be MAXIMISED.

Gradient by the chain rule (eq. 7-8):
    dh/dq = mean over views and samples of  grad I_c(p)^T . dpi_c/dX . ((1 - s) J_a + s J_b)
with J_a, J_b the world-aligned translation Jacobians of the segment ends (3 x nv), dpi_c/dX the
2 x 3 projection Jacobian (distortion included) and grad I_c the exact derivative of the bilinear
interpolant that reads I_c.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple, cast

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import EmptySilhouetteWarning, InputError
from ibik_pin.model import BodyModel
from ibik_pin.tasks.segments import SegmentCriterion, segment_ends
from ibik_pin.vision.camera import CameraLike
from ibik_pin.vision.candidate_kernels import moved_samples
from ibik_pin.vision.kernels import MIN_DEPTH, pinhole_overlap_at_segments, support_overlap_at_segments, support_values
from ibik_pin.vision.support import SupportImageLike
from ibik_pin.vision.support_window import read_box


@dataclass
class View:
    """One calibrated camera and the support image the criterion reads in it.

    Attributes:
        camera: the camera (vision.camera.CameraLike: a pinhole or orthographic camera).
        support: its support image, of the camera's size (vision.support.SupportImageLike); one
            that is not `enabled` (an empty silhouette) is skipped.

    Raises:
        InputError: the camera or the support image is not one (a bare mask array as the support),
            or the support image's size is not the camera's.
    """

    camera: CameraLike
    support: SupportImageLike

    def __post_init__(self) -> None:
        for what, value, needed, hint in (
                ("camera", self.camera, ("name", "size", "project"), "a camera of ibik_pin.vision (PinholeCamera)"),
                ("support", self.support, ("size", "enabled", "sample"),
                 "a support image: vision.support.support_from_mask(mask) for a silhouette")):
            missing = [name for name in needed if not hasattr(value, name)]
            if missing:
                raise InputError(f"View.{what}: expected {hint}, found {type(value).__name__} (it has no "
                                 f"{missing[0]!r})")
        support_size = tuple(self.support.size)
        camera_size = tuple(self.camera.size)
        if support_size != camera_size:
            raise InputError(
                f"camera {self.camera.name!r}: the support image (mask) is "
                f"{support_size[0]} x {support_size[1]} px but the camera's image is "
                f"{camera_size[0]} x {camera_size[1]} px (width x height)"
            )


class _MoveLayout(NamedTuple):
    """ImageTask.values_at_moves' arrays for one set of moves (rows and candidate counts)."""

    candidates: np.ndarray  # (moves,) candidates of each move
    bounds: np.ndarray  # (moves + 1,) where each move's candidates start
    changing: np.ndarray  # (moves, M) bool, the samples each move changes
    unchanged: np.ndarray  # its negation
    placed_rows: np.ndarray  # (moves,) the end each move places
    point_count: int  # changing samples over every candidate
    starts: np.ndarray  # where each candidate with changing samples starts among the points
    filled: np.ndarray  # (P,) bool, the candidates with changing samples
    slices: list  # each move's (start, stop) among the candidates


class ImageTask(SegmentCriterion):
    """Maximise the overlap h(q) of the projected skeleton segments with the views' supports.

    Attributes:
        body: the body model (keypoints and segments).
        views: the views; replace with `set_views` per frame.
        samples_per_segment: n of eq. (5).
        segment_weights: relative weight of each segment's samples, shape (S,).
    """

    def __init__(
        self,
        body: BodyModel,
        views: Sequence[View] = (),
        samples_per_segment: int = 8,
        segments: Sequence[tuple[str, str]] | None = None,
        max_step_size: float = 0.05,
        min_step_size: float = 1e-4,
    ) -> None:
        super().__init__(max_step_size, min_step_size)
        if int(samples_per_segment) < 1:
            raise InputError(f"samples_per_segment must be >= 1, got {samples_per_segment}")
        self.body = body
        self.samples_per_segment = int(samples_per_segment)
        # Unique end frames, so each Jacobian is fetched once even when segments share a joint.
        segments, self._frame_ids, starts, ends = segment_ends(body, segments, "the image task")
        n = self.samples_per_segment
        s = (np.arange(n) + 0.5) / n
        # Sample m = segment * n + i is interpolation_weights[m] @ positions of the unique frames.
        weights = np.zeros((len(segments) * n, len(self._frame_ids)))
        rows = np.arange(len(segments) * n)
        np.add.at(weights, (rows, np.repeat(starts, n)), np.tile(1.0 - s, len(segments)))
        np.add.at(weights, (rows, np.repeat(ends, n)), np.tile(s, len(segments)))
        self._interpolation = weights
        # The same, per sample: its segment's two end rows and its s.
        self._sample_start, self._sample_end = np.repeat(starts, n), np.repeat(ends, n)
        self._sample_fraction = np.tile(s, len(segments))
        self._changing: dict[bytes, np.ndarray] = {}  # values_at's changing samples per moved rows
        self._gradient_frames = np.zeros((len(self._frame_ids), 3))  # _evaluate's, kept between steps
        self.segments = segments
        self.views: list[View] = []
        self.set_views(views)
        self._cache_version = -1
        self._cache: tuple[float, np.ndarray] | None = None

    def set_views(self, views: Sequence[View]) -> None:
        """Replace the views (e.g. the next frame's supports); empty silhouettes are skipped."""
        self.views = list(views)
        for view in self.views:
            if not view.support.enabled:
                warnings.warn(
                    f"camera {view.camera.name!r}: the silhouette is empty, "
                    "the image term is disabled for this view",
                    EmptySilhouetteWarning,
                    stacklevel=2,
                )
        self._active_views = [v for v in self.views if v.support.enabled]
        # What each view's support holds (its window until a sample falls outside), and its size,
        # read once; the samples a value averages over.
        self._held = [view.support.held_values() for view in self._active_views]
        self._sizes = [tuple(view.support.size) for view in self._active_views]
        self._count = max(len(self._active_views), 1) * len(self._sample_start)
        # Pinhole cameras are projected inside the overlap kernel; any other camera projects itself.
        self._pinholes, project, self._pixels = self._projections([view.camera for view in self._active_views])
        self._project = project if self._pinholes is None else None
        self.enabled = bool(self._active_views)
        self._cache_version = -1

    def sample_points(self, configuration: Configuration) -> np.ndarray:
        """World positions [m] of every segment sample, shape (S * n, 3)."""
        return self._interpolation @ configuration.frame_positions(self._frame_ids)

    def _evaluate(self, configuration: Configuration) -> tuple[float, np.ndarray]:
        if self._cache_version == configuration.version and self._cache is not None:
            return self._cache
        positions, _ = configuration.frame_arrays(self._frame_ids)
        value = 0.0
        gradient_frames = self._gradient_frames  # dh/dX of each end frame, (K, 3), summed into
        gradient_frames.fill(0.0)
        # Pinhole cameras place, project and read the samples in one compiled call per view; any
        # other camera projects them itself first.
        pinholes = self._pinholes
        projections = ([] if self._project is None else
                       self._project(self.sample_points(configuration)))
        for index, (view, (width, height)) in enumerate(zip(self._active_views, self._sizes, strict=True)):
            for attempt in range(3):  # the window around the body; one wider, or the whole frame
                values, row, column = self._held[index]
                if pinholes is not None:
                    total, complete = pinhole_overlap_at_segments(
                        positions, self._frame_ids, self._sample_start, self._sample_end, self._sample_fraction,
                        pinholes[index], values, row, column, width, height, gradient_frames)
                else:
                    total, complete = support_overlap_at_segments(
                        *projections[index], values, row, column, width, height, self._sample_start,
                        self._sample_end, self._sample_fraction, gradient_frames)
                if complete:
                    break
                covering = (_covering(*self._pixels(self.sample_points(configuration))[index], width, height)
                            if attempt == 0 else None)
                self._held[index] = view.support.held_values(whole_frame=covering is None, covering=covering)
            value += total
        count = self._count
        self._cache = (value / count, configuration.velocity_gradient(self._frame_ids, gradient_frames, count))
        self._cache_version = configuration.version
        return self._cache

    def at_pose(self, frame_positions: np.ndarray) -> list[np.ndarray]:
        """Per view, the support at every sample of the segments placed at `frame_positions` (K, 3)
        (0 behind the camera), shape (1, M)."""
        return self._support_values(self._samples(self._interpolation, frame_positions[None]))

    def values_at(self, frame_positions: np.ndarray, moved: np.ndarray | None = None,
                  pose: object | None = None) -> np.ndarray:
        """h for (C, K, 3) placements of the segment ends, shape (C,) (see SegmentCriterion.values_at).

        The samples of the segments that no `moved` row ends are read once, not per candidate
        (read in `pose` when given).
        """
        samples = self._interpolation.shape[0]
        if moved is None:
            values = sum(view_values.sum(axis=1) for view_values in
                         self._support_values(self._samples(self._interpolation, frame_positions)))
            return values / (samples * max(len(self._active_views), 1))
        known = cast(list | None, pose)
        changing = self._changing_samples(moved)
        values = np.zeros(frame_positions.shape[0])
        moving = self._support_values(self._samples(self._interpolation[changing], frame_positions))
        still = ([at_pose[:, ~changing] for at_pose in known] if known is not None else
                 self._support_values(self._samples(self._interpolation[~changing], frame_positions[:1])))
        for moving_values, still_values in zip(moving, still, strict=True):
            values += moving_values.sum(axis=1) + still_values.sum()
        return values / (samples * max(len(self._active_views), 1))

    def values_at_moves(self, positions: np.ndarray, pose: object | None,
                        moves: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[np.ndarray]:
        """values_at for each move (SegmentCriterion.values_at_moves): every move's changing samples
        placed in one compiled call (each moves with the placed end, from the pose's samples) and
        read in one pass per view; values_at's within rounding (tested to 1e-13)."""
        if pose is None or not moves:
            return super().values_at_moves(positions, pose, moves)
        known = cast(list, pose)
        samples = self._interpolation.shape[0]
        placed = np.concatenate([np.asarray(points, dtype=float).reshape(-1, 3) for _, points in moves])
        layout = self._kept_for_moves(moves, self._move_layout)
        points = np.empty((layout.point_count, 3))
        positions = np.ascontiguousarray(positions, dtype=float)
        moved_samples(self._interpolation @ positions, self._interpolation, layout.changing, layout.placed_rows,
                      layout.bounds, placed, positions, points)
        totals = np.zeros(len(placed))
        for view, at_pose, projected in zip(self._active_views, known, self._pixels(points), strict=True):
            totals += np.repeat(layout.unchanged @ at_pose[0], layout.candidates)  # each move's unchanged samples
            if points.size:
                totals[layout.filled] += np.add.reduceat(support_at(view, points, projected=projected), layout.starts)
        totals /= samples * max(len(self._active_views), 1)
        return [totals[start:stop] for start, stop in layout.slices]

    def _move_layout(self, moves: Sequence[tuple[np.ndarray, np.ndarray]]) -> _MoveLayout:
        """values_at_moves' arrays for these moves (built once per set: SegmentCriterion._kept_for_moves)."""
        candidates = np.array([len(points) for _, points in moves])
        bounds = np.concatenate([[0], np.cumsum(candidates)]).astype(np.int64)
        changing = np.array([self._changing_samples(rows) for rows, _ in moves])  # (moves, M)
        per_candidate = changing.sum(axis=1)  # changing samples of each move's candidates
        # Each candidate's changing samples are consecutive: summed by one reduceat per view.
        starts = np.repeat(np.concatenate([[0], np.cumsum(candidates * per_candidate)[:-1]]), candidates) \
            + np.concatenate([np.arange(count) * size for count, size in zip(candidates, per_candidate, strict=True)])
        filled = np.repeat(per_candidate, candidates) > 0  # (reduceat reads an empty group as one value)
        return _MoveLayout(candidates, bounds, changing, ~changing,
                           np.array([rows[0] for rows, _ in moves], dtype=np.int64), int(candidates @ per_candidate),
                           starts[filled], filled, list(itertools.pairwise(bounds.tolist())))

    def _changing_samples(self, moved: np.ndarray) -> np.ndarray:
        """(M,) bool: the samples on a segment that a `moved` row ends (kept per set of rows)."""
        key = np.asarray(moved).tobytes()
        changing = self._changing.get(key)
        if changing is None:
            changing = self._changing[key] = np.any(self._interpolation[:, moved] != 0.0, axis=1)
        return changing

    @staticmethod
    def _samples(interpolation: np.ndarray, frame_positions: np.ndarray) -> np.ndarray:
        """The samples (C, M, 3) [m] of (C, K, 3) placements of the ends: one product for all
        placements (numpy's stacked matmul costs several times it)."""
        candidates, frames = frame_positions.shape[:2]
        flat = interpolation @ frame_positions.transpose(1, 0, 2).reshape(frames, 3 * candidates)
        return flat.reshape(-1, candidates, 3).transpose(1, 0, 2)

    def _support_values(self, points: np.ndarray) -> list[np.ndarray]:
        """Per view, the support at (C, M, 3) points [m] (0 behind the camera), shape (C, M)."""
        return [values.reshape(points.shape[:2]) for values in self.supports_at(points.reshape(-1, 3))]

    def supports_at(self, points: np.ndarray) -> list[np.ndarray]:
        """Per enabled view, the support at world points (N, 3) [m] (0 behind the camera), shape
        (N,): every view's projection in one call."""
        flat = np.ascontiguousarray(points, dtype=float)
        return [support_at(view, flat, projected=projected)
                for view, projected in zip(self._active_views, self._pixels(flat), strict=True)]

    def inside_silhouettes(self, points: np.ndarray, tolerance_px: float = 2.0) -> np.ndarray:
        """(N,) bool: each world point (N, 3) [m] projects inside the silhouette, or within
        `tolerance_px` of it, in every enabled view (the support is a signed distance, positive
        inside: the silhouette's border is 0; a point behind a camera is outside)."""
        inside = np.ones(len(points), dtype=bool)
        for view, projected in zip(self._active_views, self._pixels(points), strict=True):
            inside &= support_at(view, points, behind=-np.inf, projected=projected) > -float(tolerance_px)
        return inside

    def compute_value(self, configuration: Configuration) -> float:
        return self._evaluate(configuration)[0]

    def compute_gradient(self, configuration: Configuration) -> np.ndarray:
        return self._evaluate(configuration)[1]


def support_at(view: View, points: np.ndarray, behind: float = 0.0,
               projected: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """A view's support at the projections of world points (N, 3) [m], `behind` for the points
    behind the camera, shape (N,); `projected`: the points' pixels and depth in the view, if known."""
    if projected is None:
        projection = view.camera.project_with_jacobian(np.asarray(points, dtype=float))
        projected = projection.pixels, projection.depth
    pixels, depth = projected
    width, height = view.support.size
    read = np.empty(len(depth))
    held = view.support.held_values()
    for attempt in range(3):  # the window around the body; one wider, or the whole frame
        if support_values(pixels, depth, *held, width, height, float(behind), read):
            break
        covering = _covering(pixels, depth, width, height) if attempt == 0 else None
        held = view.support.held_values(whole_frame=covering is None, covering=covering)
    return read


def _covering(pixels: np.ndarray, depth: np.ndarray, width: int, height: int) -> tuple[slice, slice] | None:
    """What reading a support at these projections (N, 2), (N,) touches (read_box) of the points
    in front of the camera (NaN pixels read nothing)."""
    return read_box(pixels[(depth > MIN_DEPTH) & np.isfinite(pixels).all(axis=1)], width, height)
