"""Support images: what the image criterion reads, and its exact derivative.

A support image I_c holds, for one view, how much a projected skeleton sample is rewarded at
each pixel [support units; px for a distance]. The image criterion reads it at projected points
with bilinear interpolation and follows the exact derivative of that interpolant.

Pixel convention (OpenCV's, as in :mod:`ibik_pin.vision.camera`): the centre of pixel (row i,
column j) is at ``u = j, v = i``.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import NamedTuple, Protocol, cast

import numpy as np

from ibik_pin.checks import as_mask
from ibik_pin.exceptions import EmptySilhouetteWarning, InputError
from ibik_pin.vision.distance import (
    InsideDistance,
    ScannedMask,
    inside_distance,
    scan_mask,
    signed_distance,
)
from ibik_pin.vision.kernels import support_sample
from ibik_pin.vision.support_window import TARGETS_MARGIN_PX, Recipe, Window, holds, read_box


class SupportSample(NamedTuple):
    """A support image read at points.

    Attributes:
        values: (N,) interpolated support [support units].
        gradient: (N, 2) derivative of ``values`` with respect to (u, v) [support units/px].
    """

    values: np.ndarray
    gradient: np.ndarray


class SupportImageLike(Protocol):
    """What the image criterion needs of a support image; :class:`SupportImage` satisfies it.

    Attributes:
        size: (width, height) of the image [px]; must be its camera's.
        enabled: False when the view has no usable silhouette: the image term skips the view.
    """

    @property
    def size(self) -> tuple[int, int]: ...

    @property
    def enabled(self) -> bool: ...

    def sample(self, pixels: np.ndarray) -> SupportSample:
        """Values (N,) and gradient (N, 2) d values / d (u, v) at (N, 2) pixels [px]."""
        ...

    def held_values(self, whole_frame: bool = False,
                    covering: tuple[slice, slice] | None = None) -> tuple[np.ndarray, int, int]:
        """The values computed so far, (h, w) float32, and the (row, column) of the frame where
        they start; with `covering`, values that hold those pixels of the frame too; with
        `whole_frame`, the frame's (H, W) values from (0, 0)."""
        ...


def _as_pixels(pixels) -> np.ndarray:
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim != 2 or pixels.shape[1] != 2:
        raise InputError(f"pixels: expected an array of shape (N, 2) [px], found shape {pixels.shape}")
    if np.isnan(pixels).any():  # infinite coordinates are fine: clamped to the border
        nan_rows = np.isnan(pixels).any(axis=1)
        raise InputError(f"pixels: expected coordinates that are not NaN, found {int(nan_rows.sum())} row(s) with NaN")
    return pixels


