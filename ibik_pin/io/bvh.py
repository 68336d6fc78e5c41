"""Biovision hierarchy files (.bvh): read, forward kinematics over frames, write.

Conventions, those of the format:

- Each joint's local rotation is the product of its rotation channels in the order the file
  lists them, intrinsic: for ``CHANNELS 3 Zrotation Xrotation Yrotation``,
  R_local = R_z @ R_x @ R_y, angles in degrees.
- A joint's local translation is its OFFSET plus its position channels, if it has any (the root
  always does): position = parent_position + parent_R @ (OFFSET + channels).
- An ``End Site`` is a joint without channels, named after its parent: ``LeftToe_end``.
- Lengths have no declared unit; the caller chooses the metres per file unit (``scale``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.euler import euler_to_matrices, matrices_to_euler
from ibik_pin.io.files import (
    check_declared_count,
    is_number,
    read_text,
    write_text_atomically,
)
from ibik_pin.io.skeleton import SkeletonMotion

#: The channel names a BVH file may hold.
CHANNEL_NAMES = (
    "Xposition",
    "Yposition",
    "Zposition",
    "Xrotation",
    "Yrotation",
    "Zrotation",
)
_CANONICAL_CHANNELS = {name.lower(): name for name in CHANNEL_NAMES}

#: Metres per unit of the CMU motion capture BVH conversions (cgspeed, e.g. 131_01.bvh): they
#: keep the lengths of CMU's ASF files, whose unit is 1/0.45 inch (see :func:`read_bvh`).
CMU_BVH_SCALE = 0.0254 / 0.45


@dataclass
class BvhSkeleton:
    """The hierarchy of a BVH file.

    Attributes:
        names: The J joint names in file order (depth first); end sites included, named
            ``<parent>_end``.
        parents: Index of each joint's parent, shape (J,), int; -1 for the root (joint 0),
            otherwise smaller than the joint's own index.
        offsets: Each joint's offset from its parent in the parent's frame, shape (J, 3), in file
            units.
        channels: Each joint's channel names in file order (e.g. ``["Zrotation", "Xrotation",
            "Yrotation"]``), empty for end sites.
    """

    names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    channels: list[list[str]]

    def __post_init__(self) -> None:
        self.names = list(self.names)
        self.parents = np.asarray(self.parents, dtype=int)
        self.offsets = np.asarray(self.offsets, dtype=float)
        self.channels = [list(joint_channels) for joint_channels in self.channels]
        joint_count = len(self.names)
        if joint_count == 0:
            raise InputError("names: expected at least one joint, got none")
        if self.parents.shape != (joint_count,):
            raise InputError(f"parents: expected shape ({joint_count},), got {self.parents.shape}")
        expected_parent_range = (self.parents[0] == -1) and np.all(
            (self.parents[1:] >= 0) & (self.parents[1:] < np.arange(1, joint_count))
        )
        if not expected_parent_range:
            raise InputError(
                f"parents: expected -1 for joint 0 and, for every other joint, a parent index "
                f"smaller than its own, got {self.parents.tolist()}"
            )
        if self.offsets.shape != (joint_count, 3):
            raise InputError(
                f"offsets: expected shape ({joint_count}, 3), got {self.offsets.shape}"
            )
        if len(self.channels) != joint_count:
            raise InputError(
                f"channels: expected one list per joint ({joint_count}), got {len(self.channels)}"
            )
        for name, joint_channels in zip(self.names, self.channels, strict=True):
            unknown = [channel for channel in joint_channels if channel not in CHANNEL_NAMES]
            if unknown or len(set(joint_channels)) != len(joint_channels):
                raise InputError(
                    f"channels of {name!r}: expected distinct names among {CHANNEL_NAMES}, "
                    f"got {joint_channels}"
                )

    @property
    def channel_count(self) -> int:
        """The number C of channels of a frame."""
        return sum(len(joint_channels) for joint_channels in self.channels)


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
            local_rotations = euler_to_matrices(
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
    - Files written by :func:`write_bvh` are in metres: 1.0.

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
    tokens = [
        (token, number)
        for number, line in enumerate(lines[:motion_index], 1)
        for token in line.split()
    ]
    skeleton = _HierarchyParser(path, tokens, motion_index + 1).parse()

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


def write_bvh(
    path: str | os.PathLike[str],
    names: list[str],
    parents: np.ndarray,
    offsets: np.ndarray,
    local_rotations: np.ndarray,
    root_positions: np.ndarray,
    frame_time: float,
    rotation_order: str = "ZXY",
    end_sites: dict[int, np.ndarray] | None = None,
) -> None:
    """Write a BVH file in metres (read it back with ``scale=1.0``).

    The root gets 6 channels (``Xposition Yposition Zposition`` then its rotations), every other
    joint 3 rotation channels in ``rotation_order``; the angles are the intrinsic Euler angles
    of the local rotations (robust at gimbal lock, see :func:`matrices_to_euler`). The root's
    position channels hold ``root_positions - offsets[root]``, so that the root ends at
    ``root_positions``. Joints are written depth first from the root, children in index order;
    :func:`read_bvh` returns them in that order. Every joint without children gets an End Site.
    The file is written atomically (see :func:`write_text_atomically`).

    Args:
        path: The .bvh file to write.
        names: The J joint names, unique, without whitespace.
        parents: Index of each joint's parent, shape (J,), int; -1 for the one root. The joints
            must form one tree.
        offsets: Each joint's offset from its parent in the parent's frame, shape (J, 3) [m].
        local_rotations: Each joint's rotation relative to its parent (the root's: relative to
            the world), shape (F, J, 3, 3).
        root_positions: World position of the root, shape (F, 3) [m].
        frame_time: Time between frames [s].
        rotation_order: Three distinct letters among "XYZ": the order of the rotation channels.
        end_sites: End Site offsets of joints without children, index to shape (3,) [m];
            missing ones are zero.

    Raises:
        InputError: An argument has the wrong shape or value (the message names it), or the
            file cannot be written.
    """
    names = list(names)
    parents = np.asarray(parents, dtype=int)
    offsets = np.asarray(offsets, dtype=float)
    local_rotations = np.asarray(local_rotations, dtype=float)
    root_positions = np.asarray(root_positions, dtype=float)
    order = _check_rotation_order(rotation_order)
    joint_count = len(names)
    children = _check_tree(names, parents)
    root = int(np.flatnonzero(parents == -1)[0])
    if offsets.shape != (joint_count, 3) or not np.all(np.isfinite(offsets)):
        raise InputError(
            f"offsets: expected finite values, shape ({joint_count}, 3), got {offsets.shape}"
        )
    if local_rotations.ndim != 4 or local_rotations.shape[1:] != (joint_count, 3, 3):
        raise InputError(
            f"local_rotations: expected shape (F, {joint_count}, 3, 3), got {local_rotations.shape}"
        )
    _check_rotation_matrices(local_rotations)
    frame_count = local_rotations.shape[0]
    if root_positions.shape != (frame_count, 3) or not np.all(np.isfinite(root_positions)):
        raise InputError(
            f"root_positions: expected finite values, shape ({frame_count}, 3), "
            f"got {root_positions.shape}"
        )
    if not np.isfinite(frame_time) or frame_time <= 0.0:
        raise InputError(f"frame_time: expected a positive number [s], got {frame_time}")
    end_site_offsets = _check_end_sites(end_sites, children)

    rotation_channels = " ".join(f"{axis}rotation" for axis in order)
    lines = ["HIERARCHY"]
    joint_order = []

    def write_joint(joint: int, depth: int) -> None:
        indent = "\t" * depth
        keyword = "ROOT" if joint == root else "JOINT"
        channels = (
            f"6 Xposition Yposition Zposition {rotation_channels}"
            if joint == root
            else f"3 {rotation_channels}"
        )
        joint_order.append(joint)
        lines.extend(
            [
                f"{indent}{keyword} {names[joint]}",
                f"{indent}{{",
                f"{indent}\tOFFSET {_format_vector(offsets[joint])}",
                f"{indent}\tCHANNELS {channels}",
            ]
        )
        for child in children[joint]:
            write_joint(child, depth + 1)
        if not children[joint]:
            end_offset = end_site_offsets.get(joint, np.zeros(3))
            lines.extend(
                [
                    f"{indent}\tEnd Site",
                    f"{indent}\t{{",
                    f"{indent}\t\tOFFSET {_format_vector(end_offset)}",
                    f"{indent}\t}}",
                ]
            )
        lines.append(f"{indent}}}")

    write_joint(root, 0)
    angles = np.rad2deg(matrices_to_euler(local_rotations[:, joint_order], order))
    values = np.concatenate(
        [root_positions - offsets[root], angles.reshape(frame_count, 3 * joint_count)], axis=1
    )
    lines += ["MOTION", f"Frames: {frame_count}", f"Frame Time: {float(frame_time)!r}"]
    lines += [" ".join(map(repr, row)) for row in values.tolist()]
    write_text_atomically(path, "\n".join(lines) + "\n")


class _HierarchyParser:
    """Parses the HIERARCHY section from its whitespace-separated tokens."""

    def __init__(
        self, path: str | os.PathLike[str], tokens: list[tuple[str, int]], motion_line: int
    ):
        self.path = path
        self.tokens = tokens
        self.motion_line = motion_line
        self.position = 0
        self.names: list[str] = []
        self.parents: list[int] = []
        self.offsets: list[list[float]] = []
        self.channels: list[list[str]] = []

    def parse(self) -> BvhSkeleton:
        self._expect("HIERARCHY")
        self._expect("ROOT")
        self._joint(self._next("the root's name"), -1)
        if self.position < len(self.tokens):
            token, number = self.tokens[self.position]
            raise FileFormatError(
                f"{self.path}, line {number}: expected 'MOTION' after the root's closing brace "
                f"(one root only), got {token!r}"
            )
        return BvhSkeleton(
            self.names, np.array(self.parents), np.array(self.offsets), self.channels
        )

    def _joint(self, name: str, parent: int) -> None:
        if name in self.names:
            raise FileFormatError(
                f"{self.path}, line {self._line()}: joint name {name!r} appears twice"
            )
        index = self._add(name, parent)
        self._expect("{")
        self.offsets[index] = self._offset()
        self._expect("CHANNELS")
        count_token = self._next("a channel count")
        if not count_token.isdigit():
            raise FileFormatError(
                f"{self.path}, line {self._line()}: CHANNELS of {name!r}: expected a count, "
                f"got {count_token!r}"
            )
        channels = [self._next("a channel name") for _ in range(int(count_token))]
        canonical = [_CANONICAL_CHANNELS.get(channel.lower()) for channel in channels]
        if None in canonical or len(set(canonical)) != len(canonical):
            raise FileFormatError(
                f"{self.path}, line {self._line()}: CHANNELS of {name!r}: expected "
                f"{count_token} distinct names among {CHANNEL_NAMES}, got {channels}"
            )
        self.channels[index] = canonical
        while True:
            token = self._next("JOINT, End Site or '}'")
            if token.upper() == "JOINT":
                self._joint(self._next("a joint name"), index)
            elif token.upper() == "END":
                self._expect("Site")
                end_name = f"{name}_end"
                suffix = 2
                while end_name in self.names:
                    end_name, suffix = f"{name}_end{suffix}", suffix + 1
                end_index = self._add(end_name, index)
                self._expect("{")
                self.offsets[end_index] = self._offset()
                self._expect("}")
            elif token == "}":
                return
            else:
                raise FileFormatError(
                    f"{self.path}, line {self._line()}: in joint {name!r}: expected JOINT, "
                    f"End Site or '}}', got {token!r}"
                )

    def _add(self, name: str, parent: int) -> int:
        """Append a joint with a zero offset and no channels; return its index."""
        self.names.append(name)
        self.parents.append(parent)
        self.offsets.append([0.0, 0.0, 0.0])
        self.channels.append([])
        return len(self.names) - 1

    def _offset(self) -> list[float]:
        self._expect("OFFSET")
        texts = [self._next("an OFFSET coordinate") for _ in range(3)]
        if not all(is_number(text) for text in texts):
            raise FileFormatError(
                f"{self.path}, line {self._line()}: OFFSET: expected 3 numbers, got {texts}"
            )
        return [float(text) for text in texts]

    def _next(self, expected: str) -> str:
        if self.position >= len(self.tokens):
            raise FileFormatError(
                f"{self.path}, line {self.motion_line}: expected {expected}, got 'MOTION' "
                f"(the hierarchy is incomplete)"
            )
        token = self.tokens[self.position][0]
        self.position += 1
        return token

    def _expect(self, keyword: str) -> None:
        token = self._next(repr(keyword))
        if token.upper() != keyword.upper():
            raise FileFormatError(
                f"{self.path}, line {self._line()}: expected {keyword!r}, got {token!r}"
            )

    def _line(self) -> int:
        """The line of the last token read."""
        return self.tokens[self.position - 1][1]


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


def _check_rotation_order(rotation_order: str) -> str:
    order = rotation_order.upper() if isinstance(rotation_order, str) else ""
    if sorted(order) != ["X", "Y", "Z"]:
        raise InputError(
            f"rotation_order: expected three distinct letters among 'XYZ', got {rotation_order!r}"
        )
    return order


def _check_tree(names: list[str], parents: np.ndarray) -> list[list[int]]:
    """Check names and parents describe one tree; return each joint's children."""
    joint_count = len(names)
    for name in names:
        if not isinstance(name, str) or not name or len(name.split()) != 1 or name != name.strip():
            raise InputError(f"names: expected non-empty names without whitespace, got {name!r}")
    if len(set(names)) != joint_count:
        raise InputError(f"names: expected unique names, got {names}")
    if parents.shape != (joint_count,) or np.any((parents < -1) | (parents >= joint_count)):
        raise InputError(
            f"parents: expected shape ({joint_count},) with indices in [-1, {joint_count - 1}], "
            f"got {parents.tolist()}"
        )
    roots = np.flatnonzero(parents == -1)
    if roots.size != 1:
        raise InputError(f"parents: expected exactly one root (-1), got {roots.size}")
    children: list[list[int]] = [[] for _ in range(joint_count)]
    for joint, parent in enumerate(parents.tolist()):
        if parent >= 0:
            children[parent].append(joint)
    reached, stack = set(), [int(roots[0])]
    while stack:
        joint = stack.pop()
        reached.add(joint)
        stack.extend(children[joint])
    if len(reached) != joint_count:
        unreached = [names[joint] for joint in range(joint_count) if joint not in reached]
        raise InputError(f"parents: expected one tree, but {unreached} are not below the root")
    return children


