"""What `ibik track` does with what the user keeps around its outputs: files saved inside an earlier
output folder, old-style markers, hostile manifests, names too long for the file system, camera
names that cannot name a file.

Each case runs in a folder holding real inputs (the demo's walking, 2 views) and an earlier output
of ibik (tests.test_hostile_inputs' `case`). A run that goes on must exit 0, say what it did in one
warning line, keep every file of the user's byte for byte and replace only ibik's; a refusal must
exit 2 with one stderr line and leave the whole folder as it was.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

from ibik_pin.app import outdir
from ibik_pin.app.manifest import MARKER, read_manifest
from ibik_pin.cli import main
from ibik_pin.exceptions import IbikWarning
from tests import test_hostile_inputs as hostile
from tests.test_hostile_inputs import Case, tree_digest

pristine, case = hostile.pristine, hostile.case  # the fixtures: real inputs and an earlier output

BLIND = ("--no-image",)  # the output folder is the matter here, not the image: a quicker run


def run_cli(arguments: list[str], capfd) -> tuple[int, list[str]]:
    """main's exit code and every line it would print on stderr: its own, and its IbikWarnings in
    the one-line form the command gives them."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = main(arguments)
        except SystemExit as stop:  # argparse's refusals
            code = int(stop.code or 0)
    lines = capfd.readouterr().err.splitlines()
    lines += [f"ibik: warning: {' '.join(str(w.message).split())}" for w in caught
              if issubclass(w.category, IbikWarning)]
    return code, lines


def user_files(case: Case) -> dict[str, str]:
    """The digest of the output folder without what ibik writes there (its manifest lists it)."""
    listed = set((read_manifest(case.out).files or {}) if read_manifest(case.out) else {})
    return {name: digest for name, digest in tree_digest(case.out).items() if name not in listed and name != MARKER}


# -- A run into an earlier output keeps the user's files, replaces ibik's, and says so -------------

def _write(path: Path, data: bytes | str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data if isinstance(data, bytes) else data.encode())


def _notes(c: Case) -> str:
    _write(c.out / "analysis_notes.txt", "knee angles look high in frame 12\n")
    return "analysis_notes.txt"


def _nested(c: Case) -> str:
    _write(c.out / "analysis" / "plots" / "knee.png", bytes(range(256)) * 8)
    return "analysis/plots/knee.png"


def _empty_folder(c: Case) -> str:
    (c.out / "later").mkdir()
    return "later"


def _link(c: Case) -> str:
    os.symlink("../in", c.out / "inputs_link")
    return "inputs_link"


def _hidden(c: Case) -> str:
    _write(c.out / ".my_settings", "x = 1\n")
    return ".my_settings"


def _edited_copy(c: Case) -> str:
    _write(c.out / "joints_cleaned.trc", (c.out / "joints.trc").read_bytes()[:1000])
    return "joints_cleaned.trc"


def _read_only(c: Case) -> str:
    _write(c.out / "locked.csv", "a,b\n1,2\n")
    (c.out / "locked.csv").chmod(0o444)
    return "locked.csv"


def _old_marker(c: Case) -> str:
    (c.out / MARKER).write_text("written by ibik track; a later run may replace this folder\n")
    return _notes(c)


def _garbled_manifest(c: Case) -> str:
    (c.out / MARKER).write_text(json.dumps({"written_by": "ibik_pin", "files": "everything"}))
    return _nested(c)


def _unicode_name(c: Case) -> str:
    _write(c.out / "résumé de l'essai.txt", "é\n")
    return "résumé de l'essai.txt"


KEPT: list[tuple[str, Callable[[Case], str]]] = [
    ("notes-file", _notes), ("nested-folders", _nested), ("empty-folder", _empty_folder),
    ("symlink-to-the-inputs", _link), ("hidden-file", _hidden), ("edited-copy-of-an-output", _edited_copy),
    ("read-only-file", _read_only), ("old-plain-text-marker", _old_marker),
    ("manifest-without-a-file-list", _garbled_manifest), ("accented-name", _unicode_name),
]


