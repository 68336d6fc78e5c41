"""Silhouettes of a posed model rendered into calibrated cameras.

The body is drawn as capsules along its segments (radii from the model) and a sphere for the
head, by :func:`ibik_pin.vision.render.render_capsules`; the pixels that only a forearm or a shank
covers are rendered apart, for the defect that loses a limb (:mod:`ibik_pin.synthetic.defects`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.vision.render import render_capsules

__all__ = ["MISSING_LIMB_SEGMENTS", "keypoint_positions", "render_limb_masks", "render_silhouettes"]

#: Keypoints a forearm or shank capsule ends on: the limbs a segmentation may lose.
MISSING_LIMB_SEGMENTS = (("LElbow", "LWrist"), ("RElbow", "RWrist"), ("LKnee", "LAnkle"), ("RKnee", "RAnkle"))


def keypoint_positions(body: BodyModel, q: np.ndarray) -> dict[str, np.ndarray]:
    """World position of every keypoint of the body at a configuration.

    Args:
        body: The model and its keypoints.
        q: Configuration, shape (nq,).

    Returns:
        Keypoint name -> position, shape (3,) [m], in the body's order.

    Raises:
        InputError: ``q`` is not of shape (nq,).
    """
    q = np.asarray(q, dtype=float)
    if q.shape != (body.model.nq,):
        raise InputError(f"q: expected shape ({body.model.nq},), got {q.shape}")
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, q)
    return {name: data.oMf[body.frame_id(name)].translation.copy() for name in body.keypoints}


def _head_sphere(points: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Centre (1, 3) [m] and radius (1,) [m] of the head: 60 % of the way from Neck to Head, with a
    radius of 42 % of that length, so that its top reaches the Head keypoint (the top of the head)."""
    if "Neck" not in points or "Head" not in points:
        return np.zeros((0, 3)), np.zeros(0)
    neck_to_head = points["Head"] - points["Neck"]
    centre = points["Neck"] + 0.6 * neck_to_head
    return centre[np.newaxis], np.array([0.42 * np.linalg.norm(neck_to_head)])


def render_silhouettes(body: BodyModel, q: np.ndarray, cameras: Sequence) -> list[np.ndarray]:
    """Silhouettes of the posed model: its segment capsules (``body.segments``,
    ``body.segment_radii``) and a head sphere, one mask per camera.

    Args:
        body: the model.
        q: configuration, shape (nq,).
        cameras: cameras whose extrinsics map model-frame points.

    Returns:
        One (H, W) bool mask per camera.
    """
    points = keypoint_positions(body, q)
    starts = np.array([points[a] for a, _ in body.segments]).reshape(-1, 3)
    ends = np.array([points[b] for _, b in body.segments]).reshape(-1, 3)
    spheres, sphere_radii = _head_sphere(points)
    return [
        render_capsules(camera, starts, ends, body.segment_radii, spheres, sphere_radii)
        for camera in cameras
    ]


def render_limb_masks(body: BodyModel, q: np.ndarray, camera) -> list[np.ndarray]:
    """Pixels that only a forearm or a shank covers, per limb of :data:`MISSING_LIMB_SEGMENTS`.

    A segmentation that loses a limb loses those pixels; where the limb is in front of the trunk
    the trunk's pixels stay.

    Returns:
        One (H, W) bool mask per limb segment the body has.
    """
    points = keypoint_positions(body, q)
    spheres, sphere_radii = _head_sphere(points)
    masks = []
    for limb in MISSING_LIMB_SEGMENTS:
        if limb not in body.segments:
            continue
        index = body.segments.index(limb)
        others = [i for i in range(len(body.segments)) if i != index]
        limb_mask = render_capsules(
            camera, points[limb[0]][np.newaxis], points[limb[1]][np.newaxis], body.segment_radii[index]
        )
        rest = render_capsules(
            camera,
            np.array([points[body.segments[i][0]] for i in others]).reshape(-1, 3),
            np.array([points[body.segments[i][1]] for i in others]).reshape(-1, 3),
            body.segment_radii[others],
            spheres,
            sphere_radii,
        )
        masks.append(limb_mask & ~rest)
    return masks
