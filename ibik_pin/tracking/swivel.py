"""A global search of each free limb's swivel on the image criterion.

With the shoulder and wrist (hip and ankle) on their targets, an elbow (knee) that is not a target
can only lie on a circle: the swivel of the limb about the line between its ends. The image level
climbs the criterion from where the previous frame left the limb, and on fast motion (a punch) the
elbow falls into another basin within a few frames and stays there: on real boxing, elbows tracked
from the true pose were 100-200 mm off ten frames later, although the criterion (overlap plus
silhouette axis) had its maximum within a few millimetres of the truth on most frames.

So once each frame's targets are met the swivel circle of every free middle joint is sampled, the
criterion is evaluated at each sample with the rest of the body where the solve left it (segment
ends moved, nothing re-solved: a few hundred projections), and the best sample becomes a hint when
it is clearly better than where the joint is. The tracker then pulls the joint there and lets the
image level refine.

A global search trusts the silhouettes far more than a local climb does, so a limb is searched
only when its two ends (shoulder and wrist, hip and ankle: targets) lie inside the silhouette in
every view. Background subtraction on the real Pose2Sim video keeps little but the moving limbs of
a subject balancing in place; searched anyway, the left knee ended 100 mm from Pose2Sim's
triangulation against 63 mm without the image (4 views).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.tasks.segments import SegmentCriterion
from ibik_pin.tracking.views import LIMB_HALF_WIDTH

__all__ = ["LIMB_ENDS", "SwivelSearch", "swivel_circle", "views_cross"]

#: Middle joint -> the two limb ends it swivels between.
LIMB_ENDS: dict[str, tuple[str, str]] = {
    "LElbow": ("LShoulder", "LWrist"),
    "RElbow": ("RShoulder", "RWrist"),
    "LKnee": ("LHip", "LAnkle"),
    "RKnee": ("RHip", "RAnkle"),
}


def views_cross(cameras: Sequence, min_angle_deg: float = 45.0) -> bool:
    """Whether two of the cameras look across each other (optical axes at least `min_angle_deg`
    from parallel or antiparallel).

    A swivel moves the middle joint mostly along some direction; views that all look along one
    line (one camera, or two facing each other) do not see depth along it, and a swivel and its
    mirror then score almost alike: a global search would trade one for the other at random, so
    it is worth running only when the views cross.
    """
    axes = [np.asarray(camera.rotation)[2] for camera in cameras]
    limit = np.cos(np.deg2rad(min_angle_deg))
    return any(abs(float(a @ b)) < limit for index, a in enumerate(axes) for b in axes[index + 1:])


def swivel_circle(root: np.ndarray, middle: np.ndarray, end: np.ndarray, count: int) -> np.ndarray:
    """Positions of the middle joint swivelled about the root-end line, distances to both kept.

    Args:
        root, middle, end: (3,) positions [m]; count: number of samples.

    Returns:
        (count, 3) positions [m]; the first is `middle` itself (swivel 0).
    """
    axis = end - root
    length = np.linalg.norm(axis)
    if length < 1e-9:
        return np.repeat(middle[None], count, axis=0)
    axis = axis / length
    centre = root + ((middle - root) @ axis) * axis
    radial = middle - centre
    radius = np.linalg.norm(radial)
    if radius < 1e-9:
        return np.repeat(middle[None], count, axis=0)
    first = radial / radius
    second = np.array([axis[1] * first[2] - axis[2] * first[1], axis[2] * first[0] - axis[0] * first[2],
                       axis[0] * first[1] - axis[1] * first[0]])  # axis x first (np.cross costs ten times this)
    angles = 2.0 * np.pi * np.arange(count) / count
    return centre + radius * (np.cos(angles)[:, None] * first + np.sin(angles)[:, None] * second)


def _distance_to_line(point: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    """Distance [m] of a point to the line through start and end (to start if they coincide)."""
    axis = end - start
    length = np.linalg.norm(axis)
    offset = point - start
    if length < 1e-9:
        return float(np.linalg.norm(offset))
    return float(np.linalg.norm(offset - (offset @ axis) / length**2 * axis))


@dataclass
class SwivelSearch:
    """Sample every free middle joint's swivel circle on a weighted sum of criteria.

    The best sample of the sum becomes a hint only if no term is worse there than at the joint's
    current position: a global jump needs every piece of evidence to agree. The one-way overlap
    alone rewards any position inside the silhouette, so it favours an arm laid over the trunk;
    on walking with the two cameras from behind added (4 views), the sum's best sample was
    37-48 mm from the true elbow (the overlap preferring it in the back views, the silhouette-axis
    term preferring the truth), and following it took the elbows from 14-20 to 38-42 mm. With the
    agreement rule: 14/20 mm there, and the boxing elbows keep their gain.

    Attributes:
        body: the body model.
        terms: (task, weight) pairs; each task reads the segment ends `frame_ids` and gives
            `at_pose(positions (K, 3))` and `values_at(positions (C, K, 3), moved, pose)`
            (tasks.segments.SegmentCriterion).
        samples: points on each circle.
        min_gain: a hint needs a criterion this much above the current pose's, as a fraction of
            the criterion's range over the circle (a flat circle gives no hint).
        min_distance: a hint must be at least this far from the joint's current position [m].
        min_radius: a limb whose middle joint lies closer than this to the line between its ends
            is not searched [m]. Wherever such a nearly straight limb swivels, its centre line
            stays within its own silhouette (two half-widths, tracking.views.LIMB_HALF_WIDTH):
            the silhouettes cannot tell the swivel. Searched anyway, walking elbows (circle radius
            60-70 mm) went 15-21 -> 34-45 mm with 4 views, where the criterion's best point on
            the circle was itself 37-48 mm from the truth.
        inside_silhouettes: (N, 3) points [m] -> (N,) bool, whether each lies inside the
            silhouettes (tasks.image.ImageTask.inside_silhouettes); a limb whose two ends do not
            gets no hint. None: every limb is searched.
    """

    body: BodyModel
    terms: Sequence[tuple[SegmentCriterion, float]]
    samples: int = 36
    min_gain: float = 0.02
    min_distance: float = 0.02
    min_radius: float = 2.0 * LIMB_HALF_WIDTH
    inside_silhouettes: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        if int(self.samples) < 3:
            raise InputError(f"samples: expected at least 3 points on a swivel circle, found {self.samples}")
        self._limb_ids: dict[str, np.ndarray] = {}

    def _limb_frame_ids(self, name: str) -> np.ndarray:
        """The frames of a limb's root, middle joint and end, shape (3,) (looked up once)."""
        ids = self._limb_ids.get(name)
        if ids is None:
            ids = self._limb_ids[name] = self.body.frame_ids([LIMB_ENDS[name][0], name, LIMB_ENDS[name][1]])
        return ids

    def hints(self, configuration: Configuration, free: Sequence[str]) -> dict[str, np.ndarray]:
        """Better positions [m] of the free middle joints (those among LIMB_ENDS), by name."""
        hints: dict[str, np.ndarray] = {}
        limbs = [name for name in free if name in LIMB_ENDS and name in self.body.keypoints]
        limb_ids = [self._limb_frame_ids(name) for name in limbs]
        # Every limb's two ends read in the silhouettes at once (a projection per view, not per limb).
        ends_inside = np.ones((len(limbs), 2), dtype=bool)
        if self.inside_silhouettes is not None and limbs:
            ends = np.array([configuration.frame_positions(ids[[0, 2]]) for ids in limb_ids]).reshape(-1, 3)
            ends_inside = self.inside_silhouettes(ends).reshape(-1, 2)
        # The limbs to search, each with its candidates (its middle joint moved alone).
        searched = []
        for name, ids, inside in zip(limbs, limb_ids, ends_inside, strict=True):
            root, middle, end = configuration.frame_positions(ids)
            if not inside.all():
                continue
            if _distance_to_line(middle, root, end) < self.min_radius:
                continue
            searched.append((name, ids, middle, swivel_circle(root, middle, end, int(self.samples))))
        # Each term at the frame's pose once, and every limb's candidates in one call per term.
        term_values: list[list[np.ndarray]] = [[] for _ in searched]  # per limb, each term's weighted values
        for task, weight in self.terms:
            if weight == 0.0 or not getattr(task, "enabled", True) or not searched:
                continue
            moves, movers = [], []
            for index, (_, ids, _, candidates) in enumerate(searched):
                rows = np.flatnonzero(task.frame_ids == ids[1])
                if rows.size:
                    moves.append((rows, candidates))
                    movers.append(index)
            if not moves:
                continue
            current = configuration.frame_positions(task.frame_ids)
            for index, values in zip(movers, task.values_at_moves(current, task.at_pose(current), moves), strict=True):
                term_values[index].append(weight * values)
        for (name, _, middle, candidates), terms in zip(searched, term_values, strict=True):
            if not terms:
                continue
            values = np.sum(terms, axis=0)
            best = int(np.argmax(values))
            spread = values.max() - values.min()
            # Every term must agree (none worse at the hint than where the joint is): see the class.
            agreed = all(term[best] >= term[0] for term in terms)
            if (agreed and spread > 0.0 and values[best] - values[0] > self.min_gain * spread
                    and np.linalg.norm(candidates[best] - middle) > self.min_distance):
                hints[name] = candidates[best]
        return hints