class SupportImage:
    """A support image of one view and whether the image term uses it.

    A support built from a silhouette (:func:`support_from_mask`) may hold its values on a window
    around the body only: samples inside it, nearly all of them while tracking, are read there; a
    read outside it computes a wider window that holds what was read (held_values' `covering`), or
    the whole frame (the same values either way).

    Attributes:
        values: (H, W) float32 support [support units], read-only.
        enabled: False when the view has no usable silhouette (empty mask): the image term
            skips the view.
        size: (width, height) [px].
    """

    def __init__(self, values, enabled: bool = True) -> None:
        values = np.asarray(values)
        if values.ndim != 2 or values.shape[0] < 1 or values.shape[1] < 1:
            raise InputError(f"values: expected a non-empty (H, W) array, found shape {values.shape}")
        if not np.issubdtype(values.dtype, np.number) or np.issubdtype(values.dtype, np.complexfloating):
            raise InputError(f"values: expected real numbers, found dtype {values.dtype}")
        values = np.array(values, dtype=np.float32, order="C", copy=True)
        if not np.all(np.isfinite(values)):
            raise InputError("values: expected finite support values, found NaN or infinity")
        values.setflags(write=False)
        self._values: np.ndarray | None = values
        self._enabled = bool(enabled)
        self._size = (values.shape[1], values.shape[0])
        self._window: Window | None = None
        self._whole_frame: Callable[[], np.ndarray] | None = None
        self._wider: Callable[[Window, tuple[slice, slice]], Window | None] | None = None
        self._recipe: Recipe | None = None  # set by support_from_mask on a windowed support

    @classmethod
    def _windowed(cls, window: Window, size: tuple[int, int], whole_frame: Callable[[], np.ndarray],
                  wider: Callable[[Window, tuple[slice, slice]], Window | None]) -> SupportImage:
        """An enabled support known on `window`, the whole frame from `whole_frame()` when needed,
        and `wider(window, covering)` a window that holds both (None: only the whole frame does)."""
        support = cls.__new__(cls)
        support._values = None
        support._enabled = True
        support._size = size
        support._window = window
        support._whole_frame = whole_frame
        support._wider = wider
        support._recipe = None
        return support

    @property
    def values(self) -> np.ndarray:
        if self._values is None:
            values = cast(Callable[[], np.ndarray], self._whole_frame)()
            values.setflags(write=False)
            self._values, self._whole_frame, self._wider = values, None, None  # the mask it was computed from let go
            self._recipe = None
        return self._values

    @property
    def enabled(self) -> bool:
        return self._enabled

    def held_values(self, whole_frame: bool = False,
                    covering: tuple[slice, slice] | None = None) -> tuple[np.ndarray, int, int]:
        """The values computed so far, (h, w) float32, and the (row, column) of the frame where
        they start: the window around the body; with `covering` ((rows, columns) of the frame), a
        window that also holds those pixels, computed wider if need be; with `whole_frame` (or once
        computed, or where a wider window would be the frame), the frame's (H, W) values from (0, 0).

        On the Pose2Sim video a tenth of the views read outside their window, each the whole frame
        until covering was asked for: a wider window is a fraction of it.
        """
        if self._values is None and not whole_frame:
            window = cast(Window, self._window)
            if covering is not None and not holds(window, covering) and self._wider is not None:
                wider = self._wider(window, covering)
                if wider is None:
                    return self.values, 0, 0
                window = self._window = wider
            return window.values, window.row, window.column
        return self.values, 0, 0

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) [px]."""
        return self._size

    def __add__(self, other: SupportImage) -> SupportImage:
        """Pixel-wise sum, e.g. a silhouette support plus an :func:`obstacle_support`.

        The sum is enabled only if both terms are: a view disabled for an empty silhouette
        stays disabled.
        """
        if not isinstance(other, SupportImage):
            return NotImplemented
        if other.size != self.size:
            raise InputError(
                f"other: expected a support image of size (w, h) = {self.size}, found {other.size}"
            )
        return SupportImage(self.values + other.values, self.enabled and other.enabled)

    def sample_mask(self, pixels: np.ndarray) -> np.ndarray:
        """(N,) True for pixels (N, 2) [px] inside the image (0 <= u <= W - 1, 0 <= v <= H - 1)."""
        pixels = _as_pixels(pixels)
        width, height = self.size
        u, v = pixels[:, 0], pixels[:, 1]
        return (u >= 0.0) & (u <= width - 1) & (v >= 0.0) & (v <= height - 1)

    def sample(self, pixels: np.ndarray) -> SupportSample:
        """Bilinear interpolation of the support and its exact derivative at pixels.

        The gradient is the derivative of the same piecewise-bilinear interpolant, so it agrees
        with finite differences to rounding inside each pixel cell. Outside the image
        (infinity included) the coordinates are clamped to the border and the gradient along a
        clamped axis is zero.

        Args:
            pixels: (N, 2) image coordinates (u, v) [px].

        Returns:
            :class:`SupportSample` with values (N,) and gradient (N, 2) d values / d (u, v).
        """
        pixels = _as_pixels(pixels)
        values, gradient = np.empty(len(pixels)), np.empty((len(pixels), 2))
        held = self.held_values()
        for attempt in range(3):  # the window around the body; one wider, or the whole frame
            if support_sample(pixels, *held, *self.size, values, gradient):
                break
            covering = read_box(pixels, *self.size) if attempt == 0 else None
            held = self.held_values(whole_frame=covering is None, covering=covering)
        return SupportSample(values, gradient)


def _positive_or_none(value, name: str) -> float | None:
    if value is None:
        return None
    value = float(value)
    if not np.isfinite(value) or value <= 0.0:
        raise InputError(f"{name}: expected a positive number of pixels or None, found {value}")
    return value


def support_from_mask(
    mask: np.ndarray | ScannedMask,
    inside_cap_px: float | None = 6.0,
    outside_cap_px: float | None = None,
    smooth_sigma_px: float = 1.0,
    inside: InsideDistance | None = None,
    also_around: tuple[slice, slice] | None = None,
) -> SupportImage:
    """The signed-distance support of a silhouette.

    Inside the silhouette: the distance to its border, capped at ``inside_cap_px`` (about a
    limb's half-width: the uncapped distance peaks in the trunk and pulls limb segments through
    it). Outside: minus the distance to the body (optionally truncated at ``outside_cap_px``),
    so that a segment lying outside is pulled in. Then a light Gaussian blur.

    Args:
        mask: (H, W) bool or uint8 silhouette, non-zero = person; or its vision.distance.ScannedMask.
        inside_cap_px: cap of the inside distance [px]; None for no cap.
        outside_cap_px: truncation of the outside distance [px]; None for none.
        smooth_sigma_px: standard deviation of the Gaussian blur [px]; 0 for none.
        inside: the mask's vision.distance.inside_distance if known (shared with the medial axis);
            one computed with a `limit` needs an inside cap of at most limit - 0.5 px.
        also_around: (rows, columns) of the frame that the window of computed values covers besides
            the silhouette, with a wider margin (where the skeleton is expected: the tracker's
            projected targets; vision.support_window's margins). A read outside the window
            computes a wider one around it, which happens most where silhouettes are partial
            (background subtraction keeps the moving limbs).

    Returns:
        The support [px]. An empty mask gives zeros with ``enabled=False`` and an
        :class:`EmptySilhouetteWarning`.

    Raises:
        InputError: the mask is not a 2D bool/uint8 array, or a parameter is out of range.
    """
    scanned = mask if isinstance(mask, ScannedMask) else scan_mask(mask)
    mask = scanned.mask
    inside_cap_px = _positive_or_none(inside_cap_px, "inside_cap_px")
    outside_cap_px = _positive_or_none(outside_cap_px, "outside_cap_px")
    smooth_sigma_px = float(smooth_sigma_px)
    if not np.isfinite(smooth_sigma_px) or smooth_sigma_px < 0.0:
        raise InputError(f"smooth_sigma_px: expected a non-negative number of pixels, found {smooth_sigma_px}")
    if scanned.set_pixels == 0:
        warnings.warn(
            f"mask: the silhouette of size (w, h) = {(mask.shape[1], mask.shape[0])} is empty; "
            "the image term is disabled for this view",
            EmptySilhouetteWarning,
            stacklevel=2,
        )
        return SupportImage(np.zeros(mask.shape, np.float32), enabled=False)
    if scanned.set_pixels == mask.size:
        # No border in the image: every pixel is deep inside.
        inside_value = inside_cap_px if inside_cap_px is not None else float(max(mask.shape))
        return SupportImage(np.full(mask.shape, inside_value, np.float32))
    if inside is None:
        inside = inside_distance(mask, scanned.box)
    elif inside.limit is not None and (inside_cap_px is None or inside_cap_px + 0.5 > inside.limit):
        # The support reads the inside distance less half a pixel, capped (vision.distance.signed_distance).
        raise InputError(f"inside: its values are exact up to {inside.limit} px only, which an inside cap "
                         f"of {inside_cap_px} px exceeds (the cap must be at most limit - 0.5)")
    recipe = Recipe(mask, inside, inside_cap_px, outside_cap_px, smooth_sigma_px)
    boxes = []
    if also_around is not None:
        rows, columns = also_around
        if rows.start < rows.stop and columns.start < columns.stop:  # clipped to the frame by window_around
            boxes.append((also_around, TARGETS_MARGIN_PX))
    window = recipe.window(boxes)
    if window is None:
        return SupportImage(recipe.values(None))
    support = SupportImage._windowed(window, (mask.shape[1], mask.shape[0]), functools.partial(recipe.values, None),
                                     recipe.wider)
    support._recipe = recipe
    return support


def obstacle_support(object_mask: np.ndarray, influence_px: float) -> SupportImage:
    """A repulsive support around an object drawn into the image (the paper's Figure 8).

    With s the signed distance to the object's border [px] (positive outside, L = influence_px):
    0 for s >= L, ``-L (1 - s/L)^2`` for 0 <= s < L (smooth at s = L, slope 2 at the border) and
    ``-L + 2 s`` inside (s < 0: keeps decreasing toward the object's middle, so a sample inside
    is pushed out). Add it to a silhouette support with ``+``; scale ``influence_px`` to make
    the obstacle weigh more or less against the silhouette.

    Args:
        object_mask: (H, W) bool or uint8, non-zero = object.
        influence_px: distance over which the object repels [px].

    Returns:
        The support [px], all zeros (and enabled) if the object mask is empty.

    Raises:
        InputError: the mask is not a 2D bool/uint8 array, or ``influence_px`` is not positive.
    """
    mask = as_mask(object_mask, "object_mask")
    influence = _positive_or_none(influence_px, "influence_px")
    if influence is None:
        raise InputError("influence_px: expected a positive number of pixels, found None")
    if not mask.any():
        return SupportImage(np.zeros(mask.shape, np.float32))
    if mask.all():
        return SupportImage(np.full(mask.shape, -influence - float(max(mask.shape)), np.float32))
    distance = -signed_distance(mask).astype(np.float64)  # positive outside the object
    ramp = 1.0 - np.clip(distance, 0.0, influence) / influence
    values = np.where(distance >= 0.0, -influence * ramp * ramp, -influence + 2.0 * distance)
    return SupportImage(values)
