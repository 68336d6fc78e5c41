"""Exact Euclidean distance transforms of silhouettes, on the part of the frame that needs them.

The support images (:mod:`ibik_pin.vision.support`) and the medial axis
(:mod:`ibik_pin.vision.medial_axis`) read distances to a silhouette's border; both compute them on
boxes around the silhouette, which give the whole frame's values there.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ibik_pin.checks import as_mask
from ibik_pin.exceptions import InputError

__all__ = ["InsideDistance", "ScannedMask", "box_around", "distance_to_background", "grown", "inside_distance",
           "scan_mask", "shifted", "signed_distance"]


class InsideDistance(NamedTuple):
    """A silhouette's distance to the background on its bounding box grown by one pixel.

    Attributes:
        values: (h, w) float32 distance [px] of each pixel of `box` to the nearest unset pixel; with
            a `limit`, exact up to it, and above it (infinity included) where the distance is.
        box: (rows, columns) the silhouette's bounding box grown by one pixel, clipped to the frame.
        silhouette_box: (rows, columns) the silhouette's bounding box (box_around(mask)).
        limit: None, or the distance [px] up to which the values are exact.
    """

    values: np.ndarray
    box: tuple[slice, slice]
    silhouette_box: tuple[slice, slice]
    limit: float | None = None


class ScannedMask(NamedTuple):
    """A silhouette read once: what the support image and the medial axis ask of it first.

    Attributes:
        mask: (H, W) bool copy of the silhouette (non-zero = set).
        set_pixels: number of set pixels.
        box: (rows, columns) bounding box of the set pixels; None when there is none.
    """

    mask: np.ndarray
    set_pixels: int
    box: tuple[slice, slice] | None


def scan_mask(mask: np.ndarray) -> ScannedMask:
    """A 2D bool or uint8 mask's bool copy, its count of set pixels and their bounding box, in one
    compiled pass (as_mask's copy, any(), all() and box_around() each read the whole frame, and
    each numpy call is a point where a thread working beside the solver gives up and takes back
    the GIL: ibik_pin.readahead.frames_ahead).

    Raises:
        InputError: as checks.as_mask.
    """
    if (not isinstance(mask, np.ndarray) or mask.dtype not in (np.bool_, np.uint8) or mask.ndim != 2
            or 0 in mask.shape):
        as_mask(mask)  # raises its error
    copy, count, row_start, row_stop, column_start, column_stop = _scan(mask.view(np.uint8))
    box = (slice(row_start, row_stop), slice(column_start, column_stop)) if count else None
    return ScannedMask(copy, int(count), box)


@njit(cache=True, nogil=True)
def _scan(mask):
    """(bool copy, count of set pixels, first and past-last row and column of the set pixels)."""
    height, width = mask.shape
    copy = np.empty((height, width), np.bool_)
    columns = np.zeros(width, np.uint8)
    count, row_start, row_stop = 0, height, 0
    for i in range(height):
        in_row = 0
        for j in range(width):
            is_set = mask[i, j] != 0
            copy[i, j] = is_set
            columns[j] |= is_set
            in_row += is_set
        if in_row:
            count += in_row
            row_start = min(row_start, i)
            row_stop = i + 1
    column_start, column_stop = width, 0
    for j in range(width):
        if columns[j]:
            column_start = min(column_start, j)
            column_stop = j + 1
    if count == 0:
        return copy, 0, 0, 0, 0, 0
    return copy, count, row_start, row_stop, column_start, column_stop


def inside_distance(mask: np.ndarray, box: tuple[slice, slice] | None = None,
                    limit: float | None = None) -> InsideDistance:
    """The distance to the background of a non-empty (H, W) bool mask on its bounding box grown by
    one pixel (`box`: that bounding box if known, box_around(mask)); what both the support image
    and the medial axis read, computed once for them. `limit` [px]: the values need only be exact
    up to it (a capped support's, without a medial axis, which needs them all): the transform then
    looks no farther than it along rows and columns, half its time on silhouettes at a 7 px limit.

    Raises:
        InputError: `limit` is not a positive number of pixels.
    """
    box = box_around(mask) if box is None else box
    grown_box = grown(box, 1, mask.shape)
    pixels = mask[grown_box].view(np.uint8)  # the compiled transforms read the strided view: no copy first
    if limit is None:
        return InsideDistance(_distances(pixels, False, -1), grown_box, box)
    if not (np.isfinite(limit) and limit > 0.0):
        raise InputError(f"limit: expected a positive number of pixels or None, found {limit}")
    # A pixel within `limit` of its nearest source lies within `limit` of it along its row and its
    # column: the near transform, within a support's usual caps; beyond them, the separable one.
    reach = int(np.floor(limit))
    values = _near_distances(pixels, False, reach) if reach <= _NEAR_REACH else _distances(pixels, False, reach)
    return InsideDistance(values, grown_box, box, float(limit))


def signed_distance(mask: np.ndarray, region: tuple[slice, slice] | None = None,
                    box: tuple[slice, slice] | None = None, inside: InsideDistance | None = None,
                    inside_cap_px: float | None = None) -> np.ndarray:
    """(h, w) float32 signed Euclidean distance [px] to the mask's border, positive inside, on
    `region` of the frame: a box that holds the silhouette's bounding box grown by one pixel (None:
    the whole frame). `box`: that bounding box if known (box_around(mask)); `inside`: the mask's
    inside_distance if known; `inside_cap_px`: the inside distances capped there (a positive
    number of pixels; None: no cap).

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
    rows, columns = shifted(inside.box, region)
    pixels = mask.view(np.uint8) if mask.dtype == np.bool_ else _as_uint8(mask)
    # One compiled call for the outside transform, the inside values and the cap: a thread that
    # builds supports beside the solver then gives up the GIL once here, not at five numpy calls.
    return _signed(pixels[region], inside.values, rows.start, columns.start, pixels[inside.box],
                   np.nan if inside_cap_px is None else float(inside_cap_px))


