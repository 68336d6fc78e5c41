"""C3D motion capture files in: labelled marker trajectories, then the keypoints the tracker takes.

`read_c3d_markers` reads every labelled point of a C3D file (through ezc3d) as a `TrcData`: the
file's units and rate, its first frame number, and gaps as NaN (a point whose residual is negative,
the C3D convention for "not reconstructed", or that sits exactly at the origin, as some exporters
write gaps). `markers_to_keypoints` turns marker trajectories into Pose2Sim keypoints by a mapping:
each keypoint is the mean of the markers listed for it, the first listed set the file holds. The
default mapping knows two common conventions:

- markers already named as the keypoints (``LKnee``), taken as they are;
- Vicon BodyBuilder's joint points, as in the CMU database's C3D files: each ``<bone>0`` point is
  the distal end of that bone of the skeleton (``LFE0`` the femur's end: the knee; ``LTI0`` the
  ankle; ``LHU0`` the elbow; ``LWR0`` the wrist; ``LCL0`` the shoulder; ``LHJ0`` the hip joint;
  ``LNK0`` the lower neck's end; ``HED0`` the head);
- Plug-in Gait's skin markers (``LSHO``, ``LELB``, ``LWRA``/``LWRB``, ``LKNE``, ``LANK``, ``LHEE``,
  ``LTOE``, head and trunk markers), with hip joint centres from the pelvis markers by Harrington
  et al.'s regression (J. Biomech. 40(3), 2007: from the mid-ASIS, 0.24 PD + 9.9 mm posterior,
  0.30 PW + 10.9 mm inferior, 0.33 PW + 7.3 mm lateral, PW the inter-ASIS width, PD the
  ASIS-PSIS depth). Skin markers lie some centimetres off the joint centres.

A mapping file (TOML) replaces the default: a ``[keypoints]`` table of keypoint = [markers].
"""

from __future__ import annotations

import difflib
import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError, UnknownNameError
from ibik_pin.io.files import PathLike, as_path
from ibik_pin.io.trc import METRES_PER_UNIT, TrcData

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["DEFAULT_KEYPOINT_MARKERS", "c3d_axes", "is_c3d", "markers_to_keypoints", "read_c3d", "read_c3d_markers",
           "read_mapping"]

# The byte at offset 1 of every C3D file: its parameter section's key.
_C3D_KEY = 0x50

# Per keypoint, the marker sets that give it, in order of preference: a marker of the keypoint's
# name, BodyBuilder's joint points, Plug-in Gait's markers. HARRINGTON stands for the regression.
HARRINGTON = "hip joint centre"
DEFAULT_KEYPOINT_MARKERS: dict[str, tuple[tuple[str, ...], ...]] = {
    "Hip": (("Hip",), ("LHJ0", "RHJ0"), ("LHJC", "RHJC"), (HARRINGTON,)),
    "Neck": (("Neck",), ("LNK0",), ("C7", "CLAV")),
    "Head": (("Head",), ("HED0",), ("LFHD", "RFHD", "LBHD", "RBHD")),
}
for _side in "LR":
    DEFAULT_KEYPOINT_MARKERS |= {
        f"{_side}Hip": ((f"{_side}Hip",), (f"{_side}HJ0",), (f"{_side}HJC",), (HARRINGTON,)),
        f"{_side}Knee": ((f"{_side}Knee",), (f"{_side}FE0",), (f"{_side}KNE",)),
        f"{_side}Ankle": ((f"{_side}Ankle",), (f"{_side}TI0",), (f"{_side}ANK",)),
        f"{_side}Heel": ((f"{_side}Heel",), (f"{_side}HEE",),),
        f"{_side}BigToe": ((f"{_side}BigToe",), (f"{_side}TO0",), (f"{_side}TOE",)),
        f"{_side}Shoulder": ((f"{_side}Shoulder",), (f"{_side}CL0",), (f"{_side}SHO",)),
        f"{_side}Elbow": ((f"{_side}Elbow",), (f"{_side}HU0",), (f"{_side}ELB",)),
        f"{_side}Wrist": ((f"{_side}Wrist",), (f"{_side}WR0",), (f"{_side}WRA", f"{_side}WRB")),
    }
# The pelvis markers of Harrington's regression, by the names the common marker sets give them.
PELVIS_MARKER_SETS = (("LASI", "RASI", "LPSI", "RPSI"), ("LFWT", "RFWT", "LBWT", "RBWT"))


def _import_ezc3d():
    try:
        import ezc3d
    except ImportError:
        raise InputError("reading C3D files needs the ezc3d package: pip install 'ibik_pin[c3d]'") from None
    return ezc3d


