"""Euler angles.
"""

from __future__ import annotations

import numpy as np

from ibik_pin.exceptions import (
    InputError,
)


def euler_to_matrices(angles: np.ndarray, axes: str, intrinsic: bool = True) -> np.ndarray:
    """Rotation matrices from successive rotations about coordinate axes.

    For ``axes = "ZXY"`` and angles (a, b, c), intrinsic rotations give
    R = R_z(a) @ R_x(b) @ R_y(c) (the BVH convention: each rotation about the axes already
    rotated), extrinsic ones R = R_y(c) @ R_x(b) @ R_z(a) (each about the fixed axes).

    Args:
        angles: Angles, shape (..., n) [rad], n = len(axes).
        axes: The n rotation axes in order, letters among "XYZ" (case-insensitive); any
            length, repetitions allowed.
        intrinsic: Whether the rotations are about the moving axes.

    Returns:
        Rotation matrices, shape (..., 3, 3).

    Raises:
        InputError: ``axes`` holds another letter or its length is not ``angles.shape[-1]``.
    """
    angles = np.asarray(angles, dtype=float)
    axis_indices = _axis_indices(axes)
    if angles.ndim == 0 or angles.shape[-1] != len(axis_indices):
        raise InputError(
            f"angles: expected shape (..., {len(axis_indices)}) for axes {axes!r}, "
            f"got {angles.shape}"
        )
    rotations = np.broadcast_to(np.eye(3), (*angles.shape[:-1], 3, 3))
    for position, axis in enumerate(axis_indices):
        rotation = _axis_rotations(axis, angles[..., position])
        rotations = rotations @ rotation if intrinsic else rotation @ rotations
    return np.array(rotations)



def matrices_to_euler(rotations: np.ndarray, axes: str) -> np.ndarray:
    """Intrinsic Euler angles of rotation matrices, the inverse of :func:`euler_to_matrices`.

    For ``axes = "ZXY"`` it returns (a, b, c) with R = R_z(a) @ R_x(b) @ R_y(c),
    a, c in [-pi, pi] and b in [-pi/2, pi/2]. Near gimbal lock (b = +-pi/2) only a + c or a - c
    is defined: a is then taken from the matrix and c fitted to what remains, so the angles
    always rebuild the matrix to rounding error.

    Args:
        rotations: Rotation matrices, shape (..., 3, 3).
        axes: Three distinct letters among "XYZ" (case-insensitive).

    Returns:
        Angles, shape (..., 3) [rad].

    Raises:
        InputError: ``axes`` is not three distinct axes, or ``rotations`` is not (..., 3, 3).
    """
    rotations = np.asarray(rotations, dtype=float)
    axis_indices = _axis_indices(axes)
    if sorted(axis_indices) != [0, 1, 2]:
        raise InputError(f"axes: expected three distinct letters among 'XYZ', got {axes!r}")
    i, j, k = axis_indices
    if rotations.ndim < 2 or rotations.shape[-2:] != (3, 3):
        raise InputError(f"rotations: expected shape (..., 3, 3), got {rotations.shape}")
    sign = 1.0 if (j - i) % 3 == 1 else -1.0
    cos_middle = np.hypot(rotations[..., i, i], rotations[..., i, j])
    middle = np.arctan2(sign * rotations[..., i, k], cos_middle)
    first = np.where(
        cos_middle > 1e-10,
        np.arctan2(-sign * rotations[..., j, k], rotations[..., k, k]),
        np.arctan2(sign * rotations[..., k, j], rotations[..., j, j]),
    )
    # The third angle is fitted to the residual rotation R_j(b)^T R_i(a)^T R, so that rounding
    # in the first two never shows in the rebuilt matrix.
    residual = (
        np.swapaxes(_axis_rotations(i, first) @ _axis_rotations(j, middle), -1, -2) @ rotations
    )
    p, q = (k + 1) % 3, (k + 2) % 3
    last = np.arctan2(residual[..., q, p], residual[..., p, p])
    return np.stack([first, middle, last], axis=-1)



def _axis_indices(axes: str) -> list[int]:
    """The indices (0, 1, 2) of axis letters "XYZ"."""
    if not isinstance(axes, str) or any(letter not in "XYZxyz" for letter in axes):
        raise InputError(f"axes: expected letters among 'XYZ', got {axes!r}")
    return ["XYZ".index(letter) for letter in axes.upper()]



def _axis_rotations(axis: int, angles: np.ndarray) -> np.ndarray:
    """Rotations about one coordinate axis (0, 1, 2), shape (..., 3, 3), angles (...) [rad]."""
    cos, sin = np.cos(angles), np.sin(angles)
    p, q = (axis + 1) % 3, (axis + 2) % 3
    rotations = np.zeros((*np.shape(angles), 3, 3))
    rotations[..., axis, axis] = 1.0
    rotations[..., p, p] = cos
    rotations[..., q, q] = cos
    rotations[..., q, p] = sin
    rotations[..., p, q] = -sin
    return rotations
