"""Criteria read along the skeleton's segments, and the unique end frames those segments share.

The image overlap (:mod:`ibik_pin.tasks.image`) and the silhouette-axis term
(:mod:`ibik_pin.tasks.silhouette_axis`) both lie on segments between two keypoints. They set up
the segments' end frames alike (each frame once, so that each position and Jacobian is computed
once per step even where segments share a joint), and the swivel search
(:mod:`ibik_pin.tracking.swivel`) evaluates both for many placements of those frames at once.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Callable, Sequence
from typing import NamedTuple, TypeVar

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.tasks.base import GradientTask
from ibik_pin.vision.camera import CameraLike, Projection
from ibik_pin.vision.pinhole import pixel_projector, projector, stacked_pinhole_parameters

__all__ = ["SegmentCriterion", "SegmentEnds", "segment_ends"]

Moves = Sequence[tuple[np.ndarray, np.ndarray]]  # per move: the rows it places, and their candidates (C, 3)
Layout = TypeVar("Layout")
_KEPT_MOVE_LAYOUTS = 64  # sets of moves kept at most (a caller whose moves keep changing starts afresh)


class SegmentEnds(NamedTuple):
    """The segments of a criterion and their unique end frames.

    Attributes:
        segments: the S keypoint pairs.
        frame_ids: (K,) the model frames of the segment ends, each once (sorted).
        start_index: (S,) row of `frame_ids` of each segment's first end.
        end_index: (S,) row of `frame_ids` of each segment's second end.
    """

    segments: list[tuple[str, str]]
    frame_ids: np.ndarray
    start_index: np.ndarray
    end_index: np.ndarray


def segment_ends(body: BodyModel, segments: Sequence[tuple[str, str]] | None, task_name: str) -> SegmentEnds:
    """The segments (the body's when None) and their unique end frames.

    Args:
        body: the body model whose keypoints name the segment ends.
        segments: keypoint pairs, or None for ``body.segments``.
        task_name: names the task in the error message, e.g. "the image task".

    Raises:
        InputError: there is no segment.
    """
    segments = list(body.segments if segments is None else segments)
    if not segments:
        raise InputError(f"{task_name} needs at least one segment")
    segment_frames = np.array([[body.frame_id(a), body.frame_id(b)] for a, b in segments], dtype=int)
    frame_ids, inverse = np.unique(segment_frames, return_inverse=True)
    inverse = inverse.reshape(-1, 2)
    return SegmentEnds(segments, frame_ids, inverse[:, 0], inverse[:, 1])


class SegmentCriterion(GradientTask):
    """A gradient task that depends on the configuration only through its segments' end frames.

    Subclasses set ``_frame_ids`` (see :func:`segment_ends`) and implement :meth:`values_at`.
    """

    _frame_ids: np.ndarray

    def __init__(self, max_step_size: float = 0.05, min_step_size: float = 1e-4) -> None:
        super().__init__(max_step_size, min_step_size)
        self._move_layouts: dict[tuple, object] = {}
        self._kept_projections: tuple | None = None

    def _projections(self, cameras: Sequence[CameraLike]) -> tuple[
            np.ndarray | None, Callable[[np.ndarray], list[Projection]],
            Callable[[np.ndarray], list[tuple[np.ndarray, np.ndarray]]]]:
        """The cameras' stacked pinhole parameters (None unless all are pinhole), projector and
        pixel_projector (vision.pinhole), kept while the same camera objects come: a tracker gives the
        same cameras' views every frame. Safe to keep: a PinholeCamera is frozen, and the projectors
        call any other camera's own projection each time."""
        kept = self._kept_projections
        if kept is None or len(kept[0]) != len(cameras) or any(
                a is not b for a, b in zip(kept[0], cameras, strict=True)):
            kept = self._kept_projections = (tuple(cameras), stacked_pinhole_parameters(list(cameras)),
                                             projector(cameras), pixel_projector(cameras))
        return kept[1], kept[2], kept[3]

    def _kept_for_moves(self, moves: Moves, build: Callable[[Moves], Layout]) -> Layout:
        """build(moves): what values_at_moves reads of the moves' rows and candidate counts alone,
        kept per such set (the swivel search asks the same limbs with as many candidates every frame)."""
        key = tuple((np.asarray(rows).tobytes(), len(points)) for rows, points in moves)
        layout = self._move_layouts.get(key)
        if layout is None:
            if len(self._move_layouts) >= _KEPT_MOVE_LAYOUTS:
                self._move_layouts.clear()
            layout = self._move_layouts[key] = build(moves)
        return layout  # type: ignore[return-value]

    @property
    def frame_ids(self) -> np.ndarray:
        """The model frames of the segment ends, in the order `values_at` takes them, shape (K,)."""
        return self._frame_ids

    def at_pose(self, frame_positions: np.ndarray) -> object | None:
        """What `values_at` may reuse for candidates that leave their unmoved rows at these positions
        (K, 3) (the swivel search tries every free limb of a frame about one pose); None: nothing."""
        return None

    def values_at_moves(self, positions: np.ndarray, pose: object | None,
                        moves: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[np.ndarray]:
        """The criterion for several sets of candidates about one pose: per move (rows (r,), placed
        (C, 3)), the values (C,) with row rows[0] of `positions` (K, 3) at each placed point and the
        rest kept (values_at's `moved` is `rows`); `pose`: at_pose(positions). The same values as
        values_at per move; a subclass answers all the moves at once (the swivel search's limbs)."""
        values = []
        for rows, placed in moves:
            candidates = np.repeat(positions[None], len(placed), axis=0)
            candidates[:, rows[0]] = placed
            values.append(self.values_at(candidates, moved=rows, pose=pose))
        return values

    @abstractmethod
    def values_at(self, frame_positions: np.ndarray, moved: np.ndarray | None = None,
                  pose: object | None = None) -> np.ndarray:
        """The criterion for several placements of the segment ends at once (no configuration needed).

        Args:
            frame_positions: (C, K, 3) world positions [m] of the frames `frame_ids`, per candidate.
            moved: rows of `frame_ids` whose positions differ between candidates (None: any may);
                what depends only on the other rows is then computed once, not per candidate.
            pose: `at_pose` of positions equal to every candidate's outside the `moved` rows (with
                `moved` only): what depends on those rows alone is read there.

        Returns:
            (C,) the criterion of each candidate.
        """
