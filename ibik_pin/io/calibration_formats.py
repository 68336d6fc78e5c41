"""Calibrations of other motion-capture systems, read into pinhole cameras as Pose2Sim converts them.

- **Qualisys** ``.qca.txt`` (XML; the calibration Pose2Sim's demos ship): the video cameras (model
  "video", "hybrid" or "none"), sorted by name in natural order. Image size from ``fov_video``;
  focal lengths, principal point and distortion coefficients in QTM's 1/64-pixel units, divided
  by 64, the principal point shifted by the video window's corner; ``transform`` holds the
  camera's position [mm] and rotation in the world, and its camera looks along -Z: turned by pi
  about its X axis, it becomes OpenCV's world-to-camera rotation and translation. These are the
  steps of Pose2Sim's ``calib_qca_fun`` (Pose2Sim/calibration.py), so the cameras equal those of
  the TOML that Pose2Sim converts from the same file.
- **EasyMocap** ``intri.yml`` + ``extri.yml`` (OpenCV FileStorage YAML, beside each other): per
  camera of ``names``, ``K_<name>`` and ``dist_<name>`` (k1, k2, p1, p2[, k3]), ``R_<name>``
  (Rodrigues, world to camera) and ``T_<name>`` [m]; the image size from ``H_<name>``,
  ``W_<name>`` where written, else twice the principal point (as Pose2Sim does), with a warning.
"""

from __future__ import annotations

import re
import warnings
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import cv2
import numpy as np

from ibik_pin.exceptions import FileFormatError, IbikWarning, InputError
from ibik_pin.vision.pinhole import PinholeCamera

__all__ = ["read_easymocap", "read_qualisys"]

# QTM writes intrinsics in 1/64 of a pixel.
_QUALISYS_SUBPIXELS = 64.0
_QUALISYS_VIDEO_MODELS = ("video", "hybrid", "none")
# Qualisys' camera looks along its -Z axis, OpenCV's along +Z: pi about X turns one into the other.
_FLIP_X = np.diag([1.0, -1.0, -1.0])


def _natural_key(name: str) -> list:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def _float(path: Path, element: ElementTree.Element, key: str, where: str) -> float:
    text = element.get(key)
    try:
        value = float(text) if text is not None else float("nan")
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise FileFormatError(f"calibration file '{path}', {where}: attribute {key}: expected a finite number, "
                              f"found {text!r}")
    return value


def read_qualisys(path: Path, text: str) -> list[PinholeCamera]:
    """The video cameras of a Qualisys .qca.txt calibration (module docstring).

    Raises:
        FileFormatError: not the XML of a Qualisys calibration, no video camera, or an attribute
            missing or not a number (named with its camera).
    """
    try:
        root = ElementTree.fromstring(text.encode("utf-8") if text.lstrip().startswith("<?xml") else text)
    except ElementTree.ParseError as error:
        raise FileFormatError(f"calibration file '{path}': expected Qualisys XML, {error}") from None
    cameras = []
    for element in root.findall("cameras/camera"):
        name = element.get("serial") or ""
        if not any(model in (element.get("model") or "").lower() for model in _QUALISYS_VIDEO_MODELS):
            continue
        where = f"camera {name!r}"
        window, intrinsic, transform = (element.find(tag) for tag in ("fov_video", "intrinsic", "transform"))
        if window is None or intrinsic is None or transform is None or not name:
            raise FileFormatError(f"calibration file '{path}', {where}: expected a serial, <fov_video>, "
                                  "<intrinsic> and <transform>")

        def number(node: ElementTree.Element, key: str, where: str = where) -> float:
            return _float(path, node, key, where)

        left, top = number(window, "left"), number(window, "top")
        size = (int(round(number(window, "right") - left + 1)), int(round(number(window, "bottom") - top + 1)))
        intrinsics = np.array([
            [number(intrinsic, "focalLengthU") / _QUALISYS_SUBPIXELS, 0.0,
             number(intrinsic, "centerPointU") / _QUALISYS_SUBPIXELS - left],
            [0.0, number(intrinsic, "focalLengthV") / _QUALISYS_SUBPIXELS,
             number(intrinsic, "centerPointV") / _QUALISYS_SUBPIXELS - top],
            [0.0, 0.0, 1.0]])
        distortion = np.array([number(intrinsic, key) for key in ("radialDistortion1", "radialDistortion2",
                                                                  "tangentalDistortion1", "tangentalDistortion2")])
        distortion /= _QUALISYS_SUBPIXELS
        world_to_qualisys = np.array([[number(transform, f"r{row}{column}") for column in (1, 2, 3)]
                                      for row in (1, 2, 3)])
        position_m = np.array([number(transform, axis) for axis in ("x", "y", "z")]) / 1000.0
        rotation = _FLIP_X @ world_to_qualisys
        try:
            cameras.append(PinholeCamera(name, size, intrinsics, distortion, rotation, -rotation @ position_m))
        except InputError as error:
            raise FileFormatError(f"calibration file '{path}', {where}: {error}") from None
    if not cameras:
        raise FileFormatError(f"calibration file '{path}': expected Qualisys video cameras (model video, hybrid "
                              "or none), found none")
    return sorted(cameras, key=lambda camera: _natural_key(camera.name))