def is_c3d(path: PathLike) -> bool:
    """Whether a regular file starts as a C3D file does (its second byte is 0x50), whatever its
    suffix. A pipe or device is none: reading it could block, and the TRC reader names it."""
    if not as_path(path).is_file():
        return False
    try:
        with open(path, "rb") as file:
            head = file.read(2)
    except OSError:
        return False
    return len(head) == 2 and head[1] == _C3D_KEY


def c3d_axes(path: PathLike) -> str | None:
    """The axis convention a C3D file declares: "z-up" or "y-up" from POINT:Y_SCREEN (the axis
    drawn upward on screen, "+Z" in Vicon's and Qualisys' exports); None when it declares none or
    another.

    Raises:
        FileFormatError: as read_c3d_markers.
    """
    point = _read(Path(path))["parameters"]["POINT"]
    declared = point.get("Y_SCREEN", {}).get("value") or [""]
    return {"+Z": "z-up", "+Y": "y-up"}.get(str(declared[0]).strip().upper())


def _read(path: Path):
    if not path.is_file():
        raise FileFormatError(f"C3D file '{path}': expected a readable file, found "
                              + ("no such file" if not path.exists() else "not a regular file"))
    ezc3d = _import_ezc3d()
    try:
        return ezc3d.c3d(str(path))
    except (RuntimeError, ValueError, OSError) as error:
        raise FileFormatError(f"C3D file '{path}': cannot read it as C3D ({error})") from None


def read_c3d_markers(path: PathLike) -> TrcData:
    """Every labelled point of a C3D file, in the file's units, gaps as NaN.

    Labels lose a ``Subject:`` prefix (Vicon writes ``SteveWalk:LKNE``).

    Raises:
        FileFormatError: the file is missing, not a C3D file, holds no point, or repeats a label.
        InputError: ezc3d is not installed, or the file's units are not m, cm or mm.
    """
    path = Path(path)
    content = _read(path)
    point = content["parameters"]["POINT"]
    labels = [str(label).split(":")[-1].strip() for label in point["LABELS"]["value"]]
    # LABELS2, LABELS3, ... continue LABELS past 255 points.
    for extra in range(2, 10):
        labels += [str(label).split(":")[-1].strip() for label in point.get(f"LABELS{extra}", {}).get("value", [])]
    data = content["data"]["points"]  # (4, points, frames)
    if data.shape[1] == 0 or data.shape[2] == 0:
        raise FileFormatError(f"C3D file '{path}': expected marker trajectories, found no point data")
    labels = labels[: data.shape[1]]
    repeated = sorted({label for label in labels if labels.count(label) > 1 and label})
    if repeated:
        raise FileFormatError(f"C3D file '{path}': expected one point per label, found {', '.join(repeated)} "
                              "more than once")
    units = str(point["UNITS"]["value"][0]).strip().lower() if point.get("UNITS", {}).get("value") else "mm"
    if units not in METRES_PER_UNIT:
        raise InputError(f"C3D file '{path}': POINT:UNITS: expected one of {', '.join(METRES_PER_UNIT)}, "
                         f"found {units!r}")
    rate = float(content["header"]["points"]["frame_rate"])
    first = int(content["header"]["points"]["first_frame"])
    positions = np.transpose(data[:3], (2, 1, 0)).astype(float)  # (frames, points, 3)
    residuals = content["data"]["meta_points"]["residuals"][0].T  # (frames, points)
    gaps = (residuals < 0) | np.all(positions == 0.0, axis=2)
    positions[gaps] = np.nan
    frame_count = positions.shape[0]
    return TrcData(labels, np.arange(frame_count) / rate, positions, units, rate,
                   np.arange(first, first + frame_count))


def read_mapping(path: PathLike) -> dict[str, tuple[str, ...]]:
    """A keypoint mapping file: a TOML ``[keypoints]`` table of keypoint = [marker, ...].

    Raises:
        FileFormatError: not TOML, no ``[keypoints]`` table, or a value that is not a list of names.
    """
    path = Path(path)
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise FileFormatError(f"keypoint mapping '{path}': expected a TOML file, {error}") from None
    keypoints = table.get("keypoints")
    if not isinstance(keypoints, dict) or not keypoints:
        raise FileFormatError(f"keypoint mapping '{path}': expected a [keypoints] table of keypoint = [markers]")
    mapping = {}
    for name, markers in keypoints.items():
        if isinstance(markers, str):
            markers = [markers]
        if not isinstance(markers, list) or not markers or not all(isinstance(m, str) and m for m in markers):
            raise FileFormatError(f"keypoint mapping '{path}': keypoints.{name}: expected a list of marker "
                                  f"names, found {markers!r}")
        mapping[name] = tuple(markers)
    return mapping


