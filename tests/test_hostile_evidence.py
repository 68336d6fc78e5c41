"""`ibik track` on inputs whose every file reads well but whose evidence cannot be right: masks of
the wrong camera, moment or place, cameras that do not look at the subject, axes forced wrong, a
static trial with a corrupt cell, frames whose targets all leap away. The run must check its own
evidence (app.diagnosis, app.input_checks): refuse in one stderr line (exit 2, nothing touched)
where no view can hold the subject, or go on with one warning per cause that gives the figure and
a "diagnosis" finding in report.json. Good runs must raise no such warning: a false alarm is a
defect too.

The cases are the demo's inputs (real CMU walking, rendered silhouettes; tests/test_hostile_inputs'
`pristine` and `Case`), with 2 views, or 4 where the other views must outvote one.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import subprocess
import sys
import warnings
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from ibik_pin.app.axes import TRC_TO_MODEL
from ibik_pin.app.demo import prepare_demo_inputs
from ibik_pin.app.diagnosis import FRAME_RESIDUAL_FLOOR_M, VIEW_FLOOR
from ibik_pin.app.input_checks import JUMP_DISTANCE_M
from ibik_pin.cli import main
from ibik_pin.exceptions import IbikWarning
from ibik_pin.io.trc import read_trc
from tests.paths import SHARED_DATA
from tests.test_hostile_inputs import Case, pristine, tree_digest

__all__ = ["pristine"]  # the fixture, imported for this module's cases

REPOSITORY = Path(__file__).resolve().parents[1]
MASK_SHIFT_PX = 213  # a third of the demo's 640 px: the silhouette of someone standing elsewhere


@pytest.fixture(scope="module")
def pristine4(tmp_path_factory):
    """The demo's inputs with 4 views (30 frames) and an earlier output of ibik."""
    root = tmp_path_factory.mktemp("pristine4")
    paths = prepare_demo_inputs(root / "in", views=4, frame_step=8)
    paths.truth.unlink()
    assert main(["track", "--targets", str(paths.targets), "--no-image", "--quiet", "--iterations", "2",
                 "--out", str(root / "out")]) == 0
    return root


def _copy(source: Path, tmp_path: Path, monkeypatch) -> Case:
    shutil.copytree(source / "in", tmp_path / "in")
    shutil.copytree(source / "out", tmp_path / "out")
    monkeypatch.chdir(tmp_path / "in")
    return Case(tmp_path)


@pytest.fixture
def case(pristine, tmp_path, monkeypatch):
    return _copy(pristine, tmp_path, monkeypatch)


@pytest.fixture
def case4(pristine4, tmp_path, monkeypatch):
    return _copy(pristine4, tmp_path, monkeypatch)


# ----------------------------------------------------------------------------------------------
# What the cases do to the inputs.

def _each_mask(case: Case, cameras: tuple[str, ...], change: Callable[[np.ndarray], np.ndarray]) -> None:
    for camera in cameras:
        for path in sorted((case.masks / camera).glob("*.png")):
            cv2.imwrite(str(path), np.ascontiguousarray(change(cv2.imread(str(path), cv2.IMREAD_UNCHANGED))))


def _another_moment(case: Case, cameras: tuple[str, ...], offset: int = 15) -> None:
    for camera in cameras:
        paths = sorted((case.masks / camera).glob("*.png"))
        images = [path.read_bytes() for path in paths]
        for index, path in enumerate(paths):
            path.write_bytes(images[(index + offset) % len(images)])


def _swap_masks(case: Case, first: str = "cam1", second: str = "cam2") -> None:
    (case.masks / first).rename(case.masks / "swapping")
    (case.masks / second).rename(case.masks / first)
    (case.masks / "swapping").rename(case.masks / second)


def _camera(case: Case, names: tuple[str, ...], change: Callable) -> None:
    case.edit_cameras(lambda camera: change(camera) if camera.name in names else camera)


def _focal(fx: float, fy: float | None = None) -> Callable:
    def change(camera):
        intrinsics = np.array(camera.intrinsics, dtype=float)
        intrinsics[0, 0], intrinsics[1, 1] = fx, fx if fy is None else fy
        return dataclasses.replace(camera, intrinsics=intrinsics)
    return change


