"""Acclaim skeleton files (.asf), as the CMU motion capture database holds them.

An ASF file describes a skeleton in its rest pose: units, the root, every bone (direction,
length, rest frame, rotation dofs) and the hierarchy. The motions of the skeleton are AMC files,
read with it by :func:`ibik_pin.io.asf_amc.read_asf_amc`, which states how the two combine.

Both formats share one tokenizer (:func:`acclaim_words`, :func:`acclaim_numbers`): commas and
parentheses are whitespace, ``#`` starts a comment. Lengths are in file units (times
0.0254 / ``:units length`` they are metres; CMU: length 0.45, a unit of 1/0.45 inch), angles in
``:units angle`` (deg or rad).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ibik_pin.exceptions import FileFormatError
from ibik_pin.io.files import is_number, read_text

__all__ = ["AsfBone", "AsfSkeleton", "acclaim_numbers", "acclaim_words", "read_asf"]

_ROTATION_DOFS = ("rx", "ry", "rz")
_TRANSLATION_DOFS = ("tx", "ty", "tz")
_SEPARATORS = str.maketrans(",()", "   ")


@dataclass
class AsfBone:
    """A bone of an ASF file, lengths in file units, angles in file angle units.

    Attributes:
        name: The bone's name.
        line: The line of its ``name`` entry, for messages.
        direction: Unit direction from its start to its end in the rest pose, shape (3,).
        length: Its length [file units].
        axis_angles: The angles about X, Y and Z of its rest frame, shape (3,) [file angle units].
        axis_order: The order those angles apply in, about the fixed axes (e.g. ``"XYZ"``).
        dofs: Its rotation dofs in file order, among ``rx``, ``ry``, ``rz``.
        parent: The parent bone's name, ``"root"``, or None before the hierarchy is read.
    """

    name: str
    line: int
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    length: float = 0.0
    axis_angles: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis_order: str = "XYZ"
    dofs: list[str] = field(default_factory=list)
    parent: str | None = None


@dataclass
class AsfSkeleton:
    """The content of an ASF file that forward kinematics needs.

    Attributes:
        length_unit: ``:units length``: metres are lengths times 0.0254 / length_unit.
        in_degrees: Whether angles are in degrees (``:units angle deg``), else radians.
        root_order: The root's dofs in the order of an AMC line, among tx ty tz rx ry rz.
        root_axis: The order of the root's orientation angles (e.g. ``"XYZ"``).
        root_position: The root's rest position, shape (3,) [file units].
        root_orientation: The root's rest orientation angles about X, Y, Z, shape (3,).
        bones: The bones by name.
        bone_order: The bone names depth first from the root, in the order of ``:hierarchy``.
    """

    length_unit: float
    in_degrees: bool
    root_order: list[str]
    root_axis: str
    root_position: np.ndarray
    root_orientation: np.ndarray
    bones: dict[str, AsfBone]
    bone_order: list[str]


def read_asf(path: str | os.PathLike[str]) -> AsfSkeleton:
    """The skeleton of an ASF file: its units, root, bone data and hierarchy.

    Raises:
        FileFormatError: The file cannot be read or is ill-formed; the message names the line.
    """
    sections: dict[str, list[tuple[int, list[str]]]] = {}
    current = None
    for number, line in enumerate(read_text(path, "ASF").splitlines(), 1):
        words = acclaim_words(line)
        if not words:
            continue
        if words[0].startswith(":"):
            current = words[0][1:].lower()
            sections[current] = []
            if len(words) > 1:
                sections[current].append((number, words[1:]))
        elif current is not None:
            sections[current].append((number, words))
    for required in ("root", "bonedata", "hierarchy"):
        if required not in sections:
            raise FileFormatError(f"{path}: expected a ':{required}' section, found none")

    units = {words[0].lower(): (number, words[1:]) for number, words in sections.get("units", [])}
    length_unit = 1.0
    if "length" in units:
        number, values = units["length"]
        length_unit = acclaim_numbers(path, number, "units length", values, 1)[0]
        if length_unit <= 0.0:
            raise FileFormatError(
                f"{path}, line {number}: units length: expected a positive number, got {values}"
            )
    in_degrees = True
    if "angle" in units:
        number, values = units["angle"]
        if values[:1] not in (["deg"], ["rad"]):
            raise FileFormatError(
                f"{path}, line {number}: units angle: expected 'deg' or 'rad', got {values}"
            )
        in_degrees = values[0] == "deg"

    root = {words[0].lower(): (number, words[1:]) for number, words in sections["root"]}
    for key in ("order", "axis"):
        if key not in root:
            raise FileFormatError(f"{path}: :root: expected a line '{key} ...', found none")
    number, root_order = root["order"]
    root_order = [dof.lower() for dof in root_order]
    if any(dof not in _ROTATION_DOFS + _TRANSLATION_DOFS for dof in root_order) or len(
        set(root_order)
    ) != len(root_order):
        raise FileFormatError(
            f"{path}, line {number}: :root order: expected distinct values among "
            f"TX TY TZ RX RY RZ, got {root['order'][1]}"
        )
    root_axis = _axis_order(path, *root["axis"], "root axis")
    root_position = np.zeros(3)
    root_orientation = np.zeros(3)
    if "position" in root:
        root_position = np.array(
            acclaim_numbers(path, root["position"][0], "root position", root["position"][1], 3)
        )
    if "orientation" in root:
        root_orientation = np.array(
            acclaim_numbers(path, root["orientation"][0], "root orientation", root["orientation"][1], 3)
        )

    bones = _read_bone_data(path, sections["bonedata"])
    bone_order = _read_hierarchy(path, sections["hierarchy"], bones)
    return AsfSkeleton(
        length_unit=length_unit,
        in_degrees=in_degrees,
        root_order=root_order,
        root_axis=root_axis,
        root_position=root_position,
        root_orientation=root_orientation,
        bones=bones,
        bone_order=bone_order,
    )


def _read_bone_data(
    path: str | os.PathLike[str], entries: list[tuple[int, list[str]]]
) -> dict[str, AsfBone]:
    """Parse the ``begin ... end`` blocks of ``:bonedata``."""
    bones: dict[str, AsfBone] = {}
    block: list[tuple[int, list[str]]] | None = None
    for number, words in entries:
        keyword = words[0].lower()
        if keyword == "begin":
            block = []
        elif block is None:
            raise FileFormatError(
                f"{path}, line {number}: :bonedata: expected 'begin', got {words[0]!r}"
            )
        elif keyword == "end":
            bone = _bone(path, number, block)
            if bone.name in bones or bone.name == "root":
                raise FileFormatError(
                    f"{path}, line {bone.line}: bone name {bone.name!r} appears twice"
                )
            bones[bone.name] = bone
            block = None
        else:
            block.append((number, words))
    if block is not None:
        raise FileFormatError(
            f"{path}: :bonedata: expected 'end' after the last 'begin', found none"
        )
    return bones


def _bone(path: str | os.PathLike[str], end_line: int, block: list[tuple[int, list[str]]]) -> AsfBone:
    """One bone from the lines of its ``begin ... end`` block."""
    lines = {words[0].lower(): (number, words[1:]) for number, words in block}
    for key in ("name", "direction", "length", "axis"):
        if key not in lines:
            raise FileFormatError(
                f"{path}, line {end_line}: bone block ending here: expected a line '{key} ...', "
                f"found none"
            )
    number, values = lines["name"]
    bone = AsfBone(name=values[0] if values else "", line=number)
    if not bone.name:
        raise FileFormatError(f"{path}, line {number}: name: expected a bone name, got nothing")
    number, values = lines["direction"]
    bone.direction = np.array(acclaim_numbers(path, number, f"{bone.name} direction", values, 3))
    norm = np.linalg.norm(bone.direction)
    if norm == 0.0:
        raise FileFormatError(
            f"{path}, line {number}: {bone.name} direction: expected a non-zero vector, "
            f"got {values}"
        )
    bone.direction /= norm
    number, values = lines["length"]
    bone.length = acclaim_numbers(path, number, f"{bone.name} length", values, 1)[0]
    number, values = lines["axis"]
    bone.axis_angles = np.array(acclaim_numbers(path, number, f"{bone.name} axis", values[:3], 3))
    bone.axis_order = _axis_order(path, number, values[3:], f"{bone.name} axis")
    if "dof" in lines:
        number, values = lines["dof"]
        bone.dofs = [dof.lower() for dof in values]
        if any(dof not in _ROTATION_DOFS for dof in bone.dofs) or len(set(bone.dofs)) != len(
            bone.dofs
        ):
            raise FileFormatError(
                f"{path}, line {number}: {bone.name} dof: expected distinct values among "
                f"rx ry rz (translation and length dofs are not supported), got {values}"
            )
    return bone


def _read_hierarchy(
    path: str | os.PathLike[str], entries: list[tuple[int, list[str]]], bones: dict[str, AsfBone]
) -> list[str]:
    """Set each bone's parent from ``:hierarchy``; return the bones depth first from the root."""
    children: dict[str, list[str]] = {"root": []}
    for number, words in entries:
        if words[0].lower() in ("begin", "end"):
            continue
        parent, *parent_children = words
        if parent != "root" and parent not in bones:
            raise FileFormatError(
                f"{path}, line {number}: :hierarchy: {parent!r} is not a bone of :bonedata"
            )
        for child in parent_children:
            if child not in bones:
                raise FileFormatError(
                    f"{path}, line {number}: :hierarchy: {child!r} is not a bone of :bonedata"
                )
            if bones[child].parent is not None:
                raise FileFormatError(
                    f"{path}, line {number}: :hierarchy: {child!r} already has the parent "
                    f"{bones[child].parent!r}"
                )
            bones[child].parent = parent
            children.setdefault(parent, []).append(child)
    order: list[str] = []
    stack = list(reversed(children["root"]))
    while stack:
        name = stack.pop()
        order.append(name)
        stack.extend(reversed(children.get(name, [])))
    unreached = [name for name in bones if name not in order]
    if unreached:
        raise FileFormatError(
            f"{path}: :hierarchy: expected every bone below the root, but {unreached} are not"
        )
    return order


def acclaim_words(line: str) -> list[str]:
    """The words of an ASF or AMC line, comment dropped, commas and parentheses as whitespace."""
    return line.split("#", 1)[0].translate(_SEPARATORS).split()


def acclaim_numbers(
    path: str | os.PathLike[str], number: int, what: str, words: list[str], count: int
) -> list[float]:
    """Exactly ``count`` numbers from the words of a line.

    Raises:
        FileFormatError: Another count, or a word that is not a number; the message names the
            file, the line and the field (``what``).
    """
    if len(words) != count or not all(is_number(word) for word in words):
        raise FileFormatError(
            f"{path}, line {number}: {what}: expected {count} number(s), got {words}"
        )
    return [float(word) for word in words]


def _axis_order(path: str | os.PathLike[str], number: int, words: list[str], what: str) -> str:
    """A rotation order such as ``XYZ``."""
    order = words[0].upper() if len(words) == 1 else ""
    if sorted(order) != ["X", "Y", "Z"]:
        raise FileFormatError(
            f"{path}, line {number}: {what}: expected an order of X, Y and Z such as XYZ, "
            f"got {words}"
        )
    return order
