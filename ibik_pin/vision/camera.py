"""Cameras: projection of world points to pixels and its Jacobian.

Conventions (OpenCV's):
- World to camera: ``X_cam = R X_world + t`` with ``R`` (3, 3) and ``t`` (3,) [m].
- Camera frame: x right, y down, z forward (the viewing direction); ``depth`` is ``X_cam[2]`` [m].
- Pixels ``(u, v)`` [px]: u along the image columns, v along the rows; the centre of pixel
  (row i, column j) is at ``u = j, v = i``.

Two camera kinds share the same interface (``project``, ``project_with_jacobian``,
``pixel_radius``, :class:`CameraLike`): :class:`~ibik_pin.vision.pinhole.PinholeCamera`, the
calibrated OpenCV model with distortion (and :func:`~ibik_pin.vision.pinhole.look_at_camera`), in
:mod:`ibik_pin.vision.pinhole`; and :class:`OrthographicCamera`, for planar virtual experiments,
here with their common base :class:`Camera` and the helpers that select cameras or move them to
another frame.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, Protocol

import cv2
import numpy as np

from ibik_pin.checks import as_finite_array, as_image_size, as_radii
from ibik_pin.exceptions import InputError, UnknownNameError

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
    try:
        points = np.asarray(points_world, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise InputError(f"{name}: expected an array of shape (N, 3) [m], found {type(points_world).__name__} "
                         f"({error})", parameter=name) from None
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
    # Declared, not assigned: every camera kind is a dataclass (dataclasses.replace applies to it,
    # see cameras_in_frame), and this annotation says so to the type checker.
    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]

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


def select_cameras(cameras: Sequence[Camera], names: Sequence[str]) -> list[Camera]:
    """The cameras with the given names, in the order of ``names``.

    Raises:
        UnknownNameError: a name is not among the cameras; the message lists the available ones.
        InputError: a name is requested twice.
    """
    if isinstance(cameras, (str, bytes)) or not all(hasattr(camera, "name") for camera in cameras):
        raise InputError(f"cameras: expected a list of cameras (ibik_pin.vision), found {cameras!r:.60}",
                         parameter="cameras")
    by_name = {camera.name: camera for camera in cameras}
    if isinstance(names, str):
        raise InputError(f"names: expected a list of camera names, found the string {names!r}", parameter="names")
    unknown = [name for name in names if name not in by_name]
    if unknown:
        raise UnknownNameError(f"names: unknown camera name(s) {unknown}; the calibration has {list(by_name)}",
                               parameter="names")
    repeated = sorted({name for name in names if list(names).count(name) > 1})
    if repeated:
        raise InputError(f"names: expected each camera at most once, found {repeated} more than once",
                         parameter="names")
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
