"""Another body than the tracking model's: tapered capsules and ellipsoids around a mocap skeleton.

The silhouettes of the benchmark are this body's, posed by the raw mocap joints (every joint of the
skeleton, not only the keypoints), never by the project's human model:

- tapered capsules along the bone chains: thighs, shanks, feet (ankle, ball, toe tip), upper arms,
  forearms, hands (and thumbs where the skeleton has them), clavicles (neck base to shoulder), neck;
- ellipsoids: pelvis, abdomen and thorax (their vertical axes along the spine, their lateral axes
  along the hips' and the shoulders' left-right lines), and the head (its vertical axis from the
  head's base joint to its top).

Sizes are rounded typical adult values for a 1.75 m adult, chosen for this benchmark, not taken
from a particular anthropometric survey; they are scaled by the subject's stature / 1.75 (stature:
the static trial's head top above its lowest foot joint). A tapered capsule's outline is the convex
hull of the discs its two end spheres project to; an ellipsoid's the convex hull of its projected
surface samples; both are filled with cv2.fillConvexPoly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ibik_pin.exceptions import InputError, UnknownNameError

REFERENCE_STATURE_M = 1.75
# Capsule chains: (radius at the first joint, at the last joint) [m] at the reference stature;
# the radius tapers linearly along the chain's length.
CHAIN_RADII = {
    "thigh": (0.080, 0.050),
    "shank": (0.055, 0.035),
    "foot": (0.035, 0.020),
    "upper_arm": (0.045, 0.035),
    "forearm": (0.035, 0.025),
    "hand": (0.025, 0.018),
    "thumb": (0.010, 0.008),
    "clavicle": (0.050, 0.045),
    "neck": (0.055, 0.050),
}
# Ellipsoids: semi-axes (lateral, front-back, vertical) [m] at the reference stature. The thorax is
# 0.34 m wide and 0.22 m deep; the abdomen's vertical semi-axis spans the gap between thorax and pelvis.
HEAD_SEMI_AXES = (0.075, 0.095, 0.110)
THORAX_SEMI_AXES = (0.170, 0.110, 0.190)
ABDOMEN_SEMI_AXES = (0.150, 0.100, 0.0)
PELVIS_SEMI_AXES = (0.170, 0.110, 0.120)
THORAX_TOP_ABOVE_SHOULDERS = 0.04  # [m] trapezius above the shoulder joints
PELVIS_CENTRE_ABOVE_HIPS = 0.04  # [m] pelvis centre above the hip joints' midpoint
HEAD_TOP_INSIDE = 0.15  # the head-top joint lies this fraction of the vertical semi-axis inside
# The limbs a segmentation may lose (apply_defects' "lost limb"): forearms and shanks.
LOSABLE = ("forearm", "shank")

_SPHERE_SAMPLES = 256
_DISC_VERTICES = 32
_SHIFT = 4  # fixed-point bits of cv2.fillConvexPoly's coordinates
_OUTLINE_BIAS_PX = 0.5  # OpenCV fills the pixels its outline touches: shrink by as much


@dataclass(frozen=True)
class Anatomy:
    """Where a skeleton's bones are, by joint name; {side}: Left/Right, {s}: l/r, {S}: L/R.

    spine runs from the pelvis to the neck base (its last joint), neck from the neck base to the
    head's base joint; head_top is the top of the head.
    """

    spine: tuple[str, ...]
    neck: tuple[str, ...]
    head_top: str
    clavicle: tuple[str, ...]
    upper_arm: tuple[str, ...]
    forearm: tuple[str, ...]
    hand: tuple[str, ...]
    thumb: tuple[str, ...] | None
    thigh: tuple[str, ...]
    shank: tuple[str, ...]
    foot: tuple[str, ...]
    hips: tuple[str, str]  # left and right hip joints
    shoulders: tuple[str, str]  # left and right shoulder joints


# CMU ASF/AMC: a joint is the end of the bone of that name.
ASF = Anatomy(
    spine=("root", "lowerback", "upperback", "thorax"), neck=("thorax", "lowerneck", "upperneck"),
    head_top="head", clavicle=("thorax", "{s}clavicle"), upper_arm=("{s}clavicle", "{s}humerus"),
    forearm=("{s}humerus", "{s}radius", "{s}wrist"), hand=("{s}wrist", "{s}hand", "{s}fingers"),
    thumb=("{s}wrist", "{s}thumb"), thigh=("{s}hipjoint", "{s}femur"), shank=("{s}femur", "{s}tibia"),
    foot=("{s}tibia", "{s}foot", "{s}toes"), hips=("lhipjoint", "rhipjoint"),
    shoulders=("lclavicle", "rclavicle"),
)
# CMU BVH (cgspeed, 131_01's naming): a joint is the start of its bone.
CMU_BVH = Anatomy(
    spine=("Hips", "Chest", "Chest2"), neck=("Chest2", "Neck", "Head"), head_top="Head_end",
    clavicle=("{side}Collar", "{side}Shoulder"), upper_arm=("{side}Shoulder", "{side}Elbow"),
    forearm=("{side}Elbow", "{side}Wrist"), hand=("{side}Wrist", "{S}Fingers", "{S}Fingers_end"),
    thumb=("{side}Wrist", "{S}Thumb_end"), thigh=("{side}Hip", "{side}Knee"),
    shank=("{side}Knee", "{side}Ankle"), foot=("{side}Ankle", "{side}Toe", "{side}Toe_end"),
    hips=("LeftHip", "RightHip"), shoulders=("LeftShoulder", "RightShoulder"),
)
# Boxing_Toes.bvh: Hips at the hip joints' level, Neck and the collars above the shoulders.
BOXING = Anatomy(
    spine=("Hips", "Ab", "Chest", "Neck"), neck=("Neck", "Head"), head_top="Head_end",
    clavicle=("{side}Collar", "{side}Shoulder"), upper_arm=("{side}Shoulder", "{side}Elbow"),
    forearm=("{side}Elbow", "{side}Wrist"), hand=("{side}Wrist", "{side}Wrist_end"), thumb=None,
    thigh=("{side}Hip", "{side}Knee"), shank=("{side}Knee", "{side}Ankle"),
    foot=("{side}Ankle", "{side}Toes", "{side}Toes_end"), hips=("LeftHip", "RightHip"),
    shoulders=("LeftShoulder", "RightShoulder"),
)
ANATOMIES = {"asf": ASF, "cmu_bvh": CMU_BVH, "boxing": BOXING}
_SIDES = ({"side": "Left", "s": "l", "S": "L"}, {"side": "Right", "s": "r", "S": "R"})


@dataclass
class Shapes:
    """One pose of the body.

    Attributes:
        capsule_ends: (C, 2, 3) end points of each capsule [m]; capsule_radii: (C, 2) [m].
        capsule_parts: (C,) the part of each capsule, e.g. "forearm_left".
        ellipsoid_points: (E, N, 3) surface samples of each ellipsoid [m]; ellipsoid_centres (E, 3).
        ellipsoid_parts: (E,) e.g. "thorax".
    """

    capsule_ends: np.ndarray
    capsule_radii: np.ndarray
    capsule_parts: list[str]
    ellipsoid_points: np.ndarray
    ellipsoid_centres: np.ndarray
    ellipsoid_parts: list[str]


def _unit(vectors: np.ndarray) -> np.ndarray:
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def _sphere_samples(count: int) -> np.ndarray:
    """(count, 3) nearly uniform unit vectors (Fibonacci lattice)."""
    index = np.arange(count) + 0.5
    height = 1.0 - 2.0 * index / count
    radius = np.sqrt(1.0 - height**2)
    angle = np.pi * (1.0 + 5.0**0.5) * index
    return np.column_stack((radius * np.cos(angle), radius * np.sin(angle), height))


def stature(joint_names: Sequence[str], joints: np.ndarray, source: str) -> float:
    """Median over frames of the head top's height above the lowest foot joint [m] (Y up).

    Args:
        joints: (F, J, 3) [m].
    """
    anatomy = ANATOMIES[source]
    names = list(joint_names)
    feet = [names.index(name.format(**side)) for side in _SIDES for name in anatomy.foot]
    top = joints[:, names.index(anatomy.head_top), 1]
    return float(np.median(top - joints[:, feet, 1].min(axis=1)))


class MocapBody:
    """Capsules and ellipsoids of adult proportions around the joints of one mocap skeleton.

    Args:
        joint_names: the skeleton's J joints (SkeletonMotion.names).
        source: "asf", "cmu_bvh" or "boxing" (which :data:`Anatomy` names its bones).
        scale: every size is multiplied by it (the subject's stature / REFERENCE_STATURE_M).
        anatomy: where the skeleton's bones are (None: the source's, :data:`ANATOMIES`).

    Raises:
        UnknownNameError: a joint the anatomy names is not in the skeleton.
    """

    def __init__(self, joint_names: Sequence[str], source: str, scale: float = 1.0, anatomy: Anatomy | None = None):
        if anatomy is None and source not in ANATOMIES:
            raise UnknownNameError(f"source: expected one of {', '.join(ANATOMIES)}, got {source!r}")
        if not (np.isfinite(scale) and scale > 0.0):
            raise InputError(f"scale: expected a positive factor, got {scale}")
        self.source = source
        self.scale = float(scale)
        self.joint_names = list(joint_names)
        anatomy = ANATOMIES[source] if anatomy is None else anatomy
        self._anatomy = anatomy
        # (kind of chain, part name, joint indices)
        chains: list[tuple[str, str, list[int]]] = [("neck", "neck", self._indices(anatomy.neck))]
        for side in _SIDES:
            for kind in ("clavicle", "upper_arm", "forearm", "hand", "thumb", "thigh", "shank", "foot"):
                names = getattr(anatomy, kind)
                if names is not None:
                    chains.append((kind, f"{kind}_{side['side'].lower()}",
                                   self._indices([name.format(**side) for name in names])))
        self._chains = chains
        self._spine = self._indices(anatomy.spine)
        self._hips = self._indices(anatomy.hips)
        self._shoulders = self._indices(anatomy.shoulders)
        self._head_base = self._indices(anatomy.neck[-1:])[0]
        self._head_top = self._indices([anatomy.head_top])[0]
        self._sphere = _sphere_samples(_SPHERE_SAMPLES)

    @classmethod
    def for_subject(cls, joint_names: Sequence[str], source: str, static_joints: np.ndarray) -> MocapBody:
        """The body scaled by the stature measured on the static trial's joints (S, J, 3) [m]."""
        return cls(joint_names, source, stature(joint_names, static_joints, source) / REFERENCE_STATURE_M)

    def _indices(self, names: Sequence[str]) -> list[int]:
        missing = [name for name in names if name not in self.joint_names]
        if missing:
            raise UnknownNameError(f"joint(s) {missing} of the {self.source!r} anatomy are not in the skeleton; "
                                   f"its joints: {', '.join(self.joint_names)}")
        return [self.joint_names.index(name) for name in names]

    def shapes(self, joints: np.ndarray) -> Shapes:
        """The capsules and ellipsoids at one frame's joint positions (J, 3) [m]."""
        joints = np.asarray(joints, dtype=float)
        if joints.shape != (len(self.joint_names), 3):
            raise InputError(f"joints: expected shape ({len(self.joint_names)}, 3) [m], got {joints.shape}")
        s = self.scale
        ends, radii, parts = [], [], []
        for kind, part, indices in self._chains:
            points = joints[indices]
            lengths = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))))
            fractions = lengths / lengths[-1] if lengths[-1] > 0 else np.zeros_like(lengths)
            first, last = CHAIN_RADII[kind]
            chain_radii = s * (first + (last - first) * fractions)
            for k in range(len(indices) - 1):
                if lengths[k + 1] - lengths[k] > 1e-9:  # zero-length bones (CMU BVH) add nothing
                    ends.append(points[k:k + 2])
                    radii.append(chain_radii[k:k + 2])
                    parts.append(part)

        # Trunk frames: vertical axes along the spine, lateral ones along the hips and shoulders.
        spine = joints[self._spine]
        hip_left, hip_right = joints[self._hips]
        shoulder_left, shoulder_right = joints[self._shoulders]
        mid_hip = 0.5 * (hip_left + hip_right)
        mid_shoulder = 0.5 * (shoulder_left + shoulder_right)
        pelvis_up = _unit(spine[1] - spine[0])
        thorax_up = _unit(spine[-1] - spine[-2])
        pelvis_centre = mid_hip + s * PELVIS_CENTRE_ABOVE_HIPS * pelvis_up
        thorax_centre = mid_shoulder + s * (THORAX_TOP_ABOVE_SHOULDERS - THORAX_SEMI_AXES[2]) * thorax_up
        abdomen_up = _unit(thorax_centre - pelvis_centre)
        abdomen_centre = 0.5 * (pelvis_centre + thorax_centre)
        abdomen_height = max(0.55 * np.linalg.norm(thorax_centre - pelvis_centre), 0.5 * s * PELVIS_SEMI_AXES[2])
        hip_lateral = hip_left - hip_right
        shoulder_lateral = shoulder_left - shoulder_right
        head_up = _unit(joints[self._head_top] - joints[self._head_base])
        head_centre = joints[self._head_top] - s * HEAD_SEMI_AXES[2] * (1.0 - HEAD_TOP_INSIDE) * head_up
        ellipsoids = [
            ("pelvis", pelvis_centre, pelvis_up, hip_lateral, s * np.array(PELVIS_SEMI_AXES)),
            ("abdomen", abdomen_centre, abdomen_up, hip_lateral + shoulder_lateral,
             np.array([s * ABDOMEN_SEMI_AXES[0], s * ABDOMEN_SEMI_AXES[1], abdomen_height])),
            ("thorax", thorax_centre, thorax_up, shoulder_lateral, s * np.array(THORAX_SEMI_AXES)),
            ("head", head_centre, head_up, shoulder_lateral, s * np.array(HEAD_SEMI_AXES)),
        ]
        points, centres = [], []
        for _, centre, up, lateral, semi_axes in ellipsoids:
            lateral = _unit(lateral - (lateral @ up) * up)
            depth = np.cross(up, lateral)
            axes = np.stack((lateral, depth, up)) * semi_axes[:, None]  # rows: semi-axis vectors
            points.append(centre + self._sphere @ axes)
            centres.append(centre)
        return Shapes(np.array(ends), np.array(radii), parts, np.array(points), np.array(centres),
                      [name for name, *_ in ellipsoids])

    def polygons(self, shapes: Shapes, camera) -> tuple[list[np.ndarray], list[str]]:
        """The image outline (n, 2) [px] of every capsule then every ellipsoid, and their parts."""
        count = len(shapes.capsule_parts)
        ends = shapes.capsule_ends.reshape(-1, 3)
        pixels = camera.project(ends).reshape(count, 2, 2)
        radii = camera.pixel_radius(ends, shapes.capsule_radii.reshape(-1)).reshape(count, 2)
        radii = np.maximum(radii - _OUTLINE_BIAS_PX, 0.0)
        angles = np.linspace(0.0, 2.0 * np.pi, _DISC_VERTICES, endpoint=False)
        circle = np.column_stack((np.cos(angles), np.sin(angles)))
        discs = pixels[:, :, None, :] + radii[:, :, None, None] * circle  # (C, 2, n, 2)
        outlines = list(discs.reshape(count, 2 * _DISC_VERTICES, 2))
        samples = shapes.ellipsoid_points
        projected = camera.project(samples.reshape(-1, 3)).reshape(samples.shape[0], samples.shape[1], 2)
        centres = camera.project(shapes.ellipsoid_centres)
        for points, centre in zip(projected, centres, strict=True):
            offset = points - centre
            distance = np.linalg.norm(offset, axis=1, keepdims=True)
            shrink = np.maximum(distance - _OUTLINE_BIAS_PX, 0.0) / np.maximum(distance, 1e-12)
            outlines.append(centre + offset * shrink)
        return outlines, shapes.capsule_parts + shapes.ellipsoid_parts

    def render(self, joints: np.ndarray, camera, parts: Sequence[str] | None = None,
               exclude: Sequence[str] = ()) -> np.ndarray:
        """(H, W) bool silhouette at one frame's joints (J, 3) [m] (only `parts`, without `exclude`)."""
        outlines, names = self.polygons(self.shapes(joints), camera)
        return _fill(camera.size, [outline for outline, name in zip(outlines, names, strict=True)
                                   if (parts is None or name in parts) and name not in exclude])

    def render_frame(self, joints: np.ndarray, camera) -> tuple[np.ndarray, list[np.ndarray]]:
        """The silhouette and, per forearm and shank, the pixels only that limb covers.

        Returns:
            (H, W) bool silhouette; four (H, W) bool limb masks (apply_defects' limb_masks).
        """
        outlines, names = self.polygons(self.shapes(joints), camera)
        losable = [f"{limb}_{side}" for limb in LOSABLE for side in ("left", "right")]
        limbs = [_fill(camera.size, [o for o, n in zip(outlines, names, strict=True) if n == limb])
                 for limb in losable]
        rest = _fill(camera.size, [o for o, n in zip(outlines, names, strict=True) if n not in losable])
        silhouette = rest | np.logical_or.reduce(limbs)
        others = [rest | np.logical_or.reduce([m for j, m in enumerate(limbs) if j != i]) for i in range(len(limbs))]
        return silhouette, [limb & ~other for limb, other in zip(limbs, others, strict=True)]


