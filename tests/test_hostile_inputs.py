"""`ibik track` fed hostile or careless inputs, as a demanding new user would feed it.

Every refusal must end with exit code 2 and exactly one stderr line that names the input and the
fault, with no traceback, before anything the user had is touched: each case runs in a folder that
holds the inputs and a previous output of ibik, and the whole folder must be byte for byte what it
was (inputs unchanged, previous OUTDIR intact, no staging folder left behind). Runs that may go on
(an outlier target, empty silhouettes) must say so and record it. The Python API raises IbikError
subclasses for the same faults.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from ibik_pin.app.demo import prepare_demo_inputs
from ibik_pin.app.job import TrackJob
from ibik_pin.app.outdir import MARKER, OutputFolderError
from ibik_pin.app.track import run_track
from ibik_pin.cli import Terminated, main
from ibik_pin.exceptions import FileFormatError, IbikError, IbikWarning, InputError
from ibik_pin.human import human_urdf_path
from ibik_pin.io.calibration import read_calibration, write_calibration
from ibik_pin.io.files import MAX_INPUT_BYTES
from ibik_pin.io.trc import read_trc, write_trc
from ibik_pin.tracking.settings import TrackingSettings

REPOSITORY = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """Inputs (30 frames of real walking, 2 views, masks, a static trial) and a real earlier output."""
    root = tmp_path_factory.mktemp("pristine")
    paths = prepare_demo_inputs(root / "in", views=2, frame_step=8)
    (paths.truth).unlink()  # the truth is the demo's, not a user's input
    code = main(["track", "--targets", str(paths.targets), "--calibration", str(paths.calibration),
                 "--masks", str(paths.masks), "--quiet", "--no-image", "--iterations", "2",
                 "--out", str(root / "out")])
    assert code == 0 and (root / "out" / MARKER).is_file()
    return root


class Case:
    """One hostile run's folder: `inputs` (targets.trc, static.trc, calibration.toml, masks/) and
    `out`, an earlier output of ibik."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.inputs, self.out = root / "in", root / "out"
        self.targets, self.static = self.inputs / "targets.trc", self.inputs / "static.trc"
        self.calibration, self.masks = self.inputs / "calibration.toml", self.inputs / "masks"

    def arguments(self, *extra: str, **options: str | None) -> list[str]:
        """`ibik track` on the case's inputs; options replace (None: remove) one of them."""
        given: dict[str, str | None] = {"targets": str(self.targets), "static": str(self.static),
                                        "calibration": str(self.calibration), "masks": str(self.masks),
                                        "out": str(self.out), "iterations": "2"}
        given.update(options)
        listed = ["track", "--quiet"]
        for name, value in given.items():
            if value is not None:
                listed += [f"--{name.replace('_', '-')}", value]
        return listed + list(extra)

    def edit_trc(self, path: Path, change: Callable) -> None:
        data = read_trc(path)
        change(data)
        write_trc(path, data)

    def edit_cameras(self, change: Callable) -> None:
        write_calibration(self.calibration, [change(camera) for camera in read_calibration(self.calibration)])


def tree_digest(root: Path) -> dict[str, str]:
    """Every path under root (files, folders, links) and its content's hash."""
    digest = {}
    for path in sorted(root.rglob("*")):
        name = str(path.relative_to(root))
        if path.is_symlink():
            digest[name] = "link -> " + os.readlink(path)
        elif path.is_dir():
            digest[name] = "folder"
        elif path.is_file():
            digest[name] = hashlib.sha256(path.read_bytes()).hexdigest()
        else:
            digest[name] = "special"
    return digest


@pytest.fixture
def case(pristine, tmp_path, monkeypatch):
    shutil.copytree(pristine / "in", tmp_path / "in")
    shutil.copytree(pristine / "out", tmp_path / "out")
    monkeypatch.chdir(tmp_path / "in")
    return Case(tmp_path)


