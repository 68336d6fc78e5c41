"""Which free elbows and knees a frame's swivel search looks at (TrackingSettings.swivel_cadence).

The search (tracking.swivel) is a third of a frame's solve, and on walking and the demo about 97 %
of the limbs it searches get no hint: the image steps keep such a limb where the search would have
put it. A hint comes when something changed: a fast move threw the limb into another basin of the
criterion, it just became free (a target dropped), or it bent enough to have a circle worth
searching. So a limb is searched every frame while one of those holds, and otherwise every
`cadence`-th frame, the limbs staggered so that each frame searches about as many:
- it was hinted within the last `cadence` frames (a limb the search is moving is followed);
- it was not free the frame before (no search has seen it lately);
- its middle joint's distance to the line of its ends (the circle's radius) has risen past the
  search's min_radius since its last search (the search skips a straighter limb);
- more of its points lie outside the silhouettes than at its last search (swivel.outside_counts:
  the image explains the limb less well than when it was last searched).
With cadence 1 every free limb is searched every frame (no state is read).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.model import BodyModel
from ibik_pin.tracking.swivel import LIMB_ENDS, outside_counts

__all__ = ["SearchCadence"]


class SearchCadence:
    """Per limb of LIMB_ENDS, what its searches found, and which limbs a frame searches.

    Args:
        body: the body model (its keypoints name the limbs' joints).
        cadence: a quiet limb is searched every `cadence`-th frame (1: every frame).
        min_radius: the search's min_radius [m] (SwivelSearch.min_radius).
        inside_silhouettes: the search's test of points against the silhouettes (None: that
            trigger is off).
    """

    def __init__(self, body: BodyModel, cadence: int, min_radius: float,
                 inside_silhouettes: Callable[[np.ndarray], np.ndarray] | None) -> None:
        if isinstance(cadence, bool) or not isinstance(cadence, (int, np.integer)) or cadence < 1:
            raise InputError(f"swivel_cadence: expected a whole number of frames >= 1, found {cadence!r}",
                             parameter="swivel_cadence")
        self.cadence = int(cadence)
        self.min_radius = float(min_radius)
        self.inside_silhouettes = inside_silhouettes
        self.limbs = [name for name in LIMB_ENDS if name in body.keypoints and all(
            end in body.keypoints for end in LIMB_ENDS[name])]
        # Each limb's root, middle joint and end frames, (L, 3); a limb's place in the stagger.
        self._ids = (np.array([body.frame_ids([LIMB_ENDS[name][0], name, LIMB_ENDS[name][1]])
                               for name in self.limbs]) if self.limbs else np.zeros((0, 3), dtype=int))
        self._offset = {name: index for index, name in enumerate(self.limbs)}
        self.reset()

    def reset(self) -> None:
        """Forget every limb's history (a new sequence)."""
        self._frame = -1
        self._free: set[str] = set()
        self._last_hint: dict[str, int] = {}
        self._radius: dict[str, float] = {}
        self._outside: dict[str, int] = {}

    def choose(self, frame: int, configuration: Configuration, free: Sequence[str]) -> list[str]:
        """The free limbs to search at `frame`, the configuration where the search will read it (the
        first frame: every one)."""
        was_free, self._free, self._frame = self._free, set(free), frame
        if self.cadence == 1:
            return list(free)
        limbs = [name for name in free if name in self._offset]
        radius, outside = self._measure(configuration, limbs)
        chosen = []
        for name in limbs:
            due = (frame + self._offset[name]) % self.cadence == 0
            hinted = frame - self._last_hint.get(name, -self.cadence - 1) <= self.cadence
            straightened = self._radius.get(name, np.inf) < self.min_radius <= radius[name]
            left = outside is not None and outside[name] > self._outside.get(name, outside[name])
            if frame == 0 or due or hinted or name not in was_free or straightened or left:
                chosen.append(name)
        for name in chosen:
            self._radius[name] = radius[name]
            if outside is not None:
                self._outside[name] = outside[name]
        return chosen

    def found(self, hinted: Sequence[str]) -> None:
        """The limbs the frame's search hinted (after choose)."""
        for name in hinted:
            self._last_hint[name] = self._frame

    def _measure(self, configuration: Configuration,
                 limbs: Sequence[str]) -> tuple[dict[str, float], dict[str, int] | None]:
        """Each limb's circle radius [m] and its points outside the silhouettes (None without them)."""
        if not limbs:
            return {}, None if self.inside_silhouettes is None else {}
        rows = np.array([self._offset[name] for name in limbs])
        roots, middles, ends = configuration.frame_positions(self._ids[rows].reshape(-1)).reshape(
            -1, 3, 3).transpose(1, 0, 2)
        axis = ends - roots
        along = np.einsum("li,li->l", middles - roots, axis) / np.maximum(np.einsum("li,li->l", axis, axis), 1e-18)
        radius = np.linalg.norm(middles - roots - along[:, None] * axis, axis=1)
        outside = (None if self.inside_silhouettes is None
                   else outside_counts(self.inside_silhouettes, roots, middles, ends))
        return ({name: float(value) for name, value in zip(limbs, radius, strict=True)},
                None if outside is None else {name: int(value) for name, value in zip(limbs, outside, strict=True)})
