"""Which free elbows and knees a frame's swivel search looks at (TrackingSettings.swivel_cadence).

The search (tracking.swivel) is a third of a frame's solve, and on walking and the demo about 97 %
of the limbs it searches get no hint: the image steps keep such a limb where the search would have
put it. So a limb is searched every frame while one of these holds, and otherwise every
`cadence`-th frame, the limbs staggered so that each frame searches about as many:
- it was hinted within the last `cadence` frames (hints come in runs of frames);
- it was not free the frame before (no search has seen it lately);
- its middle joint's distance to the line of its ends (the circle's radius) has risen past the
  search's min_radius since its last search (the search skips a straighter limb);
- the trunk turned more than TURN_DEG since its last search (the shoulders' or the hips' line):
  the cameras then see every limb from another side, and the criterion's basins on its circle
  move even where the limb keeps its pose on the body.
The last is what holds the accuracy. On sweep conditions 0-13 (2 views, clean, 30 Hz) a cadence
of 2 or 3 without it put the elbows of a hop with turns 3.2 and 4.6 mm further off (condition 6):
there the hints' runs began on frames that a quiet limb skipped. On the searches of every limb
every frame (conditions 0, 1, 5, 6, 7, 10), the first hint of a run came with the trunk turning
0.4-15 deg a frame (medians of all frames 4.5-7.5 on the hop turns, 1.2-1.4 on walking), where
neither the limb's own axis turning, its radius changing, nor more of its points leaving the
silhouettes told those frames from the quiet ones. Replayed on those searches, a turn of 3 deg
since the limb's last search left one run's first hint unsearched (condition 5; 1.2 mm on its
elbows in the tracking), 2.5 none on the hop turns (docs/method.md, "Speed"). Counted since the
limb's last search, the turn does not depend on the frame rate.
With cadence 1 every free limb is searched every frame (no state is read).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.tracking.swivel import LIMB_ENDS, limb_circles

__all__ = ["TURN_DEG", "SearchCadence"]

#: The trunk's turn [deg] since a limb's last search past which the limb is searched again.
TURN_DEG = 2.5
#: The two lines whose turn is the trunk's.
TRUNK_LINES = (("LShoulder", "RShoulder"), ("LHip", "RHip"))


class SearchCadence:
    """Per limb of LIMB_ENDS, what its searches found, and which limbs a frame searches.

    Args:
        body: the body model (its keypoints name the limbs' joints).
        cadence: a quiet limb is searched every `cadence`-th frame (1: every frame).
        min_radius: the search's min_radius [m] (SwivelSearch.min_radius).
        turn_deg: the trunk's turn since a limb's last search that has it searched [deg].
    """

    def __init__(self, body: BodyModel, cadence: int, min_radius: float, turn_deg: float = TURN_DEG) -> None:
        if isinstance(cadence, bool) or not isinstance(cadence, (int, np.integer)) or cadence < 1:
            raise InputError(f"swivel_cadence: expected a whole number of frames >= 1, found {cadence!r}",
                             parameter="swivel_cadence")
        self.cadence = int(cadence)
        self.min_radius = float(min_radius)
        self._turn_cosine = float(np.cos(np.deg2rad(turn_deg)))
        self.limbs = [name for name in LIMB_ENDS if name in body.keypoints and all(
            end in body.keypoints for end in LIMB_ENDS[name])]
        # Each limb's root, middle joint and end frames, (L, 3); a limb's place in the stagger.
        self._ids = (np.array([body.frame_ids([LIMB_ENDS[name][0], name, LIMB_ENDS[name][1]])
                               for name in self.limbs]) if self.limbs else np.zeros((0, 3), dtype=int))
        self._offset = {name: index for index, name in enumerate(self.limbs)}
        lines = [line for line in TRUNK_LINES if all(name in body.keypoints for name in line)]
        self._line_ids = body.frame_ids([name for line in lines for name in line]) if lines else None
        self.reset()

    def reset(self) -> None:
        """Forget every limb's history (a new sequence)."""
        self._frame = -1
        self._free: set[str] = set()
        self._last_hint: dict[str, int] = {}
        self._radius: dict[str, float] = {}
        self._lines: dict[str, np.ndarray] = {}

    def choose(self, frame: int, configuration: Configuration, free: Sequence[str]) -> list[str]:
        """The free limbs to search at `frame`, the configuration where the search will read it (the
        first frame: every one)."""
        was_free, self._free, self._frame = self._free, set(free), frame
        if self.cadence == 1:
            return list(free)
        limbs = [name for name in free if name in self._offset]
        radius = self._radii(configuration, limbs)
        lines = self._trunk_lines(configuration)
        chosen = []
        for name in limbs:
            due = (frame + self._offset[name]) % self.cadence == 0
            hinted = frame - self._last_hint.get(name, -self.cadence - 1) <= self.cadence
            straightened = self._radius.get(name, np.inf) < self.min_radius <= radius[name]
            turned = name in self._lines and bool(np.any(np.einsum("li,li->l", lines, self._lines[name])
                                                         < self._turn_cosine))
            if frame == 0 or due or hinted or name not in was_free or straightened or turned:
                chosen.append(name)
        for name in chosen:
            self._radius[name] = radius[name]
            self._lines[name] = lines
        return chosen

    def found(self, hinted: Sequence[str]) -> None:
        """The limbs the frame's search hinted (after choose)."""
        for name in hinted:
            self._last_hint[name] = self._frame

    def _radii(self, configuration: Configuration, limbs: Sequence[str]) -> dict[str, float]:
        """Each limb's swivel circle radius [m]: its middle joint's distance to the line of its ends."""
        if not limbs:
            return {}
        rows = np.array([self._offset[name] for name in limbs])
        roots, middles, ends = configuration.frame_positions(self._ids[rows].reshape(-1)).reshape(
            -1, 3, 3).transpose(1, 0, 2)
        radius = limb_circles(roots, middles, ends).radius
        return {name: float(value) for name, value in zip(limbs, radius, strict=True)}

    def _trunk_lines(self, configuration: Configuration) -> np.ndarray:
        """The unit directions of the shoulders' and the hips' lines (those the body has), (2, 3)."""
        if self._line_ids is None:
            return np.zeros((0, 3))
        points = configuration.frame_positions(self._line_ids).reshape(-1, 2, 3)
        lines = points[:, 1] - points[:, 0]
        return lines / np.maximum(np.linalg.norm(lines, axis=1), 1e-12)[:, None]