def _times_ten_to_the(power: float) -> Callable:
    def change(data):
        data.positions = data.positions * 10.0 ** power
    return change


def _fifo(case: Case, name: str) -> str:
    path = case.root / name
    os.mkfifo(path)
    return str(path)


def _urdf(case: Case, text: str) -> str:
    path = case.root / "model.urdf"
    path.write_text(text)
    return str(path)


def _masks_renamed(case: Case, renames: dict[str, str]) -> str:
    """The masks folder with camera folders copied under new names (old -> new; old == new keeps
    it), the old ones that no new name keeps removed."""
    for old, new in renames.items():
        if old != new:
            shutil.copytree(case.masks / old, case.masks / new)
    for old in renames:
        if old not in renames.values():
            shutil.rmtree(case.masks / old)
    return str(case.masks)


def _videos(case: Case, names: list[str], content: bytes = b"") -> str:
    folder = case.root / "videos"
    folder.mkdir()
    for name in names:
        (folder / name).write_bytes(content or b"not a video")
    return str(folder)


def _setup_duplicate_names(case):
    case.edit_trc(case.targets, lambda d: d.marker_names.__setitem__(1, d.marker_names[0]))
    return case.arguments()


def _setup_time_backwards(case):
    def change(data):
        data.times = np.asarray(data.times, dtype=float).copy()
        data.times[5] = data.times[3]
    case.edit_trc(case.targets, change)
    return case.arguments()


def _setup_all_empty(case):
    case.edit_trc(case.targets, lambda d: d.positions.fill(np.nan))
    return case.arguments()


def _setup_static_empty(case):
    case.edit_trc(case.static, lambda d: d.positions.fill(np.nan))
    return case.arguments()


def _setup_static_few_points(case):
    def change(data):
        data.positions[:, 3:] = np.nan
    case.edit_trc(case.static, change)
    return case.arguments()


def _setup_camera_behind(case):
    half_turn = np.diag([-1.0, 1.0, -1.0])  # about the camera's own y axis: what it saw is behind it
    case.edit_cameras(lambda c: dataclasses.replace(c, rotation=half_turn @ c.rotation,
                                                    translation=half_turn @ c.translation))
    return case.arguments()


def _setup_principal_point(case):
    case.edit_cameras(lambda c: dataclasses.replace(
        c, intrinsics=c.intrinsics + np.array([[0.0, 0.0, 1e5], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])))
    return case.arguments()


def _setup_distortion(case):
    case.edit_cameras(lambda c: dataclasses.replace(c, distortion=np.full_like(np.asarray(c.distortion, float), 1e6)))
    return case.arguments()


def _setup_one_camera_blind(case):
    first = read_calibration(case.calibration)[0].name
    case.edit_cameras(lambda c: dataclasses.replace(c, translation=c.translation + np.array([0.0, 0.0, -1e3]))
                      if c.name == first else c)
    return case.arguments()


def _setup_masks_a_file(case):
    (case.root / "masks_file").write_text("not a folder")
    return case.arguments(masks=str(case.root / "masks_file"))


def _setup_corrupt_png(case):
    sorted((case.masks / "cam1").iterdir())[4].write_bytes(b"\x89PNG\r\n\x1a\n broken")
    return case.arguments()


def _setup_mask_missing(case):
    sorted((case.masks / "cam2").iterdir())[-1].unlink()
    return case.arguments()


def _setup_sparse_large(case):
    path = case.root / "huge.trc"
    with open(path, "wb") as handle:
        handle.truncate(MAX_INPUT_BYTES + 1)
    return case.arguments(targets=str(path))


def _setup_zero_origins(case):
    text = human_urdf_path().read_text()
    return case.arguments(model=_urdf(case, re.sub(r'xyz="[^"]*"', 'xyz="0 0 0"', text)))


