"""`ibik batch` on a LocalCluster of 2 workers: 6 small generated trials (2 participants, one with
a static trial), one of them corrupt. The outputs must be those of `ibik track` on each trial,
the corrupt one a failed row, the exit code 1, and a re-run must skip the 5 done ones."""

from __future__ import annotations

import csv
import io
import json
import re
import sys
from pathlib import Path

import pytest

from ibik_pin.cli import main
from ibik_pin.synthetic.trials import write_trial_tree

TRACK_OPTIONS = ["--iterations", "3"]
COMPARED_FILES = ["joints.trc", "q.csv", "motion.mot", "motion.bvh"]
CORRUPT = "P2/walk_2"
# tqdm's last drawing of the finished bar over the trials.
FINISHED_BAR = re.compile(r"trials: 100%\|.*\| 6/6 ")


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def read_summary(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "summary.csv", newline="") as stream:
        return {row["trial"]: row for row in csv.DictReader(stream)}


def output_times(out: Path) -> dict[str, int]:
    return {str(path.relative_to(out)): path.stat().st_mtime_ns for path in sorted(out.rglob("*"))
            if path.is_file() and path.name not in ("summary.csv", "summary.parquet", "runs.csv")}


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """The tree, and the first batch run's exit code, summary and output files' times."""
    folder = tmp_path_factory.mktemp("batch")
    root, out = folder / "root", folder / "out"
    write_trial_tree(root, trials_per_participant=(3, 3), frames=5)
    (root / CORRUPT / "targets.trc").write_text("PathFileType\t4\t(X/Y/Z)\tbroken\n1\t2\n")
    code = main(["batch", str(root), "--out", str(out), "--workers", "2", "--quiet", *TRACK_OPTIONS])
    return root, out, code, read_summary(out), output_times(out)


def test_five_trials_are_tracked_the_corrupt_one_is_recorded_and_the_exit_code_says_so(session):
    _, out, code, summary, _ = session

    assert code == 1
    assert sorted(summary) == ["P1/walk_1", "P1/walk_2", "P1/walk_3", "P2/walk_1", "P2/walk_2", "P2/walk_3"]
    assert {name: row["status"] for name, row in summary.items() if row["status"] != "ok"} == {CORRUPT: "failed"}
    assert "targets.trc" in summary[CORRUPT]["error"]
    assert not (out / CORRUPT).exists()
    for name, row in summary.items():
        if name != CORRUPT:
            assert int(row["frames"]) == 5 and float(row["frame_rate_hz"]) == 15.0
            assert 0.0 <= float(row["mean_residual_mm"]) <= float(row["max_residual_mm"]) < 100.0
            assert float(row["mean_overlap"]) > 0.0 and row["error"] == ""


def test_each_trials_outputs_are_those_of_ibik_track_on_it(session, tmp_path):
    root, out, _, summary, _ = session
    subject = out / "P1" / "subject.urdf"
    assert {name: row["subject"] for name, row in summary.items()} == {
        "P1/walk_1": str(subject), "P1/walk_2": str(subject), "P1/walk_3": str(subject),
        "P2/walk_1": "", CORRUPT: "", "P2/walk_3": ""}

    for name in summary:
        if name == CORRUPT:
            continue
        trial = root / name
        model = ["--model", str(subject)] if name.startswith("P1") else []
        assert main(["track", "--targets", str(trial / "targets.trc"), "--masks", str(trial / "masks"),
                     "--calibration", str(root / "calibration" / "Calib_synthetic.toml"), *model,
                     *TRACK_OPTIONS, "--quiet", "--out", str(tmp_path / name)]) == 0

        for file in COMPARED_FILES:
            assert (out / name / file).read_bytes() == (tmp_path / name / file).read_bytes(), (name, file)
        batch_report = json.loads((out / name / "report.json").read_text())
        track_report = json.loads((tmp_path / name / "report.json").read_text())
        for report in (batch_report, track_report):  # the timings differ between any two runs
            for timing in [key for key in report if key.endswith(("_seconds", "per_second"))]:
                report.pop(timing)
        assert batch_report == track_report, name


def test_the_participants_subject_is_the_one_ibik_calibrate_makes_of_its_static_trial(session, tmp_path):
    root, out, _, _, _ = session

    assert main(["calibrate", str(root / "P1" / "static" / "static.trc"), "--out", str(tmp_path / "s.urdf")]) == 0

    assert (out / "P1" / "subject.urdf").read_bytes() == (tmp_path / "s.urdf").read_bytes()
    assert not (out / "P2" / "subject.urdf").exists()  # P2 has no static trial


def test_the_summary_parquet_holds_the_same_rows(session):
    pyarrow_parquet = pytest.importorskip("pyarrow.parquet")  # the test extra installs it
    _, out, _, summary, _ = session

    table = pyarrow_parquet.read_table(out / "summary.parquet").to_pylist()

    assert [(row["trial"], row["status"], row["frames"]) for row in table] == [
        (name, row["status"], int(row["frames"]) if row["frames"] else None) for name, row in summary.items()]


def test_a_rerun_skips_the_done_trials_retries_the_failed_one_and_shows_the_bar(session, monkeypatch, capsys):
    root, out, _, _, times = session
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)

    code = main(["batch", str(root), "--out", str(out), "--workers", "1", *TRACK_OPTIONS])

    assert code == 1
    assert {name: row["status"] for name, row in read_summary(out).items()} == {
        "P1/walk_1": "skipped", "P1/walk_2": "skipped", "P1/walk_3": "skipped", "P2/walk_1": "skipped",
        CORRUPT: "failed", "P2/walk_3": "skipped"}
    assert output_times(out) == times  # nothing was written again, the subject's model neither
    assert "6 trials: 0 tracked, 5 already done, 1 failed" in capsys.readouterr().out
    drawings = [line for line in re.split(r"[\r\n]", terminal.getvalue()) if line.startswith("trials:")]
    assert drawings and FINISHED_BAR.search(drawings[-1]), terminal.getvalue()
    assert "failed=1" in drawings[-1]
    assert f"ibik: trial {CORRUPT} failed:" in terminal.getvalue()


def test_without_dask_the_command_says_how_to_install_it(session, monkeypatch, capsys):
    root, _, _, _, _ = session
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed now raises ImportError

    assert main(["batch", str(root), "--out", str(root.parent / "never")]) == 2

    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "pip install 'ibik_pin[batch]'" in error
    assert not (root.parent / "never").exists()


@pytest.mark.parametrize("option", ["--masks", "--static", "--calibration"])
def test_the_options_that_name_one_trials_files_are_refused(session, option, capsys):
    root, out, _, _, _ = session

    with pytest.raises(SystemExit) as exit_info:
        main(["batch", str(root), "--out", str(out), option, str(root)])

    assert exit_info.value.code == 2
    assert "finds it in each trial folder" in capsys.readouterr().err


def test_bad_track_options_are_refused_before_any_trial(session, capsys):
    root, out, _, _, _ = session

    assert main(["batch", str(root), "--out", str(out), "--iterations", "0"]) == 2

    assert capsys.readouterr().err == "ibik: error: --iterations: expected a whole number from 1 to 1000, found 0\n"


def test_a_root_without_trials_and_workers_with_a_scheduler_are_refused(tmp_path, capsys):
    (tmp_path / "empty").mkdir()

    assert main(["batch", str(tmp_path / "empty"), "--out", str(tmp_path / "out")]) == 2
    assert "no trial found" in capsys.readouterr().err
    assert main(["batch", str(tmp_path), "--out", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:1",
                 "--workers", "2"]) == 2
    assert "--workers" in capsys.readouterr().err
