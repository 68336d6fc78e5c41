"""The tracker's starting pose and the sizes its views are built with.

`initial_configuration` places the neutral pose on the first frame's targets; `support_caps` gives
each view's support cap (a limb's half width seen at the subject's distance). Each frame's views are
built from its silhouettes by :mod:`ibik_pin.tracking.frame_images`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from ibik_pin.model import BodyModel
from ibik_pin.vision.camera import CameraLike

__all__ = ["LIMB_HALF_WIDTH", "initial_configuration", "support_caps"]

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