def _setup_zero_origins_but_the_ankles(case):
    blocks = re.split(r"(<joint .*?</joint>)", human_urdf_path().read_text(), flags=re.S)
    text = "".join(re.sub(r'xyz="[^"]*"', 'xyz="0 0 0"', block) if block.startswith("<joint")
                   and "ankle" not in block else block for block in blocks)
    return case.arguments(model=_urdf(case, text))


def _setup_trc_header_only(case):
    lines = case.targets.read_text().splitlines()
    case.targets.write_text("\n".join(lines[:5]) + "\n")
    return case.arguments()


def _setup_trc_bad_cell(case):
    lines = case.targets.read_text().splitlines()
    cells = lines[8].split("\t")
    cells[4] = "abc"
    lines[8] = "\t".join(cells)
    case.targets.write_text("\n".join(lines) + "\n")
    return case.arguments()


def _setup_trc_units(case):
    case.targets.write_text(case.targets.read_text().replace("\tm\t", "\tfurlong\t", 1))
    return case.arguments()


def _setup_out_file(case, name):
    (case.root / name).write_text("a user's results\n")
    return case.arguments(out=str(case.root / name))


def _setup_out_symlink(case):
    (case.root / "elsewhere").mkdir()
    (case.root / "link").symlink_to(case.root / "elsewhere")
    return case.arguments(out=str(case.root / "link"))


def _setup_out_not_ours(case):
    (case.root / "mine").mkdir()
    (case.root / "mine" / "notes.txt").write_text("keep me\n")
    return case.arguments(out=str(case.root / "mine"))


def _setup_out_under_file(case):
    (case.root / "plain").write_text("x")
    return case.arguments(out=str(case.root / "plain" / "out"))


def _setup_calibration_nan(case):
    text = case.calibration.read_text()
    case.calibration.write_text(re.sub(r"translation = \[[^]]*\]", "translation = [ nan, 0.0, 3.0,]", text, count=1))
    return case.arguments()


def _setup_calibration_broken(case):
    case.calibration.write_text("[cam1\nname = ")
    return case.arguments()


def _setup_calibration_empty(case):
    case.calibration.write_text("")
    return case.arguments()


def _setup_stack_missing(case):
    return case.arguments("--stack", str(case.root / "nowhere.toml"))


def _setup_stack_garbage(case):
    (case.root / "stack.toml").write_text("[[level]]\nname = 3\n")
    return case.arguments("--stack", str(case.root / "stack.toml"))


