"""The medial axis of a silhouette: the centre lines of its limbs and trunk, as pixel samples.

A limb's silhouette is a band around the projection of its bone; the band's centre line (the ridge of
the distance to the background) is where the projected bone should lie whatever the limb's width.
That makes the medial axis the part of a silhouette a skeleton can be asked to explain without
knowing the subject's body widths (see :mod:`ibik_pin.tasks.silhouette_axis`).

A pixel is on the ridge when its distance to the background is a local maximum across at least one of
the four directions through it (horizontal, vertical, both diagonals). Pixels closer to the border
than ``min_depth_px`` are left out: there the ridge is made of the spurs a noisy outline grows.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ibik_pin.exceptions import InputError
from ibik_pin.vision.distance import InsideDistance, box_around, distance_to_background, grown

__all__ = ["axis_distance_image", "medial_axis_pixels"]


def medial_axis_pixels(
    mask: np.ndarray, min_depth_px: float = 1.5, spacing_px: int = 3, max_points: int = 600,
    inside: InsideDistance | None = None,
) -> np.ndarray:
    """Ridge pixels of a silhouette's distance transform, thinned to about one per ``spacing_px``.

    Args:
        mask: (H, W) silhouette, non-zero = person.
        min_depth_px: keep ridge pixels at least this far inside the silhouette [px].
        spacing_px: keep at most one ridge pixel per block of spacing_px x spacing_px pixels.
        max_points: at most this many pixels, taken evenly along the found ones.
        inside: the mask's vision.distance.inside_distance if known (the support image's): used
            when its box is not cut by the frame's edge, where the medial axis takes the frame's
            edge for a border and the support does not, and its values are exact at every depth
            (no `limit`).

    Returns:
        (N, 2) pixel coordinates (u, v) = (column, row) [px], N possibly 0.
    """
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise InputError(f"mask: expected a 2D (H, W) image, found shape {mask.shape}")
    if int(spacing_px) < 1 or int(max_points) < 1:
        raise InputError(f"spacing_px and max_points must be >= 1, got {spacing_px} and {max_points}")
    # Only the silhouette's bounding box: outside it the depth is 0 and no pixel is on the ridge.
    if inside is not None and inside.limit is None and inside.box == _padded(inside.silhouette_box):
        box_rows, box_columns = inside.silhouette_box  # the same pixels: the box and its ring of background
        depth = inside.values
    else:
        person = (mask != 0).view(np.uint8)
        if not person.any():
            return np.zeros((0, 2))
        box_rows, box_columns = box_around(person)
        depth = distance_to_background(np.pad(person[box_rows, box_columns], 1))
    spacing = int(spacing_px)
    columns, rows = _thinned_ridge(depth, float(min_depth_px), spacing, box_rows.start, box_columns.start)
    if columns.size > max_points:
        kept = np.linspace(0, columns.size - 1, int(max_points)).round().astype(np.int64)
        columns, rows = columns[kept], rows[kept]
    return np.column_stack((columns, rows)).astype(np.float64)


def _padded(box: tuple[slice, slice]) -> tuple[slice, slice]:
    """The box grown by one pixel on every side, not clipped to the frame."""
    return slice(box[0].start - 1, box[0].stop + 1), slice(box[1].start - 1, box[1].stop + 1)


@njit(cache=True, nogil=True)
def _thinned_ridge(depth, min_depth, spacing, row0, column0):
    """The ridge pixels of `depth` (the box's distances padded by a zero ring) at least `min_depth`
    deep, one per spacing x spacing block of the image's grid: the deepest, the first in row-major
    order among equals. Returns their image columns and rows, in the order of the blocks' indices
    (row of blocks, then column)."""
    height, width = depth.shape[0] - 2, depth.shape[1] - 2
    first_block_row, first_block_column = row0 // spacing, column0 // spacing
    block_rows = (row0 + height - 1) // spacing - first_block_row + 1
    block_columns = (column0 + width - 1) // spacing - first_block_column + 1
    best = np.full((block_rows, block_columns), -1.0)
    where = np.zeros((block_rows, block_columns, 2), dtype=np.int64)
    for i in range(1, height + 1):
        for j in range(1, width + 1):
            centre = depth[i, j]
            if centre < min_depth:
                continue
            # >= on one side and > on the other: a ridge two pixels wide keeps one of them.
            if not ((centre >= depth[i, j - 1] and centre > depth[i, j + 1])
                    or (centre >= depth[i - 1, j] and centre > depth[i + 1, j])
                    or (centre >= depth[i - 1, j - 1] and centre > depth[i + 1, j + 1])
                    or (centre >= depth[i - 1, j + 1] and centre > depth[i + 1, j - 1])):
                continue
            row, column = row0 + i - 1, column0 + j - 1
            block_row, block_column = row // spacing - first_block_row, column // spacing - first_block_column
            if centre > best[block_row, block_column]:
                best[block_row, block_column] = centre
                where[block_row, block_column, 0] = column
                where[block_row, block_column, 1] = row
    count = 0
    for block_row in range(block_rows):
        for block_column in range(block_columns):
            count += best[block_row, block_column] >= 0.0
    columns, rows = np.empty(count, dtype=np.int64), np.empty(count, dtype=np.int64)
    k = 0
    for block_row in range(block_rows):
        for block_column in range(block_columns):
            if best[block_row, block_column] >= 0.0:
                columns[k], rows[k] = where[block_row, block_column, 0], where[block_row, block_column, 1]
                k += 1
    return columns, rows


def axis_distance_image(mask: np.ndarray, min_depth_px: float = 2.0, ridge_slope: float = 0.7,
                        within_px: float = np.inf) -> np.ndarray:
    """(H, W) float32 distance [px] of every pixel to the silhouette's nearest centre-line pixel; +inf
    everywhere for a silhouette without one.

    A projected bone lies on its limb's centre line whatever the limb's width: this image scores a
    segment's samples by how far they lie from a centre line (the reverse of the silhouette-axis term,
    which asks each axis sample for its nearest segment). Here every centre-line pixel counts, so the
    ridge is the stricter one where the distance to the background stops growing (its slope, 1 across
    a band, under `ridge_slope`): :func:`medial_axis_pixels`' local maxima also mark the
    steps of an oblique outline, harmless once thinned and robustly weighed, not here.

    Args:
        mask: (H, W) silhouette, non-zero = person.
        min_depth_px: centre-line pixels at least this far inside [px] (spurs of the outline left out).
        ridge_slope: the distance's largest slope [px / px] on the ridge.
        within_px: the distances are computed only within this margin [px] around the
            silhouette's box, +inf beyond it (every pixel there is at least that far from the centre
            line; inside, the values are the whole image's: every centre-line pixel lies in the box).
            A reader whose cost is flat that far out loses nothing (a 1088 x 1920 frame with a
            person's 300 x 840 px box and 120 px around it: 40 -> 22 ms).
    """
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise InputError(f"mask: expected a 2D (H, W) image, found shape {mask.shape}")
    person = (mask != 0).view(np.uint8) if mask.dtype == bool else (mask != 0).astype(np.uint8)
    if not person.any():
        return np.full(mask.shape, np.inf, dtype=np.float32)
    rows, columns = box_around(person)
    depth = distance_to_background(np.pad(person[rows, columns], 1)).astype(np.float64)
    slope_rows, slope_columns = np.gradient(depth)
    depth, slope = depth[1:-1, 1:-1], np.hypot(slope_rows, slope_columns)[1:-1, 1:-1]
    ridge = (depth >= min_depth_px) & (slope < ridge_slope)
    window = grown((rows, columns), int(np.ceil(within_px)) if np.isfinite(within_px) else max(mask.shape),
                   mask.shape)
    off_axis = np.ones((window[0].stop - window[0].start, window[1].stop - window[1].start), dtype=np.uint8)
    off_axis[rows.start - window[0].start:rows.stop - window[0].start,
             columns.start - window[1].start:columns.stop - window[1].start][ridge] = 0
    distance = np.full(mask.shape, np.inf, dtype=np.float32)
    distance[window] = distance_to_background(off_axis)
    return distance
