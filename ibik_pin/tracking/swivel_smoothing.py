"""The free elbows' and knees' swivels low-passed over the trial, each joint kept on its own circle.

Each frame's image steps place a free elbow or knee at the criterion's peak on its swivel circle
(the circle of the points at its segments' lengths from the limb's two ends), frame by frame: the
peak jitters from one frame to the next with the silhouettes' pixels, the targets' noise and the
search's samples, while a limb's swivel moves as smoothly as any joint (most of the power of joint
motion lies below about 6 Hz, Winter, Biomechanics and Motor Control of Human Movement, ch. 2, the
figure tracking.target_filter uses for the targets).

So once every frame is solved, each limb's offset from the centre of its circle (the middle joint
less its foot on the root-end line, a 3-vector) is low-passed over time with the targets' zero-lag
filter (tracking.target_filter.lowpass), projected back onto the frame's circle
plane and brought back to the frame's radius: the limb's lengths and ends are the frame's own,
only the direction about the line changes. Filtering the vector rather than an angle needs no
reference direction and lets the frames of a nearly straight limb, whose swivel is undefined, weigh
little. On the sweep (42 conditions, 2 views, clean; docs/sweep.md), applied to the runs' joints
this way, the cutoffs 4 to 8 Hz left no condition worse by more than 1 mm; 1.5-3 Hz did.

:func:`smooth_swivels` finds every free joint's place and has the tracker move the joints there,
frame by frame, under the targets (Tracker.track's `frame_rate_hz`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.tracking.swivel import LIMB_ENDS
from ibik_pin.tracking.target_filter import MOTION_BAND_HZ, PASS_CORRECTION, lowpass

__all__ = ["MIN_MOVE_M", "SWIVEL_CUTOFF_HZ", "parse_swivel_cutoff", "smooth_swivels", "smoothed_middles",
           "smoothing_possible"]

#: The swivels' cutoff [Hz]: the band of human joint motion (tracking.target_filter.MOTION_BAND_HZ).
SWIVEL_CUTOFF_HZ = MOTION_BAND_HZ
#: A joint is moved only if its smoothed place lies farther than this [m].
MIN_MOVE_M = 5e-4


def parse_swivel_cutoff(value: str | float | None) -> float | None:
    """`--swivel-cutoff`: "off" (or None) -> None, else a positive cutoff in Hz; InputError otherwise."""
    if value is None or (isinstance(value, str) and value.strip().lower() == "off"):
        return None
    try:
        cutoff = float(value.strip().lower().removesuffix("hz") if isinstance(value, str) else value)
    except (TypeError, ValueError):
        cutoff = float("nan")
    if isinstance(value, bool) or not np.isfinite(cutoff) or cutoff <= 0:
        raise InputError(f"--swivel-cutoff: expected off or a positive cutoff in Hz, found {value!r}",
                         parameter="swivel_cutoff")
    return cutoff


def _design_fraction(rate_hz: float, cutoff_hz: float) -> float:
    """The design's cutoff as a fraction of Nyquist for a zero-lag response at `cutoff_hz`."""
    return cutoff_hz / PASS_CORRECTION / (0.5 * rate_hz)


def smoothing_possible(rate_hz: float, cutoff_hz: float) -> bool:
    """Whether a cutoff of `cutoff_hz` can be designed at this frame rate (below Nyquist, with the
    two passes' correction): at 6 Hz, frame rates above about 15 Hz."""
    return bool(np.isfinite(rate_hz) and rate_hz > 0 and 0.0 < _design_fraction(rate_hz, cutoff_hz) < 0.99)


