"""The tracker's starting pose and the sizes its views are built with.

`initial_configuration` places the neutral pose on the first frame's targets; `support_caps` gives
each view's support cap (a limb's half width seen at the subject's distance). Each frame's views are
built from its silhouettes by :mod:`ibik_pin.readahead.frame_images`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from ibik_pin.model import BodyModel
from ibik_pin.vision.camera import CameraLike

__all__ = ["LIMB_HALF_WIDTH", "initial_configuration", "support_caps", "target_boxes"]

LIMB_HALF_WIDTH = 0.04  # [m] the support's inside cap, in pixels at the subject's distance (docs/method.md)


def initial_configuration(body: BodyModel, names: list[str], targets: np.ndarray) -> np.ndarray:
    """The neutral pose placed on the pelvis target and turned to face where the hips say.

    Args:
        names: target names; targets: (K, 3) [m] in the model's frame (Y up), NaN where absent.
    """
    q = pin.neutral(body.model)
    present = {name: targets[k] for k, name in enumerate(names) if np.all(np.isfinite(targets[k]))}
    if "Hip" in present:
        q[:3] = present["Hip"]
    elif "LHip" in present and "RHip" in present:
        q[:3] = 0.5 * (present["LHip"] + present["RHip"])
    elif present:
        q[:3] = np.mean(list(present.values()), axis=0)
    if "LHip" in present and "RHip" in present:
        right = present["RHip"] - present["LHip"]  # the model's +Z points to its right
        right[1] = 0.0
        if np.linalg.norm(right) > 1e-6:
            z_axis = right / np.linalg.norm(right)
            y_axis = np.array([0.0, 1.0, 0.0])
            rotation = np.column_stack([np.cross(y_axis, z_axis), y_axis, z_axis])
            q[3:7] = pin.Quaternion(rotation).coeffs()
    return q


def support_caps(
    cameras: Sequence[CameraLike], subject_position: np.ndarray, size: float = LIMB_HALF_WIDTH
) -> list[float]:
    """Inside cap [px] of each view's support: a limb's half width (or `size` [m]) seen at the
    subject's distance, at least 1 px."""
    caps = []
    for camera in cameras:
        radius = camera.pixel_radius(subject_position[None], np.array([size]))
        caps.append(float(max(radius[0], 1.0)))
    return caps


def target_boxes(cameras: Sequence[CameraLike], targets: np.ndarray) -> np.ndarray:
    """Per frame and camera, the pixel box of the targets in front of the camera, clipped to the
    image: (F, V, 4) ints (first row, row past the last, first column, column past the last), all
    zero where none is seen. The skeleton lies around its targets, so a support's window that covers
    them holds nearly every sample even where the silhouette is partial (frame_images).

    Args:
        targets: (F, K, 3) [m] in the frame the cameras project; NaN = absent.
    """
    frames, count = targets.shape[:2]
    boxes = np.zeros((frames, len(cameras), 4), dtype=np.int64)
    flat = targets.reshape(-1, 3)
    present = np.flatnonzero(np.isfinite(flat).all(axis=1))
    if present.size == 0:
        return boxes
    for index, camera in enumerate(cameras):
        projection = camera.project_with_jacobian(flat[present])
        seen = projection.depth > 0.0
        pixels = np.full((frames * count, 2), np.nan)
        pixels[present[seen]] = projection.pixels[seen]
        pixels = pixels.reshape(frames, count, 2)
        has = np.isfinite(pixels[..., 0]).any(axis=1)
        if not has.any():
            continue
        width, height = camera.size
        low = np.floor(np.nanmin(pixels[has], axis=1))
        high = np.ceil(np.nanmax(pixels[has], axis=1)) + 1
        box = np.stack([np.clip(low[:, 1], 0, height), np.clip(high[:, 1], 0, height),
                        np.clip(low[:, 0], 0, width), np.clip(high[:, 0], 0, width)], axis=1)
        boxes[has, index] = box.astype(np.int64)
    return boxes
