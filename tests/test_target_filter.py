"""The targets' temporal filter (tracking.target_filter): what the residual analysis chooses on noisy,
noise-free, fast and already filtered signals, gaps, and `ibik track --target-filter` end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ibik_pin.app.demo import ESTIMATED, prepare_demo_inputs
from ibik_pin.app.job import TrackJob
from ibik_pin.cli import main
from ibik_pin.evaluation import mean_joint_errors_mm
from ibik_pin.exceptions import InputError
from ibik_pin.io.trc import read_trc, write_trc
from ibik_pin.tracking.target_filter import (
    MIN_RUN_FRAMES,
    filter_targets,
    lowpass,
    parse_target_filter,
    residual_cutoff,
)
from tests.paths import SHARED_DATA

POSE2SIM_REF3D = SHARED_DATA / "pose2sim_demo" / "ref3d"


def smooth_motion(rate_hz: float, frames: int) -> np.ndarray:
    """(F, 1, 3) a keypoint swinging at 1.2 Hz with a 3 Hz component [m] (a walking limb's band)."""
    t = np.arange(frames) / rate_hz
    return np.stack([0.1 * np.sin(2 * np.pi * 1.2 * t + phase) + 0.05 * np.sin(2 * np.pi * 3.0 * t)
                     for phase in (0.0, 1.0, 2.0)], axis=1)[:, None, :]


def punches(rate_hz: float, frames: int) -> np.ndarray:
    """(F, 1, 3) two punches, each 0.4 m out and back within about 0.3 s [m]."""
    t = np.arange(frames) / rate_hz
    out = sum(0.4 * np.exp(-0.5 * ((t - t0) / 0.06) ** 2) for t0 in (0.4, 0.9))
    return np.stack([out, 0.05 * np.sin(2 * np.pi * t), 0.0 * t], axis=1)[:, None, :]


def rms_mm(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(np.sum((a - b) ** 2, axis=-1))) * 1e3)


@pytest.mark.parametrize(("rate_hz", "frames"), [(30.0, 40), (30.0, 120), (120.0, 480)])
@pytest.mark.parametrize("sigma", [0.002, 0.005, 0.01])
def test_auto_takes_a_noisy_smooth_motion_closer_to_the_truth(rate_hz, frames, sigma):
    truth = smooth_motion(rate_hz, frames)
    raw = truth + np.random.default_rng(7).normal(0.0, sigma, truth.shape)
    result = filter_targets(["LWrist"], raw, rate_hz, "auto")
    # Measured 0.65-0.75 of the raw error at 30 Hz, 0.4 at 120 Hz.
    assert rms_mm(result.positions, truth) < 0.85 * rms_mm(raw, truth)
    # The noise estimate, per coordinate, within a factor of the sigma drawn.
    assert 0.5 * sigma < result.keypoints["LWrist"].noise_m < 1.5 * sigma


@pytest.mark.parametrize("motion", [smooth_motion, punches])
def test_a_noise_free_motion_is_changed_by_a_fraction_of_a_millimetre(motion):
    truth = motion(30.0, 40)
    result = filter_targets(["RWrist"], truth, 30.0, "auto")
    chosen = result.keypoints["RWrist"]
    assert chosen.change_rms_m < 0.5e-3
    assert chosen.cutoff_hz > 8.0  # of at most 0.75 x 15 Hz


def test_the_residual_analysis_keeps_punch_peaks_that_a_6_hz_filter_cuts():
    truth = punches(120.0, 180)
    peak = np.argmax(truth[:, 0, 0])
    auto = filter_targets(["RWrist"], truth, 120.0, "auto").positions
    fixed = filter_targets(["RWrist"], truth, 120.0, 6.0).positions
    # The 6 Hz filter lowers the 0.4 m peak by centimetres; the analysis's cutoff by less than a millimetre.
    assert truth[peak, 0, 0] - fixed[peak, 0, 0] > 0.01
    assert abs(truth[peak, 0, 0] - auto[peak, 0, 0]) < 1e-3


def test_the_noise_raises_the_cutoff_less_as_the_motion_gets_faster():
    rng = np.random.default_rng(3)
    slow = smooth_motion(60.0, 120) + rng.normal(0.0, 0.005, (120, 1, 3))
    fast = punches(60.0, 120) + rng.normal(0.0, 0.005, (120, 1, 3))
    assert residual_cutoff(fast[:, 0], 60.0)[0] > residual_cutoff(slow[:, 0], 60.0)[0]


