"""The paper's planar 4-segment chain seen by an orthographic camera (Section 3, Figs. 6-8).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.model import BodyModel, load_planar_chain
from ibik_pin.vision.camera import OrthographicCamera
from ibik_pin.vision.render import render_capsules
from ibik_pin.vision.support import SupportImage, obstacle_support, support_from_mask

__all__ = [
    "CHAIN_LENGTH",
    "IMAGE_SIZE",
    "PIXELS_PER_METRE",
    "PlanarScene",
    "make_scene",
    "planar_camera",
    "render_chain",
    "square_mask",
]

IMAGE_SIZE = (400, 400)  # [px]


PIXELS_PER_METRE = 150.0


CHAIN_LENGTH = 1.0  # [m], 4 segments of 0.25 m


def planar_camera() -> OrthographicCamera:
    """Looks down the world Z axis at the chain's plane; world +Y is image up."""
    return OrthographicCamera(
        name="virtual",
        size=IMAGE_SIZE,
        rotation=np.diag([1.0, -1.0, -1.0]),
        translation=np.array([0.0, 0.0, 5.0]),
        scale=PIXELS_PER_METRE,
        principal_point=np.array([IMAGE_SIZE[0] / 2, IMAGE_SIZE[1] / 2]),
    )


@dataclass
class PlanarScene:
    """The chain, its camera, the objective and the support image the criterion reads.

    Attributes:
        body: the planar chain.
        camera: the orthographic camera.
        objective_q: the configuration whose silhouette is the image, shape (4,) [rad].
        silhouette: the objective's rendered silhouette (H, W), or None (fig8: no silhouette).
        object_mask: the square object (H, W), or None.
        support: the support image.
    """

    body: BodyModel
    camera: OrthographicCamera
    objective_q: np.ndarray
    silhouette: np.ndarray | None
    object_mask: np.ndarray | None
    support: SupportImage

    def keypoint_positions(self, q: np.ndarray) -> np.ndarray:
        """World positions [m] of joint_1..joint_4 and the end effector, shape (5, 3)."""
        configuration = Configuration(self.body.model, q)
        return configuration.frame_positions(self.body.frame_ids(list(self.body.keypoints)))


def render_chain(body: BodyModel, camera, q: np.ndarray) -> np.ndarray:
    """Silhouette (H, W) bool of the chain at q, capsules of the body's segment radii."""
    configuration = Configuration(body.model, q)
    ends = configuration.frame_positions(body.segment_frame_ids.reshape(-1)).reshape(-1, 2, 3)
    return render_capsules(camera, ends[:, 0], ends[:, 1], body.segment_radii)


def square_mask(center_world: np.ndarray, half_side: float, camera) -> np.ndarray:
    """A filled square (H, W) bool centred on a world point of the plane, half side [m]."""
    width, height = camera.size
    corners = camera.project(
        np.array([center_world + [sx * half_side, sy * half_side, 0.0] for sx in (-1, 1) for sy in (-1, 1)])
    )
    u0, v0 = np.floor(corners.min(axis=0)).astype(int)
    u1, v1 = np.ceil(corners.max(axis=0)).astype(int)
    mask = np.zeros((height, width), dtype=bool)
    mask[max(v0, 0) : max(v1, 0), max(u0, 0) : max(u1, 0)] = True
    return mask


def make_scene(
    objective_q: np.ndarray,
    with_silhouette: bool = True,
    obstacle_center: np.ndarray | None = None,
    obstacle_half_side: float = 0.08,
    obstacle_influence_px: float = 25.0,
    inside_cap_px: float = 3.0,
) -> PlanarScene:
    """Build a planar scene; the support is the silhouette's signed distance plus the obstacle's
    repulsion (either may be absent)."""
    body = load_planar_chain()
    camera = planar_camera()
    objective_q = np.asarray(objective_q, dtype=float)
    width, height = camera.size
    support = SupportImage(np.zeros((height, width), dtype=np.float32))
    silhouette = None
    if with_silhouette:
        silhouette = render_chain(body, camera, objective_q)
        support = support_from_mask(silhouette, inside_cap_px=inside_cap_px, smooth_sigma_px=1.0)
    object_mask = None
    if obstacle_center is not None:
        object_mask = square_mask(np.asarray(obstacle_center, dtype=float), obstacle_half_side, camera)
        support = support + obstacle_support(object_mask, obstacle_influence_px)
    return PlanarScene(body, camera, objective_q, silhouette, object_mask, support)
