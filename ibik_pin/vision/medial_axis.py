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

from ibik_pin.exceptions import InputError
from ibik_pin.vision.distance import box_around, distance_to_background

__all__ = ["medial_axis_pixels"]

# Neighbour offsets (row, column) of the four directions through a pixel.
_DIRECTIONS = ((0, 1), (1, 0), (1, 1), (1, -1))


def medial_axis_pixels(
    mask: np.ndarray, min_depth_px: float = 1.5, spacing_px: int = 3, max_points: int = 600
) -> np.ndarray:
    """Ridge pixels of a silhouette's distance transform, thinned to about one per ``spacing_px``.

    Args:
        mask: (H, W) silhouette, non-zero = person.
        min_depth_px: keep ridge pixels at least this far inside the silhouette [px].
        spacing_px: keep at most one ridge pixel per block of spacing_px x spacing_px pixels.
        max_points: at most this many pixels, taken evenly along the found ones.

    Returns:
        (N, 2) pixel coordinates (u, v) = (column, row) [px], N possibly 0.
    """
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise InputError(f"mask: expected a 2D (H, W) image, found shape {mask.shape}")
    if int(spacing_px) < 1 or int(max_points) < 1:
        raise InputError(f"spacing_px and max_points must be >= 1, got {spacing_px} and {max_points}")
    inside = (mask != 0).astype(np.uint8)
    if not inside.any():
        return np.zeros((0, 2))
    # Only the silhouette's bounding box: outside it the depth is 0 and no pixel is on the ridge.
    box_rows, box_columns = box_around(inside)
    depth = distance_to_background(np.pad(inside[box_rows, box_columns], 1))
    centre = depth[1:-1, 1:-1]
    ridge = np.zeros(centre.shape, dtype=bool)
    height, width = centre.shape
    for row_step, column_step in _DIRECTIONS:
        before = depth[1 - row_step:1 - row_step + height, 1 - column_step:1 - column_step + width]
        after = depth[1 + row_step:1 + row_step + height, 1 + column_step:1 + column_step + width]
        # >= on one side and > on the other: a ridge two pixels wide keeps one of them.
        ridge |= (centre >= before) & (centre > after)
    ridge &= centre >= min_depth_px
    rows, columns = np.nonzero(ridge)
    if rows.size == 0:
        return np.zeros((0, 2))
    depths = centre[rows, columns]
    rows, columns = rows + box_rows.start, columns + box_columns.start  # image coordinates
    spacing = int(spacing_px)
    # One pixel per block of the image's grid: the deepest, so the kept sample sits on the crest.
    blocks = (rows // spacing) * ((inside.shape[1] + spacing - 1) // spacing) + columns // spacing
    order = np.lexsort((-depths, blocks))
    first = np.ones(order.size, dtype=bool)
    first[1:] = blocks[order[1:]] != blocks[order[:-1]]
    kept = order[first]
    if kept.size > max_points:
        kept = kept[np.linspace(0, kept.size - 1, int(max_points)).round().astype(int)]
    return np.column_stack((columns[kept], rows[kept])).astype(np.float64)
