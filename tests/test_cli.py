"""`ibik track` end to end on a short sequence rendered by the project, and its bad-input errors."""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from ibik_pin.app.demo import ESTIMATED, prepare_demo_inputs
from ibik_pin.cli import main
from ibik_pin.evaluation import mean_joint_errors_mm
from ibik_pin.exceptions import IbikWarning
from ibik_pin.io.calibration import read_calibration, write_calibration
from ibik_pin.io.keypoints import read_keypoints
from ibik_pin.io.mot import read_mot
from ibik_pin.io.trc import METRES_PER_UNIT, read_trc, write_trc

OUTPUTS = ["joints.trc", "q.csv", "motion.mot", "motion.bvh", "model.osim", "report.json"]
OVERLAYS = ["residuals.png", "angles.png", "replay.html", "overlay_cam1.mp4", "overlay_cam2.mp4"]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """30 frames of real walking (CMU 35_01 at 15 Hz), 2 views, clean masks."""
    return prepare_demo_inputs(tmp_path_factory.mktemp("walk") / "input", views=2, frame_step=8)


def track_arguments(dataset, out: Path, *extra: str) -> list[str]:
    return ["track", "--targets", str(dataset.targets), "--calibration", str(dataset.calibration),
            "--masks", str(dataset.masks), "--static", str(dataset.folder / "static.trc"),
            "--quiet", "--out", str(out), *extra]


def internal_joint_errors(dataset, out: Path) -> dict[str, float]:
    truth = read_trc(dataset.truth)
    estimate = read_trc(out / "joints.trc")
    order = [estimate.marker_names.index(name) for name in truth.marker_names]
    return mean_joint_errors_mm(estimate.positions[:, order], truth.positions, truth.marker_names, ESTIMATED)