# (id, how to make the case's arguments, a pattern the one stderr line must hold)
REFUSED: list[tuple[str, Callable[[Case], list[str]], str]] = [
    # never destroy: OUTDIR
    ("out-is-the-input-folder", lambda c: c.arguments(out=str(c.inputs)), r"--out .*in.*input"),
    ("out-is-the-masks-folder", lambda c: c.arguments(out=str(c.masks)), r"--out .*masks"),
    ("out-inside-the-masks", lambda c: c.arguments(out=str(c.masks / "cam1" / "run")), r"inside the input"),
    ("out-holds-the-inputs", lambda c: c.arguments(out=str(c.root)), r"--out .*holds the input"),
    ("out-is-the-targets-file", lambda c: c.arguments(out=str(c.targets)), r"--out .*targets\.trc"),
    ("out-is-the-calibration", lambda c: c.arguments(out=str(c.calibration)), r"calibration\.toml"),
    ("out-is-a-user-csv", lambda c: _setup_out_file(c, "results.csv"), r"--out .*results\.csv"),
    ("out-is-dot", lambda c: c.arguments(out="."), r"--out '\.'"),
    ("out-is-empty", lambda c: c.arguments(out=""), r"--out ''"),
    ("out-is-dotdot", lambda c: c.arguments(out=".."), r"--out '\.\.'"),
    ("out-is-a-symlink", _setup_out_symlink, r"symbolic link"),
    ("out-is-a-folder-not-ours", _setup_out_not_ours, r"--out .*mine"),
    ("out-under-a-file", _setup_out_under_file, r"--out .*plain"),
    ("out-not-writable", lambda c: c.arguments(out="/proc/ibik_out"), r"--out /proc/ibik_out"),
    ("out-is-the-static-trial", lambda c: c.arguments(out=str(c.static)), r"--out .*static\.trc"),
    # plausibility of the TRCs
    ("targets-mm-labelled-m", lambda c: (c.edit_trc(c.targets, _times_ten_to_the(3)), c.arguments())[1],
     r"--targets .*spans .* m .*are the values in mm"),
    ("targets-times-1e12", lambda c: (c.edit_trc(c.targets, _times_ten_to_the(12)), c.arguments())[1],
     r"--targets .*spans"),
    ("targets-m-labelled-mm", lambda c: (c.edit_trc(c.targets, _times_ten_to_the(-3)), c.arguments())[1],
     r"--targets .*spans"),
    ("static-mm-labelled-m", lambda c: (c.edit_trc(c.static, _times_ten_to_the(3)), c.arguments())[1],
     r"--static .*spans .*mm"),
    ("static-all-empty", _setup_static_empty, r"--static .*no marker has a value"),
    ("static-too-few-points", _setup_static_few_points, r"--static .*keypoints"),
    ("targets-all-empty", _setup_all_empty, r"--targets .*no marker has a value"),
    ("targets-duplicate-names", _setup_duplicate_names, r"--targets .*more than once"),
    ("targets-time-not-increasing", _setup_time_backwards, r"--targets .*Time column"),
    ("targets-header-only", _setup_trc_header_only, r"targets\.trc"),
    ("targets-non-numeric-cell", _setup_trc_bad_cell, r"targets\.trc.*abc"),
    ("targets-unknown-units", _setup_trc_units, r"targets\.trc.*furlong"),
    # cameras
    ("cameras-behind-the-subject", _setup_camera_behind, r"--calibration: camera .* behind"),
    ("principal-point-far-off", _setup_principal_point, r"--calibration: camera .* sees none"),
    ("distortion-1e6", _setup_distortion, r"--calibration: camera"),
    ("one-camera-sees-nothing", _setup_one_camera_blind, r"--calibration: camera 'cam1'"),
    ("calibration-nan", _setup_calibration_nan, r"calibration\.toml"),
    ("calibration-broken-toml", _setup_calibration_broken, r"calibration\.toml"),
    ("calibration-empty", _setup_calibration_empty, r"calibration\.toml"),
    ("camera-not-in-calibration", lambda c: c.arguments("--cameras", "cam1,cam9"), r"cam9"),
    ("cameras-empty", lambda c: c.arguments("--cameras", ""), r"--cameras: unknown camera name"),
    ("cameras-repeated", lambda c: c.arguments("--cameras", "cam1,cam1"), r"--cameras: expected each camera"),
    # bounded: what is read and how long
    ("targets-dev-zero", lambda c: c.arguments(targets="/dev/zero"), r"/dev/zero.*not a regular file"),
    ("targets-a-folder", lambda c: c.arguments(targets=str(c.masks)), r"masks.*folder"),
    ("targets-fifo", lambda c: c.arguments(targets=_fifo(c, "targets.fifo")), r"targets\.fifo.*pipe"),
    ("calibration-fifo", lambda c: c.arguments(calibration=_fifo(c, "calib.fifo")), r"calib\.fifo.*pipe"),
    ("static-fifo", lambda c: c.arguments(static=_fifo(c, "static.fifo")), r"static\.fifo.*pipe"),
    ("model-fifo", lambda c: c.arguments(model=_fifo(c, "model.fifo")), r"model\.fifo.*pipe"),
    ("stack-fifo", lambda c: c.arguments("--stack", _fifo(c, "stack.fifo")), r"stack\.fifo.*pipe"),
    ("targets-missing", lambda c: c.arguments(targets=str(c.root / "absent.trc")), r"absent\.trc"),
    ("targets-over-the-size-limit", _setup_sparse_large, r"huge\.trc.*larger than"),
    ("iterations-zero", lambda c: c.arguments(iterations="0"), r"--iterations"),
    ("iterations-huge", lambda c: c.arguments(iterations="1000000000"), r"--iterations"),
    ("iterations-negative", lambda c: c.arguments(iterations="-5"), r"--iterations"),
    ("step-tolerance-negative", lambda c: c.arguments("--step-tolerance", "-1"), r"--step-tolerance"),
    ("step-tolerance-nan", lambda c: c.arguments("--step-tolerance", "nan"), r"--step-tolerance"),
    ("mask-filter-huge", lambda c: c.arguments("--mask-filter", "31"), r"--mask-filter"),
    ("mask-filter-negative", lambda c: c.arguments("--mask-filter", "-2"), r"--mask-filter"),
    ("masks-is-a-file", _setup_masks_a_file, r"masks_file"),
    ("mask-corrupt-png", _setup_corrupt_png, r"mask file .*000004\.png"),
    ("mask-missing-one-frame", _setup_mask_missing, r"29 masks for camera 'cam2'"),
    # models and stacks
    ("model-not-xml", lambda c: c.arguments(model=_urdf(c, "not xml at all")), r"model\.urdf"),
    ("model-not-the-human", lambda c: c.arguments(model=str(REPOSITORY / "models" / "planar_chain.urdf")),
     r"planar_chain\.urdf': not the human model"),
    ("model-joint-without-limits", lambda c: c.arguments(model=_urdf(
        c, '<robot name="x"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
           '<parent link="a"/><child link="b"/></joint></robot>')), r"model\.urdf.*limits"),
    ("model-origins-all-zero", _setup_zero_origins, r"model\.urdf.*origin"),
    ("model-segments-of-zero-length", _setup_zero_origins_but_the_ankles, r"model\.urdf.*no length"),
    ("stack-missing", _setup_stack_missing, r"nowhere\.toml"),
    ("stack-garbage", _setup_stack_garbage, r"stack\.toml"),
    # exact pairing of cameras and their files
    ("masks-only-a-longer-name", lambda c: c.arguments(masks=_masks_renamed(c, {"cam1": "cam10"})), r"cam1\b"),
    ("masks-two-folders-for-one-camera",
     lambda c: c.arguments(masks=_masks_renamed(c, {"cam1": "cam1", "cam2": "CAM_1"})), r"cam1.*CAM_1|CAM_1.*cam1"),
    ("videos-only-a-longer-name", lambda c: c.arguments(masks=None, videos=_videos(c, ["cam10_side.mp4", "cam2.mp4"])),
     r"cam1\b"),
    ("videos-two-for-one-camera",
     lambda c: c.arguments(masks=None, videos=_videos(c, ["cam1.mp4", "Cam-1.avi", "cam2.mp4"])),
     r"cam1\.mp4.*Cam-1\.avi|Cam-1\.avi.*cam1\.mp4"),
    ("video-not-decodable", lambda c: c.arguments(masks=None, videos=_videos(c, ["cam1.mp4", "cam2.mp4"])),
     r"cam1\.mp4.*(decode|moov)"),
    ("masks-and-videos", lambda c: c.arguments(videos=_videos(c, ["cam1.mp4"])), r"--videos"),
    ("background-without-videos", lambda c: c.arguments("--background", str(c.targets)), r"--background"),
]


