"""One person's detections in every view, as the single-person pipeline reads them (VideoPose):
the person's landmarks, minus those the other views contradict, and the person's silhouette minus
everyone else's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ibik_pin.exceptions import InputError, UnreconciledViewsError
from ibik_pin.vision.learned_pose import LANDMARKS, VideoPose
from ibik_pin.vision.mask_store import CroppedMasks
from ibik_pin.vision.people import ViewPeople
from ibik_pin.vision.person_association import (
    _LEFT,
    _NOSE,
    _RIGHT,
    MAX_UNCONFIRMED_SHARE,
    MIN_TRIANGULATED_SHARE,
    PeopleTracks,
    side_free_points,
    triangulated_points,
)

__all__ = ["LANDMARK_MAX_M", "person_pose"]

# A landmark whose side-free point the other views place farther than this [m] is not used.
LANDMARK_MAX_M = 0.15


def person_pose(cameras: Sequence, views: Sequence[ViewPeople], tracks: PeopleTracks, person: int) -> list[VideoPose]:
    """One person's detections in every view, as the VideoPose the single-person pipeline reads:
    landmarks NaN where the view does not show that person (or no other view confirms it), the
    silhouette the tracker's minus every other tracker's in that frame. A landmark that falls on
    another person's silhouette is not used (visibility 0): in front of that person the detector
    may have taken the other's limb for this one's, behind it the landmark is a guess; the other
    views, which see it clear, place it.

    Raises:
        UnreconciledViewsError: the person is not triangulated in MIN_TRIANGULATED_SHARE of the
            frames, or too many views show people no other view confirms.
    """
    if not 0 <= person < tracks.count:
        raise InputError(f"person: expected 1 to {tracks.count}, found {person + 1}", parameter="person")
    detected = tracks.view_frames[person]
    triangulated = tracks.frames[person]
    frames = views[0].frames
    if triangulated < MIN_TRIANGULATED_SHARE * frames:
        raise UnreconciledViewsError(
            f"person {person + 1}: the views agree on this person in {triangulated} of {frames} frames "
            f"({detected} detections): the views cannot be reconciled (a wrong calibration, unsynchronised "
            "videos, or people the detector mixes)", parameter="person")
    in_frames = np.isfinite(tracks.centres_m[person, :, 0])
    used = (tracks.identity[:, in_frames] == person).any(axis=2).sum()
    unconfirmed = tracks.unconfirmed[in_frames].sum()
    if unconfirmed > MAX_UNCONFIRMED_SHARE * (used + unconfirmed):
        raise UnreconciledViewsError(
            f"person {person + 1}: in the {int(in_frames.sum())} frames two views agree on, {int(unconfirmed)} "
            f"views show people no other view confirms, against {int(used)} that agree: the views cannot be "
            "reconciled (a wrong calibration or unsynchronised videos)", parameter="person")
    poses = []
    for view, people in enumerate(views):
        keypoints = np.full((frames, len(LANDMARKS), 2), np.nan)
        visibility = np.zeros((frames, len(LANDMARKS)))
        masks = CroppedMasks(people.size)
        present = people.present()
        slots_of_view = people.keypoints.shape[1]
        for frame in range(frames):
            identities = tracks.identity[view, frame, :slots_of_view]
            slots = np.flatnonzero(identities == person)
            if slots.size == 0:
                masks.append_crop(0, 0, np.zeros((0, 0), bool))
                continue
            slot = int(slots[0])
            keypoints[frame], visibility[frame] = people.keypoints[frame, slot], people.visibility[frame, slot]
            others = [other for other in np.flatnonzero(present[frame]) if other != slot]
            if not others:  # alone in the view: the tracker's silhouette as stored
                masks.append_crop(*people.masks[slot].crop(frame))
                continue
            mask = people.masks[slot][frame]
            for other in others:
                other_mask = people.masks[other][frame]
                mask &= ~other_mask
                visibility[frame] = np.where(_inside(other_mask, keypoints[frame]), 0.0, visibility[frame])
            masks.append(mask)
        poses.append(VideoPose(keypoints, visibility, masks))
    for frame in range(frames):
        contradicted = _contradicted(cameras, np.array([pose.keypoints[frame] for pose in poses]),
                                     np.array([pose.visibility[frame] for pose in poses]))
        for view, pose in enumerate(poses):
            pose.visibility[frame, contradicted[view]] = 0.0
    return poses


def _inside(mask: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """(N,) bool: each pixel (N, 2) falls inside the mask."""
    inside = np.zeros(len(pixels), bool)
    finite = np.isfinite(pixels).all(axis=1)
    rounded = np.round(pixels[finite]).astype(int)
    height, width = mask.shape
    within = (rounded[:, 0] >= 0) & (rounded[:, 0] < width) & (rounded[:, 1] >= 0) & (rounded[:, 1] < height)
    hits = np.zeros(len(rounded), bool)
    hits[within] = mask[rounded[within, 1], rounded[within, 0]]
    inside[finite] = hits
    return inside


def _contradicted(cameras: Sequence, keypoints: np.ndarray, visibility: np.ndarray) -> np.ndarray:
    """(V, 33) bool: landmarks of one person's detections in V views (V, 33, 2) that the other
    views contradict: the side-free point they make (see _features), triangulated from the other
    views (two or more), misses it by more than LANDMARK_MAX_M at its depth. Such a landmark is
    the detector's guess of a hidden limb or a limb of someone else."""
    views = len(cameras)
    contradicted = np.zeros((views, len(LANDMARKS)), bool)
    present = np.isfinite(keypoints[..., 0]).any(axis=1)
    if present.sum() < 3:
        return contradicted
    extrinsics = np.array([np.hstack((camera.rotation, camera.translation[:, None])) for camera in cameras])
    features = [side_free_points(camera, keypoints[v], visibility[v]) if present[v] else
                (np.zeros((len(_LEFT) + 1, 2)), np.zeros(len(_LEFT) + 1, bool)) for v, camera in enumerate(cameras)]
    points = np.array([[f[0] for f in features]] * views)
    usable = np.array([[f[1] for f in features]] * views)
    left_out = usable.copy()
    left_out[np.arange(views), np.arange(views)] = False  # combination v: every view but v
    _, errors = triangulated_points(extrinsics, points, left_out)
    others = left_out.sum(axis=1) >= 2  # (V, M)
    diagonal = errors[np.arange(views), np.arange(views)]  # (V, M): view v's own point against the others
    bad = usable[0] & others & (diagonal > LANDMARK_MAX_M)
    pairs = [[_NOSE]] + [[left, right] for left, right in zip(_LEFT, _RIGHT, strict=True)]
    for m, landmarks in enumerate(pairs):
        contradicted[:, landmarks] |= bad[:, m, None]
    return contradicted
