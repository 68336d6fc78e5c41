"""Exact Euclidean distance transforms of silhouettes, on the part of the frame that needs them.

The support images (:mod:`ibik_pin.vision.support`) and the medial axis
(:mod:`ibik_pin.vision.medial_axis`) read distances to a silhouette's border; both compute them on
boxes around the silhouette, which give the whole frame's values there.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ibik_pin.exceptions import InputError

__all__ = ["InsideDistance", "box_around", "distance_to_background", "grown", "inside_distance", "shifted",
           "signed_distance"]


class InsideDistance(NamedTuple):
    """A silhouette's distance to the background on its bounding box grown by one pixel.

    Attributes:
        values: (h, w) float32 distance [px] of each pixel of `box` to the nearest unset pixel.
        box: (rows, columns) the silhouette's bounding box grown by one pixel, clipped to the frame.
        silhouette_box: (rows, columns) the silhouette's bounding box (box_around(mask)).
    """

    values: np.ndarray
    box: tuple[slice, slice]
    silhouette_box: tuple[slice, slice]


def inside_distance(mask: np.ndarray, box: tuple[slice, slice] | None = None) -> InsideDistance:
    """The distance to the background of a non-empty (H, W) bool mask on its bounding box grown by
    one pixel (`box`: that bounding box if known, box_around(mask)); what both the support image
    and the medial axis read, computed once for them."""
    box = box_around(mask) if box is None else box
    grown_box = grown(box, 1, mask.shape)
    return InsideDistance(distance_to_background(mask[grown_box].view(np.uint8)), grown_box, box)


def signed_distance(mask: np.ndarray, region: tuple[slice, slice] | None = None,
                    box: tuple[slice, slice] | None = None, inside: InsideDistance | None = None) -> np.ndarray:
    """(h, w) float32 signed Euclidean distance [px] to the mask's border, positive inside, on
    `region` of the frame: a box that holds the silhouette's bounding box grown by one pixel (None:
    the whole frame). `box`: that bounding box if known (box_around(mask)); `inside`: the mask's
    inside_distance if known.

    The border is taken halfway between a set and an unset pixel, hence the 0.5 shifts: the
    distance then grows by 1 px per pixel across the border as well. The image edge is no
    border (a body cut by the frame continues outside it). Needs both set and unset pixels.
    """
    if region is None:
        region = (slice(0, mask.shape[0]), slice(0, mask.shape[1]))
    # The inside distance only within the silhouette's bounding box grown by one pixel (the same
    # values: every pixel of that ring is background, so no nearer border lies beyond it), which on
    # a person in a 640 x 480 frame is a tenth of the pixels. The outside distance on the region is
    # the whole frame's there too: every set pixel, so the nearest, lies within the region.
    if inside is None:
        inside = inside_distance(mask, box)
    box = inside.box
    values = _distances(_as_uint8(mask[region]), True)
    np.subtract(np.float32(0.5), values, out=values)  # outside: 0.5 - distance
    box_in_region = shifted(box, region)
    # copyto, not where: numpy's where on these strided views is ten times slower.
    np.copyto(values[box_in_region], inside.values - np.float32(0.5), where=mask[box])
    return values


def shifted(box: tuple[slice, slice], region: tuple[slice, slice]) -> tuple[slice, slice]:
    """The box's slices in the coordinates of a region that holds it."""
    return tuple(slice(inner.start - outer.start, inner.stop - outer.start)  # type: ignore[return-value]
                 for inner, outer in zip(box, region, strict=True))


def distance_to_background(image: np.ndarray) -> np.ndarray:
    """(H, W) float32 exact Euclidean distance [px] of every pixel to the nearest zero pixel (+inf
    in an image without any); the image's edge is no border.

    Each value is the float32 square root of a whole number of squared pixels, so a part of an
    image transformed on its own gives the whole image's values wherever its nearest zero pixel
    lies within the part, and ties (ridges) are exact.
    """
    image = _as_uint8(image)
    return _distances(image, False) if image.size else np.zeros(image.shape, np.float32)


def _as_uint8(image: np.ndarray) -> np.ndarray:
    """A C-contiguous uint8 image, non-zero where `image` (2D, any numbers) is: one compiled kernel."""
    image = np.ascontiguousarray(image)
    if image.ndim != 2:
        raise InputError(f"image: expected a 2D (H, W) array, found shape {image.shape}")
    if image.dtype == np.uint8:
        return image
    return (image if image.dtype == np.bool_ else image != 0).view(np.uint8)


@njit(cache=True, nogil=True)
def _distances(image, to_set):
    """Exact Euclidean distance of every pixel to the nearest source pixel: the set pixels with
    `to_set`, else the zero ones. Felzenszwalb and Huttenlocher's separable transform: each
    column's distance to its nearest source, then along each row the lower envelope of the
    parabolas (x - p)^2 + g_p^2, all in whole numbers of squared pixels.
    (OpenCV's precise transform gives the same values on two threads in 1.3-2.5 times the time:
    one computed here in one thread leaves the other core to the solver.)"""
    height, width = image.shape
    far = height + width  # beyond any distance within the image: no source in that column
    column = np.empty((height, width), np.int32)
    for j in range(width):
        column[0, j] = 0 if (image[0, j] != 0) == to_set else far
    for i in range(1, height):
        for j in range(width):
            column[i, j] = 0 if (image[i, j] != 0) == to_set else min(column[i - 1, j] + 1, far)
    for i in range(height - 2, -1, -1):
        for j in range(width):
            column[i, j] = min(column[i, j], column[i + 1, j] + 1)
    out = np.empty((height, width), np.float32)
    apexes = np.empty(width, np.int64)  # the envelope's parabolas: where each is lowest,
    offsets = np.empty(width, np.int64)  # g_p^2 + p^2 of each,
    starts = np.empty(width + 1, np.float64)  # and where each starts to be the lowest
    for i in range(height):
        count = 0
        for q in range(width):
            g = np.int64(column[i, q])
            if g >= far:
                continue
            offset = g * g + q * q
            start = -np.inf
            while count > 0:
                start = (offset - offsets[count - 1]) / (2.0 * (q - apexes[count - 1]))
                if start > starts[count - 1]:
                    break
                count -= 1
                start = -np.inf
            apexes[count], offsets[count], starts[count] = q, offset, start
            count += 1
        if count == 0:
            out[i, :] = np.inf
            continue
        starts[count] = np.inf
        k = 0
        for x in range(width):
            while starts[k + 1] < x:
                k += 1
            out[i, x] = np.sqrt(np.float32(offsets[k] - 2 * apexes[k] * x + x * x))
    return out


def box_around(mask: np.ndarray, margin_px: int = 0) -> tuple[slice, slice]:
    """(rows, columns) slices of the bounding box of a non-empty mask's set pixels, grown by
    `margin_px` on every side and clipped to the image."""
    rows = np.flatnonzero(mask.any(axis=1))
    columns = np.flatnonzero(mask.any(axis=0))
    return grown((slice(int(rows[0]), int(rows[-1]) + 1), slice(int(columns[0]), int(columns[-1]) + 1)),
                 margin_px, mask.shape)


def grown(box: tuple[slice, slice], margin_px: int, shape: tuple[int, ...]) -> tuple[slice, slice]:
    """The box grown by `margin_px` on every side, clipped to an image of `shape` (H, W)."""
    return (slice(max(box[0].start - margin_px, 0), min(box[0].stop + margin_px, shape[0])),
            slice(max(box[1].start - margin_px, 0), min(box[1].stop + margin_px, shape[1])))