@pytest.mark.parametrize("setup", [pytest.param(setup, id=name) for name, setup in KEPT])
def test_a_rerun_keeps_the_users_files_replaces_ibiks_and_says_so_in_one_line(case, setup, capfd):
    example = setup(case)
    kept = {name: digest for name, digest in tree_digest(case.out).items()
            if name == example or name.startswith(example + "/") or example.startswith(name + "/")}
    inputs = tree_digest(case.inputs)
    earlier_joints = (case.out / "joints.trc").stat().st_mtime_ns

    code, lines = run_cli(case.arguments(*BLIND), capfd)

    assert code == 0, lines
    assert len(lines) == 1 and lines[0].startswith("ibik: warning: --out "), lines
    assert f"kept 1 file that ibik did not write there (e.g. {example}) beside the new outputs" in lines[0], lines
    assert user_files(case) == kept  # every path of the user's, byte for byte
    assert tree_digest(case.inputs) == inputs
    manifest = read_manifest(case.out)
    assert manifest is not None and manifest.state == "complete"
    assert set(manifest.files) >= {"joints.trc", "q.csv", "motion.mot", "motion.bvh", "model.osim", "report.json"}
    assert not set(manifest.files) & set(kept)
    assert (case.out / "joints.trc").stat().st_mtime_ns != earlier_joints  # ibik's own: written again
    report = json.loads((case.out / "report.json").read_text())
    assert [name.rstrip("/") for name in report["kept_user_files"]] == [example]
    assert [warning for warning in report["warnings"] if "ibik did not write there" in warning] == [
        lines[0].removeprefix("ibik: warning: ")]
    assert sorted(p.name for p in case.root.iterdir()) == ["in", "out"]  # no staging or set-aside folder left


def test_the_kept_files_are_recorded_in_the_manifest_and_kept_again_by_the_next_run(case, capfd):
    _notes(case)
    assert run_cli(case.arguments(*BLIND), capfd)[0] == 0
    content = json.loads((case.out / MARKER).read_text())
    assert content["kept_user_files"] == ["analysis_notes.txt"]

    code, lines = run_cli(case.arguments(*BLIND), capfd)

    assert code == 0 and len(lines) == 1 and "kept 1 file " in lines[0], lines
    assert (case.out / "analysis_notes.txt").read_text() == "knee angles look high in frame 12\n"


def test_a_manifest_listing_paths_outside_the_folder_touches_nothing_outside(case, capfd):
    content = json.loads((case.out / MARKER).read_text())
    content["files"] |= {"../in/targets.trc": 1, "/etc/hostname": 1}
    (case.out / MARKER).write_text(json.dumps(content))
    inputs = tree_digest(case.inputs)

    code, lines = run_cli(case.arguments(*BLIND), capfd)

    assert code == 0 and lines == [], lines
    assert tree_digest(case.inputs) == inputs
    assert "../in/targets.trc" not in read_manifest(case.out).files


def test_a_refusal_into_an_output_holding_the_users_files_changes_nothing(case, capfd):
    _notes(case)
    case.edit_trc(case.targets, lambda data: data.marker_names.__setitem__(0, "Nosee"))
    before = tree_digest(case.root)

    code, lines = run_cli(case.arguments(*BLIND), capfd)

    assert code == 2 and len(lines) == 1 and lines[0].startswith("ibik: error: "), lines
    assert tree_digest(case.root) == before


# -- Refused up front, before any work ------------------------------------------------------------

def _user_file_named_like_an_output(name: str) -> Callable[[Case], list[str]]:
    def setup(c: Case) -> list[str]:
        _write(c.out / name, "the user's own\n")
        return c.arguments(*BLIND)
    return setup


def _long_name(name: str) -> Callable[[Case], list[str]]:
    return lambda c: c.arguments(*BLIND, out=str(c.root / name))


def _marker_a_folder(c: Case) -> list[str]:
    mine = c.root / "mine"
    (mine / MARKER).mkdir(parents=True)
    _write(mine / "thesis.tex", "keep")
    return c.arguments(*BLIND, out=str(mine))


def _path_too_long(c: Case) -> list[str]:
    deep = c.root.joinpath(*(["d" * 200] * 21), "out")  # over 4096 bytes: no file system here holds it
    return c.arguments(*BLIND, out=str(deep))


