"""The calibrated pinhole camera with OpenCV's distortion model, and look-at pinhole cameras.

The projection and its analytic Jacobian, distortion included, are one derivation kept in one
place; the conventions and the interface it shares with the orthographic camera are in
:mod:`ibik_pin.vision.camera`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from ibik_pin.checks import as_finite_array, as_image_size, as_radii
from ibik_pin.exceptions import InputError
from ibik_pin.vision.camera import Camera, CameraLike, Projection, _as_points, _read_only, _rotation_from_rodrigues

__all__ = ["PinholeCamera", "PinholeViews", "look_at_camera", "projector"]


@dataclass(frozen=True, eq=False)
class PinholeCamera(Camera):
    """A calibrated pinhole camera with OpenCV's distortion model (k1, k2, p1, p2[, k3]).

    With ``(x, y) = (X_cam / Z_cam, Y_cam / Z_cam)``, ``r^2 = x^2 + y^2``:
    ``x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)``,
    ``y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y``,
    ``(u, v, 1) = K (x_d, y_d, 1)``; this is ``cv2.projectPoints``. K has zero skew, as in
    OpenCV's model.

    Attributes:
        name: camera name (unique within a calibration).
        size: (width, height) of the image [px].
        intrinsics: K (3, 3) [px], last row (0, 0, 1).
        distortion: (4,) or (5,) OpenCV coefficients (k1, k2, p1, p2[, k3]).
        rotation: R (3, 3), world to camera.
        translation: t (3,) [m], world to camera.
    """

    name: str
    size: tuple[int, int]
    intrinsics: np.ndarray
    distortion: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    _distortion_terms: tuple[float, float, float, float, float] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._validate_placement()
        K = as_finite_array(self.intrinsics, (3, 3), "intrinsics")
        if not np.array_equal(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0.0 or K[0, 0] <= 0.0 or K[1, 1] <= 0.0:
            raise InputError(
                "intrinsics: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, "
                f"found {K.tolist()}"
            )
        if K[0, 1] != 0.0:
            raise InputError(f"intrinsics: expected zero skew K[0, 1] (OpenCV's model), found {K[0, 1]}")
        object.__setattr__(self, "intrinsics", _read_only(K))
        object.__setattr__(self, "distortion", _read_only(as_finite_array(self.distortion, [(4,), (5,)], "distortion")))
        # The coefficients as Python floats, read at every projection (the same products as numpy's scalars).
        object.__setattr__(self, "_distortion_terms", tuple(float(term) for term in self._coefficients()))

    @classmethod
    def from_rodrigues(
        cls,
        name: str,
        size: tuple[int, int],
        intrinsics: np.ndarray,
        distortion: np.ndarray,
        rvec: np.ndarray,
        tvec: np.ndarray,
    ) -> PinholeCamera:
        """A camera from OpenCV's extrinsics: ``rvec`` (3,) Rodrigues vector [rad] and ``tvec`` (3,) [m]."""
        return cls(name, size, intrinsics, distortion, _rotation_from_rodrigues(rvec), tvec)

    @property
    def focal_px(self) -> float:
        """Mean of the focal lengths fx and fy [px]."""
        return 0.5 * (self.intrinsics[0, 0] + self.intrinsics[1, 1])

    def _coefficients(self) -> tuple[float, float, float, float, float]:
        k1, k2, p1, p2 = self.distortion[:4]
        k3 = self.distortion[4] if self.distortion.shape[0] == 5 else 0.0
        return k1, k2, p1, p2, k3

    def _normalized(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Normalised coordinates x = X/Z, y = Y/Z, depth Z [m] and 1/Z of world points (N, 3)."""
        points_camera = self.points_camera(points_world)
        depth = points_camera[:, 2]
        inverse_depth = _inverse(depth)
        return points_camera[:, 0] * inverse_depth, points_camera[:, 1] * inverse_depth, depth, inverse_depth

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """Pixels of world points (N, 3) [m], distortion included: (N, 2) [px].

        Points behind the camera (depth <= 0) get pixels all the same, as in
        ``cv2.projectPoints``; :meth:`project_with_jacobian` also returns the depth.
        """
        x, y, _, _ = self._normalized(points_world)
        k1, k2, p1, p2, k3 = self._distortion_terms
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xy = x * y
        x_distorted = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x)
        y_distorted = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy
        K = self.intrinsics
        return np.stack((K[0, 0] * x_distorted + K[0, 2], K[1, 1] * y_distorted + K[1, 2]), axis=1)

    def project_with_jacobian(self, points_world: np.ndarray) -> Projection:
        """Pixels of world points with the analytic Jacobian, distortion included.

        The Jacobian is ``diag(fx, fy) . d(x_d, y_d)/d(x, y) . d(x, y)/dX_cam . R``.

        Args:
            points_world: (N, 3) points in the world frame [m].

        Returns:
            :class:`Projection` with pixels (N, 2) [px], jacobian (N, 2, 3) [px/m], depth (N,) [m].
        """
        x, y, depth, inverse_depth = self._normalized(points_world)
        K = self.intrinsics
        return _distorted_projection(x, y, depth, inverse_depth, self._distortion_terms, K[0, 0], K[1, 1], K[:2, 2],
                                     self.rotation)

    def pixel_radius(self, points_world: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Image radius ``focal * r / depth`` [px] of spheres (N, 3) [m] of radii (N,) [m].

        Distortion is ignored (a local scale); NaN where the depth is not positive.
        """
        depth = self.points_camera(points_world)[:, 2]
        radii = as_radii(radii, depth.shape[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(depth > 0.0, self.focal_px * radii / depth, np.nan)


class PinholeViews:
    """Pinhole cameras that project the same points together: PinholeCamera.project_with_jacobian's
    arithmetic (_distorted_projection) on arrays with the views in front, so that every view's
    values are its camera's to the bit at the numpy overhead of one camera (a step of the image
    level projects the same points in every view).
    """

    def __init__(self, cameras: Sequence[PinholeCamera]) -> None:
        self.cameras = list(cameras)
        self._rotations_t = np.stack([camera.rotation for camera in self.cameras]).transpose(0, 2, 1)
        self._rotations = self._rotations_t.transpose(0, 2, 1)
        self._translations = np.stack([camera.translation for camera in self.cameras])[:, None]  # (V, 1, 3)
        terms = np.array([camera._distortion_terms for camera in self.cameras])  # (V, 5)
        self._terms = tuple(terms[:, [index]] for index in range(5))  # k1, k2, p1, p2, k3, each (V, 1)
        self._fx = np.array([[camera.intrinsics[0, 0]] for camera in self.cameras])
        self._fy = np.array([[camera.intrinsics[1, 1]] for camera in self.cameras])
        self._centres = np.stack([camera.intrinsics[:2, 2] for camera in self.cameras])[:, None]  # (V, 1, 2)

    def project_with_jacobian(self, points_world: np.ndarray) -> list[Projection]:
        """Each camera's :meth:`PinholeCamera.project_with_jacobian` of the points (N, 3)."""
        points_camera = _as_points(points_world) @ self._rotations_t + self._translations  # (V, N, 3)
        depth = points_camera[..., 2]
        inverse_depth = _inverse(depth)
        x, y = points_camera[..., 0] * inverse_depth, points_camera[..., 1] * inverse_depth
        pixels, jacobian, depth = _distorted_projection(x, y, depth, inverse_depth, self._terms, self._fx, self._fy,
                                                        self._centres, self._rotations)
        return [Projection(pixels[index], jacobian[index], depth[index]) for index in range(len(self.cameras))]


def _inverse(depth: np.ndarray) -> np.ndarray:
    """1 / depth; a point on the focal plane goes to infinity (without numpy's warning, whose
    errstate costs more than the division when no depth is zero)."""
    if depth.all():
        return 1.0 / depth
    with np.errstate(divide="ignore"):
        return 1.0 / depth


def _distorted_projection(x, y, depth, inverse_depth, terms, fx, fy, centre, rotation) -> Projection:
    """Pixels, their world Jacobian and the depth from normalised coordinates x, y (shape S: (N,) for
    one camera, (V, N) for views), OpenCV's distortion `terms` (k1, k2, p1, p2, k3), the focal
    lengths and principal point [px] and the world-to-camera rotation (scalars and (3, 3) for one
    camera, arrays with the views in front for several)."""
    k1, k2, p1, p2, k3 = terms
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    radial_slope = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r^2
    xy = x * y
    two_x_x, two_y_y = 2.0 * x * x, 2.0 * y * y  # each shared by a distorted coordinate and its slope
    x_distorted = x * radial + 2.0 * p1 * xy + p2 * (r2 + two_x_x)
    y_distorted = y * radial + p1 * (r2 + two_y_y) + 2.0 * p2 * xy
    # d(x_d, y_d) / d(x, y); the two off-diagonal terms are equal.
    dxd_dx = radial + two_x_x * radial_slope + 2.0 * p1 * y + 6.0 * p2 * x
    dyd_dy = radial + two_y_y * radial_slope + 6.0 * p1 * y + 2.0 * p2 * x
    cross = 2.0 * xy * radial_slope + 2.0 * p1 * x + 2.0 * p2 * y
    pixels = np.empty(depth.shape + (2,))
    np.multiply(fx, x_distorted, out=pixels[..., 0])
    np.multiply(fy, y_distorted, out=pixels[..., 1])
    pixels += centre
    # d(u, v) / dX_cam, with d(x, y)/dX_cam = [[1, 0, -x], [0, 1, -y]] / Z; one (2N, 3) @ (3, 3)
    # product per camera then takes it to the world.
    jacobian_camera = np.empty(depth.shape + (2, 3))
    jacobian_camera[..., 0, 0] = fx * dxd_dx * inverse_depth
    jacobian_camera[..., 0, 1] = fx * cross * inverse_depth
    jacobian_camera[..., 0, 2] = -fx * (dxd_dx * x + cross * y) * inverse_depth
    jacobian_camera[..., 1, 0] = fy * cross * inverse_depth
    jacobian_camera[..., 1, 1] = fy * dyd_dy * inverse_depth
    jacobian_camera[..., 1, 2] = -fy * (cross * x + dyd_dy * y) * inverse_depth
    jacobian = (jacobian_camera.reshape(depth.shape[:-1] + (-1, 3)) @ rotation).reshape(depth.shape + (2, 3))
    return Projection(pixels, jacobian, depth)


def projector(cameras: Sequence[CameraLike]) -> Callable[[np.ndarray], list[Projection]]:
    """points (N, 3) -> each camera's project_with_jacobian: together when all are pinholes."""
    cameras = list(cameras)
    if cameras and all(isinstance(camera, PinholeCamera) for camera in cameras):
        return PinholeViews(cast(list[PinholeCamera], cameras)).project_with_jacobian
    return lambda points: [camera.project_with_jacobian(points) for camera in cameras]


def look_at_camera(
    name: str,
    size: tuple[int, int],
    focal_px: float,
    eye: np.ndarray,
    target: np.ndarray,
    up: np.ndarray,
) -> PinholeCamera:
    """A distortion-free pinhole camera at ``eye`` looking at ``target``.

    The principal point is the image centre ((width - 1) / 2, (height - 1) / 2); image rows go
    down, against ``up``.

    Args:
        name: camera name.
        size: (width, height) [px].
        focal_px: focal length [px].
        eye: (3,) camera centre in the world [m].
        target: (3,) world point seen at the image centre [m].
        up: (3,) world direction that appears upward in the image.

    Returns:
        The camera.
    """
    width, height = as_image_size(size)
    focal = float(as_finite_array(focal_px, (), "focal_px"))
    if focal <= 0.0:
        raise InputError(f"focal_px: expected a positive focal length [px], found {focal}")
    eye = as_finite_array(eye, (3,), "eye")
    forward = as_finite_array(target, (3,), "target") - eye
    if np.linalg.norm(forward) == 0.0:
        raise InputError(f"target: expected a point different from eye, found {forward + eye} for both")
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, as_finite_array(up, (3,), "up"))
    if np.linalg.norm(right) < 1e-9:
        raise InputError(f"up: expected a direction not parallel to the viewing direction {forward}, found {up}")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.stack((right, down, forward))
    intrinsics = np.array([[focal, 0.0, 0.5 * (width - 1)], [0.0, focal, 0.5 * (height - 1)], [0.0, 0.0, 1.0]])
    return PinholeCamera(name, (width, height), intrinsics, np.zeros(5), rotation, -rotation @ eye)