def _check_rotation_matrices(rotations: np.ndarray) -> None:
    """Check (F, J, 3, 3) matrices are rotations within 1e-6."""
    identity_error = np.abs(rotations @ np.swapaxes(rotations, -1, -2) - np.eye(3)).max(
        axis=(-1, -2)
    )
    bad = ~(identity_error < 1e-6) | (np.linalg.det(rotations) < 0.0)
    if np.any(bad):
        frame, joint = np.argwhere(bad)[0]
        raise InputError(
            f"local_rotations: expected rotation matrices (R R^T = I within 1e-6, det +1), "
            f"got {rotations[frame, joint].tolist()} at frame {frame}, joint {joint}"
        )


def _check_end_sites(
    end_sites: dict[int, np.ndarray] | None, children: list[list[int]]
) -> dict[int, np.ndarray]:
    checked = {}
    for joint, given_offset in (end_sites or {}).items():
        if not 0 <= joint < len(children) or children[joint]:
            raise InputError(f"end_sites: expected indices of joints without children, got {joint}")
        offset = np.asarray(given_offset, dtype=float)
        if offset.shape != (3,) or not np.all(np.isfinite(offset)):
            raise InputError(
                f"end_sites[{joint}]: expected 3 finite numbers [m], got {offset.tolist()}"
            )
        checked[joint] = offset
    return checked


def _format_vector(vector: np.ndarray) -> str:
    return " ".join(map(repr, np.asarray(vector, dtype=float).tolist()))