@pytest.mark.parametrize(("setup", "expected"), [pytest.param(s, e, id=i) for i, s, e in REFUSED])
def test_a_hostile_input_is_refused_in_one_line_and_nothing_is_touched(case, setup, expected, capfd):
    arguments = setup(case)
    before = tree_digest(case.root)
    try:
        code = main(arguments)
    except SystemExit as stop:  # argparse's refusals
        code = stop.code
    captured = capfd.readouterr()
    assert code == 2, captured.err
    assert captured.err.count("\n") == 1 and captured.err.startswith("ibik: error: "), captured.err
    assert "Traceback" not in captured.err
    assert tree_digest(case.root) == before
    assert re.search(expected, captured.err), captured.err


def test_there_are_at_least_sixty_refusals():
    assert len(REFUSED) >= 60 and len({name for name, _, _ in REFUSED}) == len(REFUSED)


def _jump(data):
    data.positions[7, data.marker_names.index("LWrist")] = [1e12, 0.0, 0.0]


def test_a_target_that_leaps_metres_is_dropped_for_its_frame_with_a_warning_and_in_the_report(case, capfd):
    case.edit_trc(case.targets, _jump)
    inputs = tree_digest(case.inputs)
    with pytest.warns(IbikWarning, match=r"LWrist in frame 8") as caught:
        assert main(case.arguments("--no-image", calibration=None, masks=None)) == 0
    assert all("\n" not in str(warning.message) for warning in caught)
    assert "Traceback" not in capfd.readouterr().err
    report = json.loads((case.out / "report.json").read_text())
    assert report["frames_with_outlier_targets"] == {"8": ["LWrist"]}
    assert report["frames_with_dropped_targets"]["8"] == ["LWrist"]
    assert report["end_effector_residual_m"]["mean"] < 0.05
    assert tree_digest(case.inputs) == inputs


