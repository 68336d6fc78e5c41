"""The trunk's room: where an elbow's centre cannot be (tracking.swivel keeps hints out of it).

A body does not pass through itself. The trunk is modelled as a cylinder about the line from the
pelvis centre to the neck, of an elliptic cross-section scaled by the subject's half shoulder width,
so that one section fits any adult (docs/sweep.md, "Knees and elbows from the physics").
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TRUNK_KEYPOINTS", "TRUNK_SECTION", "farther_from_axis", "inside_trunk", "trunk_distance"]

#: Keypoints that place the trunk: its axis from the pelvis centre to the neck, its width from the
#: shoulders (inside_trunk).
TRUNK_KEYPOINTS = ("Hip", "Neck", "LShoulder", "RShoulder")
#: Semi-axes of the trunk's cross-section an elbow's centre never enters, sideways and front to back,
#: in half shoulder widths (between the shoulder joint centres). A trunk's half width at the waist is
#: about 0.75-0.85 of that and its half depth 0.55-0.7, and an elbow's centre keeps an arm's radius
#: (another 0.2) outside the skin. Measured on the sweep's 14 motions (1120 frames of each elbow,
#: docs/sweep.md): no true elbow inside this section; 24 of the 156 frames whose IBIK elbow was more
#: than 40 mm off were inside (an arm laid into the trunk, where both views' silhouettes cover it).
#: A third value gives the front and the back their own semi-axes (sideways, front, back): in front
#: of the chest no true elbow of those motions lay within 1.12 of (0.75, 1.2, 0.6) (the boxing guard
#: the nearest), but an arm folded across the chest would: not the default (docs/sweep.md).
TRUNK_SECTION = (0.75, 0.6)


def _norm(vector: np.ndarray) -> float:
    """|v| of a 3-vector, np.linalg.norm's float (the square root of v.v) without its wrapper."""
    return math.sqrt(vector.dot(vector))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors: np.cross's arithmetic, without its axis handling."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def trunk_distance(points: np.ndarray, hip: np.ndarray, neck: np.ndarray, left_shoulder: np.ndarray,
                   right_shoulder: np.ndarray, section: tuple[float, ...] = TRUNK_SECTION
                   ) -> tuple[np.ndarray, np.ndarray]:
    """How far points (..., 3) [m] lie from the trunk's axis (the line from the pelvis centre `hip` to
    `neck`) in the elliptic measure of semi-axes `section` (sideways, to the front and to the back; a
    pair: the same front and back; in half shoulder widths; 1 on the section's border), and their
    height along that axis as a fraction of hip-neck: two arrays (...). A degenerate trunk (no height
    or width) puts every point at infinity."""
    points = np.asarray(points, dtype=float)
    # The axes from 3-vectors: math on them costs a fraction of numpy's calls (np.cross alone was
    # most of a swivel search's trunk tests); the same arithmetic, so the same floats.
    up = neck - hip
    height = _norm(up)
    across_shoulders = left_shoulder - right_shoulder
    half_width = 0.5 * _norm(across_shoulders)
    sideways = across_shoulders - (across_shoulders @ up) * up / max(height, 1e-9) ** 2
    width = _norm(sideways)
    if height < 1e-9 or half_width < 1e-9 or width < 1e-9:
        return np.full(points.shape[:-1], np.inf), np.zeros(points.shape[:-1])
    up = up / height
    sideways = sideways / width
    forward = _cross(sideways, up)  # sideways points to the left: left x up is forward
    offset = points - hip
    across = (offset @ sideways) / (section[0] * half_width)
    depth = offset @ forward
    depth = depth / (np.where(depth >= 0.0, section[1], section[-1]) * half_width)
    return np.sqrt(across**2 + depth**2), (offset @ up) / height


def inside_trunk(points: np.ndarray, hip: np.ndarray, neck: np.ndarray, left_shoulder: np.ndarray,
                 right_shoulder: np.ndarray, section: tuple[float, ...] = TRUNK_SECTION) -> np.ndarray:
    """Whether points (..., 3) [m] lie inside the trunk: a cylinder about the line from the pelvis
    centre `hip` to `neck`, between those two heights, of two half-elliptic sections joined at the
    axis, semi-axes `section` (sideways, to the front, to the back; a pair: the same front and back)
    in half shoulder widths."""
    distance, along = trunk_distance(points, hip, neck, left_shoulder, right_shoulder, section)
    return (along > 0.0) & (along < 1.0) & (distance < 1.0)


def farther_from_axis(starts: np.ndarray, ends: np.ndarray, hip: np.ndarray, neck: np.ndarray,
                      left_shoulder: np.ndarray, right_shoulder: np.ndarray,
                      section: tuple[float, ...] = TRUNK_SECTION) -> np.ndarray:
    """Whether each of `ends` (..., 3) lies farther from the trunk's axis (trunk_distance in
    `section`) than the matching point of `starts`, shape (...)."""
    distance, _ = trunk_distance(np.stack([starts, ends], axis=-2), hip, neck, left_shoulder, right_shoulder, section)
    return distance[..., 1] > distance[..., 0]
