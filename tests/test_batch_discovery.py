"""Tests of finding `ibik batch`'s trials, their calibration and their participant's subject, on
folders laid out as Pose2Sim lays out a session (empty files: only names and places matter)."""

from __future__ import annotations

from pathlib import Path

from ibik_pin.app.batch.discovery import Subject, find_trials


def touch(*paths: Path) -> None:
    for path in paths:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.touch()


def pose2sim_session(root: Path) -> None:
    """Pose2Sim's batch layout: configs at every level, calibration at the session's top, static
    and moving trials per participant with their triangulation in pose-3d/ and their videos."""
    touch(root / "Config.toml", root / "Calibration" / "Calib_board.toml", root / "P1" / "Config.toml",
          root / "P1" / "S00_P01_StaticTrial" / "pose-3d" / "static_0-10.trc",
          root / "P1" / "S00_P01_StaticTrial" / "videos" / "cam01.mp4",
          root / "P1" / "T1" / "pose-3d" / "T1_0-100.trc", root / "P1" / "T1" / "videos" / "cam01.mp4",
          root / "P1" / "T1" / "background" / "cam01.png",
          root / "P2" / "T1" / "T1.trc", root / "P2" / "T1" / "masks" / "cam01" / "0.png")


def test_a_pose2sim_session_gives_each_trial_its_targets_videos_calibration_and_static(tmp_path):
    pose2sim_session(tmp_path)

    trials = find_trials(tmp_path)

    assert [trial.name for trial in trials] == [Path("P1/T1"), Path("P2/T1")]
    first, second = trials
    assert first.targets == tmp_path / "P1" / "T1" / "pose-3d" / "T1_0-100.trc"
    assert first.videos == tmp_path / "P1" / "T1" / "videos" and first.masks is None
    assert first.background == tmp_path / "P1" / "T1" / "background"
    assert first.calibration == tmp_path / "Calibration" / "Calib_board.toml"  # Config.toml is not one
    assert first.subject == Subject(Path("P1"), static=tmp_path / "P1" / "S00_P01_StaticTrial" / "pose-3d"
                                    / "static_0-10.trc")
    assert first.problem is None
    assert second.masks == tmp_path / "P2" / "T1" / "masks" and second.subject is None and second.problem is None


def test_two_trc_files_are_that_trials_problem_until_a_pattern_picks_one(tmp_path):
    pose2sim_session(tmp_path)
    touch(tmp_path / "P1" / "T1" / "pose-3d" / "T1_0-100_filt_butterworth.trc")

    ambiguous = {trial.name: trial for trial in find_trials(tmp_path)}
    picked = {trial.name: trial for trial in find_trials(tmp_path, "*_filt_*.trc")}

    assert "several TRC files" in ambiguous[Path("P1/T1")].problem and "--targets" in ambiguous[Path("P1/T1")].problem
    assert ambiguous[Path("P1/T1")].targets is None
    assert ambiguous[Path("P2/T1")].problem is None  # the others are not affected
    assert picked[Path("P1/T1")].targets.name == "T1_0-100_filt_butterworth.trc"


def test_the_nearest_calibration_wins_and_two_in_one_folder_are_a_problem(tmp_path):
    pose2sim_session(tmp_path)
    touch(tmp_path / "P2" / "T1" / "calib_own.toml", tmp_path / "P1" / "calibration" / "Calib_a.toml",
          tmp_path / "P1" / "calibration" / "Calib_b.toml")

    trials = {trial.name: trial for trial in find_trials(tmp_path)}

    assert trials[Path("P2/T1")].calibration == tmp_path / "P2" / "T1" / "calib_own.toml"
    assert trials[Path("P1/T1")].calibration is None
    assert "several calibration files" in trials[Path("P1/T1")].problem


def test_a_urdf_in_the_participants_folder_is_its_model_and_no_static_is_calibrated(tmp_path):
    pose2sim_session(tmp_path)
    touch(tmp_path / "P1" / "subject.urdf")

    first = find_trials(tmp_path)[0]

    assert first.subject == Subject(Path("P1"), model=tmp_path / "P1" / "subject.urdf")


def test_the_output_folder_inside_root_and_hidden_folders_are_not_searched(tmp_path):
    pose2sim_session(tmp_path)
    touch(tmp_path / "out" / "P1" / "T1" / "joints.trc", tmp_path / ".cache" / "x" / "a.trc")

    names = [trial.name for trial in find_trials(tmp_path, exclude=tmp_path / "out")]

    assert names == [Path("P1/T1"), Path("P2/T1")]


def test_masks_are_preferred_to_videos_when_a_trial_has_both(tmp_path):
    touch(tmp_path / "T" / "t.trc", tmp_path / "T" / "masks" / "cam1" / "0.png", tmp_path / "T" / "videos" / "cam1.mp4")

    trial = find_trials(tmp_path)[0]

    assert trial.masks == tmp_path / "T" / "masks" and trial.videos is None and trial.background is None