def smoothed_middles(roots: np.ndarray, middles: np.ndarray, ends: np.ndarray, rate_hz: float,
                     cutoff_hz: float = SWIVEL_CUTOFF_HZ) -> np.ndarray:
    """The middle joints (F, 3) [m] moved on their frames' circles to the low-passed swivel.

    Args:
        roots, middles, ends: (F, 3) the limb's joints in consecutive frames; a frame with any NaN
            (the joint was a target there, or the frame is missing) is a gap, bridged or splitting
            the trial as the targets' filter does (tracking.target_filter.lowpass: runs too short
            are left as they are); frames whose limb is straight or whose ends coincide are left too.
        rate_hz: the frames' rate; cutoff_hz: the zero-lag response's -3 dB point.

    Returns:
        (F, 3): the middles, moved where filtered (NaN where `middles` is).

    Raises:
        ValueError: the cutoff cannot be designed at this rate (see smoothing_possible).
    """
    if not smoothing_possible(rate_hz, cutoff_hz):
        raise ValueError(f"a {cutoff_hz:g} Hz cutoff cannot be designed at {rate_hz:g} frames/s")
    roots, middles, ends = (np.asarray(values, dtype=float) for values in (roots, middles, ends))
    axis = ends - roots
    length = np.linalg.norm(axis, axis=1, keepdims=True)
    axis = axis / np.maximum(length, 1e-12)
    centre = roots + np.sum((middles - roots) * axis, axis=1, keepdims=True) * axis
    offset = np.where(length > 1e-9, middles - centre, np.nan)
    radius = np.linalg.norm(offset, axis=1, keepdims=True)
    smooth = lowpass(offset, rate_hz, cutoff_hz)
    filtered = np.isfinite(offset).all(axis=1) & np.any(smooth != offset, axis=1)  # short runs are left
    smooth -= np.sum(smooth * axis, axis=1, keepdims=True) * axis  # back into the circle's plane
    norm = np.linalg.norm(smooth, axis=1, keepdims=True)
    moved = filtered & (norm[:, 0] > 1e-9) & (radius[:, 0] > 1e-9)
    out = middles.copy()
    out[moved] = centre[moved] + smooth[moved] * (radius[moved] / norm[moved])
    return out


def smooth_swivels(keypoint_names: Sequence[str], keypoints: np.ndarray, names: Sequence[str], targets: np.ndarray,
                   rate_hz: float, cutoff_hz: float,
                   move: Callable[[int, dict[str, np.ndarray]], None]) -> dict:
    """Every free elbow and knee (LIMB_ENDS; a target's where it is absent) moved to its smoothed
    place in each frame where one lies farther than MIN_MOVE_M from it.

    Args:
        keypoint_names, keypoints: the solved frames' keypoints (F, K, 3) [m], which `move` updates.
        names, targets: the targets (F, T, 3) [m], NaN where absent.
        move: (frame, name -> place (3,) [m]) moves that frame's joints and updates `keypoints`.

    Returns:
        The report (TrackingResult.swivel_smoothing): the cutoff and frame rate, whether it ran (and
        why not), the frames moved, per joint how far it moved and how far from its place it ended
        [mm], median and max over its free frames.
    """
    report: dict = {"cutoff_hz": cutoff_hz, "frame_rate_hz": rate_hz}
    if not smoothing_possible(rate_hz, cutoff_hz):
        return {**report, "applied": False,
                "why": f"at {rate_hz:g} frames/s a {cutoff_hz:g} Hz cutoff lies above the Nyquist frequency"}
    row = {name: k for k, name in enumerate(keypoint_names)}
    limbs = [name for name in LIMB_ENDS if name in row and all(end in row for end in LIMB_ENDS[name])]
    present = np.isfinite(targets).all(axis=2)
    places = {}
    for name in limbs:
        middles = keypoints[:, row[name]].copy()
        if name in names:  # a target where present: not the image's to place
            middles[present[:, list(names).index(name)]] = np.nan
        root, end = LIMB_ENDS[name]
        places[name] = smoothed_middles(keypoints[:, row[root]], middles, keypoints[:, row[end]], rate_hz, cutoff_hz)
    before = keypoints.copy()
    moved_frames = 0
    for frame in range(keypoints.shape[0]):
        moving = {name: places[name][frame] for name in limbs
                  if np.linalg.norm(places[name][frame] - before[frame, row[name]]) > MIN_MOVE_M}
        if moving:
            moved_frames += 1
            move(frame, moving)

    def stats(distances: np.ndarray) -> dict:
        return {"median": float(np.median(distances) * 1e3) if distances.size else None,
                "max": float(np.max(distances) * 1e3) if distances.size else None}

    joints = {}
    for name in limbs:
        free = np.isfinite(places[name]).all(axis=1)
        joints[name] = {"moved_mm": stats(np.linalg.norm(keypoints[free, row[name]] - before[free, row[name]], axis=1)),
                        "off_smoothed_mm": stats(np.linalg.norm(keypoints[free, row[name]] - places[name][free],
                                                                axis=1))}
    return {**report, "applied": True, "frames_moved": moved_frames, "joints": joints}
