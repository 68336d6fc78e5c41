"""Reading and writing files safely: text with clear errors, atomic writes.

Every reader of :mod:`ibik_pin.io` reads through :func:`read_text` (any failure becomes a
:class:`~ibik_pin.exceptions.FileFormatError` naming the file) and every writer writes through
:func:`write_atomically` (a temporary file beside the target, renamed over it when complete), so a
failure never leaves a half-written file.
"""

from __future__ import annotations

import json
import math
import os
import stat
import uuid
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from ibik_pin.exceptions import (
    FileFormatError,
    IbikWarning,
    InputError,
)

__all__ = [
    "PathLike",
    "as_path",
    "check_declared_count",
    "is_number",
    "json_ready",
    "strict_json",
    "MAX_INPUT_BYTES",
    "checked_input_file",
    "read_text",
    "write_atomically",
    "write_text_atomically",
]

#: A path as the readers and writers accept it.
PathLike = str | os.PathLike

_Result = TypeVar("_Result")


#: The largest input file read [bytes]: far above any motion, calibration or model file, small
#: enough that a wrong path (a disk image, /dev/zero) is refused before it fills the memory.
MAX_INPUT_BYTES = 1 << 30


def as_path(value: object, parameter: str = "path") -> Path:
    """`value` as a Path: a str or os.PathLike naming something (the check every reader and writer
    makes of its path argument).

    Raises:
        InputError: another type (a number, bytes, None, an array), or an empty name.
    """
    if isinstance(value, (str, os.PathLike)):
        text = os.fspath(value)
        if isinstance(text, str) and text.strip():
            return Path(text)
        if isinstance(text, str):
            raise InputError(f"{parameter}: expected a path, found an empty name {text!r}", parameter=parameter)
    raise InputError(f"{parameter}: expected a path (str or pathlib.Path), found {type(value).__name__} "
                     f"{value!r:.60}", parameter=parameter)


def checked_input_file(path: str | os.PathLike[str], what: str) -> Path:
    """The path, once it is known to be a regular file of at most MAX_INPUT_BYTES.

    Raises:
        InputError: `path` is not a path (as_path).
        FileFormatError: it does not exist, is a folder, a FIFO or device (reading one could block
            or never end), or is larger than the limit.
    """
    path = as_path(path)
    try:
        status = path.stat()
    except OSError as error:
        raise FileFormatError(f"{path}: cannot read this {what} file: {error.strerror or error}") from error
    if not stat.S_ISREG(status.st_mode):
        kind = "a folder" if stat.S_ISDIR(status.st_mode) else "not a regular file (a pipe, socket or device)"
        raise FileFormatError(f"{path}: expected a {what} file, found {kind}")
    if status.st_size > MAX_INPUT_BYTES:
        raise FileFormatError(f"{path}: {status.st_size:,} bytes, larger than the {MAX_INPUT_BYTES:,}-byte "
                              f"(1 GiB) limit of an input file; is it really a {what} file?")
    return path


def read_text(path: str | os.PathLike[str], what: str) -> str:
    """The text of a file, any failure to read it raised as a FileFormatError.

    Args:
        path: The file.
        what: The kind of file, for the message (e.g. ``"TRC"``).

    Returns:
        Its content, universal newlines. UTF-8, with or without the byte-order mark Windows tools
        write; UTF-16 (Windows' "Unicode text"), with or without its mark; failing those
        Windows-1252, in which motion-capture software of Western locales writes its headers (a file
        name with an accent).

    Raises:
        FileFormatError: The file is missing, not a regular file, too large, unreadable, or text
            in neither encoding (a binary file).
    """
    path = checked_input_file(path, what)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise FileFormatError(f"{path}: cannot read this {what} file: {error.strerror or error}") from error
    utf16 = _utf16(data)
    if utf16 is not None:
        return utf16.replace("\r\n", "\n").replace("\r", "\n")
    if b"\x00" in data:
        raise FileFormatError(f"{path}: cannot read this {what} file: it is binary, not text")
    for encoding in ("utf-8-sig", "cp1252"):
        try:
            return data.decode(encoding).replace("\r\n", "\n").replace("\r", "\n")
        except UnicodeDecodeError:
            continue
    raise FileFormatError(f"{path}: cannot read this {what} file: it is neither UTF-8 nor Windows-1252 text")


def _utf16(data: bytes) -> str | None:
    """The text of UTF-16 bytes (Windows' "Unicode text" exports), None for other bytes: with a
    byte-order mark, or without one where every other byte is zero as in Latin text."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        encoding = "utf-16"
    elif len(data) >= 4 and len(data) % 2 == 0 and data[1::2].count(0) > 0.9 * (len(data) // 2) \
            and data[0::2].count(0) == 0:
        encoding = "utf-16-le"
    elif len(data) >= 4 and len(data) % 2 == 0 and data[0::2].count(0) > 0.9 * (len(data) // 2) \
            and data[1::2].count(0) == 0:
        encoding = "utf-16-be"
    else:
        return None
    try:
        return data.decode(encoding)
    except UnicodeDecodeError:
        return None


def is_number(text: str) -> bool:
    """Whether ``float(text)`` succeeds; finds the offending cell for an error message."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def check_declared_count(path, key: str, declared: int, found: int, what: str) -> None:
    """Compare a header's declared count of rows (TRC NumFrames, MOT nRows, BVH Frames) with the
    rows the file holds: fewer is a FileFormatError, more are kept with an IbikWarning that points
    at the reader's caller."""
    message = f"{path}: {key} is {declared} but the file holds {found} {what}"
    if found < declared:
        raise FileFormatError(message)
    if found > declared:
        warnings.warn(f"{message}; all {what} are kept", IbikWarning, stacklevel=3)


def write_atomically(path: str | os.PathLike[str], write: Callable[[Path], _Result]) -> _Result:
    """Call ``write(temporary)``, then move the temporary file onto `path`; clean up on failure.

    The temporary file is in the destination folder (so ``os.replace`` is atomic on POSIX and
    Windows) and keeps the suffix (OpenCV picks a container or a format from it).

    Raises:
        InputError: The file cannot be written (missing folder, permissions, full disk).
    """
    path = Path(path)
    temporary = path.with_name(f".{path.stem}.{uuid.uuid4().hex}.tmp{path.suffix}")
    try:
        result = write(temporary)
        os.replace(temporary, path)
    except BaseException as error:
        temporary.unlink(missing_ok=True)
        if isinstance(error, OSError):
            raise InputError(f"{path}: cannot write: {error}") from error
        raise
    return result


def write_text_atomically(path: str | os.PathLike[str], text: str) -> None:
    """Write text to `path` in one ``os.replace`` (see write_atomically); newlines as given."""

    def write(temporary: Path) -> None:
        with open(temporary, "x", encoding="utf-8", newline="\n") as stream:
            stream.write(text)

    write_atomically(path, write)


def json_ready(value: Any) -> Any:
    """Plain JSON values: numpy numbers and arrays converted, paths as text, NaN and infinities as
    None (JSON has no token for them; a bare NaN makes the file unreadable to strict parsers)."""
    if isinstance(value, dict):
        return {str(key): json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(item) for item in value]
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value


def strict_json(value: Any, indent: int | None = 2) -> str:
    """`value` as strict JSON text (json_ready first), ending with a newline when indented."""
    text = json.dumps(json_ready(value), indent=indent, allow_nan=False,
                      separators=None if indent is not None else (",", ":"))
    return text + "\n" if indent is not None else text