def _hip_joint_centres(columns: Mapping[str, np.ndarray], millimetre: float) -> dict[str, np.ndarray] | None:
    """Left and right hip joint centres (F, 3) by Harrington's regression, in the markers' units
    (`millimetre`: one mm in them), or None without a complete set of pelvis markers."""
    for names in PELVIS_MARKER_SETS:
        if all(name in columns for name in names):
            left_asis, right_asis, left_psis, right_psis = (columns[name] for name in names)
            break
    else:
        return None
    mid_asis = (left_asis + right_asis) / 2
    lateral = right_asis - left_asis
    width = np.linalg.norm(lateral, axis=1, keepdims=True)
    lateral = lateral / width
    backward = (left_psis + right_psis) / 2 - mid_asis
    depth = np.linalg.norm(backward, axis=1, keepdims=True)
    backward = backward - (backward * lateral).sum(axis=1, keepdims=True) * lateral
    backward /= np.linalg.norm(backward, axis=1, keepdims=True)
    up = np.cross(backward, lateral)  # posterior x right = superior (ISB: -x cross z = y)
    posterior = 0.24 * depth + 9.9 * millimetre
    inferior = 0.30 * width + 10.9 * millimetre
    outward = 0.33 * width + 7.3 * millimetre
    centre = mid_asis + posterior * backward - inferior * up
    return {"L": centre - outward * lateral, "R": centre + outward * lateral}


def _near(name: str, known: Sequence[str]) -> str:
    close = difflib.get_close_matches(name, known, n=3)
    return f" (closest: {', '.join(close)})" if close else ""


def markers_to_keypoints(markers: TrcData, mapping: Mapping[str, Sequence[str]] | None = None,
                         source: str = "markers") -> TrcData:
    """Keypoints from marker trajectories: each the mean of its markers (NaN where one is missing).

    Args:
        markers: labelled marker trajectories (`read_c3d_markers`, or a TRC of markers).
        mapping: keypoint -> marker names; None: `DEFAULT_KEYPOINT_MARKERS`, each keypoint from the
            first of its marker sets the file holds (keypoints with none are left out).
        source: what to name in errors (the file).

    Returns:
        The keypoints, in the markers' units, rate and frame numbers.

    Raises:
        UnknownNameError: a mapping names a marker the file does not hold (closest names given).
        InputError: no keypoint could be formed.
    """
    columns: dict[str, np.ndarray] = {name: markers.positions[:, index] for index, name in
                                      enumerate(markers.marker_names)}
    hips = _hip_joint_centres(columns, 1e-3 / METRES_PER_UNIT[markers.units])
    chosen: dict[str, tuple[str, ...]] = {}
    if mapping is None:
        for keypoint, candidates in DEFAULT_KEYPOINT_MARKERS.items():
            for candidate in candidates:
                if hips is not None if candidate == (HARRINGTON,) else all(name in columns for name in candidate):
                    chosen[keypoint] = candidate
                    break
    else:
        for keypoint, listed in mapping.items():
            candidate = tuple(listed)
            missing = [name for name in candidate if name not in columns]
            if missing:
                raise UnknownNameError(f"{source}: keypoint {keypoint}: marker {missing[0]!r} is not in the file"
                                       f"{_near(missing[0], markers.marker_names)}")
            chosen[keypoint] = candidate
    if not chosen:
        raise InputError(f"{source}: expected markers of a known marker set (Vicon BodyBuilder joint points or "
                         "Plug-in Gait) or a keypoint mapping, found none; give a mapping file")
    names, trajectories = [], []
    for keypoint, candidate in chosen.items():
        if candidate == (HARRINGTON,) and hips is not None:
            trajectory = (hips["L"] + hips["R"]) / 2 if keypoint == "Hip" else hips[keypoint[0]]
        else:
            trajectory = np.mean([columns[name] for name in candidate], axis=0)
        names.append(keypoint)
        trajectories.append(trajectory)
    return TrcData(names, markers.times, np.stack(trajectories, axis=1), markers.units, markers.data_rate,
                   markers.frame_numbers, markers.camera_rate)


def read_c3d(path: PathLike, mapping: PathLike | Mapping[str, Sequence[str]] | None = None) -> TrcData:
    """The keypoints of a C3D file: `read_c3d_markers`, then `markers_to_keypoints`.

    Args:
        path: the C3D file.
        mapping: a mapping file (`read_mapping`), a mapping, or None for the default.
    """
    chosen = read_mapping(mapping) if isinstance(mapping, (str, os.PathLike)) else mapping
    return markers_to_keypoints(read_c3d_markers(path), chosen, f"C3D file '{path}'")
