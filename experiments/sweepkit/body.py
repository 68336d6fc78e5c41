"""The sweep's silhouette body: realdata's capsules and ellipsoids, reshaped per condition.

A :class:`BodyShape` scales every limb's radii (thighs, shanks, feet, upper arms, forearms, hands),
flattens the limbs' cross-sections into ellipses of the same area (wider side to side, the axis
along the pelvis' left-right line; their end caps become ellipsoids) and adds loose clothing: a
margin on the thighs' radii and around the pelvis, abdomen and thorax. The tracking model never
sees any of it: it keeps its own widths.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from realdata.body import _SIDES, REFERENCE_STATURE_M, Anatomy, MocapBody, Shapes, _sphere_samples

LIMBS = ("thigh", "shank", "foot", "upper_arm", "forearm", "hand", "thumb")
TRUNK = ("pelvis", "abdomen", "thorax")
_CAP_SAMPLES = 48


@dataclass(frozen=True)
class BodyShape:
    """How the silhouette body departs from realdata's adult proportions.

    Attributes:
        limb_radius_factor: every limb radius is multiplied by it.
        ellipticity: ratio of a limb section's axes (1: round); the area is kept.
        loose_m: loose clothing [m] added to the thighs' radii and around the trunk's ellipsoids.
    """

    limb_radius_factor: float = 1.0
    ellipticity: float = 1.0
    loose_m: float = 0.0


def stature(joint_names: Sequence[str], joints: np.ndarray, anatomy: Anatomy) -> float:
    """Median over frames of the head top's height above the lowest foot joint [m] (Y up)."""
    names = list(joint_names)
    feet = [names.index(name.format(**side)) for side in _SIDES for name in anatomy.foot]
    top = joints[:, names.index(anatomy.head_top), 1]
    return float(np.median(top - joints[:, feet, 1].min(axis=1)))


class SweepBody(MocapBody):
    """A MocapBody of `anatomy`, scaled to the static's stature and reshaped by `shape`."""

    def __init__(self, joint_names: Sequence[str], source: str, anatomy: Anatomy, static_joints: np.ndarray,
                 shape: BodyShape):
        scale = stature(joint_names, static_joints, anatomy) / REFERENCE_STATURE_M
        super().__init__(joint_names, source, scale, anatomy=anatomy)
        self.shape = shape
        self._cap = _sphere_samples(_CAP_SAMPLES)
        self._lateral = np.array([0.0, 0.0, 1.0])

    def shapes(self, joints: np.ndarray) -> Shapes:
        shapes = super().shapes(joints)
        kinds = [part.rsplit("_", 1)[0] for part in shapes.capsule_parts]
        limb = np.array([kind in LIMBS for kind in kinds])
        thigh = np.array([kind == "thigh" for kind in kinds])
        shapes.capsule_radii[limb] *= self.shape.limb_radius_factor
        shapes.capsule_radii[thigh] += self.shape.loose_m
        for k, part in enumerate(shapes.ellipsoid_parts):
            if part in TRUNK and self.shape.loose_m > 0.0:
                offset = shapes.ellipsoid_points[k] - shapes.ellipsoid_centres[k]
                distance = np.linalg.norm(offset, axis=1, keepdims=True)
                shapes.ellipsoid_points[k] += offset * (self.shape.loose_m / np.maximum(distance, 1e-9))
        left, right = np.asarray(joints, dtype=float)[self._hips]
        self._lateral = (left - right) / max(float(np.linalg.norm(left - right)), 1e-9)
        return shapes

    def polygons(self, shapes: Shapes, camera) -> tuple[list[np.ndarray], list[str]]:
        outlines, names = super().polygons(shapes, camera)
        if self.shape.ellipticity == 1.0:
            return outlines, names
        wide, narrow = np.sqrt(self.shape.ellipticity), 1.0 / np.sqrt(self.shape.ellipticity)
        for k, (ends, radii) in enumerate(zip(shapes.capsule_ends, shapes.capsule_radii, strict=True)):
            if shapes.capsule_parts[k].rsplit("_", 1)[0] not in LIMBS:
                continue
            along = ends[1] - ends[0]
            along /= np.linalg.norm(along)
            across = self._lateral - (self._lateral @ along) * along
            if np.linalg.norm(across) < 1e-6:  # a limb along the pelvis' line: any perpendicular
                across = np.cross(along, [0.0, 1.0, 0.0])
                if np.linalg.norm(across) < 1e-6:
                    across = np.cross(along, [1.0, 0.0, 0.0])
            across /= np.linalg.norm(across)
            depth = np.cross(along, across)
            axes = np.stack((wide * across, narrow * depth, along))  # rows: the cap's semi-axes / r
            points = np.concatenate([end + radius * (self._cap @ axes)
                                     for end, radius in zip(ends, radii, strict=True)])
            outlines[k] = camera.project(points)
        return outlines, names
