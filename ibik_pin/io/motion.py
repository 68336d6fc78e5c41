"""World joint positions over time, the common output of the BVH and ASF/AMC readers.

The module also holds what the readers and writers of ``ibik_pin.io`` share: :func:`read_text`
(any failure to read becomes a :class:`FileFormatError` naming the file),
:func:`write_text_atomically` (a failed write never leaves a half-written file behind),
:func:`is_number`, and the Euler-angle conversions of the motion formats,
:func:`euler_to_matrices` and :func:`matrices_to_euler`.
"""

from __future__ import annotations

import os
import uuid
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np

from ibik_pin.exceptions import FileFormatError, IbikWarning, InputError, UnknownNameError

_Result = TypeVar("_Result")


@dataclass
class SkeletonMotion:
    """Joint positions of a skeleton over a sequence of frames.

    Attributes:
        names: The J joint names; end sites are joints too, named after their parent
            (e.g. ``"LeftToe_end"``).
        parents: Index of each joint's parent, -1 for the root, shape (J,), int. The readers of
            ``ibik_pin.io`` list every parent before its children.
        positions: World joint positions, shape (F, J, 3) [m].
        frame_rate: Frames per second [Hz].
    """

    names: list[str]
    parents: np.ndarray
    positions: np.ndarray
    frame_rate: float

    def __post_init__(self) -> None:
        self.names = list(self.names)
        self.parents = np.asarray(self.parents, dtype=int)
        self.positions = np.asarray(self.positions, dtype=float)
        joint_count = len(self.names)
        if self.parents.shape != (joint_count,):
            raise InputError(
                f"parents: expected shape ({joint_count},) for {joint_count} names, "
                f"got {self.parents.shape}"
            )
        if np.any((self.parents < -1) | (self.parents >= joint_count)):
            raise InputError(
                f"parents: expected indices in [-1, {joint_count - 1}], got {self.parents.tolist()}"
            )
        if self.positions.ndim != 3 or self.positions.shape[1:] != (joint_count, 3):
            raise InputError(
                f"positions: expected shape (F, {joint_count}, 3), got {self.positions.shape}"
            )
        if len(set(self.names)) != joint_count:
            duplicates = sorted({name for name in self.names if self.names.count(name) > 1})
            raise InputError(f"names: expected unique joint names, got duplicates {duplicates}")
        if not np.isfinite(self.frame_rate) or self.frame_rate <= 0.0:
            raise InputError(f"frame_rate: expected a positive number [Hz], got {self.frame_rate}")
        self.frame_rate = float(self.frame_rate)

    def bone_lengths(self) -> np.ndarray:
        """Distance of every joint to its parent at every frame.

        Returns:
            Lengths, shape (F, J) [m]; 0 for roots.
        """
        has_parent = self.parents >= 0
        parent_positions = self.positions[:, np.where(has_parent, self.parents, 0)]
        lengths = np.linalg.norm(self.positions - parent_positions, axis=-1)
        return np.where(has_parent, lengths, 0.0)

    def index(self, name: str) -> int:
        """The index of a joint.

        Args:
            name: A joint name.

        Returns:
            Its index in ``names``.

        Raises:
            UnknownNameError: There is no joint of that name; the message lists the known ones.
        """
        try:
            return self.names.index(name)
        except ValueError:
            raise UnknownNameError(
                f"joint {name!r} does not exist; known joints: {', '.join(self.names)}"
            ) from None

    def subset(self, frames: slice) -> SkeletonMotion:
        """A copy restricted to some frames.

        Args:
            frames: The frames to keep; a step k divides the frame rate by k.

        Returns:
            A new motion with copied positions.

        Raises:
            InputError: ``frames`` is not a slice or its step is not positive.
        """
        if not isinstance(frames, slice):
            raise InputError(f"frames: expected a slice, got {type(frames).__name__}")
        step = 1 if frames.step is None else frames.step
        if step <= 0:
            raise InputError(f"frames: expected a positive step, got {step}")
        return SkeletonMotion(
            names=list(self.names),
            parents=self.parents.copy(),
            positions=self.positions[frames].copy(),
            frame_rate=self.frame_rate / step,
        )


def read_text(path: str | os.PathLike[str], what: str) -> str:
    """The text of a file, any failure to read it raised as a FileFormatError.

    Args:
        path: The file.
        what: The kind of file, for the message (e.g. ``"TRC"``).

    Returns:
        Its content, universal newlines.

    Raises:
        FileFormatError: The file is missing, unreadable or not UTF-8 text.
    """
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise FileFormatError(f"{path}: cannot read this {what} file: {error}") from error


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


