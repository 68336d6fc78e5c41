"""Plausibility of `ibik track`'s inputs, beyond their syntax: a wrong result must not be silent.

A TRC must hold a human-sized body in its declared units (the message suggests the unit that would
make it one), distinct marker names, increasing times and at least one value; a target that leaps
metres away from the rest of the body in one frame is dropped for that frame, with a warning; every
camera must see the targets in front of it and inside its image; silhouettes that are all empty
turn the image term off, with a warning. A frame whose targets all leap away from where the
neighbouring frames put them and come back (a whole-body jump) is dropped, with a warning.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ibik_pin.exceptions import IbikWarning, InputError
from ibik_pin.io.trc import METRES_PER_UNIT, TrcData

__all__ = ["JUMP_DISTANCE_M", "MAX_BODY_SPAN_M", "MIN_BODY_SPAN_M", "OUTLIER_DISTANCE_M", "FrameJumps",
           "check_camera_focal_lengths", "check_cameras_see_targets", "check_static_cells", "check_trc",
           "drop_jumping_frames", "drop_outlier_targets", "frame_jumps", "silhouettes_all_empty"]

# The largest distance between two keypoints of one frame that a human body spans (arms spread,
# a leap) and, with at least MIN_SPAN_KEYPOINTS keypoints, the smallest (a crouch, seen from the
# hips to the head) [m]: a body outside them is in the wrong units.
MAX_BODY_SPAN_M = 3.0
MIN_BODY_SPAN_M = 0.3
MIN_SPAN_KEYPOINTS = 4
# A target farther than this from the median of its frame's targets is no part of the body [m].
OUTLIER_DISTANCE_M = 2.5
# A frame (or a run of up to MAX_JUMP_RUN frames) whose targets lie farther than JUMP_DISTANCE_M (median
# over its targets) from where the frames on either side put them, by interpolation in time, has jumped;
# the frames on either side must agree with each other (a body moving at most MAX_BODY_SPEED_M_S), or the
# leap is a step that does not come back, reported but kept. The figures and their margins over real
# motion: docs/method.md, "Self-diagnosis"; experiments/diagnosis_thresholds.py.
JUMP_DISTANCE_M = 0.2
MAX_JUMP_RUN = 3
MAX_BODY_SPEED_M_S = 12.0
# A static frame with at most this many markers metres from the others holds corrupt cells; with
# more, the whole body is in other units than declared.
MAX_CORRUPT_MARKERS = 2
# A pinhole camera's focal length is at least this fraction of its image width (a field of view
# under 177 degrees; a fisheye lens of 170 degrees has about 0.044).
MIN_FOCAL_WIDTHS = 0.01
# A frame needs this many targets shared with its neighbours to be compared with them.
MIN_JUMP_TARGETS = 3


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


def check_static_cells(option: str, path: Path, data: TrcData, positions_m: np.ndarray) -> None:
    """Refuse a static trial with a value farther than OUTLIER_DISTANCE_M from its frame's other
    markers (InputError naming the file, the frame, the marker, the coordinate and its value): the
    subject's lengths are measured on it, so one corrupt cell would make a limb metres long. Only
    cells of at most MAX_CORRUPT_MARKERS markers of a frame: a whole body far apart is in the wrong
    units, which check_trc names."""
    finite = np.isfinite(positions_m)
    if not finite.any():
        return
    with warnings.catch_warnings(), np.errstate(invalid="ignore", over="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)  # a frame without any value has no median
        median = np.nanmedian(np.where(finite, positions_m, np.nan), axis=1, keepdims=True)
        far = np.where(finite & np.isfinite(median), np.abs(positions_m - median), 0.0)
    markers_far = (far > OUTLIER_DISTANCE_M).any(axis=2)
    far[markers_far.sum(axis=1) > MAX_CORRUPT_MARKERS] = 0.0
    if not (far > OUTLIER_DISTANCE_M).any():
        return
    frame, marker, axis = np.unravel_index(int(np.argmax(far)), far.shape)
    value = data.positions[frame, marker, axis]
    raise InputError(
        f"{option} {path}: frame {data.frame_numbers[frame]} (data row {frame + 1}), marker "
        f"{data.marker_names[marker]}, {'XYZ'[axis]} = {value:.6g} {data.units}: more than {OUTLIER_DISTANCE_M} m "
        "from the frame's other markers; expected a standing subject's coordinates (a corrupt cell?)",
        parameter=option)


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


@dataclass
class FrameJumps:
    """Whole-body jumps found in a trial's targets (frame indices count from 0).

    Attributes:
        departure_m: (F,) per frame, the median over its targets of the distance to where the
            frames on either side put them (interpolated in time; extrapolated at the ends); NaN
            where not measured (too few shared targets).
        dropped: (F,) bool, the frames that leapt away and came back: dropped.
        steps: (F,) bool, the frames after a leap of more than JUMP_DISTANCE_M beyond what the
            body's speed allows that did not come back (kept: which side is right is unknown).
    """

    departure_m: np.ndarray
    dropped: np.ndarray
    steps: np.ndarray


def _median_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, K, 3) twice -> (N,): the median over targets present in both of their distance; NaN
    with fewer than MIN_JUMP_TARGETS shared."""
    with np.errstate(invalid="ignore", over="ignore"):
        distance = np.linalg.norm(a - b, axis=2)
    shared = np.isfinite(a).all(axis=2) & np.isfinite(b).all(axis=2)
    distance = np.where(shared, distance, np.nan)
    enough = shared.sum(axis=1) >= MIN_JUMP_TARGETS
    out = np.full(len(a), np.nan)
    if enough.any():
        out[enough] = np.nanmedian(distance[enough], axis=1)
    return out


