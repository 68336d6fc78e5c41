"""Acclaim skeleton (.asf) and motion (.amc) files, as the CMU motion capture database holds them.

Conventions (Acclaim's, as CMU's viewer implements them):

- A bone's ``axis ax ay az XYZ`` gives its local frame in the rest pose: the angles about X, Y
  and Z, applied in the order of the letters about the fixed axes (``XYZ``:
  C = R_z(az) @ R_y(ay) @ R_x(ax)). The root's ``orientation`` and ``axis`` give its C the same
  way.
- A frame's rotation dof values (d1, d2, ...) in the order of the bone's ``dof`` line (the
  root's: its ``order`` line) give M = ... @ R(d2) @ R(d1), about the bone's local axes.
- A bone's world rotation is L = L_parent @ C @ M @ C^T (the root's: C @ M @ C^T); its end point
  is the parent bone's end point plus length * L @ direction. The root is at its ``position``
  plus the frame's TX TY TZ.
- Lengths times 0.0254 / ``:units length`` are metres (CMU: length 0.45, a unit of
  1/0.45 inch); angles are in ``:units angle`` (deg or rad).
- Commas and parentheses are whitespace, ``#`` starts a comment.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import is_number, read_text
from ibik_pin.io.skeleton import SkeletonMotion, axis_rotations

_ROTATION_DOFS = ("rx", "ry", "rz")
_TRANSLATION_DOFS = ("tx", "ty", "tz")
_SEPARATORS = str.maketrans(",()", "   ")


@dataclass
class _Bone:
    """A bone of the ASF file, lengths in file units, angles in file angle units."""

    name: str
    line: int
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    length: float = 0.0
    axis_angles: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis_order: str = "XYZ"
    dofs: list[str] = field(default_factory=list)
    parent: str | None = None


@dataclass
class _Skeleton:
    """The content of an ASF file that forward kinematics needs."""

    length_unit: float
    in_degrees: bool
    root_order: list[str]
    root_axis: str
    root_position: np.ndarray
    root_orientation: np.ndarray
    bones: dict[str, _Bone]
    bone_order: list[str]


def read_asf_amc(
    asf_path: str | os.PathLike[str], amc_path: str | os.PathLike[str], frame_rate: float = 120.0
) -> SkeletonMotion:
    """World positions of the root and of every bone's end point, over the frames of an AMC.

    The joints are the root (named ``"root"``) and every bone, named after it and placed at its
    end point (``"ltibia"`` is the left ankle), depth first from the root in the order of the
    ASF's ``:hierarchy``. Forward kinematics is vectorised over frames (see the module
    docstring for the conventions).

    Args:
        asf_path: The skeleton, e.g. CMU's ``35.asf``.
        amc_path: A motion of that skeleton, e.g. ``35_01.amc``.
        frame_rate: Frames per second [Hz]; AMC files do not state it (CMU: 120).

    Returns:
        The motion in metres, Y up as in the CMU files.

    Raises:
        FileFormatError: A file cannot be read or is ill-formed (the message names the file and
            line), or the AMC does not match the ASF.
        InputError: ``frame_rate`` is not a positive number.
    """
    if not np.isfinite(frame_rate) or frame_rate <= 0.0:
        raise InputError(f"frame_rate: expected a positive number [Hz], got {frame_rate}")
    skeleton = _read_asf(asf_path)
    dof_values, root_values = _read_amc(amc_path, skeleton)
    metres_per_unit = 0.0254 / skeleton.length_unit
    to_radians = np.pi / 180.0 if skeleton.in_degrees else 1.0
    frame_count = root_values.shape[0]

    root_rest = _rest_rotation(skeleton.root_orientation * to_radians, skeleton.root_axis)
    rotation_columns = [c for c, dof in enumerate(skeleton.root_order) if dof.startswith("r")]
    # The dof names' lower-case axis letters make axis_rotations turn about the fixed axes,
    # Acclaim's convention (see the module docstring).
    root_motion = axis_rotations(
        root_values[:, rotation_columns] * to_radians,
        "".join(skeleton.root_order[c][1] for c in rotation_columns),
    )
    translations = np.zeros((frame_count, 3))
    for column, dof in enumerate(skeleton.root_order):
        if dof.startswith("t"):
            translations[:, "xyz".index(dof[1])] = root_values[:, column]

    names = ["root", *skeleton.bone_order]
    index_of = {name: index for index, name in enumerate(names)}
    positions = np.empty((frame_count, len(names), 3))
    rotations = np.empty((frame_count, len(names), 3, 3))
    positions[:, 0] = skeleton.root_position + translations
    rotations[:, 0] = root_rest @ root_motion @ root_rest.T
    parents = [-1]
    for index, name in enumerate(skeleton.bone_order, start=1):
        bone = skeleton.bones[name]
        parent = index_of[bone.parent]
        parents.append(parent)
        rest = _rest_rotation(bone.axis_angles * to_radians, bone.axis_order)
        motion = axis_rotations(dof_values[name] * to_radians, "".join(dof[1] for dof in bone.dofs))
        rotations[:, index] = rotations[:, parent] @ rest @ motion @ rest.T
        positions[:, index] = positions[:, parent] + bone.length * (
            rotations[:, index] @ bone.direction
        )
    return SkeletonMotion(
        names=names,
        parents=np.array(parents),
        positions=positions * metres_per_unit,
        frame_rate=frame_rate,
    )


def _read_asf(path: str | os.PathLike[str]) -> _Skeleton:
    """Parse the units, root, bone data and hierarchy of an ASF file."""
    sections: dict[str, list[tuple[int, list[str]]]] = {}
    current = None
    for number, line in enumerate(read_text(path, "ASF").splitlines(), 1):
        words = _words(line)
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
        length_unit = _numbers(path, number, "units length", values, 1)[0]
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
            _numbers(path, root["position"][0], "root position", root["position"][1], 3)
        )
    if "orientation" in root:
        root_orientation = np.array(
            _numbers(path, root["orientation"][0], "root orientation", root["orientation"][1], 3)
        )

    bones = _read_bone_data(path, sections["bonedata"])
    bone_order = _read_hierarchy(path, sections["hierarchy"], bones)
    return _Skeleton(
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
) -> dict[str, _Bone]:
    """Parse the ``begin ... end`` blocks of ``:bonedata``."""
    bones: dict[str, _Bone] = {}
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


def _bone(path: str | os.PathLike[str], end_line: int, block: list[tuple[int, list[str]]]) -> _Bone:
    """One bone from the lines of its ``begin ... end`` block."""
    lines = {words[0].lower(): (number, words[1:]) for number, words in block}
    for key in ("name", "direction", "length", "axis"):
        if key not in lines:
            raise FileFormatError(
                f"{path}, line {end_line}: bone block ending here: expected a line '{key} ...', "
                f"found none"
            )
    number, values = lines["name"]
    bone = _Bone(name=values[0] if values else "", line=number)
    if not bone.name:
        raise FileFormatError(f"{path}, line {number}: name: expected a bone name, got nothing")
    number, values = lines["direction"]
    bone.direction = np.array(_numbers(path, number, f"{bone.name} direction", values, 3))
    norm = np.linalg.norm(bone.direction)
    if norm == 0.0:
        raise FileFormatError(
            f"{path}, line {number}: {bone.name} direction: expected a non-zero vector, "
            f"got {values}"
        )
    bone.direction /= norm
    number, values = lines["length"]
    bone.length = _numbers(path, number, f"{bone.name} length", values, 1)[0]
    number, values = lines["axis"]
    bone.axis_angles = np.array(_numbers(path, number, f"{bone.name} axis", values[:3], 3))
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
    path: str | os.PathLike[str], entries: list[tuple[int, list[str]]], bones: dict[str, _Bone]
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


def _read_amc(
    path: str | os.PathLike[str], skeleton: _Skeleton
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The dof values of every frame: per bone with dofs, shape (F, n); the root's, (F, 6)."""
    moving = {name: len(bone.dofs) for name, bone in skeleton.bones.items() if bone.dofs}
    expected_counts = {"root": len(skeleton.root_order), **moving}
    frames: list[dict[str, list[float]]] = []
    frame_lines: list[int] = []
    frame_number = 0
    for number, line in enumerate(read_text(path, "AMC").splitlines(), 1):
        words = _words(line)
        if not words:
            continue
        if words[0].startswith(":"):
            unit = words[0].upper()
            if unit in (":DEGREES", ":RADIANS") and (unit == ":DEGREES") != skeleton.in_degrees:
                raise FileFormatError(
                    f"{path}, line {number}: {words[0]} disagrees with the ASF's units angle "
                    f"({'deg' if skeleton.in_degrees else 'rad'})"
                )
            continue
        if len(words) == 1 and words[0].isdigit():
            if frames:
                _check_frame(path, frame_lines[-1], frames[-1], expected_counts)
            if frames and int(words[0]) != frame_number + 1:
                raise FileFormatError(
                    f"{path}, line {number}: expected frame {frame_number + 1}, got {words[0]}"
                )
            frame_number = int(words[0])
            frames.append({})
            frame_lines.append(number)
            continue
        if not frames:
            raise FileFormatError(
                f"{path}, line {number}: expected a frame number before bone values, "
                f"got {line.strip()[:40]!r}"
            )
        name = words[0]
        if name not in expected_counts:
            known = ", ".join(expected_counts)
            raise FileFormatError(
                f"{path}, line {number}: {name!r} is not a bone with dofs of the ASF; "
                f"expected one of {known}"
            )
        if name in frames[-1]:
            raise FileFormatError(
                f"{path}, line {number}: {name!r} appears twice in frame {frame_number}"
            )
        values = _numbers(path, number, name, words[1:], expected_counts[name])
        frames[-1][name] = values
    if not frames:
        raise FileFormatError(f"{path}: expected at least one frame, found none")
    _check_frame(path, frame_lines[-1], frames[-1], expected_counts)
    dof_values = {name: np.array([frame[name] for frame in frames]) for name in moving}
    dof_values.update(
        {name: np.zeros((len(frames), 0)) for name in skeleton.bones if name not in moving}
    )
    return dof_values, np.array([frame["root"] for frame in frames])


def _check_frame(
    path: str | os.PathLike[str], line: int, frame: dict[str, list[float]], expected: dict[str, int]
) -> None:
    missing = [name for name in expected if name not in frame]
    if missing:
        raise FileFormatError(f"{path}, line {line}: the frame starting here lacks {missing}")


def _rest_rotation(angles_xyz: np.ndarray, order: str) -> np.ndarray:
    """The rest frame C of a bone or the root, shape (3, 3), from its angles about X, Y and Z
    [rad], shape (3,), applied in ``order`` about the fixed axes."""
    angles = angles_xyz[["XYZ".index(axis) for axis in order]]
    return axis_rotations(angles[np.newaxis], order.lower())[0]


def _words(line: str) -> list[str]:
    """The words of a line, comment dropped, commas and parentheses as whitespace."""
    return line.split("#", 1)[0].translate(_SEPARATORS).split()


def _numbers(
    path: str | os.PathLike[str], number: int, what: str, words: list[str], count: int
) -> list[float]:
    """Exactly ``count`` numbers, else an error naming the line and the field."""
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
