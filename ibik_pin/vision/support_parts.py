"""A windowed support image as plain arrays and numbers, to rebuild in another process.

readahead.image_process prepares each frame's supports in a child process and sends them through
shared memory: a support that support_from_mask holds on a window around the body travels as its
window's values, the silhouette bit-packed and its inside distance (support_from_mask's
vision.distance.InsideDistance), from which a read outside the window computes the same wider window
or whole frame in the parent as in the child, at the same cost.
"""

from __future__ import annotations

import functools
from typing import NamedTuple, cast

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.vision.distance import InsideDistance
from ibik_pin.vision.support import SupportImage
from ibik_pin.vision.support_window import Recipe, Window

__all__ = ["WindowedParts", "support_from_parts", "windowed_parts"]

Box = tuple[int, int, int, int]  # first row, row past the last, first column, column past the last


class WindowedParts(NamedTuple):
    """A windowed support of support_from_mask: its window's values (h, w) float32 from (row,
    column) of a frame of `size` (w, h); the silhouette as np.packbits of its (H, W) mask; its inside
    distance (h', w') float32 on `inside_box`, the silhouette's box and the inside distance's limit;
    support_from_mask's parameters."""

    values: np.ndarray
    row: int
    column: int
    size: tuple[int, int]
    mask_bits: np.ndarray
    inside_values: np.ndarray
    inside_box: Box
    silhouette_box: Box
    inside_limit: float | None
    inside_cap_px: float | None
    outside_cap_px: float | None
    smooth_sigma_px: float


def _box(box: tuple[slice, slice]) -> Box:
    return (int(box[0].start), int(box[0].stop), int(box[1].start), int(box[1].stop))


def _slices(box: Box) -> tuple[slice, slice]:
    return (slice(box[0], box[1]), slice(box[2], box[3]))


def windowed_parts(support: SupportImage) -> WindowedParts | None:
    """The parts of a support that support_from_mask holds on a window (None for any other)."""
    recipe = support._recipe
    if recipe is None or support._values is not None:
        return None
    window = cast(Window, support._window)
    return WindowedParts(window.values, window.row, window.column, support.size, np.packbits(recipe.mask),
                         recipe.inside.values, _box(recipe.inside.box), _box(recipe.inside.silhouette_box),
                         recipe.inside.limit, recipe.inside_cap_px, recipe.outside_cap_px, recipe.smooth_sigma_px)


def support_from_parts(parts: WindowedParts) -> SupportImage:
    """The support of windowed_parts again: the same window values, and the same whole frame. The
    support keeps parts.values (float32, C order; made read-only), not a copy."""
    values = parts.values
    if values.dtype != np.float32 or not values.flags.c_contiguous:
        raise InputError(f"values: expected a C-ordered float32 window, found {values.dtype}")
    values.setflags(write=False)
    return SupportImage._windowed(Window(values, parts.row, parts.column), parts.size,
                                  functools.partial(_whole_frame_of_parts, parts),
                                  functools.partial(_wider_of_parts, parts))


def _recipe_of_parts(parts: WindowedParts) -> Recipe:
    """What support_from_mask computed the support from, again."""
    width, height = parts.size
    mask = np.unpackbits(parts.mask_bits, count=width * height).reshape(height, width).view(bool)
    inside = InsideDistance(parts.inside_values, _slices(parts.inside_box), _slices(parts.silhouette_box),
                            parts.inside_limit)
    return Recipe(mask, inside, parts.inside_cap_px, parts.outside_cap_px, parts.smooth_sigma_px)


def _whole_frame_of_parts(parts: WindowedParts) -> np.ndarray:
    """The whole frame as support_from_mask's own windowed support computes it."""
    return _recipe_of_parts(parts).values(None)


def _wider_of_parts(parts: WindowedParts, window: Window, covering: tuple[slice, slice]) -> Window | None:
    """A wider window as support_from_mask's own windowed support computes it."""
    return _recipe_of_parts(parts).wider(window, covering)