def _fill(size: tuple[int, int], outlines: Sequence[np.ndarray]) -> np.ndarray:
    width, height = size
    image = np.zeros((height, width), np.uint8)
    for outline in outlines:
        if not np.all(np.isfinite(outline)):
            continue  # a point behind the camera: skipped, as vision.render does
        vertices = np.rint(np.clip(outline, -1e6, 1e6) * (1 << _SHIFT)).astype(np.int32)
        cv2.fillConvexPoly(image, cv2.convexHull(vertices), 1, lineType=cv2.LINE_8, shift=_SHIFT)
    return image.astype(bool)


def draw_preview(masks: Sequence[np.ndarray], cameras: Sequence, joints: np.ndarray, parents: np.ndarray,
                 keypoints: np.ndarray | None = None, tile_height: int = 360) -> np.ndarray:
    """One BGR tile per view, side by side: the silhouette in grey, the mocap skeleton's bones
    projected in green, its joints in red and the keypoints (when given) as blue rings, each tile
    cropped around the subject and resized to `tile_height` px.

    Args:
        joints: (J, 3) [m]; parents: (J,) parent index (-1 for the root); keypoints: (K, 3) [m].
    """
    tiles = []
    for mask, camera in zip(masks, cameras, strict=True):
        pixels = camera.project(joints)
        top = int(pixels[:, 1].min()) - 15
        bottom = int(pixels[:, 1].max()) + 15
        centre = 0.5 * (pixels[:, 0].min() + pixels[:, 0].max())
        zoom = tile_height / (bottom - top)
        half_width = 0.5 * tile_height * 0.75 / zoom
        # Crop by an affine warp: pixel (u, v) -> zoom * (u - left, v - top).
        left = centre - half_width
        warp = np.array([[zoom, 0.0, -zoom * left], [0.0, zoom, -zoom * top]])
        size = (int(round(0.75 * tile_height)), tile_height)
        image = cv2.warpAffine(np.where(mask, np.uint8(150), np.uint8(30)), warp, size,
                               flags=cv2.INTER_NEAREST, borderValue=30)
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        def point(pixel: np.ndarray, warp: np.ndarray = warp) -> tuple[int, int]:
            return tuple(int(v) for v in np.rint(warp[:, :2] @ pixel + warp[:, 2]))

        for child, parent in enumerate(parents):
            if parent >= 0:
                cv2.line(image, point(pixels[parent]), point(pixels[child]), (0, 200, 0), 1, cv2.LINE_AA)
        for pixel in pixels:
            cv2.circle(image, point(pixel), 2, (0, 0, 255), -1)
        if keypoints is not None:
            for pixel in camera.project(keypoints):
                cv2.circle(image, point(pixel), 5, (255, 120, 0), 1, cv2.LINE_AA)
        cv2.putText(image, camera.name, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
        tiles.append(image)
    return np.hstack(tiles)
