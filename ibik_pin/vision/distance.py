"""Exact Euclidean distance transforms of silhouettes, on the part of the frame that needs them.

The support images (:mod:`ibik_pin.vision.support`) and the medial axis
(:mod:`ibik_pin.vision.medial_axis`) read distances to a silhouette's border; both compute them on
boxes around the silhouette, which give the whole frame's values there.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from ibik_pin.exceptions import InputError

__all__ = ["InsideDistance", "box_around", "distance_to_background", "grown", "inside_distance", "shifted",
           "signed_distance"]


class InsideDistance(NamedTuple):
    """A silhouette's distance to the background on its bounding box grown by one pixel.

    Attributes:
        values: (h, w) float32 distance [px] of each pixel of `box` to the nearest unset pixel.
        box: (rows, columns) the silhouette's bounding box grown by one pixel, clipped to the frame.
    """

    values: np.ndarray
    box: tuple[slice, slice]


def inside_distance(mask: np.ndarray, box: tuple[slice, slice] | None = None) -> InsideDistance:
    """The distance to the background of a non-empty (H, W) bool mask on its bounding box grown by
    one pixel (`box`: that bounding box if known, box_around(mask)); what both the support image
    and the medial axis read, computed once for them."""
    grown_box = grown(box_around(mask) if box is None else box, 1, mask.shape)
    return InsideDistance(distance_to_background(mask[grown_box].view(np.uint8)), grown_box)


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
    values = distance_to_background(1 - mask[region].view(np.uint8))
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
    """(H, W) float32 exact Euclidean distance [px] of every pixel to the nearest zero pixel.

    OpenCV's precise transform is exact up to its float arithmetic, whose last bits depend on the
    image's size; every squared distance between pixels is a whole number, so rounding it makes the
    result the same whatever part of an image is transformed, and ties (ridges) exact.
    """
    try:
        raw = cv2.distanceTransform(np.ascontiguousarray(image, dtype=np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    except cv2.error as error:  # pragma: no cover - OpenCV rejects only malformed input, checked above
        raise InputError(f"mask: OpenCV's distance transform failed: {error}") from None
    # In place in float32: a square below 2^20 (any 640 x 480 image) is within 0.2 of its whole
    # number in float32 as in float64, and a float32 square root is the float64 one rounded.
    np.square(raw, out=raw)
    np.rint(raw, out=raw)
    return np.sqrt(raw, out=raw)


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
