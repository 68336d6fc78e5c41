"""OpenSim / Pose2Sim marker trajectories (.trc): read and write.

The format, tab separated::

    PathFileType  4  (X/Y/Z)  <file name>
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  ...
    60  60  100  21  m  60  0  ...
    Frame#  Time  RHip  <empty>  <empty>  RKnee  ...
    <empty>  <empty>  X1  Y1  Z1  X2  ...
    <optional blank line>
    1  0.0167  x  y  z  x  y  z ...

A missing marker is an empty cell, or a row that ends before its columns; both read as NaN.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ibik_pin.exceptions import FileFormatError, IbikWarning, InputError
from ibik_pin.io.files import (
    check_declared_count,
    is_number,
    read_text,
    write_text_atomically,
)
from ibik_pin.names import normalized

__all__ = ["METRES_PER_UNIT", "TrcData", "read_trc", "write_trc"]

#: Metres per unit for the units a TRC file may declare.
METRES_PER_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001}

_REQUIRED_KEYS = ("DataRate", "NumFrames", "NumMarkers", "Units")
_HEADER_KEYS = (
    "DataRate",
    "CameraRate",
    "NumFrames",
    "NumMarkers",
    "Units",
    "OrigDataRate",
    "OrigDataStartFrame",
    "OrigNumFrames",
)


@dataclass
class TrcData:
    """Marker trajectories of a TRC file.

    Attributes:
        marker_names: The M marker names.
        times: Time of each frame, shape (F,) [s].
        positions: Marker positions, shape (F, M, 3), in ``units``; NaN where a marker is missing.
        units: The length unit of ``positions``: ``"m"``, ``"cm"`` or ``"mm"``.
        data_rate: Frames per second [Hz].
        frame_numbers: The file's frame numbers, shape (F,), int.
        camera_rate: The capture rate [Hz]; None means equal to ``data_rate``.
    """

    marker_names: list[str]
    times: np.ndarray
    positions: np.ndarray
    units: str
    data_rate: float
    frame_numbers: np.ndarray
    camera_rate: float | None = None

    def __post_init__(self) -> None:
        self.marker_names = list(self.marker_names)
        self.times = np.asarray(self.times, dtype=float)
        self.positions = np.asarray(self.positions, dtype=float)
        self.frame_numbers = np.asarray(self.frame_numbers, dtype=int)
        marker_count = len(self.marker_names)
        if self.times.ndim != 1:
            raise InputError(f"times: expected shape (F,), got {self.times.shape}")
        frame_count = self.times.shape[0]
        if self.positions.shape != (frame_count, marker_count, 3):
            raise InputError(
                f"positions: expected shape ({frame_count}, {marker_count}, 3) for {frame_count} "
                f"times and {marker_count} markers, got {self.positions.shape}"
            )
        if self.frame_numbers.shape != (frame_count,):
            raise InputError(
                f"frame_numbers: expected shape ({frame_count},), got {self.frame_numbers.shape}"
            )
        if self.units not in METRES_PER_UNIT:
            raise InputError(
                f"units: expected one of {sorted(METRES_PER_UNIT)}, got {self.units!r}"
            )
        for field in ("data_rate", "camera_rate"):
            rate = getattr(self, field)
            if rate is not None and (not np.isfinite(rate) or rate <= 0.0):
                raise InputError(f"{field}: expected a positive number [Hz], got {rate}")
        for name in self.marker_names:
            if not name or name != name.strip() or "\t" in name or "\n" in name:
                raise InputError(
                    f"marker_names: expected non-empty names without tabs, newlines or "
                    f"surrounding spaces, got {name!r}"
                )

    def in_metres(self) -> TrcData:
        """A copy with positions in metres (``units == "m"``)."""
        return TrcData(
            marker_names=list(self.marker_names),
            times=self.times.copy(),
            positions=self.positions * METRES_PER_UNIT[self.units],
            units="m",
            data_rate=self.data_rate,
            frame_numbers=self.frame_numbers.copy(),
            camera_rate=self.camera_rate,
        )


def read_trc(path: str | os.PathLike[str]) -> TrcData:
    """Read a TRC file (OpenSim, Pose2Sim), with or without the blank line after its header.

    A row that holds more frames than ``NumFrames`` declares is kept and an
    :class:`IbikWarning` is emitted; fewer rows than declared is an error (a truncated file).

    Args:
        path: The .trc file.

    Returns:
        Its markers, times and positions in the file's units (see :meth:`TrcData.in_metres`).

    Raises:
        FileFormatError: The file cannot be read, or its header or a data row is ill-formed;
            the message names the line.
    """
    text = read_text(path, "TRC")
    lines = text.splitlines()
    if len(lines) < 5:
        raise FileFormatError(f"{path}: expected a 5-line TRC header, got {len(lines)} line(s)")
    if lines[0].split(maxsplit=1)[:1] != ["PathFileType"]:
        raise FileFormatError(f"{path}, line 1: expected 'PathFileType', got {lines[0][:40]!r}")
    keys = [key.strip() for key in lines[1].split("\t")]
    values = [value.strip() for value in lines[2].split("\t")]
    if len(values) < len(keys):
        raise FileFormatError(
            f"{path}, line 3: expected {len(keys)} values for the keys of line 2, got {len(values)}"
        )
    header = dict(zip(keys, values[: len(keys)], strict=True))
    missing = [key for key in _REQUIRED_KEYS if key not in header]
    if missing:
        raise FileFormatError(f"{path}, line 2: expected the keys {missing}, got {keys}")
    data_rate = _header_rate(path, header, "DataRate")
    camera_rate = _header_rate(path, header, "CameraRate") if "CameraRate" in header else None
    declared_frames = _header_count(path, header, "NumFrames")
    declared_markers = _header_count(path, header, "NumMarkers")
    units = header["Units"]
    if units not in METRES_PER_UNIT:
        raise FileFormatError(
            f"{path}, line 3: Units: expected one of {sorted(METRES_PER_UNIT)}, got {units!r}"
        )

    labels = lines[3].split("\t")
    if [label.strip() for label in labels[:2]] != ["Frame#", "Time"]:
        raise FileFormatError(
            f"{path}, line 4: expected 'Frame#', 'Time' then marker names, got {labels[:2]}"
        )
    # Compared after normalisation: "Crème" typed with a combining accent is the same name.
    marker_names = [normalized(label) for label in labels[2:] if label.strip()]
    if len(marker_names) != declared_markers:
        raise FileFormatError(
            f"{path}, line 4: NumMarkers is {declared_markers} but the line names "
            f"{len(marker_names)} markers"
        )

    axis_labels = lines[4].split()
    if declared_markers and axis_labels[:3] != ["X1", "Y1", "Z1"]:
        raise FileFormatError(
            f"{path}, line 5: expected the axis labels 'X1 Y1 Z1 ...', got {lines[4][:40]!r}"
        )
    column_count = 2 + 3 * declared_markers
    row_numbers = [number for number in range(6, len(lines) + 1) if lines[number - 1].strip()]
    check_declared_count(path, "NumFrames", declared_frames, len(row_numbers), "data rows")
    if row_numbers and _cut_short(text, lines[row_numbers[-1] - 1], column_count):
        # A write interrupted mid-row: its last cell may be a prefix ("-0" of "-0.123"), not a value.
        warnings.warn(f"{path}, line {row_numbers[-1]}: the last row is cut short (no line end, "
                      f"{len(lines[row_numbers[-1] - 1].split(chr(9)))} of {column_count} cells): "
                      "its frame is left out", IbikWarning, stacklevel=2)
        row_numbers.pop()
    frame_numbers = np.empty(len(row_numbers), dtype=int)
    times = np.empty(len(row_numbers))
    coordinates = np.full((len(row_numbers), column_count - 2), np.nan)
    for row_index, number in enumerate(row_numbers):
        row = lines[number - 1].split("\t")
        if len(row) > column_count and any(cell.strip() for cell in row[column_count:]):
            raise FileFormatError(
                f"{path}, line {number}: expected at most {column_count} columns "
                f"(Frame#, Time, {declared_markers} markers x 3), got {len(row)}"
            )
        try:
            frame_numbers[row_index] = int(row[0])
        except ValueError:
            raise FileFormatError(
                f"{path}, line {number}: Frame#: expected an integer, got {row[0]!r}"
            ) from None
        time = row[1] if len(row) > 1 else ""
        if not is_number(time):
            raise FileFormatError(f"{path}, line {number}: Time: expected a number, got {time!r}")
        times[row_index] = float(time)
        cells = row[2:column_count]
        try:
            coordinates[row_index, : len(cells)] = [
                float(cell) if cell.strip() else np.nan for cell in cells
            ]
        except ValueError:
            column = next(i for i, cell in enumerate(cells) if cell.strip() and not is_number(cell))
            raise FileFormatError(
                f"{path}, line {number}: {marker_names[column // 3]} {'XYZ'[column % 3]}: "
                f"expected a number, got {cells[column]!r}"
            ) from None
    _check_unique_frames(path, frame_numbers, row_numbers)
    return TrcData(
        marker_names=marker_names,
        times=times,
        positions=coordinates.reshape(len(row_numbers), declared_markers, 3),
        units=units,
        data_rate=data_rate,
        frame_numbers=frame_numbers,
        camera_rate=camera_rate,
    )


def _cut_short(text: str, row: str, column_count: int) -> bool:
    """Whether the file's last row was cut by an interrupted write: no line end after it, and fewer
    cells than the header's columns."""
    return not text.endswith("\n") and len(row.split("\t")) < column_count


