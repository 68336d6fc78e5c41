"""Motion of a marker-less skeleton read from a motion-capture file (ASF/AMC, BVH).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibik_pin.exceptions import (
    InputError,
    UnknownNameError,
)


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