def _focal_times(factor: float) -> Callable:
    def change(camera):
        intrinsics = np.array(camera.intrinsics, dtype=float)
        intrinsics[:2, :2] *= factor
        return dataclasses.replace(camera, intrinsics=intrinsics)
    return change


def _turned_by_rotation_vector(length: float) -> Callable:
    """The camera's rotation composed with a turn given as a rotation vector of that length, as a
    calibration file holding a corrupt Rodrigues vector would give."""
    axis = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])
    turn, _ = cv2.Rodrigues(axis * length)

    def change(camera):
        return dataclasses.replace(camera, rotation=turn @ camera.rotation, translation=turn @ camera.translation)
    return change


def _moved(metres: float) -> Callable:
    def change(camera):
        return dataclasses.replace(camera, translation=camera.translation + np.array([metres, 0.0, 0.0]))
    return change


def _frames_shifted(frames: list[int], shift) -> Callable[[Case], None]:
    def setup(case: Case) -> None:
        def change(data):
            data.positions = np.array(data.positions, dtype=float)
            data.positions[frames] += np.asarray(shift, dtype=float)
        case.edit_trc(case.targets, change)
    return setup


def _targets_shifted(frame: int, names: tuple[str, ...], shift) -> Callable[[Case], None]:
    def setup(case: Case) -> None:
        def change(data):
            data.positions = np.array(data.positions, dtype=float)
            for name in names:
                data.positions[frame, data.marker_names.index(name)] += np.asarray(shift, dtype=float)
        case.edit_trc(case.targets, change)
    return setup


def _targets_turned_to_z_up(extra: list[str]) -> Callable[[Case], list[str]]:
    """The targets written in the calibration's Z-up world (as a Z-up TRC holds them)."""
    def setup(case: Case) -> list[str]:
        def change(data):
            data.positions = np.asarray(data.positions, dtype=float) @ TRC_TO_MODEL["z-up"]
        case.edit_trc(case.targets, change)
        return extra
    return setup


def _static_cell(marker: str, axis: int, value: float) -> Callable[[Case], None]:
    def setup(case: Case) -> None:
        def change(data):
            data.positions = np.array(data.positions, dtype=float)
            data.positions[0, data.marker_names.index(marker), axis] = value
        case.edit_trc(case.static, change)
    return setup


BOTH = ("cam1", "cam2")
LEGS = ("LHip", "RHip", "LAnkle", "RAnkle", "LBigToe", "RBigToe")
NO_VIEW = (r"^--masks: no view holds the targets: .*cam1 0\.\d\d, cam2 0\.\d\d, where a view .* at least "
           + re.escape(f"{VIEW_FLOOR:g}"))