def test_a_short_gap_is_bridged_a_long_one_splits_the_track_and_missing_frames_stay_missing():
    rng = np.random.default_rng(1)
    truth = smooth_motion(30.0, 90)[:, 0]
    raw = truth + rng.normal(0.0, 0.005, (90, 3))
    raw[20:22] = np.nan  # 2 frames: bridged for the filter
    raw[40:60, 1] = np.nan  # 20 frames (0.67 s): one missing coordinate makes the frame missing; splits
    raw[86:88] = np.nan  # leaves 2 frames at the end, after a bridged gap: still filtered with the run
    filtered = lowpass(raw, 30.0, 6.0)
    assert np.array_equal(np.isnan(filtered), np.isnan(raw))
    # Each side of the long gap filtered on its own: the same as filtering it alone.
    assert np.allclose(filtered[60:], lowpass(raw[60:], 30.0, 6.0), equal_nan=True)
    assert np.allclose(filtered[:40], lowpass(raw[:40], 30.0, 6.0), equal_nan=True)
    # Around the bridged gap the filter removes noise as elsewhere.
    around = [16, 17, 18, 19, 22, 23, 24, 25]
    assert rms_mm(filtered[around], truth[around]) < rms_mm(raw[around], truth[around])
    short = np.full((20, 3), np.nan)
    short[5:5 + MIN_RUN_FRAMES - 1] = raw[:MIN_RUN_FRAMES - 1]  # too short a run, between long gaps
    assert np.array_equal(lowpass(short, 30.0, 6.0), short, equal_nan=True)


def test_at_15_hz_auto_leaves_the_targets_and_says_why():
    truth = smooth_motion(15.0, 30) + np.random.default_rng(0).normal(0.0, 0.005, (30, 1, 3))
    result = filter_targets(["LWrist"], truth, 15.0, "auto")
    assert np.array_equal(result.positions, truth)
    assert "no band of 2 Hz lies above the motion's 6 Hz" in result.report()["unfiltered_because"]
    assert filter_targets(["LWrist"], truth, 30.0, "auto").report()["unfiltered_because"] is None


def test_a_one_frame_leap_is_kept_as_it_is_and_not_smeared_into_its_neighbours():
    rng = np.random.default_rng(4)
    truth = smooth_motion(30.0, 60)
    raw = truth + rng.normal(0.0, 0.003, truth.shape)
    raw[30, 0, 2] += 0.8  # a glitch: 0.8 m in one frame, farther than 10 m/s moves in 1/30 s
    result = filter_targets(["LAnkle"], raw, 30.0, "auto")
    assert result.keypoints["LAnkle"].leaps == 1
    assert np.array_equal(result.positions[30], raw[30])
    neighbours = [29, 31]
    # The neighbours filtered as if the glitch were not there: within a few mm of the truth.
    assert np.max(np.linalg.norm(result.positions[neighbours, 0] - truth[neighbours, 0], axis=1)) < 0.008
    # A punch's peak at 30 Hz is motion, not a leap.
    assert filter_targets(["RWrist"], punches(30.0, 40), 30.0, "auto").keypoints["RWrist"].leaps == 0


def test_a_keypoint_with_no_run_long_enough_is_left_and_reported_so():
    positions = np.full((12, 2, 3), np.nan)
    positions[:, 0] = smooth_motion(30.0, 12)[:, 0]
    positions[:5, 1] = 0.0
    result = filter_targets(["LWrist", "RWrist"], positions, 30.0, "auto")
    report = result.report()
    assert report["keypoints"]["RWrist"]["cutoff_hz"] is None
    assert np.array_equal(result.positions[:, 1], positions[:, 1], equal_nan=True)


def test_off_changes_nothing_and_a_fixed_cutoff_is_capped_below_nyquist():
    raw = smooth_motion(30.0, 40) + np.random.default_rng(2).normal(0.0, 0.003, (40, 1, 3))
    assert np.array_equal(filter_targets(["Neck"], raw, 30.0, "off").positions, raw)
    capped = filter_targets(["Neck"], raw, 30.0, "50")
    assert capped.mode == "fixed"
    assert capped.keypoints["Neck"].cutoff_hz == pytest.approx(0.75 * 15.0)


@pytest.mark.parametrize("bad", ["fast", "-3", "0", "nan", True, -1.0])
def test_a_bad_setting_is_refused_naming_the_parameter(bad):
    with pytest.raises(InputError) as raised:
        parse_target_filter(bad)
    assert raised.value.parameter == "target_filter"


