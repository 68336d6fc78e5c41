"""Which detection in which view is which person: association across views by triangulation
consistency, identities kept over time, and the subject chosen by a rule.

**Across views** (as Pose2Sim's person association: detections of one person in two views
triangulate with a small reprojection error, detections of two people do not). Every pair of
detections in two views is triangulated on its confident landmarks; its error is the median
reprojection error at the point's depth, in metres (a body-sized tolerance, whatever the cameras'
resolution), the smaller of the two side labellings (a detector may swap left and right in one
view). Pairs under PAIR_MAX_M join, best first, into groups holding at most one detection per view
and whose every pair is under the bound (complete linkage: a chain of near misses does not merge
two people). A detection no other view confirms belongs to no one: it cannot be triangulated.

**Over time.** Each group's centre (the median of its pairs' triangulated landmarks) continues the
identity whose last centre is nearest, if a person could have walked there since (MAX_SPEED_M_S,
plus CENTRE_JITTER_M of the centre's own noise); otherwise it starts a new identity.

**The subject** is, by default, the person seen in the most view-frames (detections associated
to that person, summed over views and frames), ties broken by nearness to the point the cameras'
optical axes converge on. The rule is physical: a capture rig is set up around its subject, who
stays inside the volume all the cameras see for the whole trial, while a passer-by, an operator or
a spectator is in fewer views or for part of the time. People are numbered by the same ranking,
so person 1 is the default subject.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.vision.learned_pose import LANDMARKS
from ibik_pin.vision.people import ViewPeople

__all__ = ["PeopleTracks", "associate_people", "side_free_points", "triangulated_points"]

# Two detections are one person when their triangulation reprojects within this [m] (median over
# the landmarks, at the point's depth): a calibration's and a detector's error are a few cm, a second
# person stands a body's width away at least.
PAIR_MAX_M = 0.12
# A landmark takes part in a pair's test from this visibility on.
PAIR_MIN_VISIBILITY = 0.5
PAIR_MIN_LANDMARKS = 6
# How fast a person may move between frames [m/s] (a sprint), and the noise of a group's centre [m].
MAX_SPEED_M_S = 6.0
CENTRE_JITTER_M = 0.15
# The person must be triangulated (two views or more agreeing) in this share of the frames, and in
# those frames no more than MAX_UNCONFIRMED_SHARE of the views that see someone may see only people
# no other view confirms; otherwise the views cannot be reconciled (a wrong calibration or
# unsynchronised videos leave two views agreeing by chance along an epipolar line, the others alone).
MIN_TRIANGULATED_SHARE = 0.5
MAX_UNCONFIRMED_SHARE = 0.25
# An identity lost longer than this [s] is not continued by the next frames' groups; up to MAX_GAP_S
# it may still be joined to one that appears later where none other overlaps (_joined_fragments).
LINK_GAP_S = 0.25
MAX_GAP_S = 1.0
# Beyond this many combinations of detections in a frame (about 3 people in 8 views) association refuses.
MAX_COMBINATIONS = 50_000
_NOSE = LANDMARKS.index("nose")
_LEFT = [i for i, name in enumerate(LANDMARKS) if name.startswith("left")]
_RIGHT = [LANDMARKS.index("right" + LANDMARKS[i][4:]) for i in _LEFT]
_HIP_FEATURE = 1 + _LEFT.index(LANDMARKS.index("left_hip"))


@dataclass
class PeopleTracks:
    """The people of a multi-view video.

    Attributes:
        identity: (V, F, K) the person (0-based index into `people` order) each tracker's
            detection belongs to; -1 where there is no detection or no other view confirms it.
        view_frames: per person, the number of detections associated to that person.
        frames: per person, the number of frames where two views or more associate that person.
        centres_m: (P, F, 3) each person's centre, NaN where not triangulated.
        pair_errors_m: the errors of the pairs kept (for the report).
        unassociated: per view, detections no other view confirmed.
        unconfirmed: (F, V) bool, the view shows someone no other view confirms in that frame.
    """

    identity: np.ndarray
    view_frames: list[int]
    frames: list[int]
    centres_m: np.ndarray
    pair_errors_m: list[float] = field(default_factory=list)
    unassociated: list[int] = field(default_factory=list)
    unconfirmed: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), bool))

    @property
    def count(self) -> int:
        return len(self.view_frames)


def side_free_points(camera, keypoints: np.ndarray, visibility: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A detection's side-free points: the nose and the midpoint of every left/right pair, in
    undistorted normalised coordinates (M, 2), and whether each is usable (M,) (a swap of the
    detector's left and right leaves them alone)."""
    pixels = np.vstack((keypoints[_NOSE][None], 0.5 * (keypoints[_LEFT] + keypoints[_RIGHT])))
    usable = np.concatenate(([visibility[_NOSE]], np.minimum(visibility[_LEFT], visibility[_RIGHT])))
    usable = (usable >= PAIR_MIN_VISIBILITY) & np.isfinite(pixels).all(axis=1)
    normalised = np.zeros(pixels.shape)
    if usable.any():
        normalised[usable] = cv2.undistortPoints(pixels[usable].reshape(-1, 1, 2).astype(np.float64),
                                                 camera.intrinsics, camera.distortion).reshape(-1, 2)
    return normalised, usable