# id, setup (case -> extra arguments or None), the one stderr line expected.
REFUSED: list[tuple[str, Callable, str]] = [
    ("masks_of_the_two_cameras_swapped", lambda c: _swap_masks(c), NO_VIEW),
    ("every_mask_mirrored", lambda c: _each_mask(c, BOTH, lambda m: m[:, ::-1]), NO_VIEW),
    ("every_mask_of_another_moment", lambda c: _another_moment(c, BOTH), NO_VIEW),
    ("every_mask_of_someone_standing_elsewhere",
     lambda c: _each_mask(c, BOTH, lambda m: np.roll(m, MASK_SHIFT_PX, axis=1)), NO_VIEW),
    ("trc_axes_forced_z_up_on_y_up_data", lambda c: ["--trc-axes", "z-up"],
     NO_VIEW + r".*with --trc-axes y-up, 0\.9\d of the sampled targets fall inside"),
    ("focal_length_1e-300", lambda c: _camera(c, ("cam1",), _focal(1e-300)),
     r"^--calibration: camera 'cam1' has a focal length of 1e-300 px for an image 640 px wide; expected at least 6\.4"),
    ("focal_length_1e-300_in_y_only", lambda c: _camera(c, ("cam2",), _focal(700.0, 1e-300)),
     r"^--calibration: camera 'cam2' has a focal length of 1e-300 px"),
    ("focal_length_half_a_pixel_everywhere", lambda c: _camera(c, BOTH, _focal(0.5)),
     r"^--calibration: camera 'cam1' has a focal length of 0\.5 px"),
    ("rotation_vector_1e12_in_both_cameras", lambda c: _camera(c, BOTH, _turned_by_rotation_vector(1e12)),
     r"^--(calibration: camera 'cam1' (has every target behind it|sees none of the targets)|masks: no view holds)"),
    ("both_cameras_moved_a_metre", lambda c: _camera(c, BOTH, _moved(1.0)),
     r"^--(calibration: camera 'cam1' sees none of the targets|masks: no view holds)"),
    ("static_cell_1e200", _static_cell("LAnkle", 1, 1e200),
     r"^--static \S*static\.trc: frame 1 \(data row 1\), marker LAnkle, Y = 1e\+200 m: more than 2\.5 m from the "
     r"frame's other markers; expected a standing subject's coordinates"),
    ("static_cell_minus_1e6", _static_cell("RWrist", 0, -1e6),
     r"^--static \S*static\.trc: frame 1 \(data row 1\), marker RWrist, X = -1e\+06 m"),
    ("static_cell_in_centimetres", _static_cell("Head", 2, 55.0),
     r"^--static \S*static\.trc: frame 1 \(data row 1\), marker Head, Z = 55 m"),
]

REFUSED4: list[tuple[str, Callable, str]] = [
    ("four_views_every_mask_of_another_moment", lambda c: _another_moment(c, ("cam1", "cam2", "cam3", "cam4")),
     r"^--masks: no view holds the targets: .*cam1 0\.\d\d, cam2 0\.\d\d, cam3 0\.\d\d, cam4 0\.\d\d"),
]

