"""The HIERARCHY section of a Biovision hierarchy file (.bvh): the skeleton, and its parser.

A joint's channels are listed in the file's order; an ``End Site`` is a joint without channels,
named after its parent (``LeftToe_end``). The conventions of the motion that drives the skeleton
are in :mod:`ibik_pin.io.bvh`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import is_number

__all__ = ["CHANNEL_NAMES", "BvhSkeleton", "read_hierarchy"]

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


def read_hierarchy(path: str | os.PathLike[str], lines: list[str]) -> BvhSkeleton:
    """The skeleton of the lines before ``MOTION`` of a BVH file.

    Args:
        path: The file, for the messages.
        lines: The file's lines up to, not including, the ``MOTION`` line.

    Returns:
        The hierarchy, joints depth first as the file lists them.

    Raises:
        FileFormatError: The hierarchy is ill-formed; the message names the line.
    """
    tokens = [(token, number) for number, line in enumerate(lines, 1) for token in line.split()]
    return _HierarchyParser(path, tokens, len(lines) + 1).parse()


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
        self.channels[index] = [channel for channel in canonical if channel is not None]  # none is, checked above
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
