"""Plausibility of `ibik track`'s inputs, beyond their syntax: a wrong result must not be silent.

A TRC must hold a human-sized body in its declared units (the message suggests the unit that would
make it one), distinct marker names, increasing times and at least one value; a target that leaps
metres away from the rest of the body in one frame is dropped for that frame, with a warning; every
camera must see the targets in front of it and inside its image; silhouettes that are all empty
turn the image term off, with a warning.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ibik_pin.exceptions import IbikWarning, InputError
from ibik_pin.io.trc import METRES_PER_UNIT, TrcData

__all__ = ["MAX_BODY_SPAN_M", "MIN_BODY_SPAN_M", "OUTLIER_DISTANCE_M", "check_cameras_see_targets",
           "check_trc", "drop_outlier_targets", "silhouettes_all_empty"]

# The largest distance between two keypoints of one frame that a human body spans (arms spread,
# a leap) and, with at least MIN_SPAN_KEYPOINTS keypoints, the smallest (a crouch, seen from the
# hips to the head) [m]: a body outside them is in the wrong units.
MAX_BODY_SPAN_M = 3.0
MIN_BODY_SPAN_M = 0.3
MIN_SPAN_KEYPOINTS = 4
# A target farther than this from the median of its frame's targets is no part of the body [m].
OUTLIER_DISTANCE_M = 2.5


def check_trc(option: str, path: Path, data: TrcData, positions_m: np.ndarray) -> None:
    """Refuse a TRC that cannot be a human recorded in its declared units (InputError naming
    `option` and `path`): duplicate marker names, times that do not increase, no value at all, or a
    body that spans more than MAX_BODY_SPAN_M or less than MIN_BODY_SPAN_M (median over frames)."""
    names = list(data.marker_names)
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise InputError(f"{option} {path}: marker name(s) {', '.join(repeated)} appear more than once")
    times = np.asarray(data.times, dtype=float)
    if times.size > 1 and not np.all(np.diff(times) > 0):
        frame = int(np.argmax(~(np.diff(times) > 0))) + 1
        raise InputError(f"{option} {path}: the Time column does not increase (row {frame + 1} of the data: "
                         f"{times[frame - 1]:g} then {times[frame]:g} s)")
    if positions_m.size == 0 or not np.isfinite(positions_m).any():
        raise InputError(f"{option} {path}: no marker has a value in any frame")
    span = body_span_m(positions_m)
    if np.isfinite(span) and not MIN_BODY_SPAN_M <= span <= MAX_BODY_SPAN_M:
        declared = data.units
        fitting = [unit for unit, factor in METRES_PER_UNIT.items()
                   if MIN_BODY_SPAN_M <= span / METRES_PER_UNIT[declared] * factor <= MAX_BODY_SPAN_M]
        hint = f"; are the values in {fitting[0]}? (set Units in the header)" if fitting else ""
        raise InputError(f"{option} {path}: the body spans {span:.3g} m read in the declared units "
                         f"({declared}), not a human's {MIN_BODY_SPAN_M}-{MAX_BODY_SPAN_M} m{hint}")


def body_span_m(positions_m: np.ndarray) -> float:
    """Median over frames of the largest distance between two of a frame's keypoints [m]; NaN when
    no frame has MIN_SPAN_KEYPOINTS finite keypoints."""
    spans = []
    for frame in positions_m:
        points = frame[np.isfinite(frame).all(axis=1)]
        if len(points) >= MIN_SPAN_KEYPOINTS:
            spans.append(float(np.max(np.linalg.norm(points[:, None] - points[None], axis=2))))
    return float(np.median(spans)) if spans else float("nan")


def drop_outlier_targets(option: str, names: Sequence[str], targets_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The targets with every value farther than OUTLIER_DISTANCE_M from its frame's median set to
    NaN (dropped for that frame, as an occluded target is), and (F, T) bool: which were dropped.
    One warning counts them and names the first few."""
    cleaned = targets_m.copy()
    median = np.nanmedian(np.where(np.isfinite(targets_m), targets_m, np.nan), axis=1, keepdims=True) \
        if np.isfinite(targets_m).any() else targets_m
    with np.errstate(invalid="ignore"):
        far = np.linalg.norm(targets_m - median, axis=2) > OUTLIER_DISTANCE_M
    if far.any():
        cleaned[far] = np.nan
        frames, keypoints = np.nonzero(far)
        pairs = list(zip(frames, keypoints, strict=True))[:5]
        listed = ", ".join(f"{names[int(k)]} in frame {int(f) + 1}" for f, k in pairs)
        more = f" and {far.sum() - 5} more" if far.sum() > 5 else ""
        warnings.warn(f"{option}: {int(far.sum())} target value(s) lie more than {OUTLIER_DISTANCE_M} m from the "
                      f"rest of the body and are dropped for their frame: {listed}{more}", IbikWarning, stacklevel=2)
    return cleaned, far


def check_cameras_see_targets(cameras: Sequence, targets_trc_m: np.ndarray, frames: Sequence[int],
                              trc_to_model: Sequence[np.ndarray]) -> None:
    """Refuse a calibration where a camera sees no target in front of it and inside its image over
    the sampled frames, under every axis convention still in question (InputError naming the
    camera): a camera that fails under all of them is wrong whatever the TRC's axes.

    Args:
        cameras: cameras that project model-frame points.
        targets_trc_m: (F, K, 3) targets as the TRC holds them [m].
        frames: the frames to look at.
        trc_to_model: one (3, 3) rotation per convention in question (app.axes.TRC_TO_MODEL).
    """
    points_trc = targets_trc_m[list(frames)].reshape(-1, 3)
    points_trc = points_trc[np.isfinite(points_trc).all(axis=1)]
    if not len(points_trc):
        return
    for camera in cameras:
        width, height = camera.size
        in_front = inside = False
        for rotation in trc_to_model:
            projection = camera.project_with_jacobian(points_trc @ np.asarray(rotation).T)
            front = projection.depth > 0
            with np.errstate(invalid="ignore", over="ignore"):
                u, v = projection.pixels[:, 0], projection.pixels[:, 1]
                seen = front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
            in_front |= bool(front.any())
            inside |= bool(seen.any())
        if not in_front:
            raise InputError(f"--calibration: camera {camera.name!r} has every target behind it; check its "
                             "rotation and translation (and that --targets is the same recording)")
        if not inside:
            raise InputError(f"--calibration: camera {camera.name!r} sees none of the targets inside its "
                             f"{width} x {height} px image; check its intrinsics, distortion and pose")


def silhouettes_all_empty(frame_silhouettes: Callable[[int], Sequence[np.ndarray]], frame_count: int,
                          samples: int = 12) -> bool:
    """Whether every silhouette of `samples` frames spread over the sequence is empty."""
    frames = np.unique(np.linspace(0, frame_count - 1, min(samples, frame_count)).astype(int))
    return not any(mask.any() for frame in frames for mask in frame_silhouettes(int(frame)))
