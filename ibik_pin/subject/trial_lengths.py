"""Limb segment lengths refined on the trial itself: its targets and its silhouettes.

Joint centres computed from skin markers are not rigid across takes: a boxer's thighs measured
13-30 mm longer in the trial than in the static take. With the hips and ankles met exactly, a leg
too short is straighter than the truth and one too long more bent, and the knee's error is then
its distance from the hip-ankle line, which no swivel can repair. On the sweep (experiments/
sweep.py) the knees' error decomposed mostly that way: a shank 4 % long put the knee's circle
30 mm too wide while its swivel was within 5-15 degrees.

Two kinds of evidence, both from the trial:

- its targets: a limb's two ends (hip and ankle, shoulder and wrist) are never farther apart than
  its two segments' sum. A high quantile of the end-to-end distance over the trial is a lower
  bound of that sum (:func:`reach_bounds`, :func:`refine_from_reach`); it says nothing when the
  limb stays bent (a boxer's guard).
- its silhouettes: for each candidate pair of lengths (a grid of factors on the calibrated ones),
  every frame's middle joint is placed on the circle those lengths give between the limb's ends,
  at the swivel the image criterion prefers; the pair whose frames explain the silhouettes best
  wins (:func:`refine_from_images`). A bent limb shows where its middle joint is (the kink of its
  silhouette); a straight one shows only the sum, and the reach already bounds it from below.
  A pair that cannot reach the limb's targets in more than a few frames is not a candidate.

The result says, per segment, the calibrated length, the refined one and the change, for a
report (TrialLengths.report).
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel, set_segment_length
from ibik_pin.tasks.segments import SegmentCriterion
from ibik_pin.tracking.trunk import TRUNK_KEYPOINTS, inside_trunk

__all__ = ["DEFAULT_FACTORS", "LIMBS", "MIN_GAIN", "Limb", "TrialLengths", "apply_lengths", "reach_bounds",
           "refine_from_images", "refine_from_reach"]


@dataclass(frozen=True)
class Limb:
    """A two-segment limb: its keypoints root -> middle -> end and the names of its two lengths
    (ibik_pin.subject.scaling's length names)."""

    root: str
    middle: str
    end: str
    upper: str
    lower: str


LIMBS: dict[str, Limb] = {
    "left_leg": Limb("LHip", "LKnee", "LAnkle", "left_thigh", "left_shank"),
    "right_leg": Limb("RHip", "RKnee", "RAnkle", "right_thigh", "right_shank"),
    "left_arm": Limb("LShoulder", "LElbow", "LWrist", "left_upper_arm", "left_forearm"),
    "right_arm": Limb("RShoulder", "RElbow", "RWrist", "right_upper_arm", "right_forearm"),
}
# The joint whose placement in its parent is each limb segment (the human's keypoints of a limb sit
# at its joints' origins, and a calibration fits them on the segments near there).
SEGMENT_JOINTS = {f"{side}_{segment}": f"{side}_{joint}" for side in ("left", "right")
                  for segment, joint in (("thigh", "knee_Z"), ("shank", "ankle_Y"), ("upper_arm", "elbow_Z"),
                                         ("forearm", "wrist_Z"))}
#: Factors tried on each calibrated length: +-6 % (a static take was seen 3-7 % off), by 0.5 %. A
#: leg's knee moves far for a small error of its sum when nearly straight; on the sweep, steps of
#: 1.5 % (13 mm on a leg's sum) left the sums 4.3 mm off at the median, 0.5 % 3.6 (docs/sweep.md).
DEFAULT_FACTORS = np.linspace(0.94, 1.06, 25)
#: How much of the scores' spread over the grid the best pair must gain on the calibrated lengths to
#: replace them: 1/200. On steps of 0.5 % a preference of a thousandth of the spread moved legs
#: whose static was exact (the real-motion benchmark's cmu35_01, the test suite's walking run): a sum
#: 4 mm long, a knee 5-6 mm worse. A nearly straight knee moves far for a small error of the sum.
MIN_GAIN = 0.005


@dataclass
class TrialLengths:
    """Segment lengths after a refinement on a trial.

    Attributes:
        lengths: every length given, refined where the evidence said so [m].
        before: the lengths given [m].
        evidence: per limb, what decided (e.g. {"kind": "images", "frames": 40, "factors": [1.03, 0.97],
            "gain": 0.12}).
        middles: per limb refined on images, its middle joint (F, 3) [m] in each frame given, where
            the chosen lengths and the criteria put it (the best swivel).
    """

    lengths: dict[str, float]
    before: dict[str, float]
    evidence: dict[str, dict] = field(default_factory=dict)
    middles: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def changes(self) -> dict[str, float]:
        """Length name -> refined minus given [m], for the lengths that changed."""
        return {name: self.lengths[name] - self.before[name] for name in self.lengths
                if abs(self.lengths[name] - self.before[name]) > 0.0}

    def report(self) -> dict:
        """Per segment: given and refined length and change [mm]; per limb, the evidence."""
        return {"segments_mm": {name: {"static": 1e3 * self.before[name], "trial": 1e3 * self.lengths[name],
                                       "change": 1e3 * (self.lengths[name] - self.before[name])}
                                for name in self.lengths},
                "evidence": self.evidence}


def _limbs(limbs: Sequence[str] | None) -> list[str]:
    names = list(LIMBS) if limbs is None else list(limbs)
    unknown = [name for name in names if name not in LIMBS]
    if unknown:
        raise InputError(f"limbs: unknown {unknown}; known: {', '.join(LIMBS)}")
    return names


def reach_bounds(names: Sequence[str], targets: np.ndarray, quantile: float = 0.98,
                 limbs: Sequence[str] | None = None, smoothing_frames: int = 3) -> dict[str, float]:
    """Per limb whose two ends are targets, the `quantile` of their distance over the frames [m]: a
    lower bound of its two segments' sum (noise aside).

    Target noise inflates a high quantile: on the sweep, with 7-10 mm of noise per coordinate, the
    98th percentile exceeded the true sum by up to 17 mm (legs) and 33 mm (arms). A moving average
    of the distance over `smoothing_frames` frames divides the noise by its square root and lowers
    a true peak a little: the safe side for a lower bound (3 frames: at most +9 and +14 mm over).
    On the sweep's PIK runs (42 conditions) 3 frames instead of 1 kept the knees' gain from the
    reach (summed over conditions, 172 against 187 mm) and cut the elbows' worst loss from 19.8
    to 7.0 mm (an arm lengthened 25 mm by 9 mm of noise).

    Args:
        names: the K target names; targets: (F, K, 3) [m], NaN where absent.
    """
    targets = np.asarray(targets, dtype=float)
    if targets.ndim != 3 or targets.shape[1:] != (len(names), 3):
        raise InputError(f"targets: expected shape (F, {len(names)}, 3) [m], got {targets.shape}")
    if not 0.0 < quantile <= 1.0:
        raise InputError(f"quantile: expected a fraction in (0, 1], got {quantile}")
    if int(smoothing_frames) != smoothing_frames or smoothing_frames < 1:
        raise InputError(f"smoothing_frames: expected a positive number of frames, got {smoothing_frames}")
    index = {name: k for k, name in enumerate(names)}
    bounds = {}
    for name in _limbs(limbs):
        limb = LIMBS[name]
        if limb.root not in index or limb.end not in index:
            continue
        reach = np.linalg.norm(targets[:, index[limb.end]] - targets[:, index[limb.root]], axis=1)
        if smoothing_frames > 1 and reach.size >= smoothing_frames:  # a gap (NaN) voids its windows
            reach = np.convolve(reach, np.full(int(smoothing_frames), 1.0 / smoothing_frames), mode="valid")
        reach = reach[np.isfinite(reach)]
        if reach.size:
            bounds[name] = float(np.quantile(reach, quantile))
    return bounds


def refine_from_reach(lengths: Mapping[str, float], names: Sequence[str], targets: np.ndarray,
                      quantile: float = 0.98, slack: float = 0.003,
                      limbs: Sequence[str] | None = None, smoothing_frames: int = 3) -> TrialLengths:
    """Lengthen a limb whose segments cannot reach its targets' `quantile` distance (+ `slack` [m],
    the bend a limb keeps at full stretch): both segments by the same factor. Shorter never: a
    bent limb's reach says nothing of its length."""
    before = {name: float(value) for name, value in lengths.items()}
    refined = dict(before)
    evidence = {}
    for name, bound in reach_bounds(names, targets, quantile, limbs, smoothing_frames).items():
        limb = LIMBS[name]
        if limb.upper not in before or limb.lower not in before:
            continue
        total = before[limb.upper] + before[limb.lower]
        factor = max(1.0, (bound + slack) / total)
        refined[limb.upper], refined[limb.lower] = factor * before[limb.upper], factor * before[limb.lower]
        evidence[name] = {"kind": "reach", "reach_m": bound, "sum_m": total, "factor": factor}
    return TrialLengths(refined, before, evidence)


def _circle_frames(root: np.ndarray, middle: np.ndarray,
                   end: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """The limb's axis (unit, root to end), its length, and two unit vectors across it, the first
    toward the middle joint (any perpendicular for a straight limb)."""
    axis = end - root
    distance = float(np.linalg.norm(axis))
    axis = axis / max(distance, 1e-9)
    radial = (middle - root) - ((middle - root) @ axis) * axis
    if np.linalg.norm(radial) < 1e-6:
        radial = np.cross(axis, [0.0, 1.0, 0.0])
        if np.linalg.norm(radial) < 1e-6:
            radial = np.cross(axis, [1.0, 0.0, 0.0])
    first = radial / np.linalg.norm(radial)
    return axis, distance, first, np.cross(axis, first)


def _candidates(root: np.ndarray, middle: np.ndarray, end: np.ndarray, uppers: np.ndarray, lowers: np.ndarray,
                swivels: int, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Middle-joint candidates (G, A, 3) for G pairs of segment lengths [m] at A swivels, and
    whether each pair reaches the limb's ends (G,) (within `tolerance` [m]; a pair that cannot
    is placed straight, its segments in proportion)."""
    axis, distance, first, second = _circle_frames(root, middle, end)
    reaches = uppers + lowers >= distance - tolerance
    along = (uppers**2 - lowers**2 + distance**2) / (2.0 * max(distance, 1e-9))
    straight = uppers + lowers <= distance
    along = np.where(straight, distance * uppers / (uppers + lowers), along)
    radius = np.sqrt(np.maximum(uppers**2 - along**2, 0.0))
    radius = np.where(straight, 0.0, radius)
    angles = 2.0 * np.pi * np.arange(swivels) / swivels
    ring = np.cos(angles)[:, None] * first + np.sin(angles)[:, None] * second  # (A, 3)
    points = root + along[:, None, None] * axis + radius[:, None, None] * ring[None]
    return points, reaches


def _circle_radius(upper: float, lower: float, distance: float) -> float:
    """The radius [m] of the circle a middle joint lies on between ends `distance` apart [m]
    (0 where the segments cannot reach)."""
    if upper + lower <= distance or distance <= 0.0:
        return 0.0
    along = (upper**2 - lower**2 + distance**2) / (2.0 * distance)
    return float(np.sqrt(max(upper**2 - along**2, 0.0)))


def _lower_factors(upper: np.ndarray, lower: np.ndarray | None, lengths: Mapping[str, float],
                   limb: Limb) -> np.ndarray:
    """The lower segment's factors of a grid; None: those that keep the limb's sum with `upper`."""
    if lower is not None:
        return lower
    return 1.0 + (1.0 - upper) * lengths[limb.upper] / lengths[limb.lower]


def _inside_trunk(keypoints: Mapping[str, np.ndarray], limbs: Sequence[str], placements: Sequence[np.ndarray],
                  section: tuple[float, ...] | None) -> list[np.ndarray]:
    """Per limb, which of its middle-joint placements (G, A, 3) are elbows inside the trunk."""
    inside = [np.zeros(points.shape[:2], dtype=bool) for points in placements]
    if section is None or not all(name in keypoints for name in TRUNK_KEYPOINTS):
        return inside
    hip, neck, left_shoulder, right_shoulder = (np.asarray(keypoints[name], dtype=float) for name in TRUNK_KEYPOINTS)
    for index, name in enumerate(limbs):
        if LIMBS[name].middle in ("LElbow", "RElbow"):
            inside[index] = inside_trunk(placements[index], hip, neck, left_shoulder, right_shoulder, section)
    return inside


def refine_from_images(
    body: BodyModel,
    lengths: Mapping[str, float],
    frames: Iterable[tuple[Mapping[str, np.ndarray], Sequence[tuple[SegmentCriterion, float]]]],
    factors: np.ndarray = DEFAULT_FACTORS,
    swivels: int = 24,
    reach_tolerance: float = 0.005,
    unreachable_fraction: float = 0.05,
    min_gain: float = MIN_GAIN,
    limbs: Sequence[str] | None = None,
    keep_ratio: bool = False,
    keep_sum: bool = False,
    min_radius: float = 0.0,
    trunk_section: tuple[float, ...] | None = None,
) -> TrialLengths:
    """Each limb's two lengths, chosen on a grid of factors, by how well the trial's silhouettes
    are explained with them.

    For every pair of factors (f_upper, f_lower) and every frame, the middle joint is placed on the
    circle of radius given by the lengths f * (the calibrated lengths) between the limb's ends where
    the frame's pose left them, at `swivels` points; the frame's score is the best weighted sum of
    the criteria over the circle, and a pair's score the sum over the frames. The best pair wins
    if its score beats the calibrated pair's (1, 1) by more than `min_gain` of the scores' spread
    over the grid (a flat criterion keeps the calibrated lengths); a pair that cannot reach the
    ends (within `reach_tolerance`) in more than `unreachable_fraction` of the frames is not a
    candidate, and neither then is (1, 1): the reach alone then moves the lengths to the best pair
    that reaches.

    Args:
        body: the body model the criteria were built on (its keypoints name their frames).
        lengths: the calibrated lengths [m] (scaling's names; the limbs' upper and lower needed).
        frames: per frame, keypoint name -> position (3,) [m] of the pose a first pass found (its
            limbs' ends on their targets; every keypoint the criteria read), and (criterion,
            weight) pairs with that frame's views set (the tracker's image terms:
            tasks.image.ImageTask, tasks.silhouette_axis.SilhouetteAxisTask).
        factors: the factors tried on each length.
        swivels: points per circle.
        limbs: the limbs refined (default: every limb of LIMBS whose keypoints the body has).
        keep_ratio: scale both segments of a limb by the same factor (the static's split kept).
        keep_sum: the factors on the upper segment only, the lower one taking up the difference (the
            limb's sum kept, its split between the two segments chosen).
        min_radius: a frame scores a limb only if its middle joint's circle at the given lengths has
            at least this radius [m]: a nearly straight limb shows its sum, not its split.
        trunk_section: an elbow is never placed inside the trunk (tracking.trunk.inside_trunk with
            these semi-axes, placed by the pose's TRUNK_KEYPOINTS): two views' silhouettes cover the
            trunk's whole volume, so an arm laid into it scores as well as the true one.

    Returns:
        The lengths, the limbs' evidence (frames, factors chosen, gain, unreachable frames).
    """
    factors = np.asarray(factors, dtype=float)
    if factors.ndim != 1 or factors.size < 1 or np.any(factors <= 0.0):
        raise InputError(f"factors: expected positive factors, got {factors}")
    if int(swivels) < 3:
        raise InputError(f"swivels: expected at least 3 points per circle, got {swivels}")
    chosen = [name for name in _limbs(limbs) if all(getattr(LIMBS[name], k) in body.keypoints
                                                    for k in ("root", "middle", "end"))
              and LIMBS[name].upper in lengths and LIMBS[name].lower in lengths]
    if keep_ratio and keep_sum:
        raise InputError("keep_ratio, keep_sum: choose one (the ratio or the sum of a limb's segments kept)")
    grid_upper, grid_lower = ((factors, factors) if keep_ratio else (factors, None) if keep_sum else
                              (g.reshape(-1) for g in np.meshgrid(factors, factors, indexing="ij")))
    identity = int(np.argmin(np.abs(grid_upper - 1.0) + (0.0 if grid_lower is None else np.abs(grid_lower - 1.0))))
    ids = {name: body.frame_ids([LIMBS[name].root, LIMBS[name].middle, LIMBS[name].end]) for name in chosen}
    scores = {name: np.zeros(grid_upper.size) for name in chosen}
    unreachable = {name: np.zeros(grid_upper.size) for name in chosen}
    scored = dict.fromkeys(chosen, 0)
    best_middles: dict[str, list[np.ndarray]] = {name: [] for name in chosen}  # per frame, (G, 3)
    count = 0
    frame_names = {int(frame_id): name for name, frame_id in zip(body.keypoints, body.frame_ids(list(body.keypoints)),
                                                                  strict=True)}

    def positions_of(keypoints: Mapping[str, np.ndarray], frame_ids: np.ndarray) -> np.ndarray:
        try:
            return np.array([keypoints[frame_names[int(frame_id)]] for frame_id in frame_ids], dtype=float)
        except KeyError as error:
            raise InputError(f"frames: the pose lacks keypoint {error}, which a criterion reads") from None

    for keypoints, terms in frames:
        count += 1
        moves, placements, bent = [], [], []
        for name in chosen:
            root, middle, end = positions_of(keypoints, ids[name])
            limb = LIMBS[name]
            bent.append(_circle_radius(lengths[limb.upper], lengths[limb.lower],
                                       float(np.linalg.norm(end - root))) >= min_radius)
            points, reaches = _candidates(root, middle, end, grid_upper * lengths[limb.upper],
                                          _lower_factors(grid_upper, grid_lower, lengths, limb) * lengths[limb.lower],
                                          int(swivels), reach_tolerance)
            unreachable[name] += ~reaches
            placements.append(points)
            moves.append(ids[name][1])
        values = np.zeros((len(chosen), grid_upper.size, int(swivels)))
        forbidden = _inside_trunk(keypoints, chosen, placements, trunk_section)
        for task, weight in terms:
            if weight == 0.0 or not getattr(task, "enabled", True):
                continue
            current = positions_of(keypoints, task.frame_ids)
            pose = task.at_pose(current)
            task_moves, movers = [], []
            for index, (middle_id, points) in enumerate(zip(moves, placements, strict=True)):
                rows = np.flatnonzero(task.frame_ids == middle_id)
                if rows.size:
                    task_moves.append((rows, points.reshape(-1, 3)))
                    movers.append(index)
            if task_moves:
                for index, limb_values in zip(movers, task.values_at_moves(current, pose, task_moves), strict=True):
                    values[index] += weight * np.asarray(limb_values).reshape(grid_upper.size, int(swivels))
        for index, name in enumerate(chosen):
            # a pair whose every swivel is inside the trunk keeps them all (the pose's doing)
            kept = ~forbidden[index] | forbidden[index].all(axis=1, keepdims=True)
            allowed_values = np.where(kept, values[index], -np.inf)
            best_swivels = allowed_values.argmax(axis=1)
            best_middles[name].append(placements[index][np.arange(grid_upper.size), best_swivels])
            if bent[index]:
                scores[name] += allowed_values[np.arange(grid_upper.size), best_swivels]
                scored[name] += 1
    before = {name: float(value) for name, value in lengths.items()}
    refined = dict(before)
    evidence = {}
    middles = {}
    for name in chosen:
        if count == 0:
            break
        allowed = unreachable[name] <= unreachable_fraction * count
        if not allowed.any():
            allowed = unreachable[name] == unreachable[name].min()
        score = np.where(allowed, scores[name], -np.inf)
        best = int(np.argmax(score))
        spread = float(score[allowed].max() - score[allowed].min())
        gain = (float(score[best] - score[identity]) / spread) if allowed[identity] and spread > 0.0 else None
        if allowed[identity] and (gain is None or gain <= min_gain):
            best = identity
        limb = LIMBS[name]
        lower = _lower_factors(grid_upper, grid_lower, before, limb)
        refined[limb.upper] = float(grid_upper[best]) * before[limb.upper]
        refined[limb.lower] = float(lower[best]) * before[limb.lower]
        middles[name] = np.array(best_middles[name])[:, best]
        evidence[name] = {"kind": "images", "frames": count, "factors": [float(grid_upper[best]),
                                                                          float(lower[best])],
                          "gain": gain, "scored_frames": scored[name],
                          "calibrated_reaches": bool(allowed[identity]),
                          "unreachable_frames_calibrated": int(unreachable[name][identity])}
    return TrialLengths(refined, before, evidence, middles)


def apply_lengths(body: BodyModel, refined: TrialLengths) -> BodyModel:
    """A copy of the calibrated `body` whose refined segments are stretched by their factor, and
    nothing else moved: each segment's child joint placement in its parent scaled (model's
    set_segment_length), so that the keypoints fitted on the segment move with its end."""
    if not refined.changes:
        return body
    model = copy.deepcopy(body.model)
    for name in refined.changes:
        joint = SEGMENT_JOINTS[name]
        offset = float(np.linalg.norm(model.jointPlacements[model.getJointId(joint)].translation))
        set_segment_length(model, joint, offset * refined.lengths[name] / refined.before[name])
    return dataclasses.replace(body, model=model)
