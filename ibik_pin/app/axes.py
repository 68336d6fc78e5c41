"""Which axis convention a TRC file is written in, told from the cameras that filmed it.

Two conventions meet in practice:

- ``"y-up"``: Pose2Sim's and OpenSim's TRC files, Y up. A TRC point (x, y, z) is the calibration
  world's (z, x, y) (``POSE2SIM_TRC_TO_WORLD``).
- ``"z-up"``: the calibration's own world, Z up, as many motion-capture systems export it.

The tracker works in the model's frame, which is Pose2Sim's Y-up TRC frame (the cameras are moved
into it with ``cameras_in_frame``), so a Z-up TRC is rotated into that frame before tracking and
its results are rotated back before joints.trc is written.

Detection projects the targets of a few frames spread over the sequence into every camera under
each convention and counts the projections in front of the camera and inside its image (and, with
silhouettes, inside the silhouette). The wrong convention lays the body on its side, which the
images alone do not always rule out: on Pose2Sim's 4-camera demo (ref3d TRC, Y-up) the right
convention put 100% of the projected targets inside the images, the wrong one 67%; the same
targets written Z-up gave 100% against 44%; on a small synthetic 2-camera rig the wrong one even
put 100% inside the images. Hence a margin rather than a bare maximum, the silhouettes deciding
first when given (a body on its side does not fall inside them: 0-6% against 97-100%), and, when
neither separates the two, the body's own up direction (feet to head) as the last word.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ibik_pin.exceptions import IbikWarning, InputError
from ibik_pin.human import FOOT_KEYPOINTS
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD

TRC_AXES = ("y-up", "z-up")
AXES_DESCRIPTIONS = {
    "y-up": "Y up: Pose2Sim's and OpenSim's TRC convention",
    "z-up": "Z up: the calibration's own world, as many mocap systems export",
}
# Rotation R with model-frame point = R @ TRC point. The model's frame is Pose2Sim's Y-up TRC frame;
# a Z-up TRC point is a calibration-world point, and world = POSE2SIM_TRC_TO_WORLD @ model point.
TRC_TO_MODEL = {"y-up": np.eye(3), "z-up": POSE2SIM_TRC_TO_WORLD.T.copy()}

# A convention is possible when at least this fraction of its projected targets lies in front of
# a camera and inside its image. The right convention scored 0.97-1.00 on Pose2Sim's demo and on
# the project's synthetic rigs; half leaves room for cameras that frame only part of the volume.
MIN_INSIDE_IMAGES = 0.5
# A convention wins when its fraction (silhouettes first, then images) beats the other's by at
# least this much. Measured gaps between right and wrong: 0.93-0.99 on silhouettes, 0-0.56 on
# images alone; a gap under 0.1 is within what a few keypoints at the image border change.
DECISION_MARGIN = 0.1
# The body is upright when the median cosine between its feet-to-head direction and the model's
# up (+Y) is at least this (45 deg). The two conventions permute the axes, so at most one of them
# can reach it: a unit vector has at most one component above cos 45 deg.
MIN_UPRIGHT = float(np.cos(np.pi / 4))
SAMPLE_FRAMES = 10
HEAD_KEYPOINTS = ("Head", "Nose", "Neck")

SilhouetteSource = Callable[[int], Sequence[np.ndarray]]


@dataclass(frozen=True)
class AxesScore:
    """How well one convention fits the sampled targets.

    Attributes:
        axes: "y-up" or "z-up".
        inside_images: fraction of (target, frame, camera) projections in front of the camera and
            inside its image, in [0, 1]; None without cameras.
        inside_silhouettes: fraction of the same projections that also fall on the silhouette,
            in [0, 1]; None without silhouettes.
        upright: median over the frames of the cosine between the body's feet-to-head direction
            and the model's up, in [-1, 1]; None without head and foot keypoints.
    """

    axes: str
    inside_images: float | None = None
    inside_silhouettes: float | None = None
    upright: float | None = None


@dataclass(frozen=True)
class AxesChoice:
    """The convention used for the TRC files, and why.

    Attributes:
        axes: "y-up" or "z-up".
        how: "detected", "forced" (--trc-axes), "default" (no calibration to detect against) or
            "triangulated" (targets triangulated from --videos, in the model's Y-up frame) or "declared
            by the C3D file" (its POINT:Y_SCREEN).
        decided_by: what told the conventions apart when detected: "silhouettes", "images" or
            "upright body"; empty otherwise.
        scores: each convention's score.
        sampled_frames: indices (0-based rows of the TRC) of the frames the scores used.
    """

    axes: str
    how: str
    decided_by: str = ""
    scores: tuple[AxesScore, ...] = ()
    sampled_frames: tuple[int, ...] = ()

    @property
    def trc_to_model(self) -> np.ndarray:
        """(3, 3) rotation R: model-frame point = R @ TRC point."""
        return TRC_TO_MODEL[self.axes]

    def to_model(self, points_trc: np.ndarray) -> np.ndarray:
        """(..., 3) TRC points [any unit] in the model's frame (NaN stays NaN)."""
        return np.asarray(points_trc, dtype=float) @ self.trc_to_model.T

    def to_trc(self, points_model: np.ndarray) -> np.ndarray:
        """(..., 3) model-frame points back in the TRC's own convention."""
        return np.asarray(points_model, dtype=float) @ self.trc_to_model

    def describe(self) -> str:
        """One line: the convention, how it was chosen and the scores behind it."""
        text = f"{self.axes} ({AXES_DESCRIPTIONS[self.axes]}), {self.how}"
        if self.decided_by:
            text += f" by the {self.decided_by}"
        if self.how == "default":
            text += " (no --calibration to detect against)"
        if self.scores:
            text += ": " + "; ".join(_score_text(score) for score in self.scores)
        return text


def _score_text(score: AxesScore) -> str:
    parts = []
    if score.inside_images is not None:
        parts.append(f"{100 * score.inside_images:.0f}% of the projected targets inside the images")
    if score.inside_silhouettes is not None:
        parts.append(f"{100 * score.inside_silhouettes:.0f}% inside the silhouettes")
    if score.upright is not None:
        parts.append(f"body {np.degrees(np.arccos(np.clip(score.upright, -1.0, 1.0))):.0f} deg from upright")
    return f"{score.axes}: " + ", ".join(parts) if parts else f"{score.axes}: no evidence"


def sample_frames(targets: np.ndarray, count: int = SAMPLE_FRAMES) -> list[int]:
    """Up to `count` frame indices spread evenly over the frames that hold a finite target.

    Args:
        targets: (F, K, 3) target positions, NaN where absent.
    """
    usable = np.flatnonzero(np.any(np.all(np.isfinite(targets), axis=2), axis=1))
    if usable.size == 0:
        return []
    picks = np.unique(np.rint(np.linspace(0, usable.size - 1, min(count, usable.size))).astype(int))
    return [int(usable[pick]) for pick in picks]


def _inside_fractions(
    points_model: list[np.ndarray], cameras: Sequence, masks: list[list[np.ndarray]] | None
) -> tuple[float, float | None]:
    """Fractions of the projections inside the images and on the silhouettes.

    Args:
        points_model: per sampled frame, (N, 3) finite targets in the model's frame [m].
        masks: per sampled frame, one (H, W) bool silhouette per camera; or None.
    """
    inside_images = inside_silhouettes = total = 0
    for frame, points in enumerate(points_model):
        for index, camera in enumerate(cameras):
            projection = camera.project_with_jacobian(points)
            seen = (projection.depth > 0.0) & camera.contains(projection.pixels)
            total += len(points)
            inside_images += int(np.count_nonzero(seen))
            if masks is not None:
                pixels = np.rint(projection.pixels[seen]).astype(int)
                inside_silhouettes += int(np.count_nonzero(masks[frame][index][pixels[:, 1], pixels[:, 0]]))
    total = max(total, 1)
    return inside_images / total, (inside_silhouettes / total if masks is not None else None)


def _upright(names: Sequence[str], targets_model: np.ndarray) -> float | None:
    """Median cosine between the feet-to-head direction and +Y over (S, K, 3) frames [m]."""
    heads = [k for k, name in enumerate(names) if name in HEAD_KEYPOINTS]
    feet = [k for k, name in enumerate(names) if name in FOOT_KEYPOINTS]
    if not heads or not feet:
        return None
    with warnings.catch_warnings():  # a frame without any head or foot target is NaN, skipped
        warnings.simplefilter("ignore", RuntimeWarning)
        direction = np.nanmean(targets_model[:, heads], axis=1) - np.nanmean(targets_model[:, feet], axis=1)
    length = np.linalg.norm(direction, axis=1)
    usable = np.isfinite(length) & (length > 1e-9)
    if not np.any(usable):
        return None
    return float(np.median(direction[usable, 1] / length[usable]))


def score_axes(
    names: Sequence[str],
    targets_trc_m: np.ndarray,
    cameras: Sequence,
    frames: Sequence[int],
    silhouettes: SilhouetteSource | None = None,
) -> list[AxesScore]:
    """Each convention's fit: projections inside the images (and silhouettes), upright body.

    Args:
        names: the K target names.
        targets_trc_m: (F, K, 3) targets as the TRC holds them [m], NaN where absent.
        cameras: cameras that project model-frame points (``cameras_in_frame(..., POSE2SIM_TRC_TO_WORLD)``);
            may be empty.
        frames: the frame indices to use.
        silhouettes: frame index -> one (H, W) bool mask per camera, or None.

    Returns:
        One score per convention, in the order of TRC_AXES.
    """
    masks = [list(silhouettes(frame)) for frame in frames] if silhouettes is not None and cameras else None
    sampled = targets_trc_m[list(frames)]
    scores = []
    for axes in TRC_AXES:
        sampled_model = sampled @ TRC_TO_MODEL[axes].T
        inside_images = inside_silhouettes = None
        if cameras:
            finite = [points[np.all(np.isfinite(points), axis=1)] for points in sampled_model]
            inside_images, inside_silhouettes = _inside_fractions(finite, cameras, masks)
        scores.append(AxesScore(axes, inside_images, inside_silhouettes, _upright(names, sampled_model)))
    return scores


def _best_by(scores: list[AxesScore], value: Callable[[AxesScore], float | None]) -> AxesScore | None:
    """The score whose value beats every other's by DECISION_MARGIN, if any."""
    values = [value(score) for score in scores]
    if any(v is None for v in values):
        return None
    ranked = sorted(((float(v), index) for index, v in enumerate(values) if v is not None), reverse=True)
    (best, index), (second, _) = ranked[0], ranked[1]
    return scores[index] if best - second >= DECISION_MARGIN else None


def choose_axes(
    requested: str,
    names: Sequence[str],
    targets_trc_m: np.ndarray,
    cameras: Sequence,
    silhouettes: SilhouetteSource | None = None,
) -> AxesChoice:
    """The convention of a TRC: forced, or detected against the cameras.

    Rule: a convention is possible when at least MIN_INSIDE_IMAGES of its projections fall in
    front of a camera and inside its image. Among the possible ones, the first of these that
    separates the two by DECISION_MARGIN decides: the fractions on the silhouettes (when given),
    then the fractions inside the images; failing both, the convention under which the body
    stands upright (MIN_UPRIGHT), if it is possible. Without cameras there is nothing to detect
    against: "y-up" unless forced, with a warning when the body would stand upright only in the
    other convention.

    Args:
        requested: "auto", "y-up" or "z-up".
        names: the K target names.
        targets_trc_m: (F, K, 3) targets as the TRC holds them [m], NaN where absent.
        cameras: cameras that project model-frame points; empty for blind tracking.
        silhouettes: frame index -> one (H, W) bool mask per camera, or None.

    Returns:
        The convention and the evidence.

    Raises:
        InputError: `requested` is not a known choice; no frame holds a finite target; no
            convention puts the targets inside the images; or nothing tells the two apart (then
            --trc-axes must say which).
    """
    if requested not in ("auto", *TRC_AXES):
        raise InputError(f"--trc-axes: expected one of auto, {', '.join(TRC_AXES)}, got {requested!r}")
    frames = sample_frames(targets_trc_m)
    if not frames:
        raise InputError("--targets: no frame holds a finite target position")
    scores = score_axes(names, targets_trc_m, cameras, frames, silhouettes)
    evidence = "; ".join(_score_text(score) for score in scores)
    if requested != "auto":
        forced = scores[TRC_AXES.index(requested)]
        if forced.inside_images is not None and forced.inside_images < MIN_INSIDE_IMAGES:
            warnings.warn(f"--trc-axes {requested} keeps the targets out of the cameras' images: {evidence}",
                          IbikWarning, stacklevel=2)
        return AxesChoice(requested, "forced", "", tuple(scores), tuple(frames))
    if not cameras:
        standing = [score.axes for score in scores if score.upright is not None and score.upright >= MIN_UPRIGHT]
        if standing and standing[0] != "y-up":
            warnings.warn(f"--trc-axes auto: without --calibration the targets are read y-up, but the body "
                          f"stands upright only if they are {standing[0]} ({evidence}); pass --trc-axes "
                          f"{standing[0]} if so", IbikWarning, stacklevel=2)
        return AxesChoice("y-up", "default", "", tuple(scores), tuple(frames))
    possible = [score for score in scores if score.inside_images is not None
                and score.inside_images >= MIN_INSIDE_IMAGES]
    if not possible:
        raise InputError(
            f"no axis convention puts the targets inside the cameras' images: {evidence} "
            f"(at least {100 * MIN_INSIDE_IMAGES:.0f}% needed); check that --targets and "
            "--calibration come from the same recording and that the TRC's units are right"
        )
    deciders: list[tuple[str, Callable[[AxesScore], float | None]]] = [
        ("silhouettes", lambda score: score.inside_silhouettes),
        ("images", lambda score: score.inside_images),
    ]
    for decided_by, value in deciders:
        best = _best_by(scores, value)
        if best is not None and best in possible:
            return AxesChoice(best.axes, "detected", decided_by, tuple(scores), tuple(frames))
    upright = [score for score in possible if score.upright is not None and score.upright >= MIN_UPRIGHT]
    if upright:
        return AxesChoice(upright[0].axes, "detected", "upright body", tuple(scores), tuple(frames))
    raise InputError(
        f"--trc-axes auto: neither the cameras nor the body's posture tell the TRC's axis convention "
        f"({evidence}); pass --trc-axes y-up (Pose2Sim, OpenSim) or --trc-axes z-up (the calibration's world)"
    )


@dataclass
class TrcAxesReport:
    """The axis convention the TRC files were read and written in (app.axes).

    Attributes:
        used: "y-up" or "z-up".
        how: "detected", "forced" (--trc-axes), "default" (no calibration to detect against) or
            "triangulated" (the targets were triangulated from --videos in the model's Y-up frame) or
            "declared by the C3D file" (its POINT:Y_SCREEN, the axis drawn upward).
        decided_by: when detected, what told the conventions apart: "silhouettes", "images" or
            "upright body".
        description: the convention in words, and which outputs it applies to.
        inside_images: per convention, the fraction of the sampled targets' projections in front
            of a camera and inside its image [0-1]; empty without a calibration.
        inside_silhouettes: per convention, the fraction inside the silhouettes [0-1]; empty
            without silhouettes.
        upright_cosine: per convention, the median cosine between the body's feet-to-head
            direction and the model's up [-1, 1]; empty without head and foot targets.
        sampled_frames: TRC frame numbers of the frames these were measured on.
    """

    used: str
    how: str
    decided_by: str
    description: str
    inside_images: dict[str, float] = field(default_factory=dict)
    inside_silhouettes: dict[str, float] = field(default_factory=dict)
    upright_cosine: dict[str, float] = field(default_factory=dict)
    sampled_frames: list[int] = field(default_factory=list)

    @classmethod
    def from_choice(cls, choice: AxesChoice, frame_numbers: np.ndarray) -> TrcAxesReport:
        description = (f"{AXES_DESCRIPTIONS[choice.axes]}; the targets were read and joints.trc written "
                       "in it; q.csv, motion.mot and motion.bvh are in the model's frame (Y up)")
        if choice.how == "default":
            description += "; no --calibration to detect it against, so Pose2Sim's y-up was assumed"

        def per_axes(name: str) -> dict[str, float]:
            values = {score.axes: getattr(score, name) for score in choice.scores}
            return {axes: float(value) for axes, value in values.items() if value is not None}

        return cls(
            used=choice.axes,
            how=choice.how,
            decided_by=choice.decided_by,
            description=description,
            inside_images=per_axes("inside_images"),
            inside_silhouettes=per_axes("inside_silhouettes"),
            upright_cosine=per_axes("upright"),
            sampled_frames=[int(frame_numbers[index]) for index in choice.sampled_frames],
        )
