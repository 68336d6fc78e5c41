"""tracking.swivel_smoothing: the free elbows' and knees' swivels low-passed over the trial, each
joint kept on its circle, and the tracker's pass that moves them there under the targets."""

from __future__ import annotations

import numpy as np
import pytest

from ibik_pin.evaluation import ESTIMATED
from ibik_pin.exceptions import InputError
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.swivel_smoothing import parse_swivel_cutoff, smoothed_middles, smoothing_possible
from ibik_pin.tracking.tracker import Tracker
from tests.walking_clip import walking_clip

RATE_HZ = 30.0


def swinging_limb(frames: int, jitter_rad: float, seed: int = 0):
    """A limb of 0.3 + 0.25 m whose ends move slowly and whose middle joint swivels at 1 Hz about
    their line, the swivel read with white jitter: (roots, ends, true middles, jittered middles)."""
    t = np.arange(frames) / RATE_HZ
    roots = np.stack([0.1 * np.sin(t), 1.4 + 0.0 * t, 0.05 * t], axis=1)
    ends = roots + np.stack([0.1 + 0.0 * t, -0.45 + 0.02 * np.cos(t), 0.1 + 0.0 * t], axis=1)

    def middles(swivel):
        axis = (ends - roots) / np.linalg.norm(ends - roots, axis=1, keepdims=True)
        length = np.linalg.norm(ends - roots, axis=1)
        along = (0.3**2 - 0.25**2 + length**2) / (2 * length)  # the foot of the middle on the line
        radius = np.sqrt(0.3**2 - along**2)
        first = np.cross(axis, [0.0, 0.0, 1.0])
        first /= np.linalg.norm(first, axis=1, keepdims=True)
        second = np.cross(axis, first)
        return (roots + along[:, None] * axis
                + radius[:, None] * (np.cos(swivel)[:, None] * first + np.sin(swivel)[:, None] * second))

    swivel = 0.4 * np.sin(2 * np.pi * 1.0 * t)
    jitter = np.random.default_rng(seed).normal(0.0, jitter_rad, frames)
    return roots, ends, middles(swivel), middles(swivel + jitter)


def test_a_jittered_swivel_comes_closer_to_the_smooth_one_and_each_joint_stays_on_its_circle():
    roots, ends, truth, jittered = swinging_limb(90, 0.1)
    smoothed = smoothed_middles(roots, jittered, ends, RATE_HZ, 6.0)
    for joint in (jittered, smoothed):  # the segments' lengths are the frame's own
        np.testing.assert_allclose(np.linalg.norm(joint - roots, axis=1), 0.3, atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(joint - ends, axis=1), 0.25, atol=1e-9)
    before = np.linalg.norm(jittered - truth, axis=1).mean()
    after = np.linalg.norm(smoothed - truth, axis=1).mean()
    # White jitter keeps the part of its power below the cutoff, about 6 / 15 at 30 Hz (0.63 in rms);
    # measured 0.71.
    assert after < 0.8 * before, (before, after)


def test_a_smooth_swivel_is_left_nearly_as_it_is():
    roots, ends, truth, _ = swinging_limb(90, 0.0)
    smoothed = smoothed_middles(roots, truth, ends, RATE_HZ, 6.0)
    assert np.linalg.norm(smoothed - truth, axis=1).max() < 1e-3  # a 1 Hz swing passes a 6 Hz cutoff


def test_missing_frames_stay_missing_a_short_gap_is_bridged_a_long_one_splits_and_short_runs_are_left():
    roots, ends, _, jittered = swinging_limb(60, 0.1)
    jittered[20] = np.nan  # the joint was a target there: bridged for the filter (as the targets')
    jittered[36:55] = np.nan  # 0.63 s: splits, and leaves a last run of 5 frames, too short to filter
    smoothed = smoothed_middles(roots, jittered, ends, RATE_HZ, 6.0)
    assert np.isnan(smoothed[[20, *range(36, 55)]]).all()
    np.testing.assert_array_equal(smoothed[55:], jittered[55:])
    assert np.linalg.norm(smoothed[:20] - jittered[:20], axis=1).max() > 1e-3
    assert np.linalg.norm(smoothed[21:36] - jittered[21:36], axis=1).max() > 1e-3


