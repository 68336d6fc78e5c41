"""Cameras: projection of world points to pixels and its Jacobian.

Conventions (OpenCV's):
- World to camera: ``X_cam = R X_world + t`` with ``R`` (3, 3) and ``t`` (3,) [m].
- Camera frame: x right, y down, z forward (the viewing direction); ``depth`` is ``X_cam[2]`` [m].
- Pixels ``(u, v)`` [px]: u along the image columns, v along the rows; the centre of pixel
  (row i, column j) is at ``u = j, v = i``.

Two camera kinds share the same interface (``project``, ``project_with_jacobian``,
``pixel_radius``): :class:`PinholeCamera`, the calibrated OpenCV model with distortion, and
:class:`OrthographicCamera`, for planar virtual experiments.

This module is long because the pinhole model's distortion and its analytic Jacobian are one derivation
that reads best in one place, beside the orthographic camera that shares its interface.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from typing import NamedTuple, Protocol, Sequence

import cv2
import numpy as np

from ibik_pin.checks import as_finite_array, as_image_size, as_radii
from ibik_pin.exceptions import InputError, UnknownNameError

if sys.version_info >= (3, 11):
    pass
else:  # pragma: no cover - exercised on Python 3.10 only
    pass


_ROTATION_TOLERANCE = 1e-6



class Projection(NamedTuple):
    """Pixels of projected points, with the Jacobian of the projection and the depth.

    Attributes:
        pixels: (N, 2) image coordinates (u, v) [px].
        jacobian: (N, 2, 3) derivative of ``pixels`` with respect to the world point [px/m].
        depth: (N,) z coordinate of the points in the camera frame [m]; a pinhole projection
            is meaningful only where it is positive.
    """

    pixels: np.ndarray
    jacobian: np.ndarray
    depth: np.ndarray


class CameraLike(Protocol):
    """What the image tasks need of a camera; :class:`PinholeCamera` and
    :class:`OrthographicCamera` satisfy it, as may any other projection.

    Attributes:
        name: the camera's name, used in messages and reports.
        size: (width, height) of the image [px].
    """

    @property
    def name(self) -> str: ...

    @property
    def size(self) -> tuple[int, int]: ...

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """(N, 2) pixels (u, v) [px] of (N, 3) world points [m]."""
        ...

    def project_with_jacobian(self, points_world: np.ndarray) -> Projection:
        """Pixels (N, 2) [px], their Jacobian (N, 2, 3) [px/m] and depth (N,) [m] of (N, 3) world points [m]."""
        ...

    def pixel_radius(self, points_world: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """(N,) image radii [px] of spheres centred at (N, 3) world points [m] with radii (N,) [m]."""
        ...



def _read_only(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64, copy=True)
    array.setflags(write=False)
    return array



def _as_points(points_world, name: str = "points_world") -> np.ndarray:
    """(N, 3) float64 view of the points; non-finite values propagate to the result."""
    points = np.asarray(points_world, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"{name}: expected an array of shape (N, 3) [m], found shape {points.shape}")
    return points



def _as_rotation(rotation, name: str = "rotation") -> np.ndarray:
    R = as_finite_array(rotation, (3, 3), name)
    orthonormality_error = np.abs(R @ R.T - np.eye(3)).max()
    if orthonormality_error > _ROTATION_TOLERANCE or np.linalg.det(R) < 0.0:
        raise InputError(
            f"{name}: expected a rotation matrix (orthonormal, determinant +1), found R R^T - I up to "
            f"{orthonormality_error:.3g} and determinant {np.linalg.det(R):.6g}"
        )
    return R



def _rotation_from_rodrigues(rvec, name: str = "rvec") -> np.ndarray:
    vector = as_finite_array(rvec, [(3,), (3, 1), (1, 3)], name).reshape(3, 1)
    R, _ = cv2.Rodrigues(vector)
    return R



class Camera:
    """Common part of the camera kinds: a name, an image size and a world-to-camera placement.

    Subclasses are frozen dataclasses holding ``name``, ``size``, ``rotation`` and ``translation``
    and implement :meth:`project_with_jacobian` and :meth:`pixel_radius`.
    """

    name: str
    size: tuple[int, int]
    rotation: np.ndarray
    translation: np.ndarray

    def _validate_placement(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"name: expected a non-empty string, found {self.name!r}")
        object.__setattr__(self, "size", as_image_size(self.size))
        object.__setattr__(self, "rotation", _read_only(_as_rotation(self.rotation)))
        object.__setattr__(self, "translation", _read_only(as_finite_array(self.translation, (3,), "translation")))

    @property
    def width(self) -> int:
        """Image width [px]."""
        return self.size[0]

    @property
    def height(self) -> int:
        """Image height [px]."""
        return self.size[1]

    @property
    def rvec(self) -> np.ndarray:
        """(3,) Rodrigues vector of the world-to-camera rotation [rad]."""
        vector, _ = cv2.Rodrigues(np.ascontiguousarray(self.rotation))
        return vector.ravel()

    @property
    def center_world(self) -> np.ndarray:
        """(3,) camera centre in the world frame [m]: ``-R^T t``."""
        return -self.rotation.T @ self.translation

    def points_camera(self, points_world: np.ndarray) -> np.ndarray:
        """Points in the camera frame.

        Args:
            points_world: (N, 3) points in the world frame [m].

        Returns:
            (N, 3) ``R X_world + t`` [m].
        """
        return _as_points(points_world) @ self.rotation.T + self.translation

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """Pixels of world points.

        Args:
            points_world: (N, 3) points in the world frame [m].

        Returns:
            (N, 2) pixel coordinates (u, v) [px].
        """
        return self.project_with_jacobian(points_world).pixels

    def project_with_jacobian(self, points_world: np.ndarray) -> Projection:
        """Pixels of world points with the Jacobian of the projection; see :class:`Projection`."""
        raise NotImplementedError

    def pixel_radius(self, points_world: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Radius in the image of small spheres centred at the given points.

        Args:
            points_world: (N, 3) sphere centres in the world frame [m].
            radii: (N,) sphere radii [m], or a scalar.

        Returns:
            (N,) radii in the image [px]; NaN for a point the camera cannot see (behind a
            pinhole camera).
        """
        raise NotImplementedError

    def contains(self, pixels: np.ndarray) -> np.ndarray:
        """(N,) True for pixels (N, 2) [px] within the image, pixel centres from 0 to size - 1."""
        pixels = np.asarray(pixels, dtype=np.float64)
        return (
            (pixels[:, 0] >= 0.0)
            & (pixels[:, 0] <= self.width - 1)
            & (pixels[:, 1] >= 0.0)
            & (pixels[:, 1] <= self.height - 1)
        )

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

    @classmethod
    def from_rodrigues(
        cls,
        name: str,
        size: tuple[int, int],
        intrinsics: np.ndarray,
        distortion: np.ndarray,
        rvec: np.ndarray,
        tvec: np.ndarray,
    ) -> "PinholeCamera":
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
        with np.errstate(divide="ignore"):  # a point on the focal plane goes to infinity
            inverse_depth = 1.0 / depth
        return points_camera[:, 0] * inverse_depth, points_camera[:, 1] * inverse_depth, depth, inverse_depth

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """Pixels of world points (N, 3) [m], distortion included: (N, 2) [px].

        Points behind the camera (depth <= 0) get pixels all the same, as in
        ``cv2.projectPoints``; :meth:`project_with_jacobian` also returns the depth.
        """
        x, y, _, _ = self._normalized(points_world)
        k1, k2, p1, p2, k3 = self._coefficients()
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
        k1, k2, p1, p2, k3 = self._coefficients()
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        radial_slope = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r^2
        xy = x * y
        x_distorted = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x)
        y_distorted = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy
        # d(x_d, y_d) / d(x, y); the two off-diagonal terms are equal.
        dxd_dx = radial + 2.0 * x * x * radial_slope + 2.0 * p1 * y + 6.0 * p2 * x
        dyd_dy = radial + 2.0 * y * y * radial_slope + 6.0 * p1 * y + 2.0 * p2 * x
        cross = 2.0 * xy * radial_slope + 2.0 * p1 * x + 2.0 * p2 * y
        K = self.intrinsics
        fx, fy = K[0, 0], K[1, 1]
        pixels = np.stack((fx * x_distorted + K[0, 2], fy * y_distorted + K[1, 2]), axis=1)
        # d(u, v) / dX_cam, with d(x, y)/dX_cam = [[1, 0, -x], [0, 1, -y]] / Z.
        jacobian_camera = np.empty((depth.shape[0], 2, 3))
        jacobian_camera[:, 0, 0] = fx * dxd_dx * inverse_depth
        jacobian_camera[:, 0, 1] = fx * cross * inverse_depth
        jacobian_camera[:, 0, 2] = -fx * (dxd_dx * x + cross * y) * inverse_depth
        jacobian_camera[:, 1, 0] = fy * cross * inverse_depth
        jacobian_camera[:, 1, 1] = fy * dyd_dy * inverse_depth
        jacobian_camera[:, 1, 2] = -fy * (cross * x + dyd_dy * y) * inverse_depth
        return Projection(pixels, jacobian_camera @ self.rotation, depth)

    def pixel_radius(self, points_world: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Image radius ``focal * r / depth`` [px] of spheres (N, 3) [m] of radii (N,) [m].

        Distortion is ignored (a local scale); NaN where the depth is not positive.
        """
        depth = self.points_camera(points_world)[:, 2]
        radii = as_radii(radii, depth.shape[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(depth > 0.0, self.focal_px * radii / depth, np.nan)



@dataclass(frozen=True, eq=False)
class OrthographicCamera(Camera):
    """An orthographic camera: ``pixels = scale * X_cam[:2] + principal_point``.

    Used for planar virtual experiments; the projection is affine, so its Jacobian
    ``scale * R[:2]`` is the same for every point.

    Attributes:
        name: camera name.
        size: (width, height) of the image [px].
        rotation: R (3, 3), world to camera.
        translation: t (3,) [m], world to camera.
        scale: pixels per metre [px/m].
        principal_point: (2,) pixel of the camera axis [px].
    """

    name: str
    size: tuple[int, int]
    rotation: np.ndarray
    translation: np.ndarray
    scale: float
    principal_point: np.ndarray

    def __post_init__(self) -> None:
        self._validate_placement()
        scale = float(as_finite_array(self.scale, (), "scale"))
        if scale <= 0.0:
            raise InputError(f"scale: expected a positive number of pixels per metre, found {scale}")
        object.__setattr__(self, "scale", scale)
        object.__setattr__(
            self, "principal_point", _read_only(as_finite_array(self.principal_point, (2,), "principal_point"))
        )

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) [px] of world points (N, 3) [m]."""
        return self.scale * self.points_camera(points_world)[:, :2] + self.principal_point

    def project_with_jacobian(self, points_world: np.ndarray) -> Projection:
        """Pixels of world points with the (constant) Jacobian; see :class:`Projection`."""
        points_camera = self.points_camera(points_world)
        count = points_camera.shape[0]
        jacobian = np.repeat((self.scale * self.rotation[:2])[np.newaxis], count, axis=0)
        pixels = self.scale * points_camera[:, :2] + self.principal_point
        return Projection(pixels, jacobian, points_camera[:, 2])

    def pixel_radius(self, points_world: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Image radius ``scale * r`` [px] of spheres (N, 3) [m] of radii (N,) [m]."""
        count = _as_points(points_world).shape[0]
        return self.scale * as_radii(radii, count)



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



def select_cameras(cameras: Sequence[Camera], names: Sequence[str]) -> list[Camera]:
    """The cameras with the given names, in the order of ``names``.

    Raises:
        UnknownNameError: a name is not among the cameras; the message lists the available ones.
        InputError: a name is requested twice.
    """
    by_name = {camera.name: camera for camera in cameras}
    if isinstance(names, str):
        raise InputError(f"names: expected a list of camera names, found the string {names!r}")
    unknown = [name for name in names if name not in by_name]
    if unknown:
        raise UnknownNameError(
            f"names: unknown camera name(s) {unknown}; available cameras: {list(by_name)}"
        )
    repeated = sorted({name for name in names if list(names).count(name) > 1})
    if repeated:
        raise InputError(f"names: expected each camera at most once, found {repeated} more than once")
    return [by_name[name] for name in names]



def cameras_in_frame(cameras: Sequence[Camera], frame_to_world: np.ndarray) -> list[Camera]:
    """The same cameras seeing points expressed in another frame.

    Args:
        cameras: cameras whose extrinsics map calibration-world points.
        frame_to_world: M (3, 3) rotation, world point = M @ point in the new frame (for Pose2Sim
            TRC files, POSE2SIM_TRC_TO_WORLD).

    Returns:
        Cameras with rotation R @ M, so that they project points given in the new frame.
    """
    frame_to_world = _as_rotation(frame_to_world, "frame_to_world")
    return [dataclasses.replace(camera, rotation=camera.rotation @ frame_to_world) for camera in cameras]
