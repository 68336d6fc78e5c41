"""Whole-body jumps in a trial's targets (app.input_checks.frame_jumps), and a static trial's corrupt
cell (check_static_cells), on the demo's real walking (CMU 35_01, bundled)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from ibik_pin.app.demo import DATA
from ibik_pin.app.input_checks import JUMP_DISTANCE_M, check_static_cells, frame_jumps
from ibik_pin.exceptions import InputError
from ibik_pin.io.asf_amc import read_asf_amc
from ibik_pin.io.trc import TrcData
from ibik_pin.synthetic.mocap import keypoints_from_motion


@pytest.fixture(scope="module")
def walking():
    """(F, K, 3) keypoints of 4 s of real walking at 30 Hz [m], 10 mm of seeded noise, and times [s]."""
    motion = read_asf_amc(DATA / "35.asf", DATA / "35_01_first240.amc").subset(slice(0, None, 4))
    _, keypoints = keypoints_from_motion(motion, "asf")
    noisy = keypoints + np.random.default_rng(3).normal(0.0, 0.010, keypoints.shape)
    return noisy, np.arange(len(keypoints)) / motion.frame_rate


def test_real_walking_with_noise_has_no_jump(walking):
    targets, times = walking
    jumps = frame_jumps(targets, times)
    assert not jumps.dropped.any() and not jumps.steps.any()
    assert np.nanmax(jumps.departure_m) < JUMP_DISTANCE_M / 2  # measured 0.05 m at most over every recording


@pytest.mark.parametrize("frames", [[7], [0], [-1], [7, 8], [7, 8, 9], [0, 1], [3, 20], [5, 6, 15]])
@pytest.mark.parametrize("shift", [1e6, -1e200, 0.5, 3.0])
def test_frames_that_leap_away_and_back_are_dropped_and_no_other(walking, frames, shift):
    targets, times = walking
    shifted = targets.copy()
    shifted[frames] += np.array([shift, 0.0, shift]) / np.sqrt(2.0)
    jumps = frame_jumps(shifted, times)
    assert sorted(np.flatnonzero(jumps.dropped)) == sorted(np.arange(len(targets))[frames])
    assert not jumps.steps.any()
    kept = np.delete(jumps.departure_m, frames)
    assert np.nanmax(kept) < JUMP_DISTANCE_M / 2  # the frames around a dropped one are judged without it


def test_a_leap_that_stays_is_a_step_kept(walking):
    targets, times = walking
    shifted = targets.copy()
    shifted[15:] += [0.0, 0.0, 5.0]
    jumps = frame_jumps(shifted, times)
    assert not jumps.dropped.any()
    assert list(np.flatnonzero(jumps.steps)) == [15]


def test_frames_without_targets_are_skipped_not_judged(walking):
    targets, times = walking
    holed = targets.copy()
    holed[[4, 5, 6]] = np.nan
    holed[12] += 1e6
    jumps = frame_jumps(holed, times)
    assert list(np.flatnonzero(jumps.dropped)) == [12]
    assert np.isnan(jumps.departure_m[[4, 5, 6]]).all()


def test_a_low_frame_rate_and_a_few_frames_still_work(walking):
    targets, times = walking
    jumps = frame_jumps(targets[::3][:4], times[::3][:4])  # 10 Hz, 4 frames
    assert not jumps.dropped.any()
    assert not frame_jumps(targets[:2], times[:2]).dropped.any()


def _static(positions: np.ndarray) -> TrcData:
    names = [f"M{k}" for k in range(positions.shape[1])]
    return TrcData(marker_names=names, times=np.arange(len(positions)) / 10.0, positions=positions, units="m",
                   data_rate=10.0, frame_numbers=np.arange(1, len(positions) + 1))


def test_a_static_cell_metres_off_is_refused_naming_frame_marker_and_coordinate(walking):
    targets, _ = walking
    positions = targets[:3].copy()
    positions[2, 4, 2] = 1e200
    data = _static(positions)
    with pytest.raises(InputError, match=r"^--static s\.trc: frame 3 \(data row 3\), marker M4, Z = 1e\+200 m: "
                                         r"more than 2\.5 m from the frame's other markers") as raised:
        check_static_cells("--static", Path("s.trc"), data, positions)
    assert raised.value.parameter == "--static"


def test_a_static_trial_in_other_units_is_left_to_the_unit_check(walking):
    targets, _ = walking
    positions = targets[:2] * 1000.0  # millimetres labelled metres: every marker far, not one cell
    check_static_cells("--static", Path("s.trc"), _static(positions), positions)
    check_static_cells("--static", Path("s.trc"), _static(targets[:2]), targets[:2])
    unchanged = dataclasses.replace(_static(targets[:2]))
    assert unchanged.positions.shape == targets[:2].shape