# id, setup, {cause: [subjects]} expected in report.json's diagnosis, the warning lines expected.
VIEW_WARNING = r"^--masks: view\(s\) {camera} 0\.\d\d: share of the projected targets inside the silhouette"
FOREGROUND_WARNING = r"^--masks: view\(s\) {cameras}: share of the image the silhouette covers .* over 0\.6"
JUMP_WARNING = r"^--targets: {count} frame\(s\) whose targets all leap more than 0\.2 m away .* frame {frame} \("
WARNED: list[tuple[str, Callable, dict[str, list[str]], list[str]]] = [
    ("rotation_vector_1e12", lambda c: _camera(c, ("cam1",), _turned_by_rotation_vector(1e12)),
     {"view_targets_outside": ["cam1"]}, [VIEW_WARNING.format(camera="cam1")]),
    ("one_camera_moved_half_a_metre", lambda c: _camera(c, ("cam1",), _moved(0.5)),
     {"view_targets_outside": ["cam1"]}, [VIEW_WARNING.format(camera="cam1")]),
    ("focal_length_three_times_too_long", lambda c: _camera(c, ("cam1",), _focal_times(3.0)),
     {"view_targets_outside": ["cam1"]}, [VIEW_WARNING.format(camera="cam1")]),
    ("one_view_mirrored", lambda c: _each_mask(c, ("cam1",), lambda m: m[:, ::-1]),
     {"view_targets_outside": ["cam1"]}, [VIEW_WARNING.format(camera="cam1")]),
    ("one_view_of_another_moment", lambda c: _another_moment(c, ("cam2",)),
     {"view_targets_outside": ["cam2"]}, [VIEW_WARNING.format(camera="cam2")]),
    ("one_view_of_someone_standing_elsewhere",
     lambda c: _each_mask(c, ("cam1",), lambda m: np.roll(m, MASK_SHIFT_PX, axis=1)),
     {"view_targets_outside": ["cam1"]}, [VIEW_WARNING.format(camera="cam1")]),
    ("one_view_inverted", lambda c: _each_mask(c, ("cam1",), lambda m: 255 - m),
     {"view_targets_outside": ["cam1"], "view_mostly_foreground": ["cam1"]},
     [VIEW_WARNING.format(camera="cam1"), FOREGROUND_WARNING.format(cameras="cam1 0\\.9\\d")]),
    ("one_view_empty_in_every_frame", lambda c: _each_mask(c, ("cam1",), np.zeros_like),
     {"view_empty": ["cam1"]}, [r"^--masks: view\(s\) cam1: every sampled silhouette \(16 frames\) is empty"]),
    ("trc_axes_forced_z_up_without_the_image", lambda c: ["--trc-axes", "z-up", "--no-image"],
     {"axes_body_lying": ["z-up"]},
     [r"^--trc-axes z-up: the body lies down \(the cosine .* is -?0\.0\d, .* under y-up it stands \(1\.00\)"]),
    ("z_up_targets_forced_y_up_without_the_image", _targets_turned_to_z_up(["--trc-axes", "y-up", "--no-image"]),
     {"axes_body_lying": ["y-up"]},
     [r"^--trc-axes y-up: the body lies down .* under z-up it stands \(1\.00\); are the TRC's axes z-up\?"]),
    ("one_frame_shifted_1e6_m", _frames_shifted([10], [1e6, 0.0, 0.0]),
     {"frame_jump": ["11"]}, [JUMP_WARNING.format(count=1, frame=11) + r"1e\+06 m\)"]),
    ("one_frame_shifted_1e200_m", _frames_shifted([10], [0.0, 1e200, 0.0]),
     {"frame_jump": ["11"]}, [JUMP_WARNING.format(count=1, frame=11) + r"a distance that overflows\)"]),
    ("one_frame_jumps_half_a_metre", _frames_shifted([10], [0.0, 0.0, 0.5]),
     {"frame_jump": ["11"]}, [JUMP_WARNING.format(count=1, frame=11) + r"0\.\d+ m\)"]),
    ("one_frame_jumps_half_a_metre_down", _frames_shifted([17], [0.0, -0.5, 0.0]),
     {"frame_jump": ["18"]}, [JUMP_WARNING.format(count=1, frame=18)]),
    ("first_frame_shifted_1e6_m", _frames_shifted([0], [1e6, 1e6, 0.0]),
     {"frame_jump": ["1"]}, [JUMP_WARNING.format(count=1, frame=1)]),
    ("last_frame_shifted_1e6_m", _frames_shifted([29], [0.0, 0.0, -1e6]),
     {"frame_jump": ["30"]}, [JUMP_WARNING.format(count=1, frame=30)]),
    ("two_frames_in_a_row_shifted_1e6_m", _frames_shifted([10, 11], [1e6, 0.0, 0.0]),
     {"frame_jump": ["11", "12"]}, [JUMP_WARNING.format(count=2, frame=11)]),
    ("three_frames_in_a_row_jump_half_a_metre", _frames_shifted([20, 21, 22], [0.5, 0.0, 0.0]),
     {"frame_jump": ["21", "22", "23"]}, [JUMP_WARNING.format(count=3, frame=21)]),
    ("two_frames_apart_shifted", _frames_shifted([5, 20], [0.0, 3.0, 0.0]),
     {"frame_jump": ["6", "21"]}, [JUMP_WARNING.format(count=2, frame=6)]),
    ("the_legs_of_one_frame_shifted", _targets_shifted(10, LEGS, [0.0, 0.0, 0.8]),
     {"frame_residual": ["11"]},
     [r"^--targets: frame\(s\) 11 \(\d+ mm\): the mean end-effector residual is far above the trial's median"]),
    ("the_head_and_arms_of_one_frame_shifted",
     _targets_shifted(12, ("Head", "Neck", "LShoulder", "RShoulder", "LWrist", "RWrist"), [0.9, 0.0, 0.0]),
     {"frame_residual": ["13"]}, [r"^--targets: frame\(s\) 13 \(\d+ mm\): the mean end-effector residual"]),
]

