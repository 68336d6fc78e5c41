"""Calibration files: read calibrated pinhole cameras, write Pose2Sim's TOML.

Pose2Sim's TOML (also Anipose's, whose layout Pose2Sim took): one section per camera with the keys
``name``, ``size`` = [width, height], ``matrix`` (3 x 3), ``distortions`` (k1, k2, p1, p2[, k3]),
``rotation`` (Rodrigues vector, world to camera), ``translation`` [m] and ``fisheye``. Pose2Sim's
world is Z-up; its TRC files are Y-up. `read_calibration` also reads, recognised by content, the
formats of :mod:`ibik_pin.io.calibration_formats` (Qualisys .qca.txt, EasyMocap intri.yml +
extri.yml).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import tomli_w

from ibik_pin.checks import as_finite_array, as_image_size
from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.calibration_formats import read_easymocap, read_qualisys
from ibik_pin.io.files import PathLike, as_path, read_text, write_text_atomically
from ibik_pin.vision.pinhole import PinholeCamera

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = ["CALIBRATION_FORMATS", "POSE2SIM_TRC_TO_WORLD", "read_calibration", "write_calibration"]

#: The calibration formats `read_calibration` recognises, as named in its errors.
CALIBRATION_FORMATS = ("Pose2Sim or Anipose TOML", "Qualisys .qca.txt", "EasyMocap intri.yml + extri.yml")

# Pose2Sim sections that do not describe a camera.
_NON_CAMERA_SECTIONS = frozenset({"metadata", "capture_volume", "charuco", "checkerboard"})


def read_calibration(path: PathLike) -> list[PinholeCamera]:
    """Cameras from a calibration file, its format recognised by its content (CALIBRATION_FORMATS).

    Qualisys' XML and EasyMocap's YAML (`path` one of its two files, or their folder) are read as
    :mod:`ibik_pin.io.calibration_formats` says. In a TOML file (Pose2Sim, Anipose), cameras come
    in file order: every top-level table except Pose2Sim's non-camera sections (``metadata``,
    ``capture_volume``, ``charuco``, ``checkerboard``) is a camera with the keys ``name``,
    ``size`` [w, h], ``matrix`` (3 x 3), ``distortions`` (4 values k1, k2, p1, p2, or 5 with
    k3), ``rotation`` (Rodrigues, world to camera), ``translation`` [m] and optionally
    ``fisheye`` (absent means false).

    Args:
        path: the TOML file.

    Returns:
        The cameras.

    Raises:
        FileFormatError: the file cannot be read or parsed, a key is missing, a value has the
            wrong shape or is not finite, ``fisheye = true`` (not supported), two cameras share
            a name, or no camera section; the message names the file, section and key.
    """
    path = as_path(path)
    if path.is_dir():
        return read_easymocap(path)
    text = read_text(path, "calibration")  # a byte-order mark, which tomllib refuses, is dropped
    head = text.lstrip()[:4096]
    if head.startswith("<") and "<cameras" in head:
        return read_qualisys(path, text)
    if head.startswith("%YAML"):
        return read_easymocap(path)
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise FileFormatError(
            f"calibration file '{path}': expected valid TOML (or one of the other formats read: "
            f"{', '.join(CALIBRATION_FORMATS[1:])}), found a syntax error: {error}"
        ) from None

    cameras: list[PinholeCamera] = []
    for section, table in document.items():
        if section in _NON_CAMERA_SECTIONS or not isinstance(table, dict):
            continue
        cameras.append(_camera_from_section(path, section, table))
    if not cameras:
        raise FileFormatError(
            f"calibration file '{path}': expected at least one camera section, found sections {list(document)}"
        )
    names = [camera.name for camera in cameras]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise FileFormatError(
            f"calibration file '{path}': key 'name': expected unique camera names, found {repeated} repeated"
        )
    return cameras


def _camera_from_section(path: Path, section: str, table: dict) -> PinholeCamera:
    where = f"calibration file '{path}', section [{section}]"

    def value(key: str, shapes, description: str) -> np.ndarray:
        if key not in table:
            raise FileFormatError(f"{where}: missing key '{key}' ({description}); found keys {sorted(table)}")
        try:
            return as_finite_array(table[key], shapes, key)
        except InputError as error:
            raise FileFormatError(f"{where}, key '{key}' ({description}): {_detail(error)}") from None

    if "name" not in table:
        raise FileFormatError(f"{where}: missing key 'name' (camera name); found keys {sorted(table)}")
    name = table["name"]
    if not isinstance(name, str) or not name:
        raise FileFormatError(f"{where}, key 'name': expected a non-empty string, found {name!r}")
    fisheye = table.get("fisheye", False)
    if not isinstance(fisheye, bool):
        raise FileFormatError(f"{where}, key 'fisheye': expected true or false, found {fisheye!r}")
    if fisheye:
        raise FileFormatError(
            f"{where}, key 'fisheye': fisheye = true is not supported; expected false "
            "(OpenCV pinhole model with k1, k2, p1, p2[, k3] distortion)"
        )
    size = value("size", (2,), "[width, height] in pixels")
    intrinsics = value("matrix", (3, 3), "3 x 3 intrinsic matrix")
    distortion = value("distortions", [(4,), (5,)], "k1, k2, p1, p2[, k3]")
    rvec = value("rotation", (3,), "Rodrigues vector, world to camera")
    tvec = value("translation", (3,), "world to camera [m]")
    try:
        size_px = as_image_size(size.tolist())
    except InputError as error:
        raise FileFormatError(f"{where}, key 'size': {_detail(error)}") from None
    try:
        return PinholeCamera.from_rodrigues(name, size_px, intrinsics, distortion, rvec, tvec)
    except InputError as error:
        parameter = str(error).split(":")[0]
        key = {"intrinsics": "matrix", "distortion": "distortions", "rvec": "rotation"}.get(parameter, parameter)
        raise FileFormatError(f"{where}, key '{key}': {_detail(error)}") from None


def _detail(error: InputError) -> str:
    """The message of an InputError without its leading 'parameter: '."""
    message = str(error)
    return message.split(": ", 1)[1] if ": " in message else message


def write_calibration(path: PathLike, cameras: Sequence[PinholeCamera]) -> None:
    """Write cameras to a Pose2Sim calibration TOML file (atomically: temporary file, then rename).

    Floats are written with full precision, so :func:`read_calibration` gives the same cameras
    back (rotation up to the Rodrigues round trip, ~1e-15).

    Args:
        path: the TOML file to write.
        cameras: pinhole cameras with distinct names.

    Raises:
        InputError: a camera is not a :class:`PinholeCamera`, or names repeat or are reserved.
        OSError: the file cannot be written.
    """
    path = as_path(path)
    if not isinstance(cameras, (list, tuple)):
        raise InputError(f"cameras: expected a list of PinholeCamera, found {type(cameras).__name__}; a single "
                         "camera goes in a list: [camera]", parameter="cameras")
    document: dict[str, dict] = {}
    for index, camera in enumerate(cameras):
        if not isinstance(camera, PinholeCamera):
            raise InputError(
                f"cameras[{index}]: expected a PinholeCamera (the TOML format has no other kind), "
                f"found {type(camera).__name__}"
            )
        if camera.name in document or camera.name in _NON_CAMERA_SECTIONS:
            raise InputError(
                f"cameras[{index}].name: expected a unique name other than {sorted(_NON_CAMERA_SECTIONS)}, "
                f"found {camera.name!r}"
            )
        # Python floats: tomli-w writes them with repr, the shortest string that reads back the same.
        document[camera.name] = {
            "name": camera.name,
            "size": [float(length) for length in camera.size],  # Pose2Sim writes the size as floats
            "matrix": camera.intrinsics.tolist(),
            "distortions": camera.distortion.tolist(),
            "rotation": camera.rvec.tolist(),
            "translation": camera.translation.tolist(),
            "fisheye": False,
        }
    if not document:
        raise InputError("cameras: expected at least one camera, found none")
    document["metadata"] = {"adjusted": False, "error": 0.0}
    write_text_atomically(path, tomli_w.dumps(document))


# Pose2Sim writes TRC files Y-up while its calibration's world is Z-up: a TRC point (x, y, z) is the
# calibration-world point (z, x, y), as in Pose2Sim's demo data (docs/method.md, "Axes").
POSE2SIM_TRC_TO_WORLD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