REFUSED: list[tuple[str, Callable[[Case], list[str]], str]] = [
    ("users-replay-html", _user_file_named_like_an_output("replay.html"), r"replay\.html is not listed"),
    ("users-overlay-video", _user_file_named_like_an_output("overlay_cam1.mp4"), r"overlay_cam1\.mp4 is not listed"),
    ("users-angles-png", _user_file_named_like_an_output("angles.png"), r"angles\.png"),
    ("name-300-ascii-bytes", _long_name("o" * 300), r"300 bytes long, more than a file name can hold"),
    ("name-130-accented-letters", _long_name("é" * 130), r"260 bytes long, more than a file name can hold"),
    ("path-over-4096-bytes", _path_too_long, r"bytes a path can have here"),
    ("marker-is-a-folder", _marker_a_folder, r"not an output of ibik"),
]


@pytest.mark.parametrize(("setup", "expected"), [pytest.param(s, e, id=i) for i, s, e in REFUSED])
def test_an_outdir_that_would_fail_late_or_lose_a_file_is_refused_first(case, setup, expected, capfd):
    arguments = setup(case)
    before = tree_digest(case.root)

    code, lines = run_cli(arguments, capfd)

    assert code == 2, lines
    assert len(lines) == 1 and lines[0].startswith("ibik: error: --out "), lines
    assert re.search(expected, lines[0]), lines
    assert tree_digest(case.root) == before


# -- Legal names that used to fail only after all the work ---------------------------------------

@pytest.mark.parametrize("length", [240, 255])
def test_a_long_legal_outdir_name_is_written_and_replaced(case, length, capfd):
    out = case.root / ("r" * length)
    for _ in range(2):  # new, then over the earlier output (set aside under a name of its own)
        code, lines = run_cli(case.arguments(*BLIND, out=str(out)), capfd)
        assert code == 0 and lines == [], lines
    assert (out / "report.json").is_file()
    assert sorted(p.name for p in case.root.iterdir()) == sorted(["in", "out", out.name])


@pytest.mark.parametrize(("camera", "file"), [("cam/1", "overlay_cam_1.mp4"), ("../cam1", "overlay__._cam1.mp4")])
def test_a_camera_name_that_cannot_name_a_file_is_said_before_the_solve_and_sanitised(case, camera, file, capfd):
    case.edit_cameras(lambda c: dataclasses.replace(c, name=camera) if c.name == "cam1" else c)
    inputs = tree_digest(case.inputs)

    code, lines = run_cli(case.arguments("--overlay", *BLIND, iterations="1"), capfd)

    assert code == 0, lines
    assert len(lines) == 1 and f"camera {camera!r} cannot name a file as it is; its overlay video is {file}" in lines[0]
    assert (case.out / file).is_file() and (case.out / "overlay_cam2.mp4").is_file()
    assert file in read_manifest(case.out).files
    said = json.loads((case.out / "report.json").read_text())["warnings"]
    assert len(said) == 1 and f"camera {camera!r} cannot name a file as it is" in said[0], said
    assert tree_digest(case.inputs) == inputs
    assert not any(path.name.startswith("overlay") for path in case.root.rglob("*") if path.parent != case.out)


# -- ibik batch: where it may write, what counts as done, what killed runs left ------------------

BATCH_OPTIONS = ["--workers", "1", "--quiet", "--iterations", "2"]


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A tree of 3 generated trials (P1 with a static trial) beside nothing else of the user's."""
    from ibik_pin.synthetic.trials import write_trial_tree

    pytest.importorskip("distributed")
    folder = tmp_path_factory.mktemp("batch_session")
    write_trial_tree(folder / "root", trials_per_participant=(2, 1), frames=4)
    return folder


def _users_summary(folder: Path) -> Path:
    _write(folder / "mine" / "summary.csv", "trial,score\nwalk,3\n")
    return folder / "mine"


def _a_file(folder: Path) -> Path:
    _write(folder / "out.txt", "a file\n")
    return folder / "out.txt"


def _link_to_root(folder: Path) -> Path:
    if not (folder / "root_link").is_symlink():
        os.symlink(folder / "root", folder / "root_link")
    return folder / "root_link"


