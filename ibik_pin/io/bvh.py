"""Biovision hierarchy files (.bvh): read, and forward kinematics over frames.

Conventions, those of the format:

- Each joint's local rotation is the product of its rotation channels in the order the file
  lists them, intrinsic: for ``CHANNELS 3 Zrotation Xrotation Yrotation``,
  R_local = R_z @ R_x @ R_y, angles in degrees.
- A joint's local translation is its OFFSET plus its position channels, if it has any (the root
  always does): position = parent_position + parent_R @ (OFFSET + channels).
- An ``End Site`` is a joint without channels, named after its parent: ``LeftToe_end``.
- Lengths have no declared unit; the caller chooses the metres per file unit (``scale``).

The HIERARCHY section is parsed by :mod:`ibik_pin.io.bvh_hierarchy`; BVH files are written by
:mod:`ibik_pin.io.bvh_writer`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.bvh_hierarchy import BvhSkeleton, read_hierarchy
from ibik_pin.io.files import check_declared_count, is_number, read_text
from ibik_pin.io.skeleton import SkeletonMotion, axis_rotations

__all__ = ["CMU_BVH_SCALE", "BvhMotion", "BvhSkeleton", "read_bvh"]

#: Metres per unit of the CMU motion capture BVH conversions (cgspeed, e.g. 131_01.bvh): they
#: keep the lengths of CMU's ASF files, whose unit is 1/0.45 inch (see :func:`read_bvh`).
CMU_BVH_SCALE = 0.0254 / 0.45


@dataclass
class BvhMotion:
    """A BVH file: hierarchy and channel values, lengths in file units.

    Attributes:
        skeleton: The hierarchy.
        frame_time: Time between frames [s].
        channel_values: The values of every frame, shape (F, C), in the order of the joints and
            of their channels; positions in file units, angles [deg].
        scale: Metres per file unit if known (see :func:`read_bvh`), else None.
    """

    skeleton: BvhSkeleton
    frame_time: float
    channel_values: np.ndarray
    scale: float | None = None

    def __post_init__(self) -> None:
        self.channel_values = np.asarray(self.channel_values, dtype=float)
        channel_count = self.skeleton.channel_count
        if self.channel_values.ndim != 2 or self.channel_values.shape[1] != channel_count:
            raise InputError(
                f"channel_values: expected shape (F, {channel_count}), "
                f"got {self.channel_values.shape}"
            )
        if not np.isfinite(self.frame_time) or self.frame_time <= 0.0:
            raise InputError(f"frame_time: expected a positive number [s], got {self.frame_time}")
        if self.scale is not None:
            _check_scale(self.scale)

    def to_skeleton_motion(self, scale: float | None = None) -> SkeletonMotion:
        """World joint positions by forward kinematics, vectorised over frames.

        Args:
            scale: Metres per file unit; None takes the one given to :func:`read_bvh`.

        Returns:
            The joints of the hierarchy (end sites included) in metres, at 1 / frame_time [Hz].

        Raises:
            InputError: No scale is known, or it is not a positive number.
        """
        scale = self.scale if scale is None else scale
        if scale is None:
            raise InputError(
                "scale: BVH files do not state their length unit; expected the metres per file "
                "unit (e.g. 0.01 for centimetres), got None"
            )
        _check_scale(scale)
        skeleton = self.skeleton
        frame_count = self.channel_values.shape[0]
        joint_count = len(skeleton.names)
        positions = np.empty((frame_count, joint_count, 3))
        rotations = np.empty((frame_count, joint_count, 3, 3))
        first_column = 0
        for joint, joint_channels in enumerate(skeleton.channels):
            values = self.channel_values[:, first_column : first_column + len(joint_channels)]
            first_column += len(joint_channels)
            rotation_columns = [
                c for c, name in enumerate(joint_channels) if name.endswith("rotation")
            ]
            local_rotations = axis_rotations(
                np.deg2rad(values[:, rotation_columns]),
                "".join(joint_channels[c][0] for c in rotation_columns),
            )
            translations = np.broadcast_to(skeleton.offsets[joint], (frame_count, 3)).copy()
            for column, name in enumerate(joint_channels):
                if name.endswith("position"):
                    translations[:, "XYZ".index(name[0])] += values[:, column]
            parent = skeleton.parents[joint]
            if parent < 0:
                positions[:, joint] = translations
                rotations[:, joint] = local_rotations
            else:
                positions[:, joint] = positions[:, parent] + np.einsum(
                    "fab,fb->fa", rotations[:, parent], translations
                )
                rotations[:, joint] = rotations[:, parent] @ local_rotations
        return SkeletonMotion(
            names=list(skeleton.names),
            parents=skeleton.parents.copy(),
            positions=positions * scale,
            frame_rate=1.0 / self.frame_time,
        )


def read_bvh(path: str | os.PathLike[str], scale: float | None = None) -> BvhMotion:
    """Read a BVH file.

    BVH files do not state their length unit. Pick ``scale`` (metres per file unit) from a
    length you know, e.g. the hip-to-ankle length of an adult, about 0.8-0.9 m, or the standing
    height:

    - Boxing_Toes.bvh (Open Asset Import Library) is in centimetres: 0.01.
    - The CMU conversions by cgspeed (131_01.bvh .. 131_03.bvh, 01_01.bvh) keep the unit of
      CMU's ASF files, 1/0.45 inch: :data:`CMU_BVH_SCALE` = 0.0254 / 0.45 = 0.05644, not 1 m
      per unit as their source states. In 131_01.bvh the left hip-to-knee and knee-to-ankle
      offsets are 7.29 and 6.92 units: 0.41 m and 0.39 m with that factor (14.2 m of leg with a
      factor 1); the hips are then 0.88 m above the floor on average and the head end site at
      most 1.43 m above the lowest toe end site, as in CMU's own ASF skeletons.
    - Files written by :func:`~ibik_pin.io.bvh_writer.write_bvh` are in metres: 1.0.

    When the file holds more frames than its ``Frames:`` line declares (Boxing_Toes.bvh holds
    one more), every complete frame is kept and an :class:`IbikWarning` names both counts: the
    rows are well-formed data and the count is the header's mistake. Fewer frames than declared
    is an error (a truncated file).

    Args:
        path: The .bvh file.
        scale: Metres per file unit, stored for :meth:`BvhMotion.to_skeleton_motion`; None if
            unknown.

    Returns:
        The hierarchy and channel values, in file units.

    Raises:
        FileFormatError: The file cannot be read, or its hierarchy or motion is ill-formed; the
            message names the line.
        InputError: ``scale`` is not a positive number.
    """
    if scale is not None:
        _check_scale(scale)
    lines = read_text(path, "BVH").splitlines()
    motion_index = next(
        (index for index, line in enumerate(lines) if line.strip().upper() == "MOTION"), None
    )
    if motion_index is None:
        raise FileFormatError(f"{path}: expected a line 'MOTION' after the hierarchy, found none")
    skeleton = read_hierarchy(path, lines[:motion_index])

    header_numbers = [
        number for number in range(motion_index + 2, len(lines) + 1) if lines[number - 1].strip()
    ][:2]
    declared_frames = int(_motion_header_value(path, lines, header_numbers, 0, "Frames", int))
    frame_time = _motion_header_value(path, lines, header_numbers, 1, "Frame Time", float)
    if frame_time <= 0.0:
        raise FileFormatError(
            f"{path}, line {header_numbers[1]}: Frame Time: expected a positive number [s], "
            f"got {frame_time}"
        )

    row_numbers = [
        number
        for number in range(header_numbers[1] + 1, len(lines) + 1)
        if lines[number - 1].strip()
    ]
    rows = [lines[number - 1].split() for number in row_numbers]
    channel_count = skeleton.channel_count
    for number, row in zip(row_numbers, rows, strict=True):
        if len(row) != channel_count:
            raise FileFormatError(
                f"{path}, line {number}: expected {channel_count} channel values, got {len(row)}"
            )
    check_declared_count(path, "Frames", declared_frames, len(rows), "frames")
    try:
        channel_values = np.array(rows, dtype=float).reshape(len(rows), channel_count)
    except ValueError:
        number, bad = next(
            (number, cell)
            for number, row in zip(row_numbers, rows, strict=True)
            for cell in row
            if not is_number(cell)
        )
        raise FileFormatError(f"{path}, line {number}: expected numbers, got {bad!r}") from None
    return BvhMotion(skeleton, frame_time, channel_values, scale)


def _motion_header_value(
    path: str | os.PathLike[str],
    lines: list[str],
    header_numbers: list[int],
    position: int,
    key: str,
    kind: type,
) -> float:
    """The value of the ``Frames:`` (position 0) or ``Frame Time:`` (1) line after MOTION."""
    if position >= len(header_numbers):
        raise FileFormatError(f"{path}: expected a line '{key}: ...' after MOTION, found none")
    number = header_numbers[position]
    label, _, value = lines[number - 1].partition(":")
    if " ".join(label.split()).lower() != key.lower():
        raise FileFormatError(
            f"{path}, line {number}: expected '{key}: ...', got {lines[number - 1].strip()[:40]!r}"
        )
    try:
        return kind(value.strip())
    except ValueError:
        expected = "an integer" if kind is int else "a number"
        raise FileFormatError(
            f"{path}, line {number}: {key}: expected {expected}, got {value.strip()!r}"
        ) from None


def _check_scale(scale: float) -> None:
    if not np.isfinite(scale) or scale <= 0.0:
        raise InputError(f"scale: expected a positive number of metres per file unit, got {scale}")