WARNED4: list[tuple[str, Callable, dict[str, list[str]], list[str]]] = [
    ("four_views_two_swapped", lambda c: _swap_masks(c, "cam1", "cam2"),
     {"view_targets_outside": ["cam1", "cam2"]}, [r"^--masks: view\(s\) cam1 0\.\d\d, cam2 0\.\d\d: share"]),
    ("four_views_one_mirrored", lambda c: _each_mask(c, ("cam3",), lambda m: m[:, ::-1]),
     {"view_targets_outside": ["cam3"]}, [VIEW_WARNING.format(camera="cam3")]),
    ("four_views_one_rotation_vector_1e12", lambda c: _camera(c, ("cam2",), _turned_by_rotation_vector(1e12)),
     {"view_targets_outside": ["cam2"]}, [VIEW_WARNING.format(camera="cam2")]),
    ("four_views_one_inverted", lambda c: _each_mask(c, ("cam2",), lambda m: 255 - m),
     {"view_targets_outside": ["cam2"], "view_mostly_foreground": ["cam2"]},
     [VIEW_WARNING.format(camera="cam2"), FOREGROUND_WARNING.format(cameras="cam2 0\\.9\\d")]),
    ("four_views_one_empty", lambda c: _each_mask(c, ("cam4",), np.zeros_like),
     {"view_empty": ["cam4"]}, [r"^--masks: view\(s\) cam4: every sampled silhouette"]),
    ("four_views_one_of_another_moment", lambda c: _another_moment(c, ("cam1",)),
     {"view_targets_outside": ["cam1"]}, [VIEW_WARNING.format(camera="cam1")]),
]


