"""Silhouettes rendered from capsules (segments with a radius at each end) seen by a camera.

Shapes are filled by OpenCV with sub-pixel vertices: OpenCV's drawing functions take integer
coordinates with :data:`FIXED_POINT_SHIFT` fractional bits, which :func:`to_fixed_point` makes
(the overlays of :mod:`ibik_pin.viz.drawing` draw with them too).
"""

from __future__ import annotations

import cv2
import numpy as np

from ibik_pin.checks import as_radii
from ibik_pin.exceptions import InputError
from ibik_pin.vision.camera import Camera

__all__ = ["FIXED_POINT_SHIFT", "render_capsules", "to_fixed_point"]

#: Fractional bits of the pixel coordinates given to OpenCV's drawing functions (``shift``).
FIXED_POINT_SHIFT = 4

# Polygon vertices per projected disc: the inscribed polygon loses r (1 - cos(pi/n)),
# 0.5 % of the radius.
_DISC_VERTICES = 32

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


def to_fixed_point(pixels: np.ndarray) -> np.ndarray:
    """Pixel coordinates as OpenCV's drawing functions take them with ``shift=FIXED_POINT_SHIFT``.

    Args:
        pixels: Coordinates, any shape [px]; finite.

    Returns:
        The coordinates times 2**FIXED_POINT_SHIFT, rounded, int32, same shape; coordinates beyond
        1e6 px are clamped there first, to stay within int32.
    """
    clamped = np.clip(pixels, -_MAX_COORDINATE_PX, _MAX_COORDINATE_PX)
    return np.rint(clamped * (1 << FIXED_POINT_SHIFT)).astype(np.int32)


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
        camera: a :class:`~ibik_pin.vision.pinhole.PinholeCamera` or
            :class:`~ibik_pin.vision.camera.OrthographicCamera`.
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
    radii = as_radii(radii, starts.shape[0], "radii")
    if spheres_world is not None:
        if sphere_radii is None:
            raise InputError("sphere_radii: expected radii [m] for spheres_world, found None")
        spheres = _as_points(spheres_world, "spheres_world")
        starts = np.concatenate((starts, spheres))
        ends = np.concatenate((ends, spheres))
        radii = np.concatenate((radii, as_radii(sphere_radii, spheres.shape[0], "sphere_radii")))
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
    vertices = to_fixed_point(np.where(visible[:, np.newaxis, np.newaxis], outlines, 0.0))
    for index in np.flatnonzero(visible):
        hull = cv2.convexHull(vertices[index])
        cv2.fillConvexPoly(image, hull, 1, lineType=cv2.LINE_8, shift=FIXED_POINT_SHIFT)
    return image.astype(bool)
