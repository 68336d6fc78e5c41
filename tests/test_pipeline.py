"""`ibik track` on the TRC's axis convention and on what report.json and the summary say.

A 5-frame synthetic recording (two cameras, clean rendered masks) written by write_dataset; the
same targets are also written Z-up (in the calibration's own world) and 100 m away.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.cli import main
from ibik_pin.exceptions import IbikWarning
from ibik_pin.human import load_human
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD
from ibik_pin.io.trc import read_trc, write_trc
from ibik_pin.synthetic.dataset import write_dataset
from ibik_pin.synthetic.rig import humaneva_rig

TARGETS = ["Hip", "LHip", "LKnee", "LAnkle", "RHip", "RKnee", "RAnkle", "Neck", "Head", "LShoulder",
           "LElbow", "LWrist", "RShoulder", "RElbow", "RWrist"]
FRAMES = 5
# The Z-up TRC holds the Y-up one's numbers permuted, so the tracker sees identical model-frame
# targets; the only difference left is the TRC's decimal rounding, the same for both.
AXES_TOLERANCE_M = 1e-6


def bending_motion(body, frame_count: int) -> np.ndarray:
    """(F, nq) a body drifting 0.2 m along X while knees, elbows and a shoulder swing."""
    model = body.model
    q = np.tile(pin.neutral(model), (frame_count, 1))
    phase = np.linspace(0.0, 1.0, frame_count)
    q[:, :3] = np.column_stack([0.2 * phase, np.full(frame_count, 1.0), np.full(frame_count, 0.1)])
    for joint, amplitude in [("left_knee_Z", 0.5), ("right_knee_Z", 0.3), ("left_elbow_Z", 0.6),
                             ("right_elbow_Z", 0.4), ("left_shoulder_X", 0.3)]:
        index = model.joints[model.getJointId(joint)].idx_q
        lower, upper = model.lowerPositionLimit[index], model.upperPositionLimit[index]
        swing = 0.5 * (lower + upper) + amplitude * 0.5 * (upper - lower) * np.sin(2.0 * np.pi * phase)
        q[:, index] = np.clip(swing, lower, upper)
    return q


def write_transformed(source: Path, path: Path, transform) -> Path:
    data = read_trc(source)
    data.positions = transform(data.positions)
    write_trc(path, data)
    return path


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recording")
    body = load_human()
    cameras = humaneva_rig(2, np.array([0.1, 1.0, 0.1]), seed=1)
    paths = write_dataset(folder / "data", body, bending_motion(body, FRAMES), cameras, 30.0, TARGETS, seed=0)
    z_up = write_transformed(paths.targets, folder / "z_up.trc", lambda p: p @ POSE2SIM_TRC_TO_WORLD.T)
    far = write_transformed(paths.targets, folder / "far.trc", lambda p: p + 100.0)
    return paths, z_up, far


def arguments(recording, targets: Path, out: Path, *extra: str, image: bool = True) -> list[str]:
    paths = recording[0]
    sources = ["--masks", str(paths.masks)] if image else ["--no-image"]
    return ["track", "--targets", str(targets), "--calibration", str(paths.calibration), *sources,
            "--iterations", "3", "--quiet", "--out", str(out), *extra]


def read_report(out: Path) -> dict:
    """report.json parsed strictly: a bare NaN or Infinity token fails."""
    def refuse(token):
        raise ValueError(f"non-JSON constant {token} in report.json")

    return json.loads((out / "report.json").read_text(), parse_constant=refuse)


@pytest.fixture(scope="module")
def runs(recording, tmp_path_factory):
    """The Y-up and the Z-up TRC of the same motion, each tracked with the image."""
    paths, z_up, _ = recording
    folder = tmp_path_factory.mktemp("runs")
    codes = {"y-up": main(arguments(recording, paths.targets, folder / "y-up")),
             "z-up": main(arguments(recording, z_up, folder / "z-up"))}
    return folder, codes


def test_a_z_up_and_a_y_up_trc_of_the_same_motion_give_the_same_joints(runs):
    folder, codes = runs
    assert codes == {"y-up": 0, "z-up": 0}
    y_up = read_trc(folder / "y-up" / "joints.trc")
    z_up = read_trc(folder / "z-up" / "joints.trc")
    assert y_up.marker_names == z_up.marker_names
    # joints.trc is written back in each input's own convention.
    assert np.abs(y_up.positions @ POSE2SIM_TRC_TO_WORLD.T - z_up.positions).max() <= AXES_TOLERANCE_M


def test_auto_detection_picks_each_trc_s_convention_by_the_silhouettes(runs):
    folder, _ = runs
    for axes in ("y-up", "z-up"):
        report = read_report(folder / axes)["trc_axes"]
        assert (report["used"], report["how"], report["decided_by"]) == (axes, "detected", "silhouettes")
        other = "z-up" if axes == "y-up" else "y-up"
        assert report["inside_silhouettes"][axes] > 0.9 > 0.1 > report["inside_silhouettes"][other]
        assert report["sampled_frames"] == [1, 2, 3, 4, 5]


def test_auto_detection_without_silhouettes_falls_back_on_the_upright_body(recording, tmp_path):
    # On this rig the Z-up TRC read Y-up still projects inside both images: only posture tells.
    _, z_up, _ = recording
    assert main(arguments(recording, z_up, tmp_path / "out", image=False)) == 0
    report = read_report(tmp_path / "out")["trc_axes"]
    assert (report["used"], report["decided_by"]) == ("z-up", "upright body")
    assert report["upright_cosine"]["z-up"] > math.cos(math.radians(45.0)) > report["upright_cosine"]["y-up"]


def test_a_trc_that_fits_no_camera_is_refused_in_one_line(recording, tmp_path, capsys):
    _, _, far = recording
    # With the image, the first camera that sees none of the targets under any convention is named.
    assert main(arguments(recording, far, tmp_path / "out")) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1
    assert error.startswith("ibik: error: --calibration: camera 'cam1' sees none of the targets inside its ")
    # Blind, the cameras serve only to tell the TRC's axes, and the axes' evidence is the message.
    assert main(arguments(recording, far, tmp_path / "out", image=False)) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1
    assert error.startswith("ibik: error: no axis convention puts the targets inside the cameras' images: ")
    assert "y-up: 0% of the projected targets inside the images" in error
    assert not (tmp_path / "out").exists()


def test_trc_axes_forces_the_convention(recording, tmp_path):
    _, z_up, _ = recording
    assert main(arguments(recording, z_up, tmp_path / "out", "--trc-axes", "y-up", image=False)) == 0
    report = read_report(tmp_path / "out")["trc_axes"]
    assert (report["used"], report["how"], report["decided_by"]) == ("y-up", "forced", "")
    # Read Y-up, the body lies on its side, yet IK still reaches the targets, written back as given.
    joints = read_trc(tmp_path / "out" / "joints.trc")
    targets = read_trc(z_up)
    columns = [joints.marker_names.index(name) for name in targets.marker_names]
    assert np.abs(joints.positions[:, columns] - targets.positions).max() < 0.05


def test_a_forced_convention_that_misses_the_images_is_warned_about(recording, tmp_path):
    _, _, far = recording
    with pytest.warns(IbikWarning, match="--trc-axes z-up keeps the targets out of the cameras' images"):
        assert main(arguments(recording, far, tmp_path / "out", "--trc-axes", "z-up", image=False)) == 0


def test_without_a_calibration_the_trc_is_read_y_up_and_the_report_says_so(recording, tmp_path):
    paths = recording[0]
    command = ["track", "--targets", str(paths.targets), "--no-image", "--iterations", "3", "--quiet",
               "--out", str(tmp_path / "out")]
    assert main(command) == 0
    report = read_report(tmp_path / "out")["trc_axes"]
    assert (report["used"], report["how"]) == ("y-up", "default")
    assert "no --calibration" in report["description"]
    assert report["inside_images"] == {}


def test_without_a_calibration_a_body_lying_in_y_up_is_warned_about(recording, tmp_path):
    _, z_up, _ = recording
    command = ["track", "--targets", str(z_up), "--no-image", "--iterations", "3", "--quiet",
               "--out", str(tmp_path / "out")]
    with pytest.warns(IbikWarning, match="stands upright only if they are z-up"):
        assert main(command) == 0


def test_the_report_holds_every_target_s_residual_per_frame(runs, recording):
    folder, _ = runs
    text = (folder / "y-up" / "report.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    report = read_report(folder / "y-up")
    residuals = report["keypoint_residual_m"]
    assert list(residuals) == TARGETS
    for name, stats in residuals.items():
        assert len(stats["per_frame"]) == FRAMES, name
        values = np.array(stats["per_frame"])
        assert stats["max"] == pytest.approx(values.max(), abs=1e-12)
        assert stats["mean"] == pytest.approx(values.mean(), abs=1e-12)
        assert stats["median"] == pytest.approx(np.median(values), abs=1e-12)
        assert 0.0 <= stats["max"] < 0.02, name  # clean targets of the model's own keypoints
    overall = np.nanmean([stats["per_frame"] for stats in residuals.values()], axis=0)
    assert np.allclose(report["end_effector_residual_m"]["per_frame"], overall, atol=1e-12)
    assert report["frame_numbers"] == [1, 2, 3, 4, 5]
    assert report["frame_rate_hz"] == 30.0
    assert np.allclose(report["times_s"], np.arange(FRAMES) / 30.0, atol=1e-9)
    assert "Frame#" in report["frame_numbering"]
    levels = report["solver_levels"]
    assert levels["levels"] == ["lower-body targets", "upper-body targets", "image", "posture"]
    assert all(len(statuses) == FRAMES for statuses in levels["status_per_frame"].values())


def test_an_absent_target_is_null_in_the_report(recording, tmp_path):
    paths = recording[0]
    holed = write_transformed(paths.targets, tmp_path / "holed.trc", lambda p: np.where(
        (np.arange(FRAMES)[:, None, None] == 2) & (np.arange(len(TARGETS))[None, :, None] == TARGETS.index("RWrist")),
        np.nan, p))
    assert main(arguments(recording, holed, tmp_path / "out", image=False)) == 0
    report = read_report(tmp_path / "out")
    assert report["keypoint_residual_m"]["RWrist"]["per_frame"][2] is None
    assert report["frames_with_dropped_targets"] == {"3": ["RWrist"]}


def test_the_summary_lists_every_target_worst_first_in_mm(recording, tmp_path, capsys):
    paths = recording[0]
    command = arguments(recording, paths.targets, tmp_path / "out", image=False)
    command.remove("--quiet")
    assert main(command) == 0
    captured = capsys.readouterr()
    assert captured.err.count("ibik: TRC axes: y-up") == 1
    lines = captured.out.splitlines()
    assert lines[0].startswith(f"wrote {tmp_path / 'out'}: 5 frames at ")
    assert "mean end-effector residual" in lines[0] and lines[0].endswith(" mm")
    rows = lines[2:]
    assert sorted(row.split()[0] for row in rows) == sorted(TARGETS)
    means = [float(row.split()[1]) for row in rows]
    assert means == sorted(means, reverse=True)
    report = read_report(tmp_path / "out")
    worst = rows[0].split()[0]
    assert means[0] == pytest.approx(1000 * report["keypoint_residual_m"][worst]["mean"], abs=0.05)
