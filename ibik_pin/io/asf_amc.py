"""Acclaim motion files (.amc) on their skeleton (.asf): world joint positions over frames.

The skeleton is read by :mod:`ibik_pin.io.asf`. Conventions (Acclaim's, as CMU's viewer
implements them):

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
"""

from __future__ import annotations

import os

import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.asf import AsfSkeleton, acclaim_numbers, acclaim_words, read_asf
from ibik_pin.io.files import read_text
from ibik_pin.io.skeleton import SkeletonMotion, axis_rotations

__all__ = ["read_asf_amc"]


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
    skeleton = read_asf(asf_path)
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
        assert bone.parent is not None  # read_asf gives every bone a parent or raises
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


def _read_amc(
    path: str | os.PathLike[str], skeleton: AsfSkeleton
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The dof values of every frame: per bone with dofs, shape (F, n); the root's, (F, 6)."""
    moving = {name: len(bone.dofs) for name, bone in skeleton.bones.items() if bone.dofs}
    expected_counts = {"root": len(skeleton.root_order), **moving}
    frames: list[dict[str, list[float]]] = []
    frame_lines: list[int] = []
    frame_number = 0
    for number, line in enumerate(read_text(path, "AMC").splitlines(), 1):
        words = acclaim_words(line)
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
        values = acclaim_numbers(path, number, name, words[1:], expected_counts[name])
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