BATCH_REFUSED: list[tuple[str, Callable[[Path], Path], str]] = [
    ("inside-root-a-participant", lambda f: f / "root" / "P1", r"lies inside ROOT"),
    ("inside-root-a-trials-subfolder", lambda f: f / "root" / "P1" / "walk_1" / "results", r"lies inside ROOT"),
    ("holding-root", lambda f: f, r"holds ROOT"),
    ("root-through-a-link", _link_to_root, r"must not be ROOT"),
    ("users-folder-with-their-summary", _users_summary, r"no ibik batch wrote"),
    ("an-existing-file", _a_file, r"is an existing file"),
]


@pytest.mark.parametrize(("outroot", "expected"), [pytest.param(o, e, id=i) for i, o, e in BATCH_REFUSED])
def test_batch_refuses_an_outroot_among_the_trials_or_of_the_users(session, outroot, expected, capfd):
    out = outroot(session)
    before = tree_digest(session)

    code, lines = run_cli(["batch", str(session / "root"), "--out", str(out), *BATCH_OPTIONS], capfd)

    assert code == 2, lines
    assert len(lines) == 1 and lines[0].startswith("ibik: error: --out "), lines
    assert re.search(expected, lines[0]), lines
    assert tree_digest(session) == before


def _summary(outroot: Path) -> dict[str, dict[str, str]]:
    import csv

    with open(outroot / "summary.csv", newline="") as stream:
        return {row["trial"]: row for row in csv.DictReader(stream)}


def _runs_log(outroot: Path) -> list[dict[str, str]]:
    import csv

    with open(outroot / "runs.csv", newline="") as stream:
        return list(csv.DictReader(stream))


def _dead_pid() -> int:
    import subprocess
    import sys

    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def _staging(folder: Path, name: str, pid: int | None) -> Path:
    """A folder as a run's staging folder looks: with a staging manifest of `pid` on this machine
    (None: no manifest, a folder of the user's that only looks like one)."""
    import socket

    path = folder / name
    _write(path / "joints.trc", "half written")
    if pid is not None:
        (path / MARKER).write_text(json.dumps({"written_by": "ibik_pin", "manifest": 1, "state": "staging",
                                               "files": {}, "host": socket.gethostname(), "pid": pid}))
    return path