def test_a_cutoff_the_frame_rate_cannot_carry_is_refused_and_said_so():
    assert smoothing_possible(30.0, 6.0) and not smoothing_possible(12.0, 6.0)
    roots, ends, _, jittered = swinging_limb(30, 0.1)
    with pytest.raises(ValueError, match="cannot be designed"):
        smoothed_middles(roots, jittered, ends, 12.0, 6.0)


@pytest.mark.parametrize(("text", "expected"), [("off", None), ("OFF", None), ("6", 6.0), ("4.5hz", 4.5), (8, 8.0)])
def test_the_option_reads_off_or_a_cutoff(text, expected):
    assert parse_swivel_cutoff(text) == expected


@pytest.mark.parametrize("bad", ["abc", "0", "-3", "nan", True])
def test_a_bad_option_is_refused_naming_it(bad):
    with pytest.raises(InputError, match="--swivel-cutoff: expected off or a positive cutoff"):
        parse_swivel_cutoff(bad)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("inf"), True, "6"])
def test_the_tracker_refuses_a_bad_cutoff(human, bad):
    with pytest.raises(InputError, match="swivel_cutoff_hz") as raised:
        Tracker(human, settings=TrackingSettings(swivel_cutoff_hz=bad))
    assert raised.value.parameter == "swivel_cutoff_hz"


@pytest.fixture(scope="module")
def walking_runs():
    """The rendered walking (2 views, 30 Hz) tracked with and without the smoothing."""
    clip = walking_clip(2)
    body, cameras, masks, names, targets, _ = clip
    runs = {rate: Tracker(body, cameras, TrackingSettings(read_ahead="off")).track(
        names, targets, silhouettes=lambda frame: masks[frame], frame_rate_hz=rate) for rate in (None, RATE_HZ)}
    return clip, runs


def test_the_tracker_moves_the_free_joints_to_their_smoothed_swivels_and_keeps_the_targets(walking_runs):
    clip, runs = walking_runs
    off, on = runs[None], runs[RATE_HZ]
    assert off.swivel_smoothing is None
    report = on.swivel_smoothing
    assert report["applied"] and report["cutoff_hz"] == 6.0 and report["frames_moved"] > 0
    assert set(report["joints"]) == set(ESTIMATED)
    for name, joint in report["joints"].items():
        # Each ends at its smoothed place (measured 0.001-0.044 mm at the median, 0.47 at most),
        # a few millimetres from the frame's own (medians 0.25-2.9 mm, at most 9.4).
        assert joint["off_smoothed_mm"]["median"] < 0.5 and joint["off_smoothed_mm"]["max"] < 2.0, (name, joint)
        assert joint["moved_mm"]["max"] < 30.0, (name, joint)
    # The targets stay met: no target's distance changes by more than a millimetre (measured 0.45 mm
    # at most, a toe: the closing step takes the feet back through the ankles).
    assert np.nanmax(np.abs(on.target_distances - off.target_distances)) < 1e-3
    # Only the limbs move: the targets' keypoints and the trunk stay where each frame's solve put them.
    moved = np.linalg.norm(on.keypoints - off.keypoints, axis=2).max(axis=0)
    still = [k for k, name in enumerate(on.keypoint_names) if name in ("Hip", "Neck", "LShoulder", "RShoulder")]
    assert moved[still].max() < 1e-3, moved[still]
    # And the elbows and knees against the mocap are no worse (measured 6.98 -> 6.81 mm).
    joints = [on.keypoint_names.index(name) for name in ESTIMATED]
    truth = clip[5]
    errors = [float(np.mean(np.linalg.norm(run.keypoints[:, joints] - truth, axis=2))) for run in (off, on)]
    assert errors[1] < errors[0] + 2e-4, errors