def _check_unique_frames(path, frame_numbers: np.ndarray, row_numbers: list[int]) -> None:
    """FileFormatError naming the lines of the first frame number that appears twice."""
    _, first_rows, counts = np.unique(frame_numbers, return_index=True, return_counts=True)
    if np.any(counts > 1):
        first = int(first_rows[np.argmax(counts > 1)])
        again = next(index for index in range(first + 1, len(frame_numbers))
                     if frame_numbers[index] == frame_numbers[first])
        raise FileFormatError(f"{path}, lines {row_numbers[first]} and {row_numbers[again]}: expected each "
                              f"Frame# once, found {int(frame_numbers[first])} twice")


def write_trc(path: str | os.PathLike[str], data: TrcData) -> None:
    """Write a TRC file as OpenSim does, with a blank line after the header.

    Missing markers (NaN) are written as empty cells. ``OrigDataRate``, ``OrigDataStartFrame``
    and ``OrigNumFrames`` are written as the data rate, the first frame number and the frame
    count. The file is written atomically (see :func:`write_text_atomically`).

    Args:
        path: The .trc file to write.
        data: The markers; positions are written in ``data.units``.

    Raises:
        InputError: The file cannot be written.
    """
    if not isinstance(data, TrcData):
        raise InputError(f"data: expected a TrcData (ibik_pin.io.trc), found {type(data).__name__}", parameter="data")
    marker_count = len(data.marker_names)
    frame_count = data.times.shape[0]
    camera_rate = data.data_rate if data.camera_rate is None else data.camera_rate
    first_frame = int(data.frame_numbers[0]) if frame_count else 1
    header_values = (
        repr(float(data.data_rate)),
        repr(float(camera_rate)),
        str(frame_count),
        str(marker_count),
        data.units,
        repr(float(data.data_rate)),
        str(first_frame),
        str(frame_count),
    )
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
        "\t".join(_HEADER_KEYS),
        "\t".join(header_values),
        "Frame#\tTime\t" + "\t\t\t".join(data.marker_names) + "\t\t",
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, marker_count + 1)),
        "",
    ]
    coordinates = data.positions.reshape(frame_count, 3 * marker_count).tolist()
    for frame_number, time, row in zip(
        data.frame_numbers.tolist(), data.times.tolist(), coordinates, strict=True
    ):
        cells = "\t".join("" if math.isnan(value) else repr(value) for value in row)
        lines.append(f"{frame_number}\t{time!r}\t{cells}")
    write_text_atomically(path, "\n".join(lines) + "\n")


def _header_rate(path: str | os.PathLike[str], header: dict[str, str], key: str) -> float:
    """A rate of the TRC header [Hz], checked positive."""
    try:
        rate = float(header[key])
    except ValueError:
        rate = np.nan
    if not np.isfinite(rate) or rate <= 0.0:
        raise FileFormatError(
            f"{path}, line 3: {key}: expected a positive number [Hz], got {header[key]!r}"
        )
    return rate


def _header_count(path: str | os.PathLike[str], header: dict[str, str], key: str) -> int:
    """A count of the TRC header, checked a non-negative integer."""
    try:
        count = int(header[key])
    except ValueError:
        count = -1
    if count < 0:
        raise FileFormatError(
            f"{path}, line 3: {key}: expected a non-negative integer, got {header[key]!r}"
        )
    return count
