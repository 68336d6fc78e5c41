"""The tracker's per-frame inputs: the starting pose, and the views built from each frame's silhouettes.

`initial_configuration` places the neutral pose on the first frame's targets; `support_caps` gives
each view's support cap (a limb's half width seen at the subject's distance); `make_views` and
`axis_views` turn one frame's silhouettes into the views of the overlap criterion
(:mod:`ibik_pin.tasks.image`) and of the silhouette-axis term (:mod:`ibik_pin.tasks.silhouette_axis`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from ibik_pin.checks import as_mask
from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.tasks import View
from ibik_pin.tasks.silhouette_axis import AxisView
from ibik_pin.vision.camera import CameraLike
from ibik_pin.vision.medial_axis import medial_axis_pixels
from ibik_pin.vision.support import SupportImage, support_from_mask

__all__ = ["LIMB_HALF_WIDTH", "initial_configuration", "support_caps", "make_views", "axis_views"]

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


def make_views(
    cameras: Sequence[CameraLike], masks: Sequence[np.ndarray], caps: Sequence[float]
) -> tuple[list[View], list[str]]:
    """One view per camera from its silhouette; also the names of the cameras whose mask is empty.

    Args:
        masks: (H, W) bool silhouette per camera; caps: the support's inside cap per camera [px].
    """
    if len(masks) != len(cameras):
        raise InputError(f"expected one silhouette per camera ({len(cameras)}), got {len(masks)}")
    views, disabled = [], []
    for camera, mask, cap in zip(cameras, masks, caps, strict=True):
        # An empty silhouette is reported per frame, not warned of: and catch_warnings, which would
        # silence support_from_mask's warning, is not thread-safe (frame_images runs this in a thread).
        if not as_mask(mask).any():
            disabled.append(camera.name)
            views.append(View(camera, SupportImage(np.zeros(mask.shape, np.float32), enabled=False)))
        else:
            views.append(View(camera, support_from_mask(mask, inside_cap_px=cap)))
    return views, disabled


def axis_views(cameras: Sequence[CameraLike], masks: Sequence[np.ndarray], scales: Sequence[float]) -> list[AxisView]:
    """One silhouette-axis view per camera: the medial axis of its mask, robust scale [px]."""
    return [AxisView(camera, medial_axis_pixels(mask), scale)
            for camera, mask, scale in zip(cameras, masks, scales, strict=True)]