@njit(cache=True, nogil=True)
def _signed(region, inside, row, column, inside_pixels, cap):
    """0.5 - the distance to the set pixels over `region` (h, w); on the set pixels of the box
    (`inside_pixels`, at (row, column) of the region), inside - 0.5, at most `cap` (NaN: no cap).
    The same float32 arithmetic as numpy's on the arrays."""
    half = np.float32(0.5)
    values = _transform(region, True, -1, half)
    capped = not np.isnan(cap)
    limit = np.float32(cap) if capped else np.float32(0.0)
    rows, columns = inside.shape
    for i in range(rows):
        for j in range(columns):
            if inside_pixels[i, j] != 0:
                value = inside[i, j] - half
                values[row + i, column + j] = min(value, limit) if capped else value
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
    return _distances(image, False, -1) if image.size else np.zeros(image.shape, np.float32)


def _as_uint8(image: np.ndarray) -> np.ndarray:
    """A C-contiguous uint8 image, non-zero where `image` (2D, any numbers) is: one compiled kernel."""
    image = np.ascontiguousarray(image)
    if image.ndim != 2:
        raise InputError(f"image: expected a 2D (H, W) array, found shape {image.shape}")
    if image.dtype == np.uint8:
        return image
    return (image if image.dtype == np.bool_ else image != 0).view(np.uint8)


@njit(cache=True, nogil=True, inline="always")
def _column_distances(image, to_set, far, column):
    """Each pixel's distance along its column to the nearest source pixel (the set pixels with
    `to_set`, else the zero ones), at most `far`, into `column` (H, W) of whole numbers. Inlined:
    called, it left the transforms that share it 20-60% slower."""
    height, width = image.shape
    for j in range(width):
        column[0, j] = 0 if (image[0, j] != 0) == to_set else far
    for i in range(1, height):
        for j in range(width):
            column[i, j] = 0 if (image[i, j] != 0) == to_set else min(column[i - 1, j] + 1, far)
    for i in range(height - 2, -1, -1):
        for j in range(width):
            column[i, j] = min(column[i, j], column[i + 1, j] + 1)


@njit(cache=True, nogil=True)
def _distances(image, to_set, column_limit):
    """Exact Euclidean distance of every pixel to the nearest source pixel: the set pixels with
    `to_set`, else the zero ones. Felzenszwalb and Huttenlocher's separable transform: each
    column's distance to its nearest source, then along each row the lower envelope of the
    parabolas (x - p)^2 + g_p^2, all in whole numbers of squared pixels. With `column_limit` >= 0,
    only the parabolas of g_p <= column_limit: exact up to column_limit, above it beyond.
    (OpenCV's precise transform gives the same values on two threads in 1.3-2.5 times the time:
    one computed here in one thread leaves the other core to the solver.)"""
    return _transform(image, to_set, column_limit, np.float32(np.nan))


