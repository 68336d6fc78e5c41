"""Drawing on images: a projected skeleton, a silhouette mask.

Both return a drawn copy and leave the image alone. Segments are drawn anti-aliased at sub-pixel
positions (OpenCV's fixed-point coordinates, :func:`ibik_pin.vision.render.to_fixed_point`).
"""

from __future__ import annotations

import cv2
import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.vision.render import FIXED_POINT_SHIFT, to_fixed_point

__all__ = ["draw_skeleton", "overlay_mask"]


def _as_bgr(image_bgr) -> np.ndarray:
    image = np.asarray(image_bgr)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise InputError(
            f"image_bgr: expected a (H, W, 3) uint8 BGR image, found shape {image.shape} and dtype {image.dtype}"
        )
    return image


def draw_skeleton(
    image_bgr: np.ndarray,
    pixels_start: np.ndarray,
    pixels_end: np.ndarray,
    color: tuple[int, int, int] = (0, 255, 0),
    thickness: int = 2,
) -> np.ndarray:
    """A copy of the image with segments drawn on it (anti-aliased).

    Args:
        image_bgr: (H, W, 3) uint8 BGR image (not modified).
        pixels_start: (S, 2) first end of each segment [px].
        pixels_end: (S, 2) second end [px].
        color: BGR colour.
        thickness: line thickness [px].

    Returns:
        (H, W, 3) uint8 image; segments with a non-finite end are skipped.
    """
    image = _as_bgr(image_bgr).copy()
    starts = np.asarray(pixels_start, dtype=np.float64)
    ends = np.asarray(pixels_end, dtype=np.float64)
    if starts.ndim != 2 or starts.shape[1] != 2 or ends.shape != starts.shape:
        raise InputError(
            f"pixels_start, pixels_end: expected two arrays of the same shape (S, 2) [px], "
            f"found shapes {starts.shape} and {ends.shape}"
        )
    if int(thickness) != thickness or thickness < 1:
        raise InputError(f"thickness: expected a positive integer [px], found {thickness!r}")
    finite = np.isfinite(starts).all(axis=1) & np.isfinite(ends).all(axis=1)
    fixed_starts, fixed_ends = to_fixed_point(starts[finite]), to_fixed_point(ends[finite])
    bgr = tuple(int(c) for c in color)
    for start, end in zip(fixed_starts.tolist(), fixed_ends.tolist(), strict=True):
        cv2.line(image, tuple(start), tuple(end), bgr, int(thickness), cv2.LINE_AA, FIXED_POINT_SHIFT)
    return image


def overlay_mask(
    image_bgr: np.ndarray,
    mask: np.ndarray,
    color: tuple[int, int, int] = (0, 0, 255),
    alpha: float = 0.5,
) -> np.ndarray:
    """A copy of the image with a mask blended over it in a colour.

    Args:
        image_bgr: (H, W, 3) uint8 BGR image (not modified).
        mask: (H, W) bool or uint8, non-zero = drawn.
        color: BGR colour.
        alpha: opacity of the colour in [0, 1].

    Returns:
        (H, W, 3) uint8 image.
    """
    image = _as_bgr(image_bgr)
    mask = np.asarray(mask)
    if mask.shape != image.shape[:2] or mask.dtype not in (np.bool_, np.uint8):
        raise InputError(
            f"mask: expected a bool or uint8 array of shape {image.shape[:2]}, "
            f"found shape {mask.shape} and dtype {mask.dtype}"
        )
    if not 0.0 <= alpha <= 1.0:
        raise InputError(f"alpha: expected an opacity in [0, 1], found {alpha!r}")
    selected = mask != 0
    blended = image.copy()
    color_bgr = np.asarray(color, dtype=np.float64)
    blended[selected] = np.rint((1.0 - alpha) * image[selected] + alpha * color_bgr).astype(np.uint8)
    return blended