@pytest.fixture(scope="module")
def runs(dataset, tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    codes = {
        "ibik": main(track_arguments(dataset, folder / "ibik", "--overlay")),
        "pik": main(track_arguments(dataset, folder / "pik", "--no-image")),
    }
    return folder, codes


def test_track_with_and_without_the_image_exits_0_and_writes_every_output(runs):
    folder, codes = runs
    assert codes == {"ibik": 0, "pik": 0}
    for variant in ("ibik", "pik"):
        for name in OUTPUTS:
            assert (folder / variant / name).stat().st_size > 0, (variant, name)
    for name in OVERLAYS:
        assert (folder / "ibik" / name).stat().st_size > 0, name


def test_the_image_lowers_every_elbow_and_knee_error(dataset, runs):
    folder, _ = runs
    ibik = internal_joint_errors(dataset, folder / "ibik")
    pik = internal_joint_errors(dataset, folder / "pik")
    assert all(ibik[joint] < pik[joint] for joint in ESTIMATED), (ibik, pik)


def test_joints_trc_has_one_row_per_input_frame_with_the_input_times(dataset, runs):
    folder, _ = runs
    targets = read_trc(dataset.targets)
    joints = read_trc(folder / "ibik" / "joints.trc")
    assert joints.positions.shape[0] == targets.positions.shape[0]
    assert np.allclose(joints.times, targets.times)
    for name in ["Hip", "Neck", "Head", "LShoulder", "LElbow", "LWrist", "RShoulder", "RElbow",
                 "RWrist", "LHip", "LKnee", "LAnkle", "RHip", "RKnee", "RAnkle"]:
        assert name in joints.marker_names
    assert joints.units == targets.units


def test_the_report_and_mot_are_readable(dataset, runs):
    folder, _ = runs
    report = json.loads((folder / "ibik" / "report.json").read_text())
    assert report["frames"] == 30 and report["image"] is True
    assert report["end_effector_residual_m"]["mean"] < 0.01
    assert set(report["overlap_per_view"]) == {"cam1", "cam2"}
    assert set(report["keypoint_residual_m"]) == set(read_trc(dataset.targets).marker_names)
    assert report["trc_axes"]["used"] == "y-up" and report["trc_axes"]["how"] == "detected"
    mot = read_mot(folder / "ibik" / "motion.mot")
    assert mot.in_degrees and mot.values.shape[0] == 30


def test_the_mask_filter_runs_and_is_reported(dataset, tmp_path):
    assert main(track_arguments(dataset, tmp_path / "filtered", "--mask-filter", "1")) == 0
    report = json.loads((tmp_path / "filtered" / "report.json").read_text())
    assert report["mask_filter_radius"] == 1
    assert report["end_effector_residual_m"]["mean"] < 0.01


def test_every_read_ahead_mode_gives_the_same_motion_and_silhouette_report(dataset, tmp_path):
    """The mask filter on, so that the child process reads each frame's masks through the temporal
    filter ahead of the frame it prepares, and sends the silhouette figures back."""
    reports, motions = {}, {}
    for mode in ("process", "thread", "off"):
        out = tmp_path / mode
        assert main(track_arguments(dataset, out, "--mask-filter", "1", "--read-ahead", mode)) == 0
        reports[mode] = json.loads((out / "report.json").read_text())
        motions[mode] = (out / "q.csv").read_text()
    assert motions["process"] == motions["thread"] == motions["off"]
    areas = reports["off"]["silhouettes"]["mask_area_per_view"]
    assert all(len(per_frame) == 30 and min(per_frame) > 0 for per_frame in areas.values())
    for mode in ("process", "thread"):
        assert reports[mode]["silhouettes"] == reports["off"]["silhouettes"]
    assert main(track_arguments(dataset, tmp_path / "alias", "--no-read-ahead")) == 0


def test_the_image_stop_is_taken_from_the_command_line_and_reported(dataset, runs, tmp_path):
    folder, _ = runs
    peaked = json.loads((folder / "ibik" / "report.json").read_text())
    assert peaked["image_stop"] == "peak" and peaked["mean_iterations_per_frame"] < 15
    assert main(track_arguments(dataset, tmp_path / "counted", "--image-stop", "count")) == 0
    counted = json.loads((tmp_path / "counted" / "report.json").read_text())
    assert counted["image_stop"] == "count" and counted["mean_iterations_per_frame"] == 15


def test_angles_png_draws_the_motion_mot_columns_it_names(runs):
    """angles.png is written with every --overlay run, from motion.mot's flexion columns."""
    from ibik_pin.io.mot import read_mot
    from ibik_pin.viz import plots

    folder, _ = runs
    png = (folder / "ibik" / "angles.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000
    motion = read_mot(folder / "ibik" / "motion.mot")
    columns = dict(zip(motion.column_names, motion.values.T, strict=True))
    drawn = plots.joint_angle_panels(columns)
    assert [panel.title for panel in drawn] == [title for title, _, _ in plots.JOINT_ANGLES]
    for panel, (_, left, right) in zip(drawn, plots.JOINT_ANGLES, strict=True):
        np.testing.assert_array_equal(panel.series["left"], columns[left])
        np.testing.assert_array_equal(panel.series["right"], columns[right])
    # The knee bends in walking: its curve is an angle in degrees, not radians or a constant.
    assert 20.0 < np.ptp(columns["left_knee_Z"]) < 90.0


def test_the_targets_as_c3d_give_the_joints_of_their_trc_within_a_millimetre(dataset, runs, tmp_path):
    from tests.c3d_files import write_c3d

    folder, _ = runs
    trc = read_trc(dataset.targets)
    c3d = tmp_path / "targets.c3d"
    write_c3d(c3d, trc.marker_names, trc.positions / METRES_PER_UNIT["mm"] * METRES_PER_UNIT[trc.units],
              trc.data_rate)
    arguments = track_arguments(dataset, tmp_path / "out")
    arguments[arguments.index("--targets") + 1] = str(c3d)
    read_back = read_keypoints(c3d)
    order = [read_back.marker_names.index(name) for name in trc.marker_names]  # the mapping's order
    input_difference_mm = np.abs(read_back.positions[:, order] * METRES_PER_UNIT[read_back.units]
                                 - trc.positions * METRES_PER_UNIT[trc.units]) * 1000
    assert np.nanmax(input_difference_mm) < 1e-3  # C3D stores float32 millimetres
    assert main(arguments) == 0
    from_trc, from_c3d = read_trc(folder / "ibik" / "joints.trc"), read_trc(tmp_path / "out" / "joints.trc")
    assert from_c3d.marker_names == from_trc.marker_names
    scale = METRES_PER_UNIT[from_c3d.units] / METRES_PER_UNIT["mm"]
    difference_mm = np.linalg.norm(from_c3d.positions * scale
                                   - from_trc.positions * METRES_PER_UNIT[from_trc.units] * 1000, axis=2)
    # Float32 rounding may move a frame's targets-only steps across target_step_tolerance, so a
    # frame can take one step more or less: the joints then differ by a few millimetres at most.
    assert np.nanmean(difference_mm) < 0.5 and np.nanmax(difference_mm) < 10.0, difference_mm.max()
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert (report["trc_axes"]["used"], report["trc_axes"]["how"]) == ("y-up", "declared by the C3D file")


def test_a_static_take_5_percent_small_is_lengthened_to_reach_the_trial_and_reported(dataset, tmp_path):
    static = read_trc(dataset.folder / "static.trc")
    centre = np.nanmean(static.positions, axis=(0, 1))
    static.positions = centre + 0.95 * (static.positions - centre)  # every segment 5 % short
    write_trc(tmp_path / "small_static.trc", static)
    arguments = track_arguments(dataset, tmp_path / "out", "--no-image", "--trial-lengths", "reach")
    arguments[arguments.index("--static") + 1] = str(tmp_path / "small_static.trc")
    assert main(arguments) == 0
    segments = json.loads((tmp_path / "out" / "report.json").read_text())["trial_lengths"]["segments_mm"]
    truth = read_trc(dataset.truth)
    position = dict(zip(truth.marker_names, np.transpose(truth.positions * METRES_PER_UNIT[truth.units] * 1e3,
                                                         (1, 0, 2)), strict=True))
    for side, limb in (("L", "left"), ("R", "right")):
        true_sum = np.median(np.linalg.norm(position[f"{side}Hip"] - position[f"{side}Knee"], axis=1)
                             + np.linalg.norm(position[f"{side}Knee"] - position[f"{side}Ankle"], axis=1))
        static_sum = segments[f"{limb}_thigh"]["static"] + segments[f"{limb}_shank"]["static"]
        trial_sum = segments[f"{limb}_thigh"]["trial"] + segments[f"{limb}_shank"]["trial"]
        # The static's legs are about 40 mm short; the trial's reach, a lower bound (a walking leg is
        # never quite straight), gives back most of it (measured 30 of 44 mm on the right) and no more.
        assert static_sum < true_sum - 25.0, (limb, static_sum, true_sum)
        assert static_sum + 0.5 * (true_sum - static_sum) < trial_sum < true_sum + 5.0, (limb, trial_sum, true_sum)
    assert all(segment["change"] >= 0.0 for segment in segments.values())


def test_the_qp_backend_is_chosen_on_the_command_line_and_reported(dataset, tmp_path):
    out = tmp_path / "out"
    assert main(track_arguments(dataset, out, "--no-image", "--qp-solver", "proxsuite", "--iterations", "3")) == 0
    assert json.loads((out / "report.json").read_text())["qp_solver"] == "proxsuite"


def test_an_unknown_qp_backend_is_refused_with_the_installed_ones(dataset, tmp_path, capsys):
    error = run_bad(track_arguments(dataset, tmp_path / "out", "--qp-solver", "gurobi"), capsys)
    assert "--qp-solver: expected one of active_set, proxsuite" in error and "'gurobi'" in error
    assert not (tmp_path / "out").exists()


def test_a_qp_backend_given_twice_differently_is_refused(dataset, tmp_path, capsys):
    stack = tmp_path / "stack.toml"
    stack.write_text('qp_solver = "proxsuite"\n\n[[level]]\nname = "targets"\n[[level.tasks]]\nkind = "position"\n'
                     'keypoints = "present"\n')
    error = run_bad(track_arguments(dataset, tmp_path / "out", "--qp-solver", "active_set", "--stack", str(stack)),
                    capsys)
    assert "--qp-solver active_set and --stack" in error and "'proxsuite': give the backend once" in error


def test_the_overlay_video_decodes_to_one_frame_per_input_frame(runs):
    folder, _ = runs
    capture = cv2.VideoCapture(str(folder / "ibik" / "overlay_cam1.mp4"))
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    ok, frame = capture.read()
    capture.release()
    assert ok and frame.shape == (480, 640, 3) and count == 30


def test_a_trc_in_millimetres_gives_joints_in_millimetres(dataset, tmp_path):
    targets = read_trc(dataset.targets)
    targets.positions = targets.positions * 1000.0
    targets.units = "mm"
    path = tmp_path / "targets_mm.trc"
    write_trc(path, targets)
    arguments = track_arguments(dataset, tmp_path / "out", "--no-image", "--iterations", "3")
    arguments[arguments.index("--targets") + 1] = str(path)
    assert main(arguments) == 0
    joints = read_trc(tmp_path / "out" / "joints.trc")
    assert joints.units == "mm"
    assert np.nanmax(np.abs(joints.positions)) > 100.0


def test_an_occluded_target_is_dropped_for_that_frame_and_reported(dataset, tmp_path):
    targets = read_trc(dataset.targets)
    targets.positions[3, targets.marker_names.index("LWrist")] = np.nan
    path = tmp_path / "occluded.trc"
    write_trc(path, targets)
    arguments = track_arguments(dataset, tmp_path / "out", "--no-image", "--iterations", "3")
    arguments[arguments.index("--targets") + 1] = str(path)
    assert main(arguments) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    # Row 3 (0-based) of a TRC whose frame numbers start at 1 is frame 4.
    assert report["frames_with_dropped_targets"] == {"4": ["LWrist"]}
    assert report["keypoint_residual_m"]["LWrist"]["per_frame"][3] is None


def run_bad(arguments, capsys) -> str:
    code = main(arguments)
    error = capsys.readouterr().err
    assert code == 2
    assert error.count("\n") == 1 and error.startswith("ibik: error: ")
    assert "Traceback" not in error
    return error


def track_with_target_renamed(dataset, tmp_path, capsys, old: str, new: str) -> str:
    """The error of a run whose targets TRC calls its keypoint `old` `new` instead."""
    targets = read_trc(dataset.targets)
    targets.marker_names[targets.marker_names.index(old)] = new
    path = tmp_path / "renamed.trc"
    write_trc(path, targets)
    arguments = track_arguments(dataset, tmp_path / "out")
    arguments[arguments.index("--targets") + 1] = str(path)
    return run_bad(arguments, capsys)


def test_unknown_keypoint_names_say_which_are_known(dataset, tmp_path, capsys):
    first = read_trc(dataset.targets).marker_names[0]
    error = track_with_target_renamed(dataset, tmp_path, capsys, first, "LeftFoot")
    assert "unknown keypoint name(s) LeftFoot; known keypoints: Hip, LHip" in error
    assert not (tmp_path / "out").exists()


def test_a_keypoint_name_with_a_look_alike_letter_is_explained(dataset, tmp_path, capsys):
    # A Cyrillic e, which prints as the Latin one.
    error = track_with_target_renamed(dataset, tmp_path, capsys, "RAnkle", "RAnkl\u0435")
    assert "character 6 is '\u0435' (CYRILLIC SMALL LETTER IE, U+0435), not 'e' (LATIN SMALL LETTER E" in error


def test_a_frame_count_that_differs_from_the_masks_is_refused(dataset, tmp_path, capsys):
    masks = tmp_path / "masks"
    shutil.copytree(dataset.masks, masks)
    sorted((masks / "cam2").iterdir())[-1].unlink()
    arguments = track_arguments(dataset, tmp_path / "out")
    arguments[arguments.index("--masks") + 1] = str(masks)
    error = run_bad(arguments, capsys)
    assert "29 masks for camera 'cam2' but the targets have 30 frames" in error


def test_a_negative_mask_filter_is_refused(dataset, tmp_path, capsys):
    error = run_bad(track_arguments(dataset, tmp_path / "out", "--mask-filter", "-1"), capsys)
    assert "--mask-filter" in error


def test_a_camera_the_calibration_lacks_is_refused(dataset, tmp_path, capsys):
    error = run_bad(track_arguments(dataset, tmp_path / "out", "--cameras", "cam1,cam9"), capsys)
    assert "cam9" in error and "cam1" in error


def test_an_unreadable_mask_is_refused(dataset, tmp_path, capsys):
    masks = tmp_path / "masks"
    shutil.copytree(dataset.masks, masks)
    sorted((masks / "cam1").iterdir())[0].write_bytes(b"not a png")
    arguments = track_arguments(dataset, tmp_path / "out")
    arguments[arguments.index("--masks") + 1] = str(masks)
    error = run_bad(arguments, capsys)
    assert "000000.png" in error


def test_a_mask_whose_size_is_not_the_calibrations_is_refused(dataset, tmp_path, capsys):
    cameras = read_calibration(dataset.calibration)
    calibration = tmp_path / "calibration.toml"
    write_calibration(calibration, [dataclasses.replace(camera, size=(800, 600)) for camera in cameras])
    arguments = track_arguments(dataset, tmp_path / "out")
    arguments[arguments.index("--calibration") + 1] = str(calibration)
    error = run_bad(arguments, capsys)
    assert "800" in error and "640" in error


def test_an_unreadable_video_is_refused(dataset, tmp_path, capsys):
    videos = tmp_path / "videos"
    videos.mkdir()
    (videos / "cam1.mp4").write_bytes(b"garbage")
    (videos / "cam2.mp4").write_bytes(b"garbage")
    arguments = track_arguments(dataset, tmp_path / "out")
    index = arguments.index("--masks")
    arguments[index : index + 2] = ["--videos", str(videos)]
    error = run_bad(arguments, capsys)
    assert "cam1.mp4" in error


def test_a_failed_run_leaves_a_previous_outdir_untouched(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("previous results")
    run_bad(track_arguments(dataset, out, "--cameras", "cam9"), capsys)
    assert (out / "keep.txt").read_text() == "previous results"


def test_another_urdf_with_the_human_joint_names_is_accepted(dataset, tmp_path):
    from ibik_pin.human import human_urdf_path

    urdf = tmp_path / "my_human.urdf"
    urdf.write_text(human_urdf_path().read_text())
    arguments = track_arguments(dataset, tmp_path / "out", "--no-image", "--iterations", "3",
                                "--model", str(urdf))
    assert main(arguments) == 0


def test_the_console_script_is_installed_and_reports_errors_in_one_line(tmp_path):
    script = Path(sys.executable).with_name("ibik")
    completed = subprocess.run([str(script), "track", "--targets", str(tmp_path / "none.trc"),
                                "--no-image", "--out", str(tmp_path / "out")],
                               capture_output=True, text=True, timeout=120)
    assert completed.returncode == 2
    assert completed.stderr.startswith("ibik: error: ") and completed.stderr.count("\n") == 1


def write_videos(dataset, folder: Path, width: int) -> None:
    """One mp4 per camera: the masks drawn as a person on a textured still background."""
    from ibik_pin.io.masks import list_mask_files, read_mask

    folder.mkdir()
    rng = np.random.default_rng(0)
    background = rng.integers(0, 90, (480, width, 3), dtype=np.uint8)
    for camera in ("cam1", "cam2"):
        writer = cv2.VideoWriter(str(folder / f"{camera}.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 15, (width, 480))
        for path in list_mask_files(dataset.masks / camera):
            frame = background.copy()
            frame[read_mask(path)[:, :width]] = (40, 200, 230)
            writer.write(frame)
        writer.release()


def test_videos_drive_track_and_an_encoder_aligned_width_is_padded_with_a_warning(dataset, tmp_path):
    write_videos(dataset, tmp_path / "videos", width=632)
    arguments = track_arguments(dataset, tmp_path / "out", "--segmenter", "mog2")  # rendered bodies, no person
    index = arguments.index("--masks")
    arguments[index : index + 2] = ["--videos", str(tmp_path / "videos")]
    with pytest.warns(IbikWarning, match="frames are 632 x 480 px, camera 'cam[12]' 640 x 480 px"):
        assert main(arguments) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["frames"] == 30
    assert all(value is not None for value in report["overlap_per_view"]["cam1"][5:])


def test_a_video_far_from_the_calibrated_size_is_refused(dataset, tmp_path, capsys):
    write_videos(dataset, tmp_path / "videos", width=600)
    arguments = track_arguments(dataset, tmp_path / "out")
    index = arguments.index("--masks")
    arguments[index : index + 2] = ["--videos", str(tmp_path / "videos")]
    error = run_bad(arguments, capsys)
    assert "frames are 600 x 480 px but camera 'cam1' is 640 x 480 px" in error
