"""One frame's image inputs built from its silhouettes: per camera the overlap criterion's support
image and, for the two-way criterion, the silhouette's medial axis (what the read-ahead prepares)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.readahead.view_workers import map_views
from ibik_pin.tasks import View
from ibik_pin.tasks.silhouette_axis import AxisView
from ibik_pin.vision.camera import CameraLike
from ibik_pin.vision.distance import inside_distance, scan_mask
from ibik_pin.vision.medial_axis import medial_axis_pixels
from ibik_pin.vision.support import SupportImage, support_from_mask

__all__ = ["FrameImages", "frame_images"]


@dataclass(frozen=True)
class FrameImages:
    """One frame's image inputs.

    Attributes:
        views: one overlap view per camera; disabled: the cameras whose silhouette is empty.
        axis_views: one medial-axis view per camera, or None when the criterion needs none.
    """

    views: list[View]
    disabled: list[str]
    axis_views: list[AxisView] | None


def frame_images(source: Callable[[int], Sequence[np.ndarray]], cameras: Sequence[CameraLike],
                 caps: Sequence[float | None], axis_scales: Sequence[float] | None, frame: int,
                 target_boxes: np.ndarray | None = None, workers: int = 1) -> FrameImages:
    """Frame `frame`'s views from its silhouettes: per camera, the overlap criterion's support (its
    inside cap from `caps` [px], None for none) and, when `axis_scales` is given, the medial axis of the
    silhouette-axis term (its robust scale [px]); both read one distance transform of the silhouette.
    `target_boxes` (F, V, 4): per frame and camera, pixels the support's window covers besides the
    silhouette (tracking.views.target_boxes).

    An empty silhouette gives a disabled view and an empty axis, reported in `disabled` rather than
    warned of (catch_warnings, which would silence support_from_mask's warning, is not thread-safe).
    `workers`: threads building the views side by side (readahead.view_workers; 1 where this runs
    beside the solver in its process).
    """
    masks = source(frame)
    if len(masks) != len(cameras):
        raise InputError(f"expected one silhouette per camera ({len(cameras)}), got {len(masks)}")

    def view(index: int) -> tuple[View, np.ndarray, bool]:
        camera, mask = cameras[index], masks[index]
        # Each whole-image numpy call here would be a point where this thread, working beside the
        # solver, gives up the GIL and takes it back, and each such handover stalls the solver:
        # measured, 30 handovers a frame slowed its steps by a third. So the silhouette is read in
        # a few compiled calls: one scan, one inside and one outside distance transform.
        scanned = scan_mask(mask)
        if scanned.box is None:
            return View(camera, SupportImage(np.zeros(scanned.mask.shape, np.float32), enabled=False)), \
                np.zeros((0, 2)), True
        # Without a medial axis only the support reads the inside distance: up to its cap, if it has one.
        cap = caps[index]
        limit = None if axis_scales is not None or cap is None else cap + 0.5
        inside = inside_distance(scanned.mask, scanned.box, limit)
        around = None
        if target_boxes is not None:
            top, bottom, left, right = (int(value) for value in target_boxes[frame, index])
            around = (slice(top, bottom), slice(left, right))
        support = View(camera, support_from_mask(scanned, inside_cap_px=cap, inside=inside, also_around=around))
        axis = medial_axis_pixels(scanned.mask, inside=inside) if axis_scales is not None else np.zeros((0, 2))
        return support, axis, False

    built = map_views(view, range(len(cameras)), workers)
    views = [support for support, _, _ in built]
    axes = [axis for _, axis, _ in built]
    disabled = [camera.name for camera, (_, _, empty) in zip(cameras, built, strict=True) if empty]
    axis_views = (None if axis_scales is None else
                  [AxisView(camera, pixels, scale) for camera, pixels, scale in zip(cameras, axes, axis_scales,
                                                                                     strict=True)])
    return FrameImages(views, disabled, axis_views)