def _run(case: Case, extra: list[str] | None, *options: str) -> tuple[int, list[str]]:
    """`ibik track` in this process; its exit code and its warnings, one text each."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(case.arguments(*(extra or []), *options))
    return code, [str(warning.message) for warning in caught if issubclass(warning.category, IbikWarning)]


def _assert_refused(case: Case, setup: Callable, expected: str, capfd) -> None:
    extra = setup(case)
    before = tree_digest(case.root)
    capfd.readouterr()
    code, _ = _run(case, extra)
    err = capfd.readouterr().err
    assert code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("ibik: error: "), err
    assert re.search(expected, lines[0].removeprefix("ibik: error: ")), lines[0]
    assert tree_digest(case.root) == before  # inputs and the earlier output untouched, no staging left


def _assert_warned(case: Case, setup: Callable, findings: dict[str, list[str]], expected: list[str]) -> dict:
    extra = setup(case)
    inputs = tree_digest(case.inputs)
    code, said = _run(case, extra)
    assert code == 0
    assert len(said) == len(expected), said
    for pattern, message in zip(expected, said, strict=True):
        assert "\n" not in message and re.search(pattern, message), (pattern, message)
    report = json.loads((case.out / "report.json").read_text())
    found: dict[str, list[str]] = {}
    for finding in report["diagnosis"]["findings"]:
        found.setdefault(finding["cause"], []).append(finding["subject"])
    # A view whose targets miss its silhouette may hold too little of the tracked skeleton too.
    also = found.pop("view_skeleton_outside", [])
    assert set(also) <= set(findings.get("view_targets_outside", [])), also
    assert found == findings
    assert tree_digest(case.inputs) == inputs
    return report


@pytest.mark.parametrize(("setup", "expected"), [pytest.param(s, e, id=i) for i, s, e in REFUSED])
def test_evidence_that_cannot_be_right_is_refused_in_one_line_and_nothing_is_touched(case, setup, expected, capfd):
    _assert_refused(case, setup, expected, capfd)


@pytest.mark.parametrize(("setup", "expected"), [pytest.param(s, e, id=i) for i, s, e in REFUSED4])
def test_four_views_that_all_miss_are_refused(case4, setup, expected, capfd):
    _assert_refused(case4, setup, expected, capfd)


@pytest.mark.parametrize(("setup", "findings", "expected"),
                         [pytest.param(s, f, e, id=i) for i, s, f, e in WARNED])
def test_suspect_evidence_is_warned_of_once_per_cause_with_its_figure_and_in_the_report(case, setup, findings,
                                                                                       expected):
    report = _assert_warned(case, setup, findings, expected)
    for finding in report["diagnosis"]["findings"]:
        if finding["cause"] == "view_targets_outside":
            assert finding["figure"] < finding["threshold"] and finding["threshold"] >= VIEW_FLOOR
        if finding["cause"] == "frame_residual":
            assert finding["figure"] > finding["threshold"] >= FRAME_RESIDUAL_FLOOR_M
        if finding["cause"] == "frame_jump":
            assert finding["figure"] is None or finding["figure"] > JUMP_DISTANCE_M


@pytest.mark.parametrize(("setup", "findings", "expected"),
                         [pytest.param(s, f, e, id=i) for i, s, f, e in WARNED4])
def test_one_suspect_view_among_four_is_warned_of(case4, setup, findings, expected):
    _assert_warned(case4, setup, findings, expected)


def test_there_are_at_least_thirty_evidence_cases():
    names = [case[0] for case in REFUSED + REFUSED4 + WARNED + WARNED4]
    assert len(names) >= 30 and len(set(names)) == len(names)


# ----------------------------------------------------------------------------------------------
# A frame whose targets all leap: dropped, not solved, the frames after it as if it had not leapt.

@pytest.fixture(scope="module")
def unshifted(pristine, tmp_path_factory):
    """joints.trc of the demo tracked with the image, as the cases below are."""
    out = tmp_path_factory.mktemp("unshifted") / "out"
    case = Case(pristine)
    assert main(case.arguments(out=str(out))) == 0
    return read_trc(out / "joints.trc").positions


@pytest.mark.parametrize("shift", [[1e6, 0.0, 0.0], [0.0, 1e200, 0.0], [0.0, 0.0, 0.5]],
                         ids=["1e6_m", "1e200_m", "half_a_metre"])
def test_a_shifted_frame_is_left_unsolved_and_the_frames_after_it_are_unharmed(case, unshifted, shift):
    _frames_shifted([10], shift)(case)
    code, said = _run(case, None)
    assert code == 0 and len(said) == 1 and "frame 11 (" in said[0]
    joints = read_trc(case.out / "joints.trc").positions
    gaps = np.linalg.norm(joints - unshifted, axis=2).max(axis=1)  # per frame, the farthest joint [m]
    others = np.delete(gaps, 10)
    assert others.max() < 1e-3, others  # measured: 0.28 mm on the frame after, 0 before
    assert gaps[10] < 0.05  # interpolated between frames 10 and 12 of a walk at 15 Hz (measured 28 mm)
    report = json.loads((case.out / "report.json").read_text())
    assert sorted(report["frames_with_dropped_targets"]["11"]) == sorted(read_trc(case.targets).marker_names)
    assert report["end_effector_residual_m"]["per_frame"][10] is None
    assert report["end_effector_residual_m"]["max"] < 1e-3
    assert all(levels[10] == "empty" for levels in report["solver_levels"]["status_per_frame"].values())


# ----------------------------------------------------------------------------------------------
# Good runs: no diagnosis warning, no finding (false alarms are defects too).

def _diagnosis_warnings(said: list[str]) -> list[str]:
    return [message for message in said if re.search(r"view\(s\)|leap|whole body moves|residual is far", message)]


def _assert_quiet(code: int, said: list[str], out: Path) -> dict:
    assert code == 0
    assert _diagnosis_warnings(said) == []
    report = json.loads((out / "report.json").read_text())
    assert report["diagnosis"]["findings"] == []
    return report


def test_the_demo_with_two_views_raises_no_diagnosis_warning(case):
    report = _assert_quiet(*_run(case, None), case.out)
    assert min(report["diagnosis"]["targets_inside_sampled"].values()) > 0.9
    assert min(report["diagnosis"]["skeleton_inside_median"].values()) > 0.9
    assert max(value for value in report["diagnosis"]["departure_per_frame_m"] if value is not None) < 0.05


def test_the_demo_with_four_views_raises_no_diagnosis_warning(case4):
    report = _assert_quiet(*_run(case4, None), case4.out)
    assert sorted(report["diagnosis"]["targets_inside_sampled"]) == ["cam1", "cam2", "cam3", "cam4"]


def test_noisy_targets_tracked_blind_raise_no_diagnosis_warning(case):
    """10 mm of Gaussian noise on every coordinate, the sweep's largest."""
    def noisy(data):
        data.positions = data.positions + np.random.default_rng(7).normal(0.0, 0.010, data.positions.shape)
    case.edit_trc(case.targets, noisy)
    _assert_quiet(*_run(case, ["--no-image"]), case.out)