def test_black_silhouettes_everywhere_fall_back_to_no_image_and_say_so(case):
    for mask in case.masks.rglob("*.png"):
        cv2.imwrite(str(mask), np.zeros((480, 640), np.uint8))
    with pytest.warns(IbikWarning, match=r"every silhouette is empty; tracking without the image"):
        assert main(case.arguments()) == 0
    report = json.loads((case.out / "report.json").read_text())
    assert report["image"] is False


def test_report_json_is_strict_when_a_frame_has_no_target(case):
    def empty_frame(data):
        data.positions[4] = np.nan
    case.edit_trc(case.targets, empty_frame)
    assert main(case.arguments("--no-image", calibration=None, masks=None)) == 0
    text = (case.out / "report.json").read_text()
    json.loads(text, parse_constant=lambda token: pytest.fail(f"report.json holds {token}"))
    assert "NaN" not in text and "Infinity" not in text


def test_sigterm_while_solving_exits_143_and_leaves_the_previous_output_and_no_staging(case, tmp_path_factory):
    before = tree_digest(case.root)
    # A cold Numba cache, as in CI's fresh clone: the signal lands while kernels compile.
    cold_cache = tmp_path_factory.mktemp("numba_cache")
    environment = dict(os.environ, PYTHONPATH=str(REPOSITORY), NUMBA_CACHE_DIR=str(cold_cache))
    process = subprocess.Popen([sys.executable, "-m", "ibik_pin.cli", *case.arguments(iterations="200")],
                               stderr=subprocess.PIPE, text=True, env=environment, cwd=case.inputs)
    deadline = time.monotonic() + 60
    while not any(path.name.startswith(".out.") for path in case.root.iterdir()):
        assert process.poll() is None and time.monotonic() < deadline, "the run never staged its outputs"
        time.sleep(0.05)
    time.sleep(0.5)
    process.send_signal(signal.SIGTERM)
    _, error = process.communicate(timeout=60)
    assert process.returncode == 143, error  # what the run printed, if it ended otherwise
    assert error.strip().splitlines()[-1] == "ibik: terminated" and "Traceback" not in error
    assert tree_digest(case.root) == before


# The Python API: the same checks, IbikError subclasses.

def _job(case: Case, **changes) -> TrackJob:
    fields = {"targets": str(case.targets), "out": str(case.root / "api"), "calibration": str(case.calibration),
                  "masks": str(case.masks), "quiet": True, "settings": TrackingSettings(iterations=2)}
    fields.update(changes)
    return TrackJob(**fields)


def _no_change(case: Case) -> None:
    pass


def _targets_in_mm_labelled_m(case: Case) -> None:
    case.edit_trc(case.targets, _times_ten_to_the(3))