@njit(cache=True, nogil=True, inline="always")
def _transform(image, to_set, column_limit, half):
    """_distances; with `half` a number, half - the distance instead, and the source pixels left
    with any value (the signed distance writes the inside over them)."""
    height, width = image.shape
    far = height + width  # beyond any distance within the image: no source in that column
    skipped = far if column_limit < 0 else min(column_limit + 1, far)  # a column distance left out
    column = np.empty((height, width), np.int32)
    _column_distances(image, to_set, far, column)
    out = np.empty((height, width), np.float32)
    signed = not np.isnan(half)
    # The envelope's parabolas: where each is lowest, g_p^2 + p^2 of each, and where each starts
    # to be the lowest, as the fraction numerators / denominators (denominator 0: from the left end).
    apexes = np.empty(width, np.int64)
    offsets = np.empty(width, np.int64)
    numerators = np.empty(width, np.int64)
    denominators = np.empty(width, np.int64)
    ends = np.zeros(width + 1, np.int32)  # per pixel, how many parabolas end there
    squared = np.empty(width, np.int64)
    for i in range(height):
        count = 0
        q = 0
        while q < width:
            g = np.int64(column[i, q])
            if g >= skipped:
                q += 1
                continue
            last = q
            if g == 0:
                # A run of sources: a pixel outside it is nearest to one of its ends, so only
                # those enter the envelope (the run's own pixels are set to 0 at the end). Measured on
                # silhouettes, the inside transform took 0.55-0.72 of the time of every pixel's.
                while last + 1 < width and column[i, last + 1] == 0:
                    last += 1
            p = q
            while True:
                offset = g * g + p * p
                numerator, denominator = np.int64(0), np.int64(0)
                while count > 0:
                    # The last parabola is dropped while the new one starts at or before its start.
                    numerator, denominator = offset - offsets[count - 1], 2 * (p - apexes[count - 1])
                    if (denominators[count - 1] == 0
                            or numerator * denominators[count - 1] > numerators[count - 1] * denominator):
                        break
                    count -= 1
                    numerator, denominator = np.int64(0), np.int64(0)
                apexes[count], offsets[count] = p, offset
                numerators[count], denominators[count] = numerator, denominator
                count += 1
                if p == last:
                    break
                p = last
            q = last + 1
        out_row = out[i]
        if count == 0:
            out_row[:] = -np.inf if signed else np.inf
            continue
        # Parabola k is the lowest from where k - 1 ends to where it ends itself: pixel x takes the
        # parabola that counts the ends at or before x. Branch-free: a loop per parabola, which
        # covers 2-3 pixels each, mispredicts its exits (the fill 135 -> 110 us on the arm's window).
        for k in range(1, count):
            end = numerators[k] // denominators[k] + 1  # past the floor of where k starts
            ends[min(max(end, 0), width)] += 1
        k = 0
        for x in range(width):
            k += ends[x]
            ends[x] = 0
            squared[x] = offsets[k] - 2 * apexes[k] * x + x * x
        ends[width] = 0
        row = column[i]
        if signed:
            for x in range(width):
                out_row[x] = half - np.sqrt(np.float32(squared[x]))
        else:
            for x in range(width):
                out_row[x] = 0.0 if row[x] == 0 else np.sqrt(np.float32(squared[x]))
    return out


# Up to this reach [px] the near transform is the faster: 109 against 196 us at 7 px on a boxing
# silhouette's box of 47,000 pixels, 203 against 242 at 20 (each shift of the row pass adds ~7 us).
_NEAR_REACH = 20


@njit(cache=True, nogil=True)
def _near_distances(image, to_set, reach):
    """The distance of every pixel to the nearest source pixel (see _distances), exact up to `reach`
    (whole pixels, at most 20) and above it beyond: a source within reach lies within reach along
    the row and along the column, so each pixel takes the least s^2 + g^2 over the columns s
    pixels away (|s| <= reach) whose own distance g to a source is at most reach. Shift by shift
    over whole rows, which the compiler vectorises (16-bit lanes), where the envelope of
    _distances is a sequential search with a test per parabola."""
    height, width = image.shape
    far = np.int16(reach + 1)  # a column distance left out
    none = np.int16(16384)  # no source within reach; none + reach^2 stays within 16 bits
    column = np.empty((height, width), np.int16)
    _column_distances(image, to_set, far, column)
    padded = np.full(width + 2 * reach, none, np.int16)  # a row's squared column distances, padded
    inner = padded[reach:reach + width]
    least = np.empty(width, np.int16)
    out = np.empty((height, width), np.float32)
    for i in range(height):
        row = column[i]
        for j in range(width):
            squared = none if row[j] == far else row[j] * row[j]
            inner[j] = squared
            least[j] = squared
        for s in range(1, reach + 1):
            # Slices, not padded[j - s]: an index that may be negative keeps the loop from vectorising.
            left, right, s2 = padded[reach - s:reach - s + width], padded[reach + s:reach + s + width], np.int16(s * s)
            for j in range(width):
                least[j] = min(least[j], min(left[j], right[j]) + s2)
        out_row = out[i]
        for j in range(width):
            out_row[j] = np.inf if least[j] >= none else np.sqrt(np.float32(least[j]))
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