def triangulated_points(extrinsics: np.ndarray, points: np.ndarray, usable: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """DLT of C combinations at once: extrinsics (V, 3, 4), points (C, V, M, 2), usable (C, V, M).
    Returns the points (C, M, 3) and every view's reprojection error at their depth (C, V, M) [m]."""
    weights = usable.astype(float)
    rows_x = points[..., 0, None] * extrinsics[None, :, None, 2] - extrinsics[None, :, None, 0]
    rows_y = points[..., 1, None] * extrinsics[None, :, None, 2] - extrinsics[None, :, None, 1]
    system = np.concatenate((rows_x * weights[..., None], rows_y * weights[..., None]), axis=1)  # (C, 2V, M, 4)
    _, _, vt = np.linalg.svd(system.transpose(0, 2, 1, 3))
    homogeneous = vt[..., -1, :]  # (C, M, 4)
    with np.errstate(divide="ignore", invalid="ignore"):
        triangulated = homogeneous[..., :3] / homogeneous[..., 3:4]
        camera = np.einsum("vij,cmj->cvmi", extrinsics[:, :, :3], triangulated) + extrinsics[None, :, None, :, 3]
        depth = camera[..., 2]
        errors = np.linalg.norm(camera[..., :2] / depth[..., None] - points, axis=-1) * np.abs(depth)
    return triangulated, errors


def _combination_errors(extrinsics: np.ndarray, points: np.ndarray, usable: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate C combinations of detections at once: extrinsics (V, 3, 4), points (C, V, M, 2),
    usable (C, V, M) (False for a view the combination leaves out). Returns each combination's
    worst view's median reprojection error at the points' depth [m] (inf where a view has fewer
    than PAIR_MIN_LANDMARKS points two views see) and its centre (C, 3): the hips' midpoint, else
    the points' median."""
    triangulated, errors = triangulated_points(extrinsics, points, usable)
    seen_twice = usable.sum(axis=1) >= 2  # (C, M)
    counted = usable & seen_twice[:, None, :]
    errors = np.where(counted, errors, np.nan)
    chosen = usable.any(axis=2)
    enough = counted.sum(axis=2) >= PAIR_MIN_LANDMARKS
    with warnings.catch_warnings():  # a view with no counted point: NaN, handled below
        warnings.simplefilter("ignore", RuntimeWarning)
        per_view = np.nanmedian(errors, axis=2)
        per_view = np.where(chosen & ~enough, np.inf, np.where(chosen, per_view, -np.inf))
        worst = per_view.max(axis=1)
        points_3d = np.where(seen_twice[..., None], triangulated, np.nan)
        centres = np.where(seen_twice[:, [_HIP_FEATURE]], points_3d[:, _HIP_FEATURE],
                           np.nanmedian(points_3d, axis=1))
    return np.where(chosen.sum(axis=1) >= 2, worst, np.inf), centres


def _frame_groups(cameras: Sequence, views: Sequence[ViewPeople], frame: int) -> tuple[list, list[float]]:
    """The frame's people: (members {view: slot}, centre (3,)) and each one's error [m].

    Every combination of one detection or none per view is triangulated; those whose every view
    reprojects within PAIR_MAX_M are consistent; the one with the most views (then the smallest
    error) is a person, its detections are taken out, and so on."""
    options = [[-1, *map(int, np.flatnonzero(people.present()[frame]))] for people in views]
    combinations = np.array(list(itertools.product(*options)))
    combinations = combinations[(combinations >= 0).sum(axis=1) >= 2]
    if len(combinations) == 0:
        return [], []
    if len(combinations) > MAX_COMBINATIONS:
        raise InputError(f"videos: {len(combinations)} combinations of detections in frame {frame}, more than "
                         f"{MAX_COMBINATIONS}: too many people in too many views to associate")
    features = {(v, k): side_free_points(cameras[v], views[v].keypoints[frame, k], views[v].visibility[frame, k])
                for v, choices in enumerate(options) for k in choices if k >= 0}
    marks = len(_LEFT) + 1
    points = np.zeros((len(combinations), len(views), marks, 2))
    usable = np.zeros((len(combinations), len(views), marks), bool)
    for index, combination in enumerate(combinations):
        for view, chosen in enumerate(combination):
            if chosen >= 0:
                points[index, view], usable[index, view] = features[(view, int(chosen))]
    extrinsics = np.array([np.hstack((camera.rotation, camera.translation[:, None])) for camera in cameras])
    errors, centres = _combination_errors(extrinsics, points, usable)
    consistent = np.flatnonzero(errors <= PAIR_MAX_M)
    order = sorted(consistent, key=lambda c: (-(combinations[c] >= 0).sum(), errors[c]))
    taken: set[tuple[int, int]] = set()
    found, kept = [], []
    for best in order:
        members = {view: int(chosen) for view, chosen in enumerate(combinations[best]) if chosen >= 0}
        if any((view, slot) in taken for view, slot in members.items()):
            continue
        taken.update(members.items())
        found.append((members, centres[best]))
        kept.append(float(errors[best]))
    return found, kept


def associate_people(cameras: Sequence, views: Sequence[ViewPeople], frame_rate: float) -> PeopleTracks:
    """Associate every view's detections into people and keep their identities over time (see the
    module's docstring), people ranked by view-frames.

    Args:
        cameras: V calibrated cameras (their world is the returned centres' frame).
        views: V ViewPeople of one synchronised video each, F frames.
        frame_rate: the videos' frame rate [Hz].
    """
    if len(views) != len(cameras) or len(cameras) < 2:
        raise InputError(f"associate_people: expected one ViewPeople per camera and two cameras or more, found "
                         f"{len(views)} and {len(cameras)}")
    frames = views[0].frames
    slots = max(people.keypoints.shape[1] for people in views)
    identity = np.full((len(views), frames, slots), -1)
    tracks: list[dict] = []  # last centre, last frame
    centres: list[dict[int, np.ndarray]] = []
    errors: list[float] = []
    for frame in range(frames):
        groups, frame_errors = _frame_groups(cameras, views, frame)
        errors += frame_errors
        # A tracker that stayed on its person carries the identity: links it supports come first.
        links = sorted((-_support(identity, frame, members, t), float(np.linalg.norm(centre - track["centre"])), g, t)
                       for g, (members, centre) in enumerate(groups) for t, track in enumerate(tracks)
                       if np.isfinite(centre).all() and frame - track["frame"] <= LINK_GAP_S * frame_rate)
        taken_groups: set[int] = set()
        taken_tracks: set[int] = set()
        assigned: dict[int, int] = {}
        for _, distance, g, t in links:
            if g in taken_groups or t in taken_tracks:
                continue
            reach = MAX_SPEED_M_S * (frame - tracks[t]["frame"]) / frame_rate + CENTRE_JITTER_M
            if distance <= reach:
                assigned[g] = t
                taken_groups.add(g)
                taken_tracks.add(t)
        for g, (members, centre) in enumerate(groups):
            if not np.isfinite(centre).all():
                continue
            if g not in assigned:
                tracks.append({"centre": centre, "frame": frame})
                centres.append({})
                assigned[g] = len(tracks) - 1
            person = assigned[g]
            tracks[person] = {"centre": centre, "frame": frame}
            centres[person][frame] = centre
            for view, slot in members.items():
                identity[view, frame, slot] = person
    identity, centres = _joined_fragments(identity, centres, frame_rate)
    view_frames = [int((identity == person).sum()) for person in range(len(centres))]
    order = _ranking(cameras, view_frames, centres)
    renumber = np.full(len(centres) + 1, -1)
    renumber[np.array(order, dtype=int)] = np.arange(len(order))
    identity = renumber[identity]  # -1 indexes the trailing -1
    centre_array = np.full((len(order), frames, 3), np.nan)
    for rank, person in enumerate(order):
        for frame, centre in centres[person].items():
            centre_array[rank, frame] = centre
    present = [people.present() for people in views]
    alone = [present[v] & (identity[v][:, : present[v].shape[1]] < 0) for v in range(len(views))]
    unassociated = [int(view.sum()) for view in alone]
    unconfirmed = np.array([view.any(axis=1) for view in alone]).T
    return PeopleTracks(identity, [view_frames[p] for p in order], [len(centres[p]) for p in order], centre_array,
                        errors, unassociated, unconfirmed)


def _joined_fragments(identity: np.ndarray, centres: list[dict[int, np.ndarray]], frame_rate: float
                      ) -> tuple[np.ndarray, list[dict[int, np.ndarray]]]:
    """Identities that are one person lost for a while (occluded, out of the views): one that starts
    after another ends, within MAX_GAP_S and where a person could have walked in the gap, continues
    it (the nearest in time first)."""
    order = sorted(range(len(centres)), key=lambda person: min(centres[person]))
    joined_to = list(range(len(centres)))
    for position, later in enumerate(order):
        start = min(centres[later])
        best = None
        for earlier in order[:position]:
            root = joined_to[earlier]
            if root != earlier:
                continue
            end = max(centres[root])
            gap = start - end
            if not 0 < gap <= MAX_GAP_S * frame_rate:
                continue
            reach = MAX_SPEED_M_S * gap / frame_rate + CENTRE_JITTER_M
            if np.linalg.norm(centres[root][end] - centres[later][start]) <= reach and (best is None or gap < best[0]):
                best = (gap, root)
        if best is not None:
            joined_to[later] = best[1]
            centres[best[1]].update(centres[later])
    roots = sorted(set(joined_to))
    renumber = np.full(len(centres) + 1, -1)
    for person, root in enumerate(joined_to):
        renumber[person] = roots.index(root)
    return renumber[identity], [centres[root] for root in roots]


def _support(identity: np.ndarray, frame: int, members: dict[int, int], person: int) -> int:
    """How many of a group's detections come from trackers that held `person` in the frame before."""
    if frame == 0:
        return 0
    return sum(int(identity[view, frame - 1, slot] == person) for view, slot in members.items())


def _ranking(cameras: Sequence, view_frames: list[int], centres: list[dict[int, np.ndarray]]) -> list[int]:
    """People by view-frames, most first; ties by the distance of their median centre to the point
    nearest every camera's optical axis."""
    target = _axes_convergence(cameras)

    def distance(person: int) -> float:
        points = np.array(list(centres[person].values()))
        return float(np.linalg.norm(np.median(points, axis=0) - target)) if len(points) else np.inf

    return sorted(range(len(view_frames)), key=lambda person: (-view_frames[person], distance(person)))


def _axes_convergence(cameras: Sequence) -> np.ndarray:
    """The point nearest, in least squares, to every camera's optical axis."""
    system, rhs = np.zeros((3, 3)), np.zeros(3)
    for camera in cameras:
        centre = -camera.rotation.T @ camera.translation
        axis = camera.rotation[2]  # the camera's z axis in the world
        projector = np.eye(3) - np.outer(axis, axis)
        system += projector
        rhs += projector @ centre
    return np.linalg.lstsq(system, rhs, rcond=None)[0]