def _alpha_silhouette(mask: np.ndarray) -> np.ndarray:
    image = np.zeros((*mask.shape[:2], 4), np.uint8)
    image[..., 3] = mask
    return image


@pytest.mark.parametrize("encode", [_alpha_silhouette, lambda m: (m > 0).astype(np.uint16),
                                    lambda m: (m > 0).astype(np.uint16) * 65535,
                                    lambda m: (m > 0).astype(np.uint8) * 3],
                         ids=["alpha_channel", "16_bit_labels_0_1", "16_bit_full_range", "labels_0_3"])
def test_masks_in_the_usual_encodings_raise_no_diagnosis_warning(case, encode):
    _each_mask(case, BOTH, encode)
    report = _assert_quiet(*_run(case, None), case.out)
    assert min(report["diagnosis"]["targets_inside_sampled"].values()) > 0.9


POSE2SIM = SHARED_DATA / "pose2sim_demo"


@pytest.mark.skipif(not POSE2SIM.is_dir(), reason=f"the real Pose2Sim demo is not in {SHARED_DATA}")
def test_a_real_markerless_trial_raises_no_diagnosis_warning(tmp_path):
    """Pose2Sim's own triangulation of its real 4-camera demo (100 frames at 60 Hz), tracked blind
    with its calibration (the axes are detected against its cameras)."""
    targets = POSE2SIM / "ref3d" / "S00_P00_T01_BalancingTrial_0-100.trc"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(["track", "--targets", str(targets), "--no-image",
                     "--calibration", str(POSE2SIM / "Calib_qualisys_converted.toml"), "--quiet",
                     "--out", str(tmp_path / "out")])
    _assert_quiet(code, [str(warning.message) for warning in caught], tmp_path / "out")


@pytest.mark.skipif(not (SHARED_DATA / "cmu" / "39_01.c3d").is_file(),
                    reason=f"CMU 39_01.c3d is not in {SHARED_DATA}")
def test_a_real_mocap_recording_raises_no_diagnosis_warning(tmp_path):
    """CMU 39_01's raw Vicon recording (its markers mapped to keypoints by io.c3d), tracked blind."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(["track", "--targets", str(SHARED_DATA / "cmu" / "39_01.c3d"), "--no-image", "--quiet",
                     "--iterations", "2", "--out", str(tmp_path / "out")])
    _assert_quiet(code, [str(warning.message) for warning in caught], tmp_path / "out")


# ----------------------------------------------------------------------------------------------
# The real command's stderr: one line for a refusal, one line per cause for a warning.

def _command(case: Case, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ibik_pin.cli", *case.arguments(*extra)], capture_output=True,
                          text=True, cwd=case.inputs, timeout=300)


def test_the_command_refuses_swapped_masks_in_one_stderr_line(case):
    _swap_masks(case)
    before = tree_digest(case.root)
    finished = _command(case)
    assert finished.returncode == 2
    assert re.fullmatch(r"ibik: error: --masks: no view holds the targets: [^\n]*\n", finished.stderr)
    assert tree_digest(case.root) == before


def test_the_command_warns_of_a_shifted_frame_in_one_stderr_line(case):
    _frames_shifted([10], [1e6, 0.0, 0.0])(case)
    inputs = tree_digest(case.inputs)
    finished = _command(case)
    assert finished.returncode == 0
    assert re.fullmatch(r"ibik: warning: --targets: 1 frame\(s\) whose targets all leap [^\n]* frame 11 "
                        r"\(1e\+06 m\)\n", finished.stderr), finished.stderr
    assert tree_digest(case.inputs) == inputs