def _easymocap_pair(path: Path) -> tuple[Path, Path]:
    """intri.yml and extri.yml of the folder `path` is in (or is)."""
    folder = path if path.is_dir() else path.parent
    pair = folder / "intri.yml", folder / "extri.yml"
    missing = [candidate.name for candidate in pair if not candidate.is_file()]
    if missing:
        raise FileFormatError(f"calibration '{path}': an EasyMocap calibration is intri.yml and extri.yml side by "
                              f"side; {' and '.join(missing)} is missing from '{folder}'")
    return pair


def _matrix(storage: cv2.FileStorage, path: Path, key: str, sizes: tuple[int, ...]) -> np.ndarray:
    node = storage.getNode(key)
    value = None if node.empty() else node.mat()
    if value is None or value.size not in sizes or not np.all(np.isfinite(value)):
        raise FileFormatError(f"calibration file '{path}': key {key}: expected a matrix of "
                              f"{' or '.join(map(str, sizes))} finite numbers, found "
                              + ("none" if value is None else f"{value.size} values"))
    return value.astype(float)


def _names(storage: cv2.FileStorage, path: Path) -> list[str]:
    node = storage.getNode("names")
    names = [node.at(index).string() for index in range(node.size())] if node.isSeq() else []
    if not names or not all(names):
        raise FileFormatError(f"calibration file '{path}': expected a 'names' list of cameras, found none")
    return names


def read_easymocap(path: Path) -> list[PinholeCamera]:
    """The cameras of an EasyMocap calibration: intri.yml and extri.yml beside `path` (module docstring).

    Raises:
        FileFormatError: one of the files is missing, a camera lacks a key, or a value is not finite.
    """
    intri_path, extri_path = _easymocap_pair(path)
    intri = cv2.FileStorage(str(intri_path), cv2.FILE_STORAGE_READ)
    extri = cv2.FileStorage(str(extri_path), cv2.FILE_STORAGE_READ)
    if not intri.isOpened() or not extri.isOpened():
        raise FileFormatError(f"calibration '{path}': OpenCV cannot read intri.yml or extri.yml as YAML")
    try:
        cameras = []
        for name in _names(intri, intri_path):
            intrinsics = _matrix(intri, intri_path, f"K_{name}", (9,)).reshape(3, 3)
            distortion = _matrix(intri, intri_path, f"dist_{name}", (4, 5)).ravel()
            rvec = _matrix(extri, extri_path, f"R_{name}", (3,)).ravel()
            tvec = _matrix(extri, extri_path, f"T_{name}", (3,)).ravel()
            height, width = (intri.getNode(f"{key}_{name}") for key in ("H", "W"))
            if not height.empty() and not width.empty():
                size = (int(width.real()), int(height.real()))
            else:
                size = (int(round(2 * intrinsics[0, 2])), int(round(2 * intrinsics[1, 2])))
                warnings.warn(f"calibration file '{intri_path}': camera {name!r} has no H_{name}, W_{name}; its "
                              f"image size is taken as twice its principal point, {size[0]} x {size[1]} px",
                              IbikWarning, stacklevel=2)
            try:
                cameras.append(PinholeCamera.from_rodrigues(name, size, intrinsics, distortion, rvec, tvec))
            except InputError as error:
                raise FileFormatError(f"calibration '{path}', camera {name!r}: {error}") from None
        return cameras
    finally:
        intri.release()
        extri.release()
