"""World joint positions over time, the common output of the BVH and ASF/AMC readers.

The module also holds the two file helpers every reader and writer of ``ibik_pin.io`` shares:
:func:`read_text` (any failure to read becomes a :class:`FileFormatError` naming the file) and
:func:`write_text_atomically` (a failed write never leaves a half-written file behind).
"""

from __future__ import annotations

import os
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError, UnknownNameError


@dataclass
class SkeletonMotion:
    """Joint positions of a skeleton over a sequence of frames.

    Attributes:
        names: The J joint names; end sites are joints too, named after their parent
            (e.g. ``"LeftToe_end"``).
        parents: Index of each joint's parent, -1 for the root, shape (J,), int. A parent may
            come after its child in this order.
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

    @property
    def frame_count(self) -> int:
        """The number of frames F."""
        return self.positions.shape[0]

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


def write_text_atomically(path: str | os.PathLike[str], text: str) -> None:
    """Write a text file so that a failure leaves either the old file or none, never half a file.

    The text goes to a temporary file in the destination folder, which then replaces the
    destination in one ``os.replace`` (atomic on POSIX and Windows within one file system).

    Args:
        path: The destination file.
        text: Its content; ``\\n`` newlines are written as they are.

    Raises:
        InputError: The file cannot be written (missing folder, permissions, full disk).
    """
    path = Path(path)
    # A unique name in the same folder, created with the usual permissions (unlike mkstemp's 0600).
    temporary = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(temporary, "x", encoding="utf-8", newline="\n") as stream:
            stream.write(text)
        os.replace(temporary, path)
    except BaseException as error:
        temporary.unlink(missing_ok=True)
        if isinstance(error, OSError):
            raise InputError(f"{path}: cannot write: {error}") from error
        raise
