"""Silhouettes of a body made of capsules, and overlays, drawn with OpenCV.

Used to make synthetic test data: a posed model's segments become capsules (a segment between
two joints, with a radius), rendered into a binary silhouette per camera; the overlays draw a
projected skeleton and a mask over a video frame.
"""

from __future__ import annotations

import cv2
import numpy as np

from ibik_pin.cameras import Camera
from ibik_pin.exceptions import InputError

__all__ = ["draw_skeleton", "overlay_mask", "render_capsules"]

# Polygon vertices per projected disc: the inscribed polygon loses r (1 - cos(pi/n)),
# 0.5 % of the radius.
_DISC_VERTICES = 32
# OpenCV's fixed-point drawing: coordinates carry _SHIFT fractional bits.
_SHIFT = 4
# OpenCV fills the pixels its outline touches, about half a pixel beyond the exact boundary:
# the discs are shrunk by as much, so that rendered widths and areas are unbiased.
_OUTLINE_BIAS_PX = 0.5
# Vertices far outside the image are clamped to keep the fixed-point coordinates in int32.
_MAX_COORDINATE_PX = 1e6


def _as_points(points, name: str, count: int | None = None) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or (count is not None and points.shape[0] != count):
        expected = f"({count if count is not None else 'S'}, 3)"
        raise InputError(f"{name}: expected an array of shape {expected} [m], found shape {points.shape}")
    return points


def _as_radii(radii, name: str, count: int) -> np.ndarray:
    radii = np.asarray(radii, dtype=np.float64)
    if radii.ndim == 0:
        radii = np.full(count, float(radii))
    if radii.shape != (count,):
        raise InputError(f"{name}: expected shape ({count},) [m] or a scalar, found shape {radii.shape}")
    if not np.all(np.isfinite(radii)) or np.any(radii < 0.0):
        raise InputError(f"{name}: expected finite non-negative radii [m], found {radii.tolist()}")
    return radii


def _as_bgr(image_bgr) -> np.ndarray:
    image = np.asarray(image_bgr)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise InputError(
            f"image_bgr: expected a (H, W, 3) uint8 BGR image, found shape {image.shape} and dtype {image.dtype}"
        )
    return image


def _fixed_point(pixels: np.ndarray) -> np.ndarray:
    clamped = np.clip(pixels, -_MAX_COORDINATE_PX, _MAX_COORDINATE_PX)
    return np.rint(clamped * (1 << _SHIFT)).astype(np.int32)


def render_capsules(
    camera: Camera,
    starts_world: np.ndarray,
    ends_world: np.ndarray,
    radii: np.ndarray,
    spheres_world: np.ndarray | None = None,
    sphere_radii: np.ndarray | None = None,
) -> np.ndarray:
    """The silhouette of capsules and spheres seen by a camera.

    Each capsule's projection is approximated by the convex hull of the two discs its end
    spheres project to (radius ``camera.pixel_radius``: focal * r / depth for a pinhole camera,
    scale * r for an orthographic one); a sphere is a disc. Capsules or spheres with a point
    the camera cannot see (behind a pinhole camera) are skipped, not clipped.

    Args:
        camera: a :class:`~ibik_pin.cameras.PinholeCamera` or
            :class:`~ibik_pin.cameras.OrthographicCamera`.
        starts_world: (S, 3) first end of each capsule's axis [m].
        ends_world: (S, 3) second end [m].
        radii: (S,) capsule radii [m], or a scalar.
        spheres_world: (K, 3) sphere centres [m], or None.
        sphere_radii: (K,) sphere radii [m], or a scalar; required with ``spheres_world``.

    Returns:
        (H, W) bool silhouette, image size from the camera.
    """
    starts = _as_points(starts_world, "starts_world")
    ends = _as_points(ends_world, "ends_world", starts.shape[0])
    radii = _as_radii(radii, "radii", starts.shape[0])
    if spheres_world is not None:
        if sphere_radii is None:
            raise InputError("sphere_radii: expected radii [m] for spheres_world, found None")
        spheres = _as_points(spheres_world, "spheres_world")
        starts = np.concatenate((starts, spheres))
        ends = np.concatenate((ends, spheres))
        radii = np.concatenate((radii, _as_radii(sphere_radii, "sphere_radii", spheres.shape[0])))
    width, height = camera.size
    image = np.zeros((height, width), np.uint8)
    if starts.shape[0] == 0:
        return image.astype(bool)

    ends_both = np.concatenate((starts, ends))
    pixels = camera.project(ends_both)
    pixel_radii = camera.pixel_radius(ends_both, np.concatenate((radii, radii)))
    count = starts.shape[0]
    visible = np.isfinite(pixels).all(axis=1) & np.isfinite(pixel_radii)
    visible = visible[:count] & visible[count:]

    angles = np.linspace(0.0, 2.0 * np.pi, _DISC_VERTICES, endpoint=False)
    circle = np.column_stack((np.cos(angles), np.sin(angles)))
    # (2 S, n, 2) disc outlines, then (S, 2 n, 2): both discs of each capsule.
    outline_radii = np.maximum(pixel_radii - _OUTLINE_BIAS_PX, 0.0)
    outlines = pixels[:, np.newaxis, :] + outline_radii[:, np.newaxis, np.newaxis] * circle
    outlines = np.concatenate((outlines[:count], outlines[count:]), axis=1)
    vertices = _fixed_point(np.where(visible[:, np.newaxis, np.newaxis], outlines, 0.0))
    for index in np.flatnonzero(visible):
        hull = cv2.convexHull(vertices[index])
        cv2.fillConvexPoly(image, hull, 1, lineType=cv2.LINE_8, shift=_SHIFT)
    return image.astype(bool)


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
    fixed_starts, fixed_ends = _fixed_point(starts[finite]), _fixed_point(ends[finite])
    color = tuple(int(c) for c in color)
    for start, end in zip(fixed_starts, fixed_ends):
        cv2.line(image, tuple(start.tolist()), tuple(end.tolist()), color, int(thickness), cv2.LINE_AA, _SHIFT)
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
