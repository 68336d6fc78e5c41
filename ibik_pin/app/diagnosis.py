"""A run that checks its own evidence: `ibik track` judges what it measured of its inputs and of its
result, warns once per cause with the figure, lists every finding in report.json ("diagnosis") and
refuses inputs that cannot be right.

Before the solve (cheap: a few frames' masks read, the targets projected):

- a view is suspect when the share of the projected targets inside its silhouette, median over
  sampled frames, is below VIEW_FLOOR, or below VIEW_RATIO times the best view's: two cameras'
  masks swapped, masks of another moment or person, the wrong channel, a wrong camera matrix, TRC
  axes forced wrong. When no view reaches VIEW_FLOOR, the inputs cannot be right: refused.
- a view whose sampled silhouettes are all empty is reported (the tracker leaves it out).
- frames of whole-body jumps (app.input_checks.frame_jumps) are dropped there, and listed here.

After the solve: a frame is suspect when its mean end-effector residual exceeds both
FRAME_RESIDUAL_FLOOR_M and FRAME_RESIDUAL_RATIO times the trial's median; a view is suspect when the
skeleton's share inside its silhouette, median over the frames, is below VIEW_FLOOR.

The thresholds and the figures they sit between: docs/method.md, "Self-diagnosis", measured by
experiments/diagnosis_thresholds.py.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ibik_pin.app.axes import MIN_UPRIGHT, AxesChoice
from ibik_pin.app.input_checks import JUMP_DISTANCE_M, FrameJumps
from ibik_pin.app.video_inputs import points_inside
from ibik_pin.exceptions import IbikWarning, InputError

__all__ = ["EVIDENCE_FRAMES", "FRAME_RESIDUAL_FLOOR_M", "FRAME_RESIDUAL_RATIO", "MAX_FOREGROUND", "VIEW_FLOOR",
           "VIEW_RATIO", "Diagnosis", "Finding", "ViewEvidence", "ViewsLeftOut", "add_jumps", "axes_hint",
           "check_axes", "check_views", "diagnose_result", "view_evidence"]

# A view holds the subject when at least this share of the projected targets falls inside its
# silhouette (median over the sampled frames), and at least VIEW_RATIO of the best view's share.
# Good views, measured: 0.91-1.00 on the sweep's 42 conditions (336 views, clean and with defects);
# on Pose2Sim's real video 0.35-0.50 with background subtraction, 0.71-0.94 with MediaPipe; the
# worst view's share over the best's: 0.91, 0.70 and 0.75. Broken views on the demo: 0.00-0.08;
# cam1 and cam2 swapped among 4 views, 0.50 and 0.54 of the best's (docs/method.md).
VIEW_FLOOR = 0.2
VIEW_RATIO = 0.6
# A silhouette covering more of its image than this (median over the sampled frames) is the
# background read as the subject (inverted, or a channel that is uniform). Good views: at most
# 0.063 on the sweep's conditions, 0.02-0.07 on Pose2Sim's real video (0.09 its largest frame);
# an inverted mask of the demo covers 0.95.
MAX_FOREGROUND = 0.6
# Frames whose masks are read for the views' evidence, spread over the trial.
EVIDENCE_FRAMES = 16
# A frame's mean end-effector residual above both of these is far above the trial's.
FRAME_RESIDUAL_FLOOR_M = 0.06
FRAME_RESIDUAL_RATIO = 5.0

CAUSES = {
    "view_targets_outside": "a view's silhouettes hold too few of the projected targets",
    "view_empty": "a view's silhouettes are empty in every sampled frame",
    "view_mostly_foreground": "a view's silhouettes cover most of the image (inverted, or the wrong channel?)",
    "view_skeleton_outside": "a view's silhouettes hold too little of the tracked skeleton",
    "axes_body_lying": "under the TRC axes given, the body lies down; under the other convention it stands",
    "frame_jump": "a frame's targets all leapt away from the frames on either side and back (dropped)",
    "frame_step": "the whole body moved faster than a body can into a frame and stayed there (kept)",
    "frame_residual": "a frame's end-effector residual is far above the trial's",
}


@dataclass
class Finding:
    """One thing the run found wrong with its evidence.

    Attributes:
        cause: one of CAUSES' keys.
        subject: the camera's name, or the TRC frame number.
        figure: the measured figure (its unit: the cause's threshold's); None when not a number.
        threshold: what the figure was judged against.
        consequence: what the run did about it.
    """

    cause: str
    subject: str
    figure: float | None
    threshold: float | None
    consequence: str


@dataclass
class ViewEvidence:
    """The share of the projected targets inside each view's silhouette on sampled frames.

    Attributes:
        cameras: the cameras' names.
        frames: the sampled frame indices (0-based rows of the TRC).
        shares: (frames, cameras) share of the frame's present targets inside the silhouette [0-1],
            NaN where the silhouette is empty or no target is present.
        foreground: (frames, cameras) share of the image the silhouette covers [0-1].
    """

    cameras: list[str]
    frames: list[int]
    shares: np.ndarray
    foreground: np.ndarray

    def median_foreground(self) -> dict[str, float]:
        """Per camera, the median over the frames of the share of the image its silhouette covers."""
        return {name: float(np.median(column)) if column.size else 0.0
                for name, column in zip(self.cameras, self.foreground.T, strict=True)}

    def median_share(self) -> dict[str, float | None]:
        """Per camera, the median of its shares over the frames (None when never measured)."""
        return {name: (float(np.nanmedian(column)) if np.isfinite(column).any() else None)
                for name, column in zip(self.cameras, self.shares.T, strict=True)}


@dataclass
class Diagnosis:
    """report.json's "diagnosis": what the run judged of its evidence.

    Attributes:
        findings: every finding, views first, then frames by frame number.
        targets_inside_sampled: per camera, the median share of the projected targets inside its
            silhouette over the sampled frames [0-1] (before the solve); empty without silhouettes.
        sampled_frames: TRC frame numbers of those frames.
        foreground_sampled: per camera, the median share of the image its silhouette covers over
            the same frames [0-1].
        views_left_out: the cameras left out of the image term, their targets' share too low.
        skeleton_inside_median: per camera, the median over the frames of the tracked skeleton's
            share inside the silhouette [0-1] (after the solve).
        departure_per_frame_m: per frame, how far its targets lie (median over them) from where the
            frames on either side put them [m] (app.input_checks.frame_jumps); None where unmeasured.
        thresholds: every threshold the findings were judged against.
    """

    findings: list[Finding] = field(default_factory=list)
    targets_inside_sampled: dict[str, float | None] = field(default_factory=dict)
    sampled_frames: list[int] = field(default_factory=list)
    foreground_sampled: dict[str, float] = field(default_factory=dict)
    views_left_out: list[str] = field(default_factory=list)
    skeleton_inside_median: dict[str, float | None] = field(default_factory=dict)
    departure_per_frame_m: list[float | None] = field(default_factory=list)
    thresholds: dict[str, float] = field(default_factory=lambda: {
        "view_floor": VIEW_FLOOR, "view_ratio": VIEW_RATIO, "max_foreground": MAX_FOREGROUND,
        "jump_distance_m": JUMP_DISTANCE_M,
        "frame_residual_floor_m": FRAME_RESIDUAL_FLOOR_M, "frame_residual_ratio": FRAME_RESIDUAL_RATIO})

    def to_report(self) -> dict[str, Any]:
        """As report.json holds it (plain values)."""
        return dataclasses.asdict(self)


def view_evidence(cameras: Sequence, masks_of_frame: Callable[[int], Sequence[np.ndarray]],
                  targets_m: np.ndarray, count: int = EVIDENCE_FRAMES) -> ViewEvidence:
    """Per camera, the share of the projected targets inside its silhouette on `count` frames
    spread over the trial (those holding targets).

    Args:
        cameras: the cameras, in the masks' order; they project model-frame points.
        masks_of_frame: frame index -> its (H, W) bool silhouettes, one per camera.
        targets_m: (F, T, 3) the targets in the model's frame [m], NaN where absent.
    """
    usable = np.flatnonzero(np.isfinite(targets_m).all(axis=2).any(axis=1))
    picks = np.unique(np.rint(np.linspace(0, usable.size - 1, min(count, usable.size))).astype(int)) \
        if usable.size else np.zeros(0, dtype=int)
    frames = [int(usable[pick]) for pick in picks]
    shares = np.full((len(frames), len(cameras)), np.nan)
    foreground = np.zeros((len(frames), len(cameras)))
    for row, frame in enumerate(frames):
        points = targets_m[frame]
        points = points[np.isfinite(points).all(axis=1)]
        for column, (camera, mask) in enumerate(zip(cameras, masks_of_frame(frame), strict=True)):
            if mask.any():
                shares[row, column] = float(np.mean(points_inside(camera, mask, points)))
            foreground[row, column] = float(np.count_nonzero(mask)) / mask.size
    return ViewEvidence([camera.name for camera in cameras], frames, shares, foreground)


def _warn_once(text: str) -> None:
    warnings.warn(text, IbikWarning, stacklevel=3)


def check_views(evidence: ViewEvidence, option: str, frame_numbers: Sequence[int] | np.ndarray,
                axes_hint: str = "") -> Diagnosis:
    """Judge the views' evidence before the solve; refuse (InputError naming `option`) when no view
    reaches VIEW_FLOOR; otherwise a Diagnosis holding the suspect views, each cause warned once.

    Args:
        evidence: view_evidence's measure.
        option: the option the silhouettes came from ("--masks" or "--videos").
        frame_numbers: (F,) the TRC's frame numbers.
        axes_hint: a sentence on the TRC axes to add when refusing (what the other convention
            would give), or "".
    """
    medians = evidence.median_share()
    diagnosis = Diagnosis(targets_inside_sampled=medians,
                          sampled_frames=[int(frame_numbers[frame]) for frame in evidence.frames])
    measured = {name: share for name, share in medians.items() if share is not None}
    empty = [name for name, share in medians.items() if share is None]
    figures = ", ".join(f"{name} {share:.2f}" for name, share in measured.items())
    if measured and max(measured.values()) < VIEW_FLOOR:
        raise InputError(
            f"{option}: no view holds the targets: the share of the projected targets inside the silhouettes "
            f"(median over {len(evidence.frames)} frames) is {figures}, where a view that sees the subject holds "
            f"at least {VIEW_FLOOR:g}; check that each camera's silhouettes are its own (not swapped, mirrored or "
            f"of another moment), the calibration's cameras and the TRC axes{axes_hint}", parameter=option)
    best = max(measured.values(), default=0.0)
    suspect = {name: share for name, share in measured.items()
               if share < VIEW_FLOOR or share < VIEW_RATIO * best}
    for name, share in suspect.items():
        diagnosis.findings.append(Finding("view_targets_outside", name, share, max(VIEW_FLOOR, VIEW_RATIO * best),
                                          "left out of the image term (its silhouettes taken as empty)"))
    if suspect:
        listed = ", ".join(f"{name} {share:.2f}" for name, share in suspect.items())
        _warn_once(f"{option}: view(s) {listed}: share of the projected targets inside the silhouette (median "
                   f"over {len(evidence.frames)} frames), under {VIEW_FLOOR:g} or under {VIEW_RATIO:g} x the best "
                   f"view's {best:.2f}; left out of the image term: are these cameras' silhouettes swapped, "
                   "mirrored, of another moment, or their calibration wrong?")
    covering = {name: share for name, share in evidence.median_foreground().items() if share > MAX_FOREGROUND}
    for name, share in covering.items():
        diagnosis.findings.append(Finding("view_mostly_foreground", name, share, MAX_FOREGROUND, "kept"))
    if covering:
        listed = ", ".join(f"{name} {share:.2f}" for name, share in covering.items())
        _warn_once(f"{option}: view(s) {listed}: share of the image the silhouette covers (median over "
                   f"{len(evidence.frames)} frames), over {MAX_FOREGROUND:g}; is the background read as the subject "
                   "(inverted masks, or the wrong channel)?")
    diagnosis.foreground_sampled = evidence.median_foreground()
    diagnosis.views_left_out = list(suspect)
    for name in empty:
        diagnosis.findings.append(Finding("view_empty", name, None, None,
                                          "left out of the image term in every frame whose silhouette is empty"))
    if empty and measured:
        _warn_once(f"{option}: view(s) {', '.join(empty)}: every sampled silhouette ({len(evidence.frames)} "
                   "frames) is empty; left out where empty")
    return diagnosis


class ViewsLeftOut:
    """The silhouettes with those of the views left out taken as empty: the tracker disables a view
    whose silhouette is empty, so its image term pulls nothing.

    Args:
        source: frame index -> its masks, one per camera.
        left_out: the indices of the cameras left out.
    """

    def __init__(self, source: Callable[[int], Sequence[np.ndarray]], left_out: Sequence[int]) -> None:
        self._source = source
        self._left_out = set(left_out)

    def __call__(self, frame: int) -> list[np.ndarray]:
        return [np.zeros_like(mask) if index in self._left_out else mask
                for index, mask in enumerate(self._source(frame))]


def add_jumps(diagnosis: Diagnosis, jumps: FrameJumps, frame_numbers: Sequence[int] | np.ndarray) -> None:
    """List the frames input_checks.drop_jumping_frames dropped (and the steps it kept; it warned)."""
    frame_numbers = [int(number) for number in frame_numbers]
    diagnosis.departure_per_frame_m = [float(value) if np.isfinite(value) else None for value in jumps.departure_m]
    for frame in np.flatnonzero(jumps.dropped):
        value = float(jumps.departure_m[frame])
        diagnosis.findings.append(Finding("frame_jump", str(frame_numbers[frame]), value if np.isfinite(value)
                                          else None, JUMP_DISTANCE_M, "targets dropped; pose interpolated "
                                          "between the frames on either side"))
    for frame in np.flatnonzero(jumps.steps):
        diagnosis.findings.append(Finding("frame_step", str(frame_numbers[frame]), None, None, "kept"))


def diagnose_result(diagnosis: Diagnosis, frame_numbers: Sequence[int] | np.ndarray, residuals_m: np.ndarray,
                    camera_names: Sequence[str], inside_fraction: np.ndarray) -> None:
    """Judge the solve's evidence into `diagnosis`: frames whose residual is far above the trial's,
    views that hold too little of the skeleton; each cause warned once.

    Args:
        frame_numbers: (F,) the TRC's frame numbers.
        residuals_m: (F,) per frame, the mean distance of the present targets to their keypoints [m].
        camera_names: the views used, in inside_fraction's column order.
        inside_fraction: (F, V) the skeleton's share inside each view's silhouette, NaN where disabled.
    """
    frame_numbers = [int(number) for number in frame_numbers]
    residuals = np.asarray(residuals_m, dtype=float)
    if np.isfinite(residuals).any():
        median = float(np.nanmedian(residuals))
        limit = max(FRAME_RESIDUAL_FLOOR_M, FRAME_RESIDUAL_RATIO * median)
        with np.errstate(invalid="ignore"):
            high = np.flatnonzero(residuals > limit)
        for frame in high:
            diagnosis.findings.append(Finding("frame_residual", str(frame_numbers[frame]), float(residuals[frame]),
                                              limit, "kept"))
        if high.size:
            listed = ", ".join(f"{frame_numbers[f]} ({1000 * residuals[f]:.0f} mm)" for f in high[:5])
            more = f" and {high.size - 5} more" if high.size > 5 else ""
            _warn_once(f"--targets: frame(s) {listed}{more}: the mean end-effector residual is far above the "
                       f"trial's median {1000 * median:.1f} mm (limit {1000 * limit:.0f} mm); check those frames' "
                       "targets (a part of the body swapped or shifted?)")
    inside = np.asarray(inside_fraction, dtype=float)
    if inside.ndim == 2 and inside.shape[1] == len(camera_names):
        for name, column in zip(camera_names, inside.T, strict=True):
            diagnosis.skeleton_inside_median[name] = float(np.nanmedian(column)) if np.isfinite(column).any() else None
        low = {name: share for name, share in diagnosis.skeleton_inside_median.items()
               if share is not None and share < VIEW_FLOOR}
        for name, share in low.items():
            diagnosis.findings.append(Finding("view_skeleton_outside", name, share, VIEW_FLOOR, "kept"))
        said = {finding.subject for finding in diagnosis.findings if finding.cause == "view_targets_outside"}
        if set(low) - said:  # a view already warned of before the solve is not warned of again
            listed = ", ".join(f"{name} {share:.2f}" for name, share in low.items())
            _warn_once(f"view(s) {listed}: share of the tracked skeleton inside the silhouette (median over the "
                       f"frames), under {VIEW_FLOOR:g}: the result disagrees with these views")
    order = {cause: index for index, cause in enumerate(CAUSES)}
    diagnosis.findings.sort(key=lambda finding: (finding.cause.startswith("frame"),
                                                 int(finding.subject) if finding.subject.isdigit() else 0,
                                                 order[finding.cause]))


def axes_hint(choice: AxesChoice) -> str:
    """For a refusal: what the other TRC axis convention would give, when the user forced one."""
    if choice.how != "forced":
        return ""
    others = [score for score in choice.scores if score.axes != choice.axes and score.inside_silhouettes is not None]
    return "".join(f"; with --trc-axes {score.axes}, {score.inside_silhouettes:.2f} of the sampled targets fall "
                   "inside the silhouettes" for score in others)


def check_axes(diagnosis: Diagnosis, choice: AxesChoice) -> None:
    """Warn (once) when the TRC axes the user forced, or a C3D file declared, lay the body down
    while the other convention stands it up (the median cosine of its feet-to-head direction with
    the up axis under MIN_UPRIGHT, the other's at least MIN_UPRIGHT); detected axes were chosen on
    the cameras' evidence, and a run without calibration says so in app.axes."""
    if choice.how not in ("forced", "declared by the C3D file"):
        return
    used = next((score for score in choice.scores if score.axes == choice.axes), None)
    others = [score for score in choice.scores if score.axes != choice.axes and score.upright is not None
              and score.upright >= MIN_UPRIGHT]
    if used is None or used.upright is None or used.upright >= MIN_UPRIGHT or not others:
        return
    diagnosis.findings.append(Finding("axes_body_lying", choice.axes, float(used.upright), MIN_UPRIGHT, "kept"))
    source = "--trc-axes" if choice.how == "forced" else "the C3D file's declared axes"
    _warn_once(f"{source} {choice.axes}: the body lies down (the cosine of its feet-to-head direction with the up "
               f"axis is {used.upright:.2f}, median over the sampled frames; upright from {MIN_UPRIGHT:.2f}), while "
               f"under {others[0].axes} it stands ({others[0].upright:.2f}); are the TRC's axes {others[0].axes}?")
