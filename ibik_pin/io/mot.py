"""OpenSim storage files (.mot, .sto), version 1: write and read.

The format OpenSim reads (``Storage``), tab separated::

    motion
    version=1
    nRows=100
    nColumns=34
    inDegrees=yes
    endheader
    time    pelvis_tilt    pelvis_list    ...
    0.0     1.25           -0.5           ...

``nColumns`` counts the time column. Readers also accept other ``key=value`` lines and free
text before ``endheader``, as OpenSim writes them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import (
    check_declared_count,
    is_number,
    read_text,
    write_text_atomically,
)

__all__ = ["MotData", "read_mot", "write_mot"]


@dataclass
class MotData:
    """The content of an OpenSim storage file.

    Attributes:
        header: The ``key=value`` lines of the header, keys and values stripped.
        column_names: The C column names after ``time``.
        times: Time of each row, shape (F,) [s].
        values: The C columns, shape (F, C); angles in [deg] if ``in_degrees`` else [rad].
        in_degrees: Whether rotational values are in degrees (``inDegrees=yes``).
        name: The first line of the file (e.g. ``"Coordinates"``).
    """

    header: dict[str, str]
    column_names: list[str]
    times: np.ndarray
    values: np.ndarray
    in_degrees: bool
    name: str = "motion"


def write_mot(
    path: str | os.PathLike[str],
    times: np.ndarray,
    column_names: list[str],
    values: np.ndarray,
    in_degrees: bool = True,
    name: str = "motion",
) -> None:
    """Write an OpenSim storage file, version 1 (atomically, see :func:`write_text_atomically`).

    Args:
        path: The .mot or .sto file to write.
        times: Time of each row, shape (F,) [s].
        column_names: The C column names, ``time`` excluded (e.g. OpenSim coordinate names).
        values: The columns, shape (F, C); angles in [deg] if ``in_degrees`` else [rad].
        in_degrees: Written as ``inDegrees=yes`` or ``inDegrees=no``.
        name: The first line of the file.

    Raises:
        InputError: The shapes disagree, a column name is empty or holds whitespace, or the
            file cannot be written.
    """
    times = np.asarray(times, dtype=float)
    values = np.asarray(values, dtype=float)
    column_names = list(column_names)
    if times.ndim != 1:
        raise InputError(f"times: expected shape (F,), got {times.shape}")
    if values.shape != (times.shape[0], len(column_names)):
        raise InputError(
            f"values: expected shape ({times.shape[0]}, {len(column_names)}) for "
            f"{times.shape[0]} times and {len(column_names)} column names, got {values.shape}"
        )
    for column_name in column_names:
        if not column_name.strip() or any(character in column_name for character in " \t\r\n"):
            raise InputError(
                f"column_names: expected non-empty names without spaces, tabs or newlines, "
                f"got {column_name!r}"
            )
    if not name.strip() or any(character in name for character in "=\r\n") or name == "endheader":
        raise InputError(
            f"name: expected a non-empty line without '=' other than 'endheader', got {name!r}"
        )
    lines = [
        name,
        "version=1",
        f"nRows={times.shape[0]}",
        f"nColumns={len(column_names) + 1}",
        f"inDegrees={'yes' if in_degrees else 'no'}",
        "endheader",
        "\t".join(["time", *column_names]),
    ]
    lines += [
        "\t".join(map(repr, [time, *row]))
        for time, row in zip(times.tolist(), values.tolist(), strict=True)
    ]
    write_text_atomically(path, "\n".join(lines) + "\n")


def read_mot(path: str | os.PathLike[str]) -> MotData:
    """Read an OpenSim storage file (.mot, .sto), version 1.

    Rows beyond ``nRows`` are kept with an :class:`IbikWarning`; fewer rows than ``nRows`` is an
    error (a truncated file). A missing ``inDegrees`` means radians, as in OpenSim.

    Args:
        path: The file.

    Returns:
        Its header, columns and rows.

    Raises:
        FileFormatError: The file cannot be read, has no ``endheader``, a header value is not
            what OpenSim expects, or a row has the wrong number of values; the message names
            the line.
    """
    lines = read_text(path, "MOT").splitlines()
    try:
        end_index = next(i for i, line in enumerate(lines) if line.strip() == "endheader")
    except StopIteration:
        raise FileFormatError(f"{path}: expected a line 'endheader', found none") from None
    header = {}
    for line in lines[1:end_index]:
        key, equals, value = line.partition("=")
        if equals:
            header[key.strip()] = value.strip()
    if end_index + 1 >= len(lines):
        raise FileFormatError(
            f"{path}, line {end_index + 2}: expected the column names after 'endheader', "
            f"got the end of the file"
        )
    labels_line = lines[end_index + 1]
    labels = (
        [label.strip() for label in labels_line.split("\t")]
        if "\t" in labels_line
        else labels_line.split()
    )
    if not labels or labels[0].lower() != "time":
        raise FileFormatError(
            f"{path}, line {end_index + 2}: expected the first column to be 'time', "
            f"got {labels[:1]}"
        )
    declared_columns = _header_count(path, lines, header, "nColumns")
    if declared_columns != len(labels):
        raise FileFormatError(
            f"{path}: nColumns is {declared_columns} but line {end_index + 2} names "
            f"{len(labels)} columns"
        )
    in_degrees_text = header.get("inDegrees", "no").lower()
    if in_degrees_text not in ("yes", "no"):
        raise FileFormatError(
            f"{path}: inDegrees: expected 'yes' or 'no', got {header['inDegrees']!r}"
        )
    declared_rows = _header_count(path, lines, header, "nRows")

    row_numbers = [
        number for number in range(end_index + 3, len(lines) + 1) if lines[number - 1].strip()
    ]
    check_declared_count(path, "nRows", declared_rows, len(row_numbers), "rows")
    table = np.empty((len(row_numbers), len(labels)))
    for row_index, number in enumerate(row_numbers):
        cells = lines[number - 1].split()
        if len(cells) != len(labels):
            raise FileFormatError(
                f"{path}, line {number}: expected {len(labels)} values, got {len(cells)}"
            )
        try:
            table[row_index] = [float(cell) for cell in cells]
        except ValueError:
            bad = next(cell for cell in cells if not is_number(cell))
            raise FileFormatError(f"{path}, line {number}: expected numbers, got {bad!r}") from None
    return MotData(
        header=header,
        column_names=labels[1:],
        times=table[:, 0],
        values=table[:, 1:],
        in_degrees=in_degrees_text == "yes",
        name=lines[0].strip(),
    )


def _header_count(
    path: str | os.PathLike[str], lines: list[str], header: dict[str, str], key: str
) -> int:
    """A non-negative integer of the header; the message names its line."""
    if key not in header:
        raise FileFormatError(f"{path}: expected a header line '{key}=...', found none")
    try:
        count = int(header[key])
    except ValueError:
        count = -1
    if count < 0:
        number = next(i for i, line in enumerate(lines, 1) if line.partition("=")[0].strip() == key)
        raise FileFormatError(
            f"{path}, line {number}: {key}: expected a non-negative integer, got {header[key]!r}"
        )
    return count
