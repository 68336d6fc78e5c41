"""Biovision hierarchy files (.bvh) written from a skeleton's local rotations, in metres.

The conventions are those :mod:`ibik_pin.io.bvh` reads (intrinsic rotation channels, OFFSET in
the parent's frame, End Site offsets), so that :func:`~ibik_pin.io.bvh.read_bvh` with
``scale=1.0`` gives back the joint positions written.
"""

from __future__ import annotations

import os

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.io.files import write_text_atomically
from ibik_pin.io.skeleton import euler_angles

__all__ = ["write_bvh"]


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
    of the local rotations (:func:`~ibik_pin.io.skeleton.euler_angles`: they rebuild the
    rotation also at gimbal lock). The root's position channels hold
    ``root_positions - offsets[root]``, so that the root ends at ``root_positions``. Joints are
    written depth first from the root, children in index order;
    :func:`~ibik_pin.io.bvh.read_bvh` returns them in that order. Every joint without children
    gets an End Site. The file is written atomically
    (:func:`~ibik_pin.io.files.write_text_atomically`).

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
    angles = np.rad2deg(euler_angles(local_rotations[:, joint_order], order))
    values = np.concatenate(
        [root_positions - offsets[root], angles.reshape(frame_count, 3 * joint_count)], axis=1
    )
    lines += ["MOTION", f"Frames: {frame_count}", f"Frame Time: {float(frame_time)!r}"]
    lines += [" ".join(map(repr, row)) for row in values.tolist()]
    write_text_atomically(path, "\n".join(lines) + "\n")


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
