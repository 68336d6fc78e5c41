"""Motion of a marker-less skeleton read from a motion-capture file (ASF/AMC, BVH).

Both readers build each joint's rotation from angles about coordinate axes, in an order the file
states; :func:`axis_rotations` is that one conversion, and :class:`SkeletonMotion` what both
return.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ibik_pin.exceptions import (
    InputError,
    UnknownNameError,
)

__all__ = ["SkeletonMotion", "axis_rotations", "euler_angles", "joint_group_name"]

# Tokens dropped from the end of a joint group's name: the axis of a single joint ("_X"), "_joint".
_NAME_SUFFIXES = {"X", "Y", "Z", "x", "y", "z", "joint"}


def joint_group_name(joint_names: list[str]) -> str:
    """The ``_``-separated tokens the names share, without a trailing axis letter or "joint"
    (``left_hip_Z, left_hip_X`` -> ``left_hip``): the name of a BVH joint or an OpenSim body."""
    shared: list[str] = []
    for tokens in zip(*(name.split("_") for name in joint_names), strict=False):
        if len(set(tokens)) != 1:
            break
        shared.append(tokens[0])
    while shared and shared[-1] in _NAME_SUFFIXES:
        shared.pop()
    return "_".join(shared)


def axis_rotations(angles: np.ndarray, axes: str) -> np.ndarray:
    """Rotation matrices of successive rotations about coordinate axes, vectorised over frames.

    The letters follow scipy's convention: upper case for rotations about the moving axes
    (intrinsic: ``"ZXY"`` gives R = R_z(a) @ R_x(b) @ R_y(c), BVH's channels), lower case for
    rotations about the fixed axes (extrinsic: ``"zxy"`` gives R = R_y(c) @ R_x(b) @ R_z(a),
    Acclaim's dofs).

    Args:
        angles: Angles, shape (F, n) [rad], n = len(axes).
        axes: Up to three letters among "XYZ" (intrinsic) or "xyz" (extrinsic), no two
            neighbours alike; an empty string (a joint without rotation) gives the identity.

    Returns:
        Rotation matrices, shape (F, 3, 3).
    """
    angles = np.asarray(angles, dtype=float)
    if not axes:
        return np.repeat(np.eye(3)[np.newaxis], angles.shape[0], axis=0)
    return Rotation.from_euler(axes, angles).as_matrix()


def euler_angles(rotations: np.ndarray, axes: str) -> np.ndarray:
    """Intrinsic Euler angles of rotation matrices, the inverse of :func:`axis_rotations`.

    For ``axes = "ZXY"`` it returns (a, b, c) with R = R_z(a) @ R_x(b) @ R_y(c), a, c in
    [-pi, pi] and b in [-pi/2, pi/2]. At gimbal lock (b = +-pi/2) only a + c or a - c is
    defined: c is then 0 and a carries the whole turn, so the angles still rebuild the matrix to
    rounding error.

    Args:
        rotations: Rotation matrices, shape (..., 3, 3).
        axes: Three distinct letters among "XYZ".

    Returns:
        Angles, shape (..., 3) [rad].
    """
    with warnings.catch_warnings():
        # scipy warns at gimbal lock that it sets the third angle to zero: that is the choice
        # documented above, not a loss, so the user is not told.
        warnings.filterwarnings("ignore", "Gimbal lock", UserWarning)
        # Flattened to one batch dimension: scipy before 1.17 takes no more.
        rotations = np.asarray(rotations, dtype=float)
        angles = Rotation.from_matrix(rotations.reshape(-1, 3, 3)).as_euler(axes)
    return angles.reshape(*rotations.shape[:-2], 3)


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
