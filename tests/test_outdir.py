"""OUTDIR: staging, the marker, and publishing over an earlier output, alone and by runs that race."""

from __future__ import annotations

import multiprocessing

import pytest

from ibik_pin.app.outdir import MARKER, OutputFolderError, check_outdir, make_staging, publish


def staged(out, label: str):
    staging = make_staging(out)
    (staging / "label.txt").write_text(label)
    return staging


def test_a_staging_folder_is_beside_outdir_with_the_marker(tmp_path):
    staging = make_staging(tmp_path / "new" / "out")
    assert staging.parent == tmp_path / "new" and staging.name.startswith(".out.")
    assert (staging / MARKER).is_file()


def test_publishing_replaces_an_earlier_output_and_leaves_no_backup(tmp_path):
    out = tmp_path / "out"
    publish(staged(out, "first"), out)
    check_outdir(out, [])  # an output of ours may be replaced
    publish(staged(out, "second"), out)
    assert (out / "label.txt").read_text() == "second"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["out"]


def _publish_rounds(out, label: str, rounds: int, failures, start) -> None:
    start.wait()
    for round_ in range(rounds):
        try:
            publish(staged(out, f"{label}{round_}"), out)
        except OSError as error:
            failures.put(f"{label}{round_}: {error}")


def test_runs_that_publish_into_one_outdir_at_once_all_succeed_and_leave_one_output(tmp_path):
    out = tmp_path / "out"
    rounds = 1500
    context = multiprocessing.get_context("fork")
    failures, start = context.Queue(), context.Event()
    runs = [context.Process(target=_publish_rounds, args=(out, label, rounds, failures, start)) for label in "ab"]
    for run in runs:
        run.start()
    start.set()
    for run in runs:
        run.join(timeout=120)
    reported = []
    while not failures.empty():
        reported.append(failures.get())
    assert reported == [] and all(run.exitcode == 0 for run in runs)
    assert (out / "label.txt").read_text() in (f"a{rounds - 1}", f"b{rounds - 1}")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["out"]


def test_a_folder_of_the_users_is_never_taken_for_an_output(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("keep")
    with pytest.raises(OutputFolderError, match="not an output of ibik"):
        check_outdir(tmp_path / "mine", [])
