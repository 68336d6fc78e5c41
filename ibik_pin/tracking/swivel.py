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
from typing import NamedTuple

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.tasks.segments import SegmentCriterion
from ibik_pin.tracking.arm_support import ARM_CAP, cap_arm_overlap, outside_counts
from ibik_pin.tracking.trunk import TRUNK_KEYPOINTS, TRUNK_SECTION, farther_from_axis, inside_trunk, trunk_distance
from ibik_pin.tracking.views import LIMB_HALF_WIDTH

__all__ = ["LIMB_ENDS", "TRUNK_SECTION", "SwivelSearch", "inside_trunk", "limb_circles", "outside_counts",
           "swivel_circle", "trunk_distance", "views_cross"]

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


class _Circles(NamedTuple):
    """L limbs' swivel circles: centre and radius (L, 3), (L,); the unit vectors toward the middle
    joint and along axis x first (L, 3); the middle joints (L, 3); the limbs without a circle (L,)."""

    centre: np.ndarray
    radius: np.ndarray
    first: np.ndarray
    second: np.ndarray
    middle: np.ndarray
    degenerate: np.ndarray

    def at(self, angles: np.ndarray) -> np.ndarray:
        """The points at swivels [rad] (A,) shared by every limb, or (L, A) per limb: (L, A, 3)."""
        angles = np.atleast_2d(angles)[:, :, None]
        points = self.centre[:, None] + self.radius[:, None, None] * (np.cos(angles) * self.first[:, None]
                                                                     + np.sin(angles) * self.second[:, None])
        points[self.degenerate] = self.middle[self.degenerate][:, None]
        return points


def limb_circles(root: np.ndarray, middle: np.ndarray, end: np.ndarray) -> _Circles:
    """The swivel circles of limbs (L, 3) each (the search places two sets of points on them)."""
    axis = end - root
    length = np.sqrt(np.einsum("li,li->l", axis, axis))
    axis = axis / np.maximum(length, 1e-9)[:, None]
    centre = root + np.einsum("li,li->l", middle - root, axis)[:, None] * axis
    radial = middle - centre
    radius = np.sqrt(np.einsum("li,li->l", radial, radial))
    first = radial / np.maximum(radius, 1e-9)[:, None]
    second = np.stack([axis[:, 1] * first[:, 2] - axis[:, 2] * first[:, 1],  # axis x first
                       axis[:, 2] * first[:, 0] - axis[:, 0] * first[:, 2],
                       axis[:, 0] * first[:, 1] - axis[:, 1] * first[:, 0]], axis=1)
    return _Circles(centre, radius, first, second, middle, (length < 1e-9) | (radius < 1e-9))


def _even(count: int) -> np.ndarray:
    """`count` swivels [rad] evenly around the circle, from 0."""
    return 2.0 * np.pi * np.arange(count) / count


def swivel_circle(root: np.ndarray, middle: np.ndarray, end: np.ndarray, count: int,
                  angles: np.ndarray | None = None) -> np.ndarray:
    """Positions of the middle joint swivelled about the root-end line, distances to both kept.

    Args:
        root, middle, end: (3,) positions [m], or (L, 3) for L limbs at once; count: number of samples.
        angles: the swivels [rad] instead of `count` evenly spaced ones: (A,), or (L, A) per limb.

    Returns:
        (count, 3) positions [m], or (L, count, 3) (A for count with `angles`); swivel 0 is `middle`
        itself. A limb whose ends coincide, or whose middle joint lies on their line, keeps
        `middle` everywhere.
    """
    root, middle, end = (np.asarray(point, dtype=float) for point in (root, middle, end))
    single = root.ndim == 1
    circles = limb_circles(*(np.atleast_2d(point) for point in (root, middle, end))).at(
        _even(count) if angles is None else angles)
    return circles[0] if single else circles


