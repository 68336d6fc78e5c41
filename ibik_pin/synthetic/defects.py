"""Silhouette defects like a real segmentation's: erosion, dilation, holes, blobs, lost limbs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ibik_pin.exceptions import InputError

__all__ = ["SilhouetteDefects", "apply_defects"]


@dataclass(frozen=True)
class SilhouetteDefects:
    """How a synthetic silhouette is degraded to look like a real segmentation.

    Applied in this order by :func:`apply_defects`: a missing limb, erosion, dilation, holes, blobs.

    Attributes:
        erode_px: erosion radius [px] (elliptic structuring element of 2 r + 1 px): a tight mask.
        dilate_px: dilation radius [px]: a loose mask.
        holes: number of discs removed inside the silhouette (a colour like the background's).
        hole_radius_px: their radius [px].
        blobs: number of elliptic blobs added (shadows, clutter).
        blob_radius_px: their semi-major axis [px]; the semi-minor axis is 50-100 % of it.
        attached_blob_probability: chance that a blob is centred on the silhouette's border
            (a shadow, attached) rather than anywhere in the image (clutter, detached).
        missing_limb_probability: chance, per mask, that the pixels of one random forearm or
            shank are lost.
    """

    erode_px: int = 0
    dilate_px: int = 0
    holes: int = 0
    hole_radius_px: float = 4.0
    blobs: int = 0
    blob_radius_px: float = 12.0
    attached_blob_probability: float = 0.5
    missing_limb_probability: float = 0.0

    def __post_init__(self) -> None:
        for name in ("erode_px", "dilate_px", "holes", "blobs"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < 0:
                raise InputError(f"{name}: expected a non-negative integer, got {value!r}")
            object.__setattr__(self, name, int(value))
        for name in ("hole_radius_px", "blob_radius_px"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0.0):
                raise InputError(f"{name}: expected a positive radius [px], got {value}")
        for name in ("attached_blob_probability", "missing_limb_probability"):
            value = float(getattr(self, name))
            if not 0.0 <= value <= 1.0:
                raise InputError(f"{name}: expected a probability in [0, 1], got {value}")


def _disc_kernel(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def apply_defects(
    mask: np.ndarray,
    defects: SilhouetteDefects,
    rng: np.random.Generator,
    limb_masks: Sequence[np.ndarray] | None = None,
) -> np.ndarray:
    """A degraded copy of a silhouette (the input is not modified).

    Args:
        mask: (H, W) bool silhouette.
        defects: what to apply.
        rng: the random generator (seed it for a reproducible data set).
        limb_masks: the pixels of each forearm and shank (:func:`render_limb_masks`), needed for a
            missing limb; without them no limb goes missing.

    Returns:
        (H, W) bool mask.
    """
    mask = np.asarray(mask)
    if mask.ndim != 2 or mask.dtype != np.bool_:
        raise InputError(f"mask: expected an (H, W) bool array, got shape {mask.shape} and dtype {mask.dtype}")
    image: np.ndarray = mask.astype(np.uint8)
    if limb_masks and rng.random() < defects.missing_limb_probability:
        lost = np.asarray(limb_masks[int(rng.integers(len(limb_masks)))], dtype=bool)
        if lost.shape != mask.shape:
            raise InputError(f"limb_masks: expected masks of shape {mask.shape}, got {lost.shape}")
        image[lost] = 0
    if defects.erode_px:
        image = cv2.erode(image, _disc_kernel(defects.erode_px))
    if defects.dilate_px:
        image = cv2.dilate(image, _disc_kernel(defects.dilate_px))
    height, width = image.shape
    for _ in range(defects.holes):
        rows, columns = np.nonzero(image)
        if rows.size == 0:
            break
        pick = int(rng.integers(rows.size))
        radius = int(round(defects.hole_radius_px))
        cv2.circle(image, (int(columns[pick]), int(rows[pick])), radius, 0, thickness=-1)
    for _ in range(defects.blobs):
        border = image.astype(bool) & ~cv2.erode(image, _disc_kernel(1)).astype(bool)
        rows, columns = np.nonzero(border)
        if rows.size and rng.random() < defects.attached_blob_probability:
            pick = int(rng.integers(rows.size))
            centre = (int(columns[pick]), int(rows[pick]))
        else:
            centre = (int(rng.integers(width)), int(rng.integers(height)))
        semi_major = max(int(round(defects.blob_radius_px)), 1)
        semi_minor = max(int(round(semi_major * rng.uniform(0.5, 1.0))), 1)
        angle = float(rng.uniform(0.0, 180.0))
        cv2.ellipse(image, centre, (semi_major, semi_minor), angle, 0.0, 360.0, 1, thickness=-1)
    return image.astype(bool)