@pytest.fixture(scope="module")
def rerun(session, tmp_path_factory):
    """A first batch run, then what users and killed runs do to OUTROOT, then a second run."""
    from ibik_pin.cli import main as cli_main

    outroot = tmp_path_factory.mktemp("batch_out") / "outroot"
    assert cli_main(["batch", str(session / "root"), "--out", str(outroot), *BATCH_OPTIONS]) == 0
    first_summary, first_log = _summary(outroot), _runs_log(outroot)
    (outroot / "P1" / "walk_1" / "model.osim").unlink()
    q_csv = outroot / "P1" / "walk_2" / "q.csv"
    q_csv.write_bytes(q_csv.read_bytes()[: q_csv.stat().st_size // 2])
    set_aside = outroot / "P2" / ".walk_1.previous.0123456789ab"
    kept_digest = tree_digest(outroot / "P2" / "walk_1")
    os.replace(outroot / "P2" / "walk_1", set_aside)  # a publish killed between its two moves
    dead = _staging(outroot / "P1", ".walk_2.staging.k1ll3d", _dead_pid())
    alive = _staging(outroot / "P1", ".walk_1.staging.a1ive", os.getpid())
    users = _staging(outroot / "P1", ".walk_1.staging.mine", None)
    (outroot / ".ibik_batch").unlink()  # as an earlier version left it: its summary.csv alone
    with warnings.catch_warnings(), pytest.MonkeyPatch.context() as patch:
        warnings.simplefilter("ignore")
        patch.setattr(outdir, "STALE_SECONDS", 0.0)  # set aside just now, as if long ago
        code = cli_main(["batch", str(session / "root"), "--out", str(outroot), *BATCH_OPTIONS])
    return {"outroot": outroot, "code": code, "first_summary": first_summary, "first_log": first_log,
            "summary": _summary(outroot), "log": _runs_log(outroot), "kept_digest": kept_digest,
            "set_aside": set_aside, "dead": dead, "alive": alive, "users": users}


def test_batch_retracks_a_trial_whose_model_osim_was_deleted(rerun):
    assert rerun["code"] == 0
    assert rerun["summary"]["P1/walk_1"]["status"] == "ok"
    assert (rerun["outroot"] / "P1" / "walk_1" / "model.osim").is_file()


def test_batch_retracks_a_trial_whose_output_was_cut_short(rerun):
    assert rerun["summary"]["P1/walk_2"]["status"] == "ok"
    q_csv = rerun["outroot"] / "P1" / "walk_2" / "q.csv"
    assert read_manifest(q_csv.parent).files["q.csv"] == q_csv.stat().st_size


def test_batch_puts_back_an_output_a_killed_publish_had_set_aside(rerun):
    assert rerun["summary"]["P2/walk_1"]["status"] == "skipped"
    assert not rerun["set_aside"].exists()
    assert tree_digest(rerun["outroot"] / "P2" / "walk_1") == rerun["kept_digest"]


def test_batch_removes_a_dead_runs_staging_folder_and_nothing_it_cannot_prove_its_own(rerun):
    assert not rerun["dead"].exists()
    assert (rerun["alive"] / "joints.trc").read_text() == "half written"  # its run may still be going
    assert (rerun["users"] / "joints.trc").read_text() == "half written"  # no manifest: the user's


def test_batch_keeps_every_runs_record_and_a_skipped_trials_worker_and_time(rerun):
    first_ids = {row["batch_run"] for row in rerun["first_log"]}
    assert len(first_ids) == 1 and len(rerun["first_log"]) == 3
    assert rerun["log"][:3] == rerun["first_log"]  # the first run's rows, as written then
    assert len(rerun["log"]) == 6 and len({row["batch_run"] for row in rerun["log"]}) == 2
    skipped, earlier = rerun["summary"]["P2/walk_1"], rerun["first_summary"]["P2/walk_1"]
    assert earlier["status"] == "ok" and earlier["worker"] != "" and float(earlier["seconds"]) > 0.0
    assert (skipped["worker"], skipped["seconds"]) == (earlier["worker"], earlier["seconds"])
    assert skipped["tracked_in"] == earlier["tracked_in"] == first_ids.pop()


def test_batch_takes_an_earlier_versions_outroot_by_its_summary_and_marks_it(rerun):
    marker = json.loads((rerun["outroot"] / ".ibik_batch").read_text())
    assert marker["written_by"] == "ibik_pin"


def test_a_set_aside_output_of_a_publish_still_going_is_left_alone(tmp_path):
    out = tmp_path / "out"
    outdir.publish(outdir.make_staging(out), out)
    aside = tmp_path / f"{outdir.previous_prefix(out)}0123456789ab"
    os.replace(out, aside)  # the instant between a publish's two moves

    assert outdir.remove_leftovers(out) == []

    assert aside.is_dir() and not out.exists()


def test_a_killed_runs_staging_folder_is_cleared_by_the_next_run_and_the_earlier_output_kept(case, capfd):
    import signal
    import subprocess
    import sys
    import time

    _notes(case)
    before = tree_digest(case.out)
    environment = dict(os.environ, PYTHONPATH=str(hostile.REPOSITORY))
    process = subprocess.Popen([sys.executable, "-m", "ibik_pin.cli", *case.arguments(iterations="300")],
                               stderr=subprocess.DEVNULL, env=environment, cwd=case.inputs)
    deadline = time.monotonic() + 60
    while not any(path.name.startswith(".out.staging.") for path in case.root.iterdir()):
        assert process.poll() is None and time.monotonic() < deadline, "the run never staged its outputs"
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)  # no handler runs: the staging folder stays behind
    process.wait(timeout=60)
    (left,) = [path for path in case.root.iterdir() if path.name.startswith(".out.staging.")]
    assert tree_digest(case.out) == before

    code, lines = run_cli(case.arguments(*BLIND), capfd)

    assert code == 0 and len(lines) == 1 and "kept 1 file" in lines[0], lines
    assert not left.exists() and sorted(p.name for p in case.root.iterdir()) == ["in", "out"]
    assert (case.out / "analysis_notes.txt").read_text() == "knee angles look high in frame 12\n"
