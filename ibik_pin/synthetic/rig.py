"""Camera rigs around a subject, as in HumanEva: pinhole cameras on a horizontal circle, each
looking at the subject's centre, with seeded azimuths.
"""

from __future__ import annotations

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.synthetic.mocap import UP
from ibik_pin.vision.pinhole import PinholeCamera, look_at_camera

__all__ = ["humaneva_rig"]


def humaneva_rig(
    n_views: int,
    subject_center: np.ndarray,
    distance_m: float = 4.0,
    size: tuple[int, int] = (640, 480),
    focal_px: float = 700.0,
    height_m: float = 1.5,
    seed: int = 0,
    jitter_deg: float = 15.0,
) -> list[PinholeCamera]:
    """Cameras around the subject like HumanEva's: on a horizontal circle, looking at its centre.

    HumanEva's colour cameras stand 3-5 m from the capture volume's centre at about 1.5 m, 640 x 480
    px. Here the azimuths are spread evenly (360 deg / n_views apart) from a seeded random start,
    each with a seeded jitter of up to ``jitter_deg``; distortion is zero.

    Args:
        n_views: number of cameras (HumanEva: 3 or 4).
        subject_center: shape (3,) [m], model frame (Y up): the point every camera looks at, e.g.
            the mean Hip position over the sequence.
        distance_m: horizontal distance of each camera from the subject's centre [m].
        size: (width, height) [px].
        focal_px: focal length [px].
        height_m: height of the camera centres, model-frame Y [m] (the motion data's floor is 0).
        seed: seeds the start azimuth and the jitter.
        jitter_deg: largest deviation of an azimuth from the even spread [deg].

    Returns:
        Cameras named cam1 .. camN, extrinsics mapping model-frame points.

    Raises:
        InputError: n_views < 1, a non-positive distance, a centre that is not (3,).
    """
    if int(n_views) != n_views or n_views < 1:
        raise InputError(f"n_views: expected a positive integer, got {n_views!r}")
    distance_m = float(distance_m)
    if not (np.isfinite(distance_m) and distance_m > 0.0):
        raise InputError(f"distance_m: expected a positive distance [m], got {distance_m}")
    center = np.asarray(subject_center, dtype=float)
    if center.shape != (3,) or not np.all(np.isfinite(center)):
        raise InputError(f"subject_center: expected a finite point of shape (3,) [m], got {subject_center!r}")
    rng = np.random.default_rng(seed)
    start = rng.uniform(0.0, 2.0 * np.pi)
    jitter = np.deg2rad(float(jitter_deg)) * rng.uniform(-1.0, 1.0, int(n_views))
    azimuths = start + 2.0 * np.pi * np.arange(int(n_views)) / n_views + jitter
    cameras = []
    for index, azimuth in enumerate(azimuths, start=1):
        eye = center + distance_m * np.array([np.cos(azimuth), 0.0, np.sin(azimuth)])
        eye[1] = height_m
        cameras.append(look_at_camera(f"cam{index}", size, focal_px, eye, center, UP))
    return cameras
