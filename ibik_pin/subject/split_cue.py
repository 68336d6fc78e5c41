"""Where a limb bends, from the silhouettes' centre lines: a cue for the split of its length.

The overlap criterion (tasks.image) rewards samples inside the silhouette, so a thick thigh draws
the knee toward it; the silhouette-axis term (tasks.silhouette_axis) asks every axis sample for its
nearest segment and was biased too (docs/sweep.md). This cue goes the other way round and reads no
width: each projected sample of the limb's two segments is scored by its distance to the nearest
centre-line pixel of the view (vision.medial_axis.axis_distance_image), robustly,

    value = - mean over views and samples of  1 - exp(-(d_i / c)^2)

with c [px] a robust scale (a sample where the legs' silhouettes merge, or off every centre line,
weighs at most 1). Only the segments' middle parts are read: near the root the pelvis merges the
thigh's band with the trunk's, near the middle joint the two bands' axes bend into each other, and
near the end the foot starts. And in each view only the samples that no other segment of the pose
passes near (closer than a clearance, about two limbs' radii, in that view): where two bands
overlap (the other leg beside this one in a side view, a hand on the thigh) the centre line runs
between them. A bent limb's two centre lines meet at its middle joint; a wrong split puts one
segment off its line whatever the swivel.

It answers as refine_from_images' criteria do (frame_ids, at_pose, values_at_moves), for the
middle joints of the limbs it was built for; :func:`refine_split` chooses the split with it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.readahead.view_workers import built_ahead, map_views
from ibik_pin.subject.trial_lengths import LIMBS, TrialLengths, refine_from_images
from ibik_pin.vision.camera import CameraLike
from ibik_pin.vision.medial_axis import axis_distance_image

__all__ = ["CLEARANCE_M", "FLAT_BEYOND", "LOWER_SPAN", "MIN_RADIUS", "ROBUST_SCALE_M", "SPLIT_FACTORS", "UPPER_SPAN",
           "AxisDistanceCue", "refine_split"]

#: Fractions of each segment read, from its root end: the thigh's upper part merges with the pelvis
#: and the other thigh, the shank's lower end with the foot (chosen on the sweep, docs/sweep.md).
UPPER_SPAN = (0.6, 0.9)
LOWER_SPAN = (0.1, 0.8)


class AxisDistanceCue:
    """The limbs' segments scored by their samples' distance to the views' medial axes.

    Attributes:
        frame_ids: (K,) the model frames of the body's segment ends and the limbs' keypoints, each once.
        enabled: False until views with an axis are set.
    """

    def __init__(self, body: BodyModel, limbs: Sequence[str], samples_per_segment: int = 8,
                 upper_span: tuple[float, float] = UPPER_SPAN,
                 lower_span: tuple[float, float] = LOWER_SPAN) -> None:
        unknown = [name for name in limbs if name not in LIMBS]
        if unknown:
            raise InputError(f"limbs: unknown {unknown}; known: {', '.join(LIMBS)}")
        if int(samples_per_segment) < 1:
            raise InputError(f"samples_per_segment: expected at least 1, got {samples_per_segment}")
        for name, (start, stop) in (("upper_span", upper_span), ("lower_span", lower_span)):
            if not 0.0 <= start <= stop <= 1.0:
                raise InputError(f"{name}: expected fractions 0 <= start <= stop <= 1, got {(start, stop)}")
        keypoints = [(LIMBS[name].root, LIMBS[name].middle, LIMBS[name].end) for name in limbs]
        ends = np.array([body.frame_ids(list(names)) for names in keypoints], dtype=int).reshape(-1, 3)
        segments = np.array(body.segment_frame_ids, dtype=int).reshape(-1, 2)
        self.frame_ids = np.unique(np.concatenate((ends.reshape(-1), segments.reshape(-1))))
        rows = np.searchsorted(self.frame_ids, ends)
        segment_rows = np.searchsorted(self.frame_ids, segments)
        # middle row -> (root row, end row, the other segments' end rows (S, 2): those not touching the limb)
        self._limb_of_middle = {
            int(middle): (int(root), int(end), segment_rows[~np.isin(segment_rows, (root, middle, end)).any(axis=1)])
            for root, middle, end in rows}
        count = int(samples_per_segment)
        self._upper = np.linspace(*upper_span, count)
        self._lower = np.linspace(*lower_span, count)
        self._views: list[tuple[CameraLike, np.ndarray, float, float]] = []
        self.enabled = False

    def set_views(self, cameras: Sequence[CameraLike], distances: Sequence[np.ndarray | None],
                  robust_scales_px: Sequence[float], clearances_px: Sequence[float]) -> None:
        """One frame's views: per camera its axis_distance_image [px], or None for a view without
        any centre-line pixel (an empty silhouette: left out), its robust scale c [px] and the
        clearance [px] another segment keeps from a sample read."""
        if not len(cameras) == len(distances) == len(robust_scales_px) == len(clearances_px):
            raise InputError(f"expected one distance image, scale and clearance per camera ({len(cameras)}), got "
                             f"{len(distances)}, {len(robust_scales_px)} and {len(clearances_px)}")
        self._views = [(camera, np.asarray(distance), float(scale), float(clearance))
                       for camera, distance, scale, clearance in zip(cameras, distances, robust_scales_px,
                                                                     clearances_px, strict=True)
                       if distance is not None]
        self.enabled = bool(self._views)

    def at_pose(self, positions: np.ndarray) -> None:
        return None

    def values_at_moves(self, positions: np.ndarray, pose: object | None,
                        moves: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[np.ndarray]:
        """Per move (rows whose first is a limb's middle joint, placed (C, 3) [m]), the cue (C,) with
        that joint at each placed point and the limb's root and end where `positions` (K, 3) has them."""
        values = []
        for rows, placed in moves:
            middle = int(rows[0])
            if middle not in self._limb_of_middle:
                raise InputError(f"moves: row {middle} is no limb's middle joint of this cue")
            root_row, end_row, others = self._limb_of_middle[middle]
            root, end = positions[root_row], positions[end_row]
            placed = np.asarray(placed, dtype=float).reshape(-1, 3)
            samples = self._samples(root, np.vstack((positions[middle], placed)), end)  # (1 + C, 2n, 3)
            values.append(-self._mean_cost(samples[1:], samples[0], positions[others]))
        return values

    def _samples(self, root: np.ndarray, middles: np.ndarray, end: np.ndarray) -> np.ndarray:
        upper = root + self._upper[None, :, None] * (middles[:, None] - root)
        lower = middles[:, None] + self._lower[None, :, None] * (end - middles[:, None])
        return np.concatenate((upper, lower), axis=1)

    def _mean_cost(self, samples: np.ndarray, at_pose: np.ndarray, others: np.ndarray) -> np.ndarray:
        """Per candidate, the mean robust cost of its samples (C, N, 3) over views and samples, a
        sample counting in a view where, at the pose's own placement (`at_pose` (N, 3)), no other
        segment (`others` (S, 2, 3)) passes within the clearance (the same samples for every
        candidate: they differ by the placement only)."""
        candidates, count = samples.shape[:2]
        total = np.zeros(candidates)
        for camera, distance, scale, clearance in self._views:
            clear = _clearance_px(camera.project(at_pose), camera.project(others.reshape(-1, 3)).reshape(-1, 2, 2))
            read = clear >= clearance
            if not read.any():
                continue
            pixels = camera.project(samples[:, read].reshape(-1, 3)).reshape(candidates, -1, 2)
            columns = np.round(pixels[..., 0])
            rows = np.round(pixels[..., 1])
            height, width = distance.shape
            inside = (np.isfinite(columns) & np.isfinite(rows) & (columns >= 0) & (columns < width)
                      & (rows >= 0) & (rows < height))
            found = np.full(pixels.shape[:2], np.inf)
            found[inside] = distance[rows[inside].astype(np.int64), columns[inside].astype(np.int64)]
            total += np.sum(1.0 - np.exp(-(found / scale) ** 2), axis=1)
        return total / max(len(self._views) * count, 1)


def _clearance_px(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Each pixel's (N, 2) distance [px] to the nearest of the segments (S, 2, 2) [px] (inf without
    any; a segment with an unseen end is none)."""
    segments = segments[np.isfinite(segments).all(axis=(1, 2))]
    if not len(segments) or not len(points):
        return np.full(len(points), np.inf)
    start, step = segments[:, 0], segments[:, 1] - segments[:, 0]  # (S, 2)
    offset = points[:, None] - start[None]  # (N, S, 2)
    along = np.clip(np.sum(offset * step, axis=2) / np.maximum(np.sum(step * step, axis=1), 1e-12), 0.0, 1.0)
    nearest = np.linalg.norm(offset - along[..., None] * step[None], axis=2)
    return np.where(np.isfinite(points).all(axis=1), nearest.min(axis=1), 0.0)



#: Factors tried on a thigh, its shank taking up the difference: +-3 % by 0.5 % (a static's split was
#: off by up to 8 %, but the cue's own errors reach 20-35 mm on a few legs and a wider grid let them
#: through: on the sweep's conditions 0-13, +-8 % made the legs' mean error 6.0 -> 7.1 mm, +-3 % 4.9;
#: steps of 0.5 % rather than 1 % with the leg's sum by 0.5 %: knees better on the sweep, docs/sweep.md).
SPLIT_FACTORS = np.linspace(0.97, 1.03, 13)
#: A frame scores a leg's split only if its knee's circle has this radius [m] (the swivel search's bound).
MIN_RADIUS = 0.08
#: The cue's robust scale and the clearance another segment keeps from a sample read [m], at the
#: subject's distance: about a limb's radius, and two.
ROBUST_SCALE_M = 0.05
CLEARANCE_M = 0.15
#: Robust scales beyond which a sample's cost 1 - exp(-(d / c)^2) is 1.0 in float64 (from 6.12 c on):
#: the views' centre-line distances are computed only that far around the silhouette (the same costs).
FLAT_BEYOND = 7.0


def _centre_line_image(view: tuple[np.ndarray, float]) -> np.ndarray | None:
    """A view's axis_distance_image from its silhouette and robust scale [px], as far out as the cue
    reads; None without any centre-line pixel (decided here, on the view's worker)."""
    mask, scale = view
    image = axis_distance_image(mask, within_px=FLAT_BEYOND * scale)
    return image if np.isfinite(image).any() else None


def refine_split(body: BodyModel, legs: TrialLengths, poses: Sequence[Mapping[str, np.ndarray]],
                 masks_of_pose: Callable[[int], Sequence[np.ndarray]], cameras: Sequence[CameraLike],
                 subject_position: np.ndarray, limbs: Sequence[str] = ("left_leg", "right_leg"),
                 workers: int = 1) -> TrialLengths:
    """Each limb's split between its segments chosen on the views' centre lines, its sum kept.

    Args:
        legs: the limbs' lengths refined on the silhouettes (refine_from_images, e.g. one factor per
            limb), with each frame's middle joint (`middles`): the cue reads only the samples clear
            of the pose's other segments, and a first pass without the image puts knees cm off
            (on the sweep the split then went 12-34 mm wrong).
        poses: per frame refine_from_images read, keypoint name -> position (3,) [m].
        masks_of_pose: index into `poses` -> one silhouette per camera.
        subject_position: (3,) [m] where the scales in pixels are taken.
        workers: threads building a frame's views' centre-line images side by side, the next
            frame's while this one is scored (readahead.view_workers: the same images).

    Returns:
        The lengths with the split chosen; per limb the evidence of `legs` with "split" added.
    """
    chosen = [name for name in limbs if name in legs.middles]
    cue = AxisDistanceCue(body, chosen)
    centre = np.asarray(subject_position, dtype=float)[None]
    robust = [float(max(camera.pixel_radius(centre, np.array([ROBUST_SCALE_M]))[0], 1.0)) for camera in cameras]
    clearance = [float(max(camera.pixel_radius(centre, np.array([CLEARANCE_M]))[0], 1.0)) for camera in cameras]

    def centre_lines(index: int) -> list[np.ndarray | None]:
        return map_views(_centre_line_image, list(zip(masks_of_pose(index), robust, strict=True)), workers)

    def frames() -> Iterator:
        built = built_ahead(centre_lines, range(len(poses))) if workers > 1 else map(centre_lines, range(len(poses)))
        for index, (pose, images) in enumerate(zip(poses, built, strict=True)):
            cue.set_views(cameras, images, robust, clearance)
            placed = dict(pose)
            placed.update({LIMBS[name].middle: legs.middles[name][index] for name in chosen})
            yield placed, [(cue, 1.0)]

    split = refine_from_images(body, legs.lengths, frames(), factors=SPLIT_FACTORS, limbs=chosen, keep_sum=True,
                               min_radius=MIN_RADIUS)
    evidence = {name: ({**entry, "split": {**split.evidence[name], "kind": "centre lines"}}
                       if name in split.evidence else entry) for name, entry in legs.evidence.items()}
    return TrialLengths(split.lengths, legs.before, evidence, legs.middles)
