"""Checks of user input that several modules share.

Each function returns the value converted to the type the package computes with, or raises one
:class:`~ibik_pin.exceptions.InputError` that names the parameter, what was expected and what
came. Camera parameters are checked by the cameras and by the calibration reader alike, radii by
the cameras and the renderer, masks by the support images and the segmentation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import numpy as np
from numba import njit

from ibik_pin.exceptions import InputError

__all__ = ["as_finite_array", "as_float_array", "as_image_size", "as_mask", "as_radii", "require_instance"]


def require_instance(value: object, kinds: type | tuple[type, ...], name: str, expected: str) -> None:
    """Raise InputError naming `name` unless `value` is one of `kinds` (`expected` says what in words)."""
    if not isinstance(value, kinds):
        raise InputError(f"{name}: expected {expected}, found {type(value).__name__}", parameter=name)


def as_float_array(value, name: str) -> np.ndarray:
    """`value` as a new float64 array, or InputError naming `name` when it holds no numbers (text,
    objects): numpy's own error would name neither the parameter nor the value."""
    try:
        return np.array(value, dtype=float)
    except (TypeError, ValueError) as error:
        raise InputError(f"{name}: expected numbers, found {type(value).__name__} ({error})",
                         parameter=name) from None


@njit(cache=True, nogil=True)
def all_finite(values: np.ndarray) -> bool:
    """Whether every entry of an array is finite: the check of every solver step's rows and q, where
    numpy's isfinite and all cost five times this compiled loop."""
    for value in values.ravel():  # noqa: SIM110 (Numba compiles the loop, not a generator)
        if not np.isfinite(value):
            return False
    return True


def as_finite_array(value, shape: tuple[int, ...] | Sequence[tuple[int, ...]], name: str) -> np.ndarray:
    """A finite float64 array of one of the given shapes.

    Args:
        value: Anything numpy turns into a numeric array.
        shape: One shape, e.g. ``(3, 3)`` (``()`` for a scalar), or a list of accepted shapes,
            e.g. ``[(4,), (5,)]``.
        name: The parameter's name, for the message.

    Returns:
        The array, float64, of one of the shapes.

    Raises:
        InputError: The value is not numeric, has another shape, or holds NaN or infinity.
    """
    shapes = cast(list[tuple[int, ...]], [shape] if len(shape) == 0 or isinstance(shape[0], int) else list(shape))
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise InputError(f"{name}: expected a numeric array, found {value!r} ({error})") from None
    if array.shape not in [tuple(s) for s in shapes]:
        expected = " or ".join(str(tuple(s)) for s in shapes)
        raise InputError(f"{name}: expected shape {expected}, found shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name}: expected finite values, found {array.tolist()}")
    return array


def as_image_size(size, name: str = "size") -> tuple[int, int]:
    """An image size (width, height) [px]: two positive whole numbers (``640.0`` is accepted).

    Raises:
        InputError: Not two numbers, or one of them is not a positive whole number.
    """
    try:
        values = [float(s) for s in size]
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected (width, height) in pixels, found {size!r}") from None
    if len(values) != 2 or not all(math.isfinite(s) and s >= 1 and s == int(s) for s in values):
        raise InputError(f"{name}: expected (width, height), two positive integers [px], found {size!r}")
    return int(values[0]), int(values[1])


def as_radii(radii, count: int, name: str = "radii") -> np.ndarray:
    """Radii of `count` spheres [m], shape (count,); a scalar is the radius of every one.

    Raises:
        InputError: Another shape, or a radius that is negative or not finite.
    """
    radii = np.asarray(radii, dtype=np.float64)
    if radii.ndim == 0:
        radii = np.full(count, float(radii))
    if radii.shape != (count,):
        raise InputError(f"{name}: expected shape ({count},) [m] or a scalar, found shape {radii.shape}")
    if not np.all(np.isfinite(radii)) or np.any(radii < 0.0):
        raise InputError(f"{name}: expected finite non-negative radii [m], found {radii.tolist()}")
    return radii


def as_mask(mask, name: str = "mask") -> np.ndarray:
    """A (H, W) bool array from a bool or uint8 mask (non-zero = set).

    Raises:
        InputError: Not a numpy array, another dtype, or not two-dimensional and non-empty.
    """
    if not isinstance(mask, np.ndarray):
        raise InputError(f"{name}: expected a numpy array of dtype bool or uint8, found {type(mask).__name__}")
    if mask.dtype not in (np.bool_, np.uint8):
        raise InputError(f"{name}: expected dtype bool or uint8 (non-zero = set), found dtype {mask.dtype}")
    if mask.ndim != 2 or mask.shape[0] < 1 or mask.shape[1] < 1:
        raise InputError(f"{name}: expected a 2D (H, W) array, found shape {mask.shape}")
    return mask.copy() if mask.dtype == np.bool_ else mask != 0  # a copy, as != 0 gives, at a tenth of its time
