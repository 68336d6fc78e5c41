"""Tests of what a Dask worker runs for `ibik batch`, called here without Dask: one trial's track
job, a participant's calibration, a done trial's row; and the summary table's files."""

from __future__ import annotations

import csv
import sys

import pytest

from ibik_pin.app.batch.summary import TrialOutcome, write_summary
from ibik_pin.app.batch.tasks import SubjectOutcome, calibrate_subject_once, completed_outcome, run_trial
from ibik_pin.app.job import TrackJob
from ibik_pin.synthetic.trials import write_trial_tree
from ibik_pin.tracking.settings import TrackingSettings


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("tasks") / "root"
    write_trial_tree(root, trials_per_participant=(1,), frames=3)
    return root


def job(root, out, **changes) -> TrackJob:
    trial = root / "P1" / "walk_1"
    arguments = {"targets": trial / "targets.trc", "out": out, "masks": trial / "masks", "quiet": True,
                 "calibration": root / "calibration" / "Calib_synthetic.toml",
                 "settings": TrackingSettings(iterations=2)}
    return TrackJob(**{**arguments, **changes})


def test_a_trial_is_tracked_and_its_warnings_are_kept_in_its_row(root, tmp_path):
    lines = (root / "P1" / "walk_1" / "targets.trc").read_text().splitlines(keepends=True)
    values = lines[2].split("\t")
    values[2] = "2"  # NumFrames: the file holds 3, which are kept with a warning
    lines[2] = "\t".join(values)
    targets = tmp_path / "targets.trc"
    targets.write_text("".join(lines))

    outcome = run_trial("P1/walk_1", job(root, tmp_path / "out", targets=targets), None)

    assert outcome.status == "ok" and outcome.frames == 3 and outcome.error == ""
    assert outcome.warnings == f"{targets}: NumFrames is 2 but the file holds 3 data rows; all data rows are kept"
    assert (tmp_path / "out" / "report.json").is_file()
    assert completed_outcome("P1/walk_1", tmp_path / "out", overlay=False, subject="").status == "skipped"
    assert completed_outcome("P1/walk_1", tmp_path / "out", overlay=True, subject="") is None  # no overlays yet
    (tmp_path / "out" / "q.csv").unlink()
    assert completed_outcome("P1/walk_1", tmp_path / "out", overlay=False, subject="") is None


def test_a_failed_subject_calibration_fails_its_trials_with_the_reason(root, tmp_path):
    static = tmp_path / "static.trc"
    static.write_text("not a TRC\n")

    subject = calibrate_subject_once(static, None, tmp_path / "P1" / "subject.urdf")
    outcome = run_trial("P1/walk_1", job(root, tmp_path / "out"), subject)

    assert subject.error.startswith(f"subject calibration on {static} failed: ")
    assert not subject.urdf.exists()
    assert outcome.status == "failed" and outcome.error == subject.error
    assert not (tmp_path / "out").exists()


def test_a_calibrated_subject_is_not_calibrated_again(root, tmp_path):
    urdf = tmp_path / "subject.urdf"
    first = calibrate_subject_once(root / "P1" / "static" / "static.trc", None, urdf)
    written = urdf.stat().st_mtime_ns

    again = calibrate_subject_once(root / "P1" / "static" / "static.trc", None, urdf)

    assert first == again == SubjectOutcome(urdf)
    assert urdf.stat().st_mtime_ns == written
    assert (tmp_path / "subject.calibration.json").is_file()


def test_an_error_not_of_the_package_is_a_failed_row_that_names_its_type(root, tmp_path, monkeypatch):
    from ibik_pin.app import outputs

    def disk_full(*arguments, **keywords):
        raise OSError(28, "No space left on device")  # what a full disk gives while writing q.csv

    monkeypatch.setattr(outputs, "write_q_csv", disk_full)
    outcome = run_trial("P1/walk_1", job(root, tmp_path / "out"), None)

    assert outcome.status == "failed" and outcome.error.startswith("OSError: ")
    assert not (tmp_path / "out").exists() and not list(tmp_path.glob(".out.*"))  # the staging folder is gone
    assert outcome.seconds is not None and outcome.seconds > 0.0


def test_without_pyarrow_the_summary_is_csv_only(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    rows = [TrialOutcome("b", "failed", error="bad, \"quoted\"\nline"), TrialOutcome("a", "ok", frames=3)]

    written = write_summary(tmp_path, rows)

    assert written == [tmp_path / "summary.csv"] and not (tmp_path / "summary.parquet").exists()
    with open(tmp_path / "summary.csv", newline="") as stream:
        read = list(csv.DictReader(stream))
    assert [(row["trial"], row["status"], row["frames"], row["error"]) for row in read] == [
        ("a", "ok", "3", ""), ("b", "failed", "", "bad, \"quoted\"\nline")]
