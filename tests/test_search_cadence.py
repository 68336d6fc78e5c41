"""TrackingSettings.swivel_cadence: which free elbows and knees a frame's swivel search looks at."""

import itertools
from collections.abc import Sequence

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.tasks import FramePositionTask
from ibik_pin.tracking.search_cadence import SearchCadence
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.swivel import LIMB_ENDS
from ibik_pin.tracking.tracker import Tracker
from tests.conftest import random_human_configuration
from tests.walking_clip import walking_clip

FREE = list(LIMB_ENDS)


@pytest.fixture(scope="module")
def walking():
    """The rendered walking with 3 views (two of them cross: the search runs), without the truth."""
    return walking_clip(3)[:5]


class EveryLimbEveryFrame(Tracker):
    """The tracker as it was before the cadence: every free limb searched on every frame."""

    def _swivel_hints(self, configuration, free, frame):
        tasks = []
        for name, position in self.swivel.hints(configuration, free).items():
            if name not in self._hint_tasks:
                self._hint_tasks[name] = FramePositionTask(self.body.model, self.body.keypoints[name])
            self._hint_tasks[name].set_target(position)
            tasks.append(self._hint_tasks[name])
        return tasks


def _track(walking, tracker_type=Tracker, eager=False, **settings):
    """The motion, and per search: (searched limbs, hinted limbs), in order (one search a frame).
    eager: any sample 5 mm or more from the joint and at least as good is a hint."""
    body, cameras, masks, names, targets = walking
    tracker = tracker_type(body, cameras, TrackingSettings(read_ahead="off", **settings))
    if eager:
        tracker.swivel.min_gain, tracker.swivel.min_distance = 0.0, 0.005
    searches: list[tuple[list[str], list[str]]] = []
    hints = tracker.swivel.hints

    def recorded(configuration, free: Sequence[str]):
        found = hints(configuration, free)
        searches.append((list(free), list(found)))
        return found

    tracker.swivel.hints = recorded  # type: ignore[method-assign]
    return tracker.track(names, targets, silhouettes=lambda frame: masks[frame]), searches


def test_cadence_1_is_the_search_of_every_limb_on_every_frame_to_the_bit(walking):
    """Rendered silhouettes of real walking (3 views): cadence 1 searches the four limbs on each of
    the 30 frames and gives the motion of the tracker without a cadence exactly."""
    before, searched_before = _track(walking, EveryLimbEveryFrame, swivel_cadence=1)
    after, searched = _track(walking, swivel_cadence=1)
    assert [limbs for limbs, _ in searched] == [FREE] * 30
    assert searched == searched_before
    np.testing.assert_array_equal(after.q, before.q)
    np.testing.assert_array_equal(after.keypoints, before.keypoints)


def test_with_a_cadence_a_hinted_limb_is_searched_on_the_next_frame(walking):
    """Cadence 3 on the rendered walking, the search made eager so that hints come: every limb
    hinted on a frame is searched on the next, every limb at least once in any 3 frames, and
    fewer than the 4 a frame of cadence 1."""
    _, searches = _track(walking, eager=True, swivel_cadence=3)
    assert len(searches) == 30  # each frame searches some limb (the stagger)
    hinted = sum(len(found) for _, found in searches)
    off_turn = 0  # hinted limbs searched next off their turn in the stagger
    for frame, ((_, found), (limbs, _)) in enumerate(itertools.pairwise(searches)):
        assert set(found) <= set(limbs)
        off_turn += sum((frame + 1 + FREE.index(name)) % 3 != 0 for name in found)
    for start in range(28):
        assert set().union(*(limbs for limbs, _ in searches[start:start + 3])) == set(FREE)
    assert sum(len(limbs) for limbs, _ in searches) < 4 * 30
    assert off_turn > 0, f"{hinted} hints, none off turn: the test would check nothing"


def test_a_limb_off_its_turn_is_searched_when_hinted_lately_or_just_freed(human):
    """Cadence 4 (the limbs' turns: frame + 0, 1, 2, 3 a multiple of 4): the first frame searches
    every limb; then each its turn, a limb not free the frame before, and one hinted within the
    last 4 frames."""
    configuration = Configuration(human.model, pin.neutral(human.model))
    cadence = SearchCadence(human, 4, min_radius=0.0)
    assert cadence.choose(0, configuration, FREE) == FREE
    assert cadence.choose(1, configuration, FREE) == ["RKnee"]
    assert cadence.choose(2, configuration, ["LElbow", "RElbow"]) == []
    assert cadence.choose(3, configuration, FREE) == ["RElbow", "LKnee", "RKnee"]  # the knees freed again
    cadence.found(["LKnee"])
    assert cadence.choose(4, configuration, FREE) == ["LElbow", "LKnee"]
    assert [cadence.choose(frame, configuration, FREE) for frame in (5, 6, 7, 8)] == [
        ["LKnee", "RKnee"], ["LKnee"], ["RElbow", "LKnee"], ["LElbow"]]


def test_a_limb_bent_past_min_radius_since_its_last_search_is_searched(human, rng):
    """From the neutral pose (limbs nearly straight) to a bent one, the limbs whose circle's radius
    rose past min_radius are searched off their turn, and only those."""
    straight = Configuration(human.model, pin.neutral(human.model))
    bent = Configuration(human.model, random_human_configuration(human, rng, spread=0.8))
    cadence = SearchCadence(human, 4, min_radius=0.05, turn_deg=180.0)  # the trunk's turn left out
    before, after = cadence._radii(straight, FREE), cadence._radii(bent, FREE)
    crossed = [name for name in FREE if before[name] < 0.05 <= after[name]]
    assert crossed, "no limb crossed: the test would check nothing"
    cadence.choose(0, straight, FREE)
    assert cadence.choose(1, bent, FREE) == [name for name in FREE if name in crossed or name == "RKnee"]


@pytest.mark.parametrize(("turn_deg", "searched"), [(2.0, ["RKnee"]), (4.0, FREE)])
def test_a_limb_is_searched_when_the_trunk_turned_since_its_last_search(human, turn_deg, searched):
    """The whole body turned by 2 or 4 deg (about an axis across the shoulders' line) between two
    frames: past the 2.5 deg of TURN_DEG every limb is searched, below it only the one whose turn it is."""
    q = pin.neutral(human.model)
    configuration = Configuration(human.model, q)
    shoulders = np.subtract(*configuration.frame_positions(human.frame_ids(["RShoulder", "LShoulder"])))
    axis = np.cross(shoulders, [0.0, 0.0, 1.0]) + np.cross(shoulders, [1.0, 0.0, 0.0])
    turned = q.copy()
    turned[3:7] = pin.Quaternion(pin.AngleAxis(np.deg2rad(turn_deg), axis / np.linalg.norm(axis))).coeffs()
    cadence = SearchCadence(human, 4, min_radius=0.0)
    assert cadence.choose(0, configuration, FREE) == FREE
    assert cadence.choose(1, Configuration(human.model, turned), FREE) == searched


@pytest.mark.parametrize("cadence", [0, -1, 1.5, True, "2"])
def test_a_cadence_that_is_not_a_whole_number_of_frames_is_refused(human, cadence):
    with pytest.raises(InputError, match="swivel_cadence: expected a whole number") as raised:
        Tracker(human, settings=TrackingSettings(swivel_cadence=cadence))
    assert raised.value.parameter == "swivel_cadence"