def _interpolated(targets: np.ndarray, times: np.ndarray, before: np.ndarray, after: np.ndarray,
                  frames: np.ndarray) -> np.ndarray:
    """(N, K, 3): where frames `before` and `after` put frames `frames`' targets, linearly in time."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        weight = ((times[frames] - times[before]) / (times[after] - times[before]))[:, None, None]
        return targets[before] + weight * (targets[after] - targets[before])


def frame_jumps(targets_m: np.ndarray, times_s: np.ndarray) -> FrameJumps:
    """Find whole-body jumps: runs of 1 to MAX_JUMP_RUN frames whose targets depart by more than
    JUMP_DISTANCE_M (median over targets) from the interpolation of the frames on either side, those
    two agreeing with each other; at the ends, from the extrapolation of the next two frames.

    Args:
        targets_m: (F, T, 3) targets [m], NaN where absent.
        times_s: (F,) their times [s], increasing.
    """
    frame_count = len(targets_m)
    times = np.asarray(times_s, dtype=float)
    departure = np.full(frame_count, np.nan)
    dropped = np.zeros(frame_count, dtype=bool)
    measurable = np.isfinite(targets_m).all(axis=2).sum(axis=1) >= MIN_JUMP_TARGETS

    def departures(kept: np.ndarray, run: int) -> tuple[np.ndarray, ...]:
        """For each run of `run` kept frames (interior ones, then the first and the last): its
        frames (N, run), their departures (N, run), whether the two frames it is judged against
        agree (N,), those two frames (N,) twice, and whether it is at an end (N,)."""
        starts = np.arange(1, len(kept) - run)
        runs = [kept[starts[:, None] + np.arange(run)]]
        before, after = [kept[starts - 1]], [kept[starts + run]]
        runs += [kept[None, :run], kept[None, -run:]]  # the ends: extrapolated from the next two
        before += [kept[[run]], kept[[-run - 1]]]
        after += [kept[[run + 1]], kept[[-run - 2]]]
        frames, near, far = np.concatenate(runs), np.concatenate(before), np.concatenate(after)
        gone = np.stack([_median_distance(targets_m[frames[:, k]], _interpolated(targets_m, times, near, far,
                                                                                 frames[:, k]))
                         for k in range(run)], axis=1)
        with np.errstate(invalid="ignore"):
            agree = _median_distance(targets_m[near], targets_m[far]) \
                <= MAX_BODY_SPEED_M_S * np.abs(times[far] - times[near]) + JUMP_DISTANCE_M
        at_end = np.arange(len(frames)) >= len(starts)
        return frames, gone, agree, near, far, at_end

    # Greedily, the clearest leap first, and the ends (extrapolated: weaker evidence) after the
    # interior: a frame beside a leap departs too (by half of it when the leap is one frame), so the
    # frames a dropped run was judged against are judged again on the next round.
    while True:
        kept = np.flatnonzero(~dropped & measurable)
        candidates = []
        for run in range(1, min(MAX_JUMP_RUN, len(kept) - 2) + 1):
            frames, gone, agree, near, far, at_end = departures(kept, run)
            with np.errstate(invalid="ignore"):
                leaps = (gone > JUMP_DISTANCE_M).all(axis=1) & agree
            candidates += [(bool(at_end[row]), -float(np.min(gone[row])), frames[row], gone[row],
                            {*frames[row], near[row], far[row]}) for row in np.flatnonzero(leaps)]
        blocked: set[int] = set()
        for _, _, frames_of_run, gone_of_run, around in sorted(candidates, key=lambda item: item[:2]):
            if around & blocked:
                continue
            blocked |= around
            dropped[frames_of_run] = True
            departure[frames_of_run] = gone_of_run
        if not blocked:
            break
    # A frame dropped beside a leap that was dropped after it (the last frame leapt: the one before
    # departs by half from it, and is an interior frame, judged first) is kept again when it fits
    # the frames kept around it.
    for frame in np.flatnonzero(dropped):
        others = np.flatnonzero(~dropped & measurable)
        kept = np.sort(np.append(others, frame))
        if len(kept) < 3:
            continue
        frames, gone, agree, *_ = departures(kept, 1)
        row = int(np.flatnonzero(frames[:, 0] == frame)[0])
        with np.errstate(invalid="ignore"):
            if agree[row] and gone[row, 0] <= JUMP_DISTANCE_M:
                dropped[frame] = False
    # The frames kept, against their kept neighbours.
    kept = np.flatnonzero(~dropped & measurable)
    steps = np.zeros(frame_count, dtype=bool)
    if len(kept) >= 3:
        frames, gone, agree, *_ = departures(kept, 1)
        departure[frames[:, 0]] = np.where(agree, gone[:, 0], np.nan)
    if len(kept) > 1:  # leaps between consecutive kept frames beyond the body's speed: steps
        moved = _median_distance(targets_m[kept[1:]], targets_m[kept[:-1]])
        with np.errstate(invalid="ignore"):
            steps[kept[1:][moved > MAX_BODY_SPEED_M_S * np.diff(times[kept]) + JUMP_DISTANCE_M]] = True
    return FrameJumps(departure, dropped, steps)


def drop_jumping_frames(option: str, frame_numbers: Sequence[int] | np.ndarray, targets_m: np.ndarray,
                        times_s: np.ndarray) -> tuple[np.ndarray, FrameJumps]:
    """The targets with the frames of whole-body jumps (frame_jumps) set to NaN, and the jumps. One
    warning names the dropped frames and their departure; another the steps that were kept."""
    jumps = frame_jumps(targets_m, times_s)
    cleaned = targets_m.copy()
    if jumps.dropped.any():
        cleaned[jumps.dropped] = np.nan
        frames = np.flatnonzero(jumps.dropped)
        listed = ", ".join(f"{frame_numbers[f]} ({_metres(jumps.departure_m[f])})" for f in frames[:5])
        more = f" and {len(frames) - 5} more" if len(frames) > 5 else ""
        warnings.warn(f"{option}: {len(frames)} frame(s) whose targets all leap more than {JUMP_DISTANCE_M} m "
                      f"away from the frames on either side and back are dropped, their pose interpolated: "
                      f"frame {listed}{more}", IbikWarning, stacklevel=2)
    if jumps.steps.any():
        frames = np.flatnonzero(jumps.steps)
        listed = ", ".join(str(frame_numbers[f]) for f in frames[:5])
        warnings.warn(f"{option}: the whole body moves faster than {MAX_BODY_SPEED_M_S:g} m/s into frame(s) "
                      f"{listed}{' and more' if len(frames) > 5 else ''} and stays there; kept, but check the "
                      "file (two recordings joined, or a change of origin?)", IbikWarning, stacklevel=2)
    return cleaned, jumps


def _metres(value: float) -> str:
    return f"{value:.3g} m" if np.isfinite(value) else "a distance that overflows"


def check_camera_focal_lengths(cameras: Sequence) -> None:
    """Refuse a camera whose focal length in pixels is under MIN_FOCAL_WIDTHS of its image width
    (InputError naming the camera and the figure): its field of view would exceed 177 degrees, more
    than a pinhole camera can image; every target would project onto a few pixels."""
    for camera in cameras:
        intrinsics = getattr(camera, "intrinsics", None)
        if intrinsics is None:
            continue
        width = float(camera.size[0])
        focal = min(float(intrinsics[0, 0]), float(intrinsics[1, 1]))
        if focal < MIN_FOCAL_WIDTHS * width:
            raise InputError(f"--calibration: camera {camera.name!r} has a focal length of {focal:.3g} px for an "
                             f"image {width:g} px wide; expected at least {MIN_FOCAL_WIDTHS * width:.3g} px (a field "
                             "of view under 177 degrees): is its matrix in pixels?", parameter="--calibration")


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
