"""Where a support image holds its values: a window around the body, and what computes it.

A support (vision.support) built from a silhouette is computed on a window of the frame: the
silhouette's box and the box where the skeleton is expected, each grown by a margin. The Recipe
(what support_from_mask was given) computes the values on any region that holds the silhouette's
box, the whole frame's values there: the window, a wider one when a read falls outside it, or the
whole frame. vision.support_parts sends the recipe's parts to another process.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from ibik_pin.vision.distance import InsideDistance, shifted, signed_distance

__all__ = ["SILHOUETTE_MARGIN_PX", "TARGETS_MARGIN_PX", "Recipe", "Window", "holds", "read_box", "smooth",
           "window_around"]


def smooth(values: np.ndarray, sigma_px: float) -> np.ndarray:
    """The support's light Gaussian blur (sigma_px 0: none), the image's edge replicated."""
    if sigma_px == 0.0:
        return values
    return cv2.GaussianBlur(values, (0, 0), sigmaX=sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REPLICATE)


class Recipe(NamedTuple):
    """What support_from_mask was given: what computes a windowed support's whole frame, here or
    again in another process (vision.support_parts)."""

    mask: np.ndarray
    inside: InsideDistance
    inside_cap_px: float | None
    outside_cap_px: float | None
    smooth_sigma_px: float

    def values(self, region: tuple[slice, slice] | None) -> np.ndarray:
        """The support's values on a region holding the silhouette's box (None: the whole frame), (h, w)."""
        values = signed_distance(self.mask, region, inside=self.inside, inside_cap_px=self.inside_cap_px)
        if self.outside_cap_px is not None:
            np.maximum(values, -self.outside_cap_px, out=values)
        return smooth(values, self.smooth_sigma_px)

    def window(self, boxes: list[tuple[tuple[slice, slice], int]]) -> Window | None:
        """The whole frame's values on the silhouette's box and `boxes`, each grown by its margin
        ((box, margin [px]) pairs; see window_around); None when that is the whole frame."""
        window = window_around([(self.inside.silhouette_box, SILHOUETTE_MARGIN_PX), *boxes], self.mask.shape,
                               self.smooth_sigma_px)
        if window is None:
            return None
        region, valid = window
        values = np.ascontiguousarray(self.values(region)[shifted(valid, region)])  # read by flat indices
        values.setflags(write=False)
        return Window(values, valid[0].start, valid[1].start)

    def wider(self, window: Window, covering: tuple[slice, slice]) -> Window | None:
        """A window holding `window` and the pixels `covering`, these grown by TARGETS_MARGIN_PX
        (a read outside a window is a sample of a limb that strays; its neighbours come next)."""
        rows, columns = window.values.shape
        held = (slice(window.row, window.row + rows), slice(window.column, window.column + columns))
        return self.window([(held, 0), (covering, TARGETS_MARGIN_PX)])


# Where a support is computed: the silhouette's box grown by SILHOUETTE_MARGIN_PX, joined with the
# box where the skeleton is expected (also_around: the tracker's projected targets) grown by
# TARGETS_MARGIN_PX [px]. A sample beyond the window costs a wider window (Recipe.wider). The
# silhouette's margin stays wide for partial silhouettes: on the Pose2Sim video
# (experiments/pose2sim_video.py) 8 px instead of 32 took the whole frames then read from 278 to
# 1134 and its IBIK runs' solves from 80-145 to 26-66 frames/s, where on the real-mocap benchmark
# it saved a tenth of the windows' pixels.
SILHOUETTE_MARGIN_PX = 32
TARGETS_MARGIN_PX = 32
# OpenCV blurs float images by vectors of columns and the last few columns of a row one by one,
# which round differently; a window whose columns start on a multiple of this and that is a
# multiple of it wide (or ends at the frame's edge) is blurred column for column as the frame is.
_BLUR_COLUMN_ALIGNMENT = 32


@dataclass(frozen=True)
class Window:
    """A support's values (h, w) on the part of the frame from (row, column) on."""

    values: np.ndarray
    row: int
    column: int


def holds(window: Window, box: tuple[slice, slice]) -> bool:
    """Whether the window holds every pixel of the box ((rows, columns) of the frame)."""
    rows, columns = window.values.shape
    return (window.row <= box[0].start and box[0].stop <= window.row + rows
            and window.column <= box[1].start and box[1].stop <= window.column + columns)


def read_box(pixels: np.ndarray, width: int, height: int) -> tuple[slice, slice] | None:
    """The (rows, columns) of a frame (width, height) that bilinear reads at pixels (N, 2) [px]
    touch: each pixel clipped to the frame, and its cell's other corner (vision.kernels'
    _read_support); None for no pixel. What a support asked to cover a read outside its window
    must hold (SupportImage.held_values)."""
    if len(pixels) == 0:
        return None
    u = np.clip(pixels[:, 0], 0.0, width - 1.0)
    v = np.clip(pixels[:, 1], 0.0, height - 1.0)
    return (slice(min(int(v.min()), max(height - 2, 0)), min(int(v.max()) + 2, height)),
            slice(min(int(u.min()), max(width - 2, 0)), min(int(u.max()) + 2, width)))


def window_around(boxes: list[tuple[tuple[slice, slice], int]], shape: tuple[int, int],
                  smooth_sigma_px: float) -> tuple[tuple[slice, slice], tuple[slice, slice]] | None:
    """The region to compute a support on, around boxes each grown by its margin [px] ((box,
    margin) pairs), and the part of it that holds the whole frame's values (the blur near the
    region's inner edges differs), or None when the region is the whole frame."""
    height, width = shape
    # OpenCV's Gaussian kernel on float images reaches round(4 sigma) pixels; one more for safety.
    blur = int(np.ceil(4.0 * smooth_sigma_px)) + 1 if smooth_sigma_px > 0.0 else 0
    top = max(min(rows.start - margin for (rows, _), margin in boxes) - blur, 0)
    bottom = min(max(rows.stop + margin for (rows, _), margin in boxes) + blur, height)
    first = min(columns.start - margin for (_, columns), margin in boxes) - blur
    stop = max(columns.stop + margin for (_, columns), margin in boxes) + blur
    left = max(first, 0) // _BLUR_COLUMN_ALIGNMENT * _BLUR_COLUMN_ALIGNMENT
    right = min(left + -(-(stop - left) // _BLUR_COLUMN_ALIGNMENT) * _BLUR_COLUMN_ALIGNMENT, width)
    if (top, bottom, left, right) == (0, height, 0, width):
        return None
    valid = (slice(top + (blur if top > 0 else 0), bottom - (blur if bottom < height else 0)),
             slice(left + (blur if left > 0 else 0), right - (blur if right < width else 0)))
    return (slice(top, bottom), slice(left, right)), valid