def test_the_job_refuses_a_bad_setting_naming_the_option(tmp_path):
    with pytest.raises(InputError, match=r"^--target-filter: expected off, auto"):
        TrackJob(targets=tmp_path / "t.trc", out=tmp_path / "out", target_filter="fast")
    assert TrackJob(targets=tmp_path / "t.trc", out=tmp_path / "out", target_filter="6").target_filter == 6.0


@pytest.mark.skipif(not POSE2SIM_REF3D.is_dir(), reason="needs ../shared/data/pose2sim_demo (not in the repository)")
def test_pose2sim_keypoints_already_filtered_are_left_nearly_as_they_are():
    name = "S00_P00_T01_BalancingTrial_0-100"
    raw = read_trc(POSE2SIM_REF3D / f"{name}.trc").in_metres()
    done = read_trc(POSE2SIM_REF3D / f"{name}_filt_butterworth.trc").in_metres()
    on_done = filter_targets(done.marker_names, done.positions, done.data_rate, "auto").report()
    on_raw = filter_targets(raw.marker_names, raw.positions, raw.data_rate, "auto").report()
    # Measured: on Pose2Sim's 6 Hz output cutoffs 17-19 Hz and changes of 0.01 mm; on the triangulated
    # keypoints before it, a median cutoff of 6.4 Hz and changes of 13 mm (Pose2Sim's own filter: 17 mm).
    assert on_done["median_change_rms_mm"] < 0.1
    assert on_done["median_cutoff_hz"] > 15.0
    assert 4.0 < on_raw["median_cutoff_hz"] < 9.0
    assert on_raw["median_change_rms_mm"] > 5.0


@pytest.fixture(scope="module")
def noisy_walk(tmp_path_factory):
    """60 frames of real walking (CMU 35_01 at 30 Hz) with 8 mm of seeded noise on every target."""
    folder = tmp_path_factory.mktemp("noisy_walk")
    paths = prepare_demo_inputs(folder / "input", views=2, frame_step=4)
    targets = read_trc(paths.targets)
    scale = {"m": 1.0, "mm": 1e3}[targets.units]
    targets.positions = targets.positions + np.random.default_rng(5).normal(0.0, 0.008 * scale,
                                                                           targets.positions.shape)
    write_trc(folder / "noisy.trc", targets)
    return paths, folder / "noisy.trc"


def run_blind(paths, targets: Path, out: Path, *extra: str) -> tuple[dict, float]:
    arguments = ["track", "--targets", str(targets), "--static", str(paths.folder / "static.trc"), "--no-image",
                 "--quiet", "--out", str(out), *extra]
    assert main(arguments) == 0
    truth = read_trc(paths.truth)
    estimate = read_trc(out / "joints.trc")
    order = [estimate.marker_names.index(name) for name in truth.marker_names]
    errors = mean_joint_errors_mm(estimate.positions[:, order], truth.positions, truth.marker_names, ESTIMATED)
    return json.loads((out / "report.json").read_text()), float(np.mean(list(errors.values())))


def test_track_with_the_filter_reports_it_and_the_noise_leaves_the_joints(noisy_walk, tmp_path):
    paths, noisy = noisy_walk
    report_off, off_mm = run_blind(paths, noisy, tmp_path / "off", "--target-filter", "off")
    report_auto, auto_mm = run_blind(paths, noisy, tmp_path / "auto")  # the default
    assert report_off["target_filter"]["mode"] == "off"
    assert report_off["target_filter"]["keypoints"] == {}
    chosen = report_auto["target_filter"]
    assert chosen["mode"] == "auto" and chosen["frame_rate_hz"] == pytest.approx(30.0)
    assert set(chosen["keypoints"]) == set(read_trc(noisy).marker_names)
    assert 2.0 < chosen["median_cutoff_hz"] < 11.25
    assert auto_mm < 0.9 * off_mm, (auto_mm, off_mm)


def test_a_bad_target_filter_on_the_command_line_is_one_line_and_exit_2(noisy_walk, tmp_path, capsys):
    _, noisy = noisy_walk
    code = main(["track", "--targets", str(noisy), "--no-image", "--quiet", "--out", str(tmp_path / "out"),
                 "--target-filter", "smooth"])
    error = capsys.readouterr().err
    assert code == 2
    assert error.count("\n") == 1 and error.startswith("ibik: error: --target-filter: expected off, auto")