# (id, how the case's files are changed first, the call, the error expected)
API_REFUSED: list[tuple[str, Callable[[Case], object], Callable[[Case], object], type[IbikError]]] = [
    ("mask-filter-negative", _no_change, lambda c: _job(c, settings=TrackingSettings(mask_filter_radius=-2)),
     InputError),
    ("masks-and-videos", _no_change, lambda c: _job(c, videos=str(c.root)), InputError),
    ("iterations-zero", _no_change, lambda c: _job(c, settings=TrackingSettings(iterations=0)), InputError),
    ("iterations-huge", _no_change, lambda c: _job(c, settings=TrackingSettings(iterations=10**9)), InputError),
    ("background-without-videos", _no_change, lambda c: _job(c, background=str(c.targets)), InputError),
    ("out-is-the-targets", _no_change, lambda c: run_track(_job(c, out=str(c.targets))), OutputFolderError),
    ("out-is-the-input-folder", _no_change, lambda c: run_track(_job(c, out=str(c.inputs))), OutputFolderError),
    ("targets-dev-zero", _no_change, lambda c: run_track(_job(c, targets="/dev/zero")), FileFormatError),
    ("targets-mm-labelled-m", _targets_in_mm_labelled_m, lambda c: run_track(_job(c)), InputError),
    ("cameras-behind", _setup_camera_behind, lambda c: run_track(_job(c)), InputError),
    ("unknown-criterion", _no_change, lambda c: run_track(_job(c, settings=TrackingSettings(criterion="bogus"))),
     InputError),
]


@pytest.mark.parametrize(("change", "call", "expected"), [pytest.param(*rest, id=name) for name, *rest in API_REFUSED])
def test_the_api_refuses_the_same_faults_with_ibik_errors(case, change, call, expected):
    change(case)
    before = tree_digest(case.root)
    with pytest.raises(expected):
        call(case)
    assert tree_digest(case.root) == before


def test_the_api_takes_str_paths(case):
    job = _job(case)
    assert all(isinstance(path, Path) for path in (job.targets, job.out, job.calibration, job.masks))


_COMPILER_LIKE = """
def compile_while_signalled(signal_number, seconds):
    os.kill(os.getpid(), signal_number)
    finish = time.monotonic() + seconds
    while time.monotonic() < finish:  # Python bytecode, where a handler runs
        pass
    return "compiled"
"""


@pytest.mark.parametrize(("signal_number", "raised"), [(signal.SIGTERM, Terminated),
                                                       (signal.SIGINT, KeyboardInterrupt)])
def test_a_signal_inside_numbas_compiler_is_raised_once_the_program_is_out_of_it(signal_number, raised):
    """An exception raised inside llvmlite's ctypes callbacks is swallowed and leaves LLVM half-way
    (CI: SIGTERM during a cold-cache compile, a segfault instead of 143); it waits until the stack
    holds no frame of numba or llvmlite, then is raised where the program is."""
    compiler = {"__name__": "numba.core.compiler_like", "os": os, "time": time}
    exec(_COMPILER_LIKE, compiler)
    results = []

    def compile_then_work():
        results.append(compiler["compile_while_signalled"](signal_number, 0.2))
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            pass

    with pytest.raises(raised):
        _under_the_cli_handlers(compile_then_work)
    assert results == ["compiled"]  # the compile was not interrupted, and the signal came after it
    assert signal.getsignal(signal.SIGALRM) in (signal.SIG_DFL, signal.SIG_IGN, None)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_signal_outside_numba_is_raised_where_the_program_is():
    reached = []

    def signalled_then_work():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler runs at the next bytecode boundaries
            pass
        reached.append("after")

    with pytest.raises(Terminated):
        _under_the_cli_handlers(signalled_then_work)
    assert reached == []


def _under_the_cli_handlers(body: Callable[[], None]) -> None:
    from ibik_pin.cli import _signals_raised_where_safe

    with _signals_raised_where_safe():
        body()