def euler_to_matrices(angles: np.ndarray, axes: str, intrinsic: bool = True) -> np.ndarray:
    """Rotation matrices from successive rotations about coordinate axes.

    For ``axes = "ZXY"`` and angles (a, b, c), intrinsic rotations give
    R = R_z(a) @ R_x(b) @ R_y(c) (the BVH convention: each rotation about the axes already
    rotated), extrinsic ones R = R_y(c) @ R_x(b) @ R_z(a) (each about the fixed axes).

    Args:
        angles: Angles, shape (..., n) [rad], n = len(axes).
        axes: The n rotation axes in order, letters among "XYZ" (case-insensitive); any
            length, repetitions allowed.
        intrinsic: Whether the rotations are about the moving axes.

    Returns:
        Rotation matrices, shape (..., 3, 3).

    Raises:
        InputError: ``axes`` holds another letter or its length is not ``angles.shape[-1]``.
    """
    angles = np.asarray(angles, dtype=float)
    axis_indices = _axis_indices(axes)
    if angles.ndim == 0 or angles.shape[-1] != len(axis_indices):
        raise InputError(
            f"angles: expected shape (..., {len(axis_indices)}) for axes {axes!r}, "
            f"got {angles.shape}"
        )
    rotations = np.broadcast_to(np.eye(3), (*angles.shape[:-1], 3, 3))
    for position, axis in enumerate(axis_indices):
        rotation = _axis_rotations(axis, angles[..., position])
        rotations = rotations @ rotation if intrinsic else rotation @ rotations
    return np.array(rotations)


def matrices_to_euler(rotations: np.ndarray, axes: str) -> np.ndarray:
    """Intrinsic Euler angles of rotation matrices, the inverse of :func:`euler_to_matrices`.

    For ``axes = "ZXY"`` it returns (a, b, c) with R = R_z(a) @ R_x(b) @ R_y(c),
    a, c in [-pi, pi] and b in [-pi/2, pi/2]. Near gimbal lock (b = +-pi/2) only a + c or a - c
    is defined: a is then taken from the matrix and c fitted to what remains, so the angles
    always rebuild the matrix to rounding error.

    Args:
        rotations: Rotation matrices, shape (..., 3, 3).
        axes: Three distinct letters among "XYZ" (case-insensitive).

    Returns:
        Angles, shape (..., 3) [rad].

    Raises:
        InputError: ``axes`` is not three distinct axes, or ``rotations`` is not (..., 3, 3).
    """
    rotations = np.asarray(rotations, dtype=float)
    axis_indices = _axis_indices(axes)
    if sorted(axis_indices) != [0, 1, 2]:
        raise InputError(f"axes: expected three distinct letters among 'XYZ', got {axes!r}")
    i, j, k = axis_indices
    if rotations.ndim < 2 or rotations.shape[-2:] != (3, 3):
        raise InputError(f"rotations: expected shape (..., 3, 3), got {rotations.shape}")
    sign = 1.0 if (j - i) % 3 == 1 else -1.0
    cos_middle = np.hypot(rotations[..., i, i], rotations[..., i, j])
    middle = np.arctan2(sign * rotations[..., i, k], cos_middle)
    first = np.where(
        cos_middle > 1e-10,
        np.arctan2(-sign * rotations[..., j, k], rotations[..., k, k]),
        np.arctan2(sign * rotations[..., k, j], rotations[..., j, j]),
    )
    # The third angle is fitted to the residual rotation R_j(b)^T R_i(a)^T R, so that rounding
    # in the first two never shows in the rebuilt matrix.
    residual = (
        np.swapaxes(_axis_rotations(i, first) @ _axis_rotations(j, middle), -1, -2) @ rotations
    )
    p, q = (k + 1) % 3, (k + 2) % 3
    last = np.arctan2(residual[..., q, p], residual[..., p, p])
    return np.stack([first, middle, last], axis=-1)


def _axis_indices(axes: str) -> list[int]:
    """The indices (0, 1, 2) of axis letters "XYZ"."""
    if not isinstance(axes, str) or any(letter not in "XYZxyz" for letter in axes):
        raise InputError(f"axes: expected letters among 'XYZ', got {axes!r}")
    return ["XYZ".index(letter) for letter in axes.upper()]


def _axis_rotations(axis: int, angles: np.ndarray) -> np.ndarray:
    """Rotations about one coordinate axis (0, 1, 2), shape (..., 3, 3), angles (...) [rad]."""
    cos, sin = np.cos(angles), np.sin(angles)
    p, q = (axis + 1) % 3, (axis + 2) % 3
    rotations = np.zeros((*np.shape(angles), 3, 3))
    rotations[..., axis, axis] = 1.0
    rotations[..., p, p] = cos
    rotations[..., q, q] = cos
    rotations[..., q, p] = sin
    rotations[..., p, q] = -sin
    return rotations
