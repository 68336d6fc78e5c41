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
from ibik_pin.vision.kernels import pinhole_parameters, pinhole_pixels_views, pinhole_project, pinhole_project_views

__all__ = ["PinholeCamera", "look_at_camera", "pixel_projector", "projector", "stacked_pinhole_parameters"]


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
    kernel_parameters: np.ndarray = field(init=False, repr=False)

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
        # What the compiled projection reads (vision.kernels.pinhole_project), built once.
        object.__setattr__(self, "kernel_parameters", _read_only(pinhole_parameters(
            self.rotation, self.translation, K, self._coefficients())))

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

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """Pixels of world points (N, 3) [m], distortion included: (N, 2) [px].

        Points behind the camera (depth <= 0) get pixels all the same, as in
        ``cv2.projectPoints``; :meth:`project_with_jacobian` also returns the depth.
        """
        return self.project_with_jacobian(points_world).pixels

    def project_with_jacobian(self, points_world: np.ndarray) -> Projection:
        """Pixels of world points with the analytic Jacobian, distortion included.

        The Jacobian is ``diag(fx, fy) . d(x_d, y_d)/d(x, y) . d(x, y)/dX_cam . R``; the arithmetic is
        :func:`ibik_pin.vision.kernels.pinhole_project`'s.

        Args:
            points_world: (N, 3) points in the world frame [m].

        Returns:
            :class:`Projection` with pixels (N, 2) [px], jacobian (N, 2, 3) [px/m], depth (N,) [m].
        """
        points = np.ascontiguousarray(_as_points(points_world), dtype=np.float64)
        count = points.shape[0]
        projection = Projection(np.empty((count, 2)), np.empty((count, 2, 3)), np.empty(count))
        pinhole_project(points, self.kernel_parameters, *projection)
        return projection

    def pixel_radius(self, points_world: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Image radius ``focal * r / depth`` [px] of spheres (N, 3) [m] of radii (N,) [m].

        Distortion is ignored (a local scale); NaN where the depth is not positive.
        """
        depth = self.points_camera(points_world)[:, 2]
        radii = as_radii(radii, depth.shape[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(depth > 0.0, self.focal_px * radii / depth, np.nan)


def stacked_pinhole_parameters(cameras: list[CameraLike]) -> np.ndarray | None:
    """The cameras' kernel parameters (V, 21) when all are pinhole cameras (one compiled call
    projects them all), else None (each camera projects itself)."""
    if not cameras or not all(isinstance(camera, PinholeCamera) for camera in cameras):
        return None
    return np.array([cast(PinholeCamera, camera).kernel_parameters for camera in cameras])


def projector(cameras: Sequence[CameraLike]) -> Callable[[np.ndarray], list[Projection]]:
    """points (N, 3) -> each camera's project_with_jacobian; pinhole cameras all in one compiled
    call (the same arithmetic: a view's projection is a few microseconds of wrapper, a solver step
    projects every view twice)."""
    cameras = list(cameras)
    parameters = stacked_pinhole_parameters(cameras)
    if parameters is None:
        return lambda points: [camera.project_with_jacobian(points) for camera in cameras]

    def project(points: np.ndarray) -> list[Projection]:
        points = np.ascontiguousarray(_as_points(points), dtype=np.float64)
        views, count = len(parameters), points.shape[0]
        pixels, jacobian, depth = np.empty((views, count, 2)), np.empty((views, count, 2, 3)), np.empty((views, count))
        pinhole_project_views(points, parameters, pixels, jacobian, depth)
        return [Projection(pixels[view], jacobian[view], depth[view]) for view in range(views)]

    return project


def pixel_projector(cameras: Sequence[CameraLike]) -> Callable[[np.ndarray], list[tuple[np.ndarray, np.ndarray]]]:
    """points (N, 3) -> each camera's pixels (N, 2) and depth (N,), without the Jacobian: what a
    reading of values needs (pinhole cameras all in one compiled call, as `projector`)."""
    cameras = list(cameras)
    parameters = stacked_pinhole_parameters(cameras)
    if parameters is None:
        return lambda points: [(projection.pixels, projection.depth) for projection in
                               (camera.project_with_jacobian(points) for camera in cameras)]

    def project(points: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        points = np.ascontiguousarray(_as_points(points), dtype=np.float64)
        views, count = len(parameters), points.shape[0]
        pixels, depth = np.empty((views, count, 2)), np.empty((views, count))
        pinhole_pixels_views(points, parameters, pixels, depth)
        return [(pixels[view], depth[view]) for view in range(views)]

    return project


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
