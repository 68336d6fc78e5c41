"""Why a camera disagrees with the others, before saying it moved.

A camera whose detections miss the landmarks the other views triangulate (extrinsics_refit) may
have moved since its calibration, but the same figure comes from two causes in the images
themselves: another person where the subject should be (the detector followed, or partly took,
someone else), and a tracker that switched people during the clip. The people's association
(person_association) tells both apart from a moved camera: in the frames the camera's figure
comes from, does that view show another person overlapping the subject, and did its tracker
holding the subject change?
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ibik_pin.vision.people import ViewPeople
from ibik_pin.vision.person_association import PeopleTracks

__all__ = ["DISAGREE_FACTOR", "diagnose_cameras"]

# A camera disagrees when its error exceeds this multiple of the other cameras' median error.
DISAGREE_FACTOR = 2.0
# A cause is named when it concerns at least this share of the frames the subject is seen in that view.
CAUSE_SHARE = 0.1


def _overlaps(people: ViewPeople, frame: int, slot: int, other: int) -> bool:
    """Whether two trackers' landmark boxes overlap in a frame."""
    boxes = []
    for index in (slot, other):
        points = people.keypoints[frame, index]
        points = points[np.isfinite(points).all(axis=1)]
        if not len(points):
            return False
        boxes.append((points.min(axis=0), points.max(axis=0)))
    (low_a, high_a), (low_b, high_b) = boxes
    return bool(np.all(low_a <= high_b) and np.all(low_b <= high_a))


def diagnose_cameras(names: Sequence[str], reprojection_px: dict[str, float], views: Sequence[ViewPeople],
                     tracks: PeopleTracks, person: int) -> dict[str, str]:
    """Per camera, in words: "agrees", or which of "another person", "a tracker that switched
    people" or "moved or miscalibrated" explains its disagreement (DISAGREE_FACTOR)."""
    diagnosis = {}
    for view, name in enumerate(names):
        others = [value for key, value in reprojection_px.items() if key != name and np.isfinite(value)]
        error = reprojection_px.get(name, np.nan)
        if not others or not np.isfinite(error) or error <= DISAGREE_FACTOR * float(np.median(others)):
            diagnosis[name] = "agrees"
            continue
        people = views[view]
        identity = tracks.identity[view, :, : people.keypoints.shape[1]]
        present = people.present()
        seen = np.flatnonzero((identity == person).any(axis=1))
        crowded = switched = 0
        previous_slot = None
        for frame in seen:
            slot = int(np.flatnonzero(identity[frame] == person)[0])
            crowded += any(_overlaps(people, int(frame), slot, int(other)) for other in np.flatnonzero(present[frame])
                           if other != slot)
            switched += previous_slot is not None and slot != previous_slot
            previous_slot = slot
        causes = []
        if crowded >= CAUSE_SHARE * max(len(seen), 1):
            causes.append(f"another person overlaps the subject in {crowded} of {len(seen)} frames")
        if switched:
            causes.append(f"the subject passed from one tracker to another {switched} times (a detector that "
                          "switched people)")
        diagnosis[name] = (f"{error:.0f} px against the others' {np.median(others):.0f}: "
                           + ("; ".join(causes) + ": not the camera" if causes else
                              "the subject alone is seen there: the camera moved or is miscalibrated "
                              "(--refit-cameras turns it)"))
    return diagnosis