#: The trunk's section (trunk.trunk_distance: sideways, front, back) that measures whether a sample
#: lies nearer the trunk than the elbow (SwivelSearch.keep_unrefuted). The front counts less: an arm
#: in front of the chest lies over the trunk's silhouette in every camera that sees the subject's
#: front, and the criterion's deeper support there is what drew elbows across the chest. With the
#: symmetric section instead, walk131_01's right elbow (sweep condition 3, 2 views) kept 25.4 mm
#: where this gives 15.6 (the earlier rule 25.1).
NEARER_SECTION = (0.75, 1.2, 0.6)
def _distances_to_lines(points: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Distances [m] of points (L, 3) to the lines through starts and ends (L, 3) (to the start
    where the two coincide), shape (L,)."""
    axis = ends - starts
    offset = points - starts
    squared_length = np.einsum("li,li->l", axis, axis)
    along = np.einsum("li,li->l", offset, axis) / np.maximum(squared_length, 1e-18)
    across = offset - np.where(squared_length >= 1e-18, along, 0.0)[:, None] * axis
    return np.sqrt(np.einsum("li,li->l", across, across))


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
        refine: points tried on each side of a limb's best sample, evenly within one sample's
            spacing of it, after the first pass (0: none). The image steps after a hint refine
            it little (they stop at the criterion's peak), so the hint's spacing shows in the
            result: on the real-mocap benchmark's boxing elbows (2 views) 36, 72 and 144 samples
            gave 17.3, 14.0 and 12.3 mm (docs/method.md).
        trunk_section: an elbow is never hinted inside the trunk (inside_trunk, these semi-axes),
            and one that the solve left there is hinted to the best swivel outside it whatever the
            terms say: with two views the silhouettes cover the trunk's whole volume, so the image
            criterion scores an arm laid into the trunk as well as the true one. None: no trunk.
        keep_unrefuted: an elbow whose best sample lies nearer the trunk's axis than the elbow
            (trunk_distance in `nearer_section`, NEARER_SECTION) is hinted only as far as the
            silhouettes ask: to the nearest sample with the fewest points of the arm outside them
            (outside_counts), none if that is where it is.
            A silhouette says where the body is not, never where within itself a limb lies, and the
            support, capped at a limb's half width, is deeper over the trunk than over a thin arm:
            so the criterion prefers an arm laid over or in front of the trunk wherever both views
            see it there. On jumps (2 views, clean) such hints put right elbows 50 mm off on
            average where the prior's were 16-18 (docs/method.md, "Elbows the image made worse than no image").
        arm_cap: an elbow whose best sample on the terms lies nearer the trunk's axis (nearer_section)
            than its best with the image task's overlap of the arm read no deeper than this [m]
            (tracking.arm_support) is searched on the latter: the body-wide cap rewards an arm over
            the trunk more than on its own thinner silhouette. Everywhere instead, walking elbows
            that the body-wide overlap had kept went where the silhouette-axis term alone put them
            (docs/sweep.md, "The elbows' tail"). Default tracking.arm_support.ARM_CAP: on the 2-view
            sweep (42 conditions) the elbows went 18.7 / 36.1 -> 17.3 / 32.1 mm clean and the 90th
            percentile 44.7 -> 38.3 with defects, worse by more than 1 mm in 2 (walk131_01's
            hanging arms, up to 13 mm); real motion within 1.7 mm. None: the image task's values.
    """

    body: BodyModel
    terms: Sequence[tuple[SegmentCriterion, float]]
    samples: int = 36
    min_gain: float = 0.02
    min_distance: float = 0.02
    min_radius: float = 2.0 * LIMB_HALF_WIDTH
    inside_silhouettes: Callable[[np.ndarray], np.ndarray] | None = None
    refine: int = 4
    trunk_section: tuple[float, ...] | None = TRUNK_SECTION
    keep_unrefuted: bool = True
    nearer_section: tuple[float, ...] = NEARER_SECTION
    arm_cap: float | None = ARM_CAP

    def __post_init__(self) -> None:
        if int(self.samples) < 3:
            raise InputError(f"samples: expected at least 3 points on a swivel circle, found {self.samples}")
        if int(self.refine) < 0:
            raise InputError(f"refine: expected a number of points >= 0, found {self.refine}")
        if self.arm_cap is not None and not float(self.arm_cap) > 0.0:
            raise InputError(f"arm_cap: expected a depth > 0 [m] or None, found {self.arm_cap}", parameter="arm_cap")
        self._limb_ids: dict[str, np.ndarray] = {}
        self._term_rows: dict[tuple[SegmentCriterion, int], np.ndarray] = {}
        self._trunk_ids = (self.body.frame_ids(list(TRUNK_KEYPOINTS))
                           if self.trunk_section is not None and all(k in self.body.keypoints for k in TRUNK_KEYPOINTS)
                           else None)

    def _inside_trunk(self, configuration: Configuration, elbows: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Whether each candidate (L, C, 3) of the limbs lies inside the trunk, (L, C); only the
        limbs flagged in `elbows` (L,) can."""
        inside = np.zeros(points.shape[:2], dtype=bool)
        if self._trunk_ids is not None and self.trunk_section is not None and elbows.any():
            hip, neck, left_shoulder, right_shoulder = configuration.frame_positions(self._trunk_ids)
            inside[elbows] = inside_trunk(points[elbows], hip, neck, left_shoulder, right_shoulder, self.trunk_section)
        return inside

    def _towards_trunk(self, configuration: Configuration, elbows: np.ndarray, middles: np.ndarray,
                       picked: np.ndarray) -> np.ndarray:
        """Which of the flagged elbows (L,) would the best sample `picked` (L, 3) take nearer the
        trunk's axis than where it is (middles (L, 3)), with keep_unrefuted."""
        towards = np.zeros(len(elbows), dtype=bool)
        if not self.keep_unrefuted or self.inside_silhouettes is None or self._trunk_ids is None or not elbows.any():
            return towards
        hip, neck, left_shoulder, right_shoulder = configuration.frame_positions(self._trunk_ids)
        distance, _ = trunk_distance(np.stack([middles[elbows], picked[elbows]], axis=1), hip, neck, left_shoulder,
                                     right_shoulder, self.nearer_section)
        towards[elbows] = distance[:, 1] < distance[:, 0]
        return towards

    def _least_refuted(self, roots: np.ndarray, circles: np.ndarray, ends: np.ndarray,
                       forbidden: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For limbs (L, 3) whose candidates are `circles` (L, C, 3), sample 0 where the joint is: the
        candidate nearest the joint among those with the fewest points outside the silhouettes
        (outside_counts), not `forbidden` (L, C), and whether it is a hint (fewer than where the joint
        is): the index (L,) and (L,) bool."""
        if self.inside_silhouettes is None:
            raise InputError("the swivel search needs inside_silhouettes to count a limb's points outside them")
        counts = np.where(forbidden, np.iinfo(np.int64).max,
                          outside_counts(self.inside_silhouettes, roots, circles, ends)).astype(np.int64)
        fewest = counts.min(axis=1)
        distance = np.linalg.norm(circles - circles[:, :1], axis=2)
        nearest = np.argmin(np.where(counts == fewest[:, None], distance, np.inf), axis=1)
        return nearest, fewest < counts[:, 0]

    def _limb_frame_ids(self, name: str) -> np.ndarray:
        """The frames of a limb's root, middle joint and end, shape (3,) (looked up once)."""
        ids = self._limb_ids.get(name)
        if ids is None:
            ids = self._limb_ids[name] = self.body.frame_ids([LIMB_ENDS[name][0], name, LIMB_ENDS[name][1]])
        return ids

    def _rows_of(self, task: SegmentCriterion, frame_id: int) -> np.ndarray:
        """The rows of a term's segment ends that are frame `frame_id` (looked up once per term and
        frame: a term's segment ends are fixed)."""
        rows = self._term_rows.get((task, frame_id))
        if rows is None:
            rows = self._term_rows[(task, frame_id)] = np.flatnonzero(task.frame_ids == frame_id)
        return rows

    def _term_poses(self, configuration: Configuration) -> list[tuple[np.ndarray, object] | None]:
        """Each term's frames at the pose and its state there (None: the term is left out)."""
        current = [configuration.frame_positions(task.frame_ids) if weight != 0.0 and getattr(task, "enabled", True)
                   else None for task, weight in self.terms]
        return [None if c is None else (c, task.at_pose(c)) for (task, _), c in zip(self.terms, current, strict=True)]

    def _weighted(self, poses: list, middle_ids: np.ndarray,
                  circles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each term's weighted value (T, L, C) with each limb's middle joint at each of its
        candidates (L, C, 3), every limb in one call per term, and whether the term reads the limb
        (T, L); `poses`: per term, its segment ends at the frame's pose and its at_pose (None: a
        term left out)."""
        weighted = np.zeros((len(self.terms), len(middle_ids), circles.shape[1]))
        present = np.zeros((len(self.terms), len(middle_ids)), dtype=bool)
        for index, ((task, weight), pose) in enumerate(zip(self.terms, poses, strict=True)):
            if pose is None:
                continue
            moves, movers = [], []
            for limb, middle_id in enumerate(middle_ids):
                rows = self._rows_of(task, int(middle_id))
                if rows.size:
                    moves.append((rows, circles[limb]))
                    movers.append(limb)
            if not moves:
                continue
            current, at_pose = pose
            weighted[index, movers] = weight * np.array(task.values_at_moves(current, at_pose, moves))
            present[index, movers] = True
        return weighted, present

    def hints(self, configuration: Configuration, free: Sequence[str]) -> dict[str, np.ndarray]:
        """Better positions [m] of the free middle joints (those among LIMB_ENDS), by name."""
        limbs = [name for name in free if name in LIMB_ENDS and name in self.body.keypoints]
        if not limbs:
            return {}
        limb_ids = np.array([self._limb_frame_ids(name) for name in limbs])  # (L, 3)
        # Every limb's root, middle joint and end in one read, and its two ends read in the
        # silhouettes at once (a projection per view, not per limb).
        roots, middles, ends = configuration.frame_positions(limb_ids.reshape(-1)).reshape(-1, 3, 3).transpose(1, 0, 2)
        searched = _distances_to_lines(middles, roots, ends) >= self.min_radius
        if self.inside_silhouettes is not None:
            limb_ends = np.stack([roots, ends], axis=1).reshape(-1, 3)
            searched &= self.inside_silhouettes(limb_ends).reshape(-1, 2).all(axis=1)
        chosen = np.flatnonzero(searched)
        if chosen.size == 0:
            return {}
        samples = int(self.samples)
        circle = limb_circles(roots[chosen], middles[chosen], ends[chosen])
        circles = circle.at(_even(samples))  # (L', C, 3)
        # Each term at the frame's pose once, and every limb's candidates in one call per term.
        poses = self._term_poses(configuration)
        weighted, present = self._weighted(poses, limb_ids[chosen, 1], circles)
        elbows = np.array([limbs[limb] in ("LElbow", "RElbow") for limb in chosen])
        arm_cap = self.arm_cap
        forbidden = self._inside_trunk(configuration, elbows, circles)
        if arm_cap is not None and elbows.any():
            # An elbow reads its arm's own overlap where the image task's best swivel lies nearer the
            # trunk's axis than that reading's: there the body-wide cap's preference may be the trunk.
            arms = np.flatnonzero(elbows)
            capped = weighted[:, arms]
            cap_arm_overlap(self.terms, capped, roots[chosen[arms]], circles[arms], ends[chosen[arms]], arm_cap)
            body_wide, own = (circles[arms, np.argmax(np.where(forbidden[arms], -np.inf, terms.sum(axis=0)), axis=1)]
                              for terms in (weighted[:, arms], capped))
            trunk = configuration.frame_positions(self._trunk_ids) if self._trunk_ids is not None else None
            trunkward = (np.zeros(arms.size, dtype=bool) if trunk is None else
                         farther_from_axis(body_wide, own, trunk[0], trunk[1], trunk[2], trunk[3], self.nearer_section))
            arms = arms[trunkward]
            weighted[:, arms] = capped[:, trunkward]
        else:
            arms = np.zeros(0, dtype=int)
        if self.refine:
            # Then around each limb's best sample, within one spacing of it on either side.
            best = np.argmax(np.where(forbidden, -np.inf, weighted.sum(axis=0)), axis=1)
            offsets = np.arange(1, int(self.refine) + 1) / (int(self.refine) + 1)
            offsets = np.concatenate([-offsets[::-1], offsets]) * (2.0 * np.pi / samples)
            finer = circle.at(2.0 * np.pi * best[:, None] / samples + offsets)
            finer_forbidden = self._inside_trunk(configuration, elbows, finer)
            # The final best is the first pass's or a finer point: where all of them lie within
            # min_distance of the joint (and it is not trapped), no hint can come of the limb, so
            # its finer points are not scored (left out as forbidden): the same hints. Not for an
            # elbow that the silhouettes may move elsewhere (_least_refuted picks among every
            # candidate). On real walking (2 views) 78 of 266 limbs and 15 of 120 second passes
            # were left out before that rule.
            reach = np.linalg.norm(np.concatenate([finer, circles[np.arange(chosen.size), best][:, None]], axis=1)
                                   - middles[chosen][:, None], axis=2).max(axis=1)
            scored = (reach > self.min_distance) | forbidden[:, 0] | (elbows & self.keep_unrefuted)
            finer_weighted = np.zeros((*weighted.shape[:2], finer.shape[1]))
            if scored.any():
                finer_weighted[:, scored] = self._weighted(poses, limb_ids[chosen[scored], 1], finer[scored])[0]
            arms = arms[scored[arms]]
            if arm_cap is not None and arms.size:
                capped = finer_weighted[:, arms]
                cap_arm_overlap(self.terms, capped, roots[chosen[arms]], finer[arms], ends[chosen[arms]], arm_cap)
                finer_weighted[:, arms] = capped
            finer_forbidden[~scored] = True
            circles = np.concatenate([circles, finer], axis=1)
            weighted = np.concatenate([weighted, finer_weighted], axis=2)
            forbidden = np.concatenate([forbidden, finer_forbidden], axis=1)
        values = weighted.sum(axis=0)  # absent terms are zeros
        limbs_read = np.flatnonzero(present.any(axis=0))
        best = np.argmax(np.where(forbidden, -np.inf, values), axis=1)
        possible = ~forbidden.all(axis=1)
        spread = np.where(possible, np.where(forbidden, -np.inf, values).max(axis=1)
                          - np.where(forbidden, np.inf, values).min(axis=1), 0.0)
        at_best = np.take_along_axis(values, best[:, None], axis=1)[:, 0]
        # Every term must agree (none worse at the hint than where the joint is): see the class.
        agreed = np.all((np.take_along_axis(weighted, best[None, :, None], axis=2)[..., 0] >= weighted[..., 0])
                        | ~present, axis=0)
        moved = np.linalg.norm(circles[np.arange(chosen.size), best] - middles[chosen], axis=1)
        gained = at_best - values[:, 0] > self.min_gain * spread
        # Sample 0 is where the joint is: an elbow inside the trunk leaves it whatever the terms say.
        trapped = forbidden[:, 0]
        hinted = possible & ((agreed & (spread > 0.0) & gained) | trapped)
        towards = self._towards_trunk(configuration, elbows & hinted & ~trapped, middles[chosen],
                                      circles[np.arange(chosen.size), best])
        if towards.any():
            best[towards], hinted[towards] = self._least_refuted(roots[chosen][towards], circles[towards],
                                                                 ends[chosen][towards], forbidden[towards])
            moved = np.linalg.norm(circles[np.arange(chosen.size), best] - middles[chosen], axis=1)
        hinted &= moved > self.min_distance
        return {limbs[chosen[limb]]: circles[limb, best[limb]] for limb in limbs_read if hinted[limb]}
