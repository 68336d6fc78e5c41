"""`ibik batch` on a Pose2Sim project of videos: no TRC, the calibration a Qualisys .qca.txt in the
project's calibration/ folder, the videos of one trial as camera files and camera sub-folders.

The tree is cut from the real Pose2Sim demo (../shared/data/pose2sim_demo): 10 frames of each of
its 4 cameras at a quarter of their size, the calibration scaled to match. MediaPipe detects the
keypoints for real, so the test skips where it or the shared data is absent.
"""

from __future__ import annotations

import csv
import json
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import cv2
import pytest

from ibik_pin.app.batch.discovery import find_trials
from ibik_pin.cli import main
from ibik_pin.vision.learned_pose import MEDIAPIPE_INSTALL, learned_pose_available
from tests.paths import SHARED_DATA

DEMO = SHARED_DATA / "pose2sim_demo"
FRAMES = 10
SCALE = 4

pytestmark = [
    pytest.mark.skipif(not (DEMO / "Calib.qca.txt").is_file(), reason=f"shared data absent: {DEMO}"),
    pytest.mark.filterwarnings("ignore:.*encoder alignment"),
]


def scaled_qualisys(source: Path, destination: Path, scale: int) -> None:
    """The Qualisys calibration of cameras whose images are `scale` times smaller: the image
    window and the intrinsics (sensor units) divided alike."""
    tree = ElementTree.parse(source)
    for camera in tree.getroot().iter("camera"):
        for tag in ("fov_marker", "fov_marker_max", "fov_video", "fov_video_max"):
            window = camera.find(tag)
            for side in ("bottom", "right"):
                window.set(side, str((int(window.get(side)) + 1) // scale - 1))
        intrinsic = camera.find("intrinsic")
        for key in ("centerPointU", "centerPointV", "focalLengthU", "focalLengthV", "sensorMaxU", "sensorMaxV"):
            intrinsic.set(key, repr(float(intrinsic.get(key)) / scale))
    tree.write(destination)


def cut_video(source: Path, destination: Path, frames: int, scale: int) -> None:
    capture = cv2.VideoCapture(str(source))
    writer = None
    try:
        for _ in range(frames):
            found, frame = capture.read()
            assert found, source
            frame = cv2.resize(frame, (frame.shape[1] // scale, frame.shape[0] // scale), interpolation=cv2.INTER_AREA)
            if writer is None:
                destination.parent.mkdir(parents=True, exist_ok=True)
                writer = cv2.VideoWriter(str(destination), cv2.VideoWriter_fourcc(*"mp4v"),
                                         capture.get(cv2.CAP_PROP_FPS), (frame.shape[1], frame.shape[0]))
            writer.write(frame)
    finally:
        capture.release()
        if writer is not None:
            writer.release()


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """ROOT/calibration/Calib.qca.txt and ROOT/S00/T01/videos/: cam01.mp4 and cam02.mp4 as files,
    cam03/ and cam04/ as sub-folders of one video each."""
    root = tmp_path_factory.mktemp("pose2sim_project") / "project"
    (root / "calibration").mkdir(parents=True)
    scaled_qualisys(DEMO / "Calib.qca.txt", root / "calibration" / "Calib.qca.txt", SCALE)
    videos = root / "S00" / "T01" / "videos"
    for index, source in enumerate(sorted((DEMO / "videos").glob("cam*.mp4"))):
        target = videos / source.name if index < 2 else videos / source.stem / f"{source.stem}_take1.mp4"
        cut_video(source, target, FRAMES, SCALE)
    return root


def test_a_project_of_videos_is_a_trial_with_its_calibration_found_by_content(project):
    (trial,) = find_trials(project)

    assert trial.name == Path("S00/T01") and trial.targets is None and trial.problem is None
    assert trial.videos == project / "S00" / "T01" / "videos"
    assert trial.calibration == project / "calibration" / "Calib.qca.txt"


def test_a_project_without_a_calibration_is_that_trials_problem(project, tmp_path):
    bare = tmp_path / "bare"
    cut_video(DEMO / "videos" / "cam01.mp4", bare / "T01" / "videos" / "cam01.mp4", 2, SCALE)

    (trial,) = find_trials(bare)

    assert trial.problem is not None and "no calibration found for the videos" in trial.problem


@pytest.mark.skipif(not learned_pose_available(), reason=f"MediaPipe not installed: {MEDIAPIPE_INSTALL}")
def test_batch_tracks_the_project_from_its_videos_alone(project, tmp_path, capfd):
    pytest.importorskip("distributed")
    outroot = tmp_path / "outroot"

    code = main(["batch", str(project), "--out", str(outroot), "--workers", "1", "--quiet", "--iterations", "3"])

    assert code == 0, capfd.readouterr().err
    with open(outroot / "summary.csv", newline="") as stream:
        (row,) = list(csv.DictReader(stream))
    assert (row["trial"], row["status"], row["frames"], row["error"]) == ("S00/T01", "ok", str(FRAMES), "")
    report = json.loads((outroot / "S00" / "T01" / "report.json").read_text())
    assert report["frames"] == FRAMES and sorted(report["overlap_per_view"]) == ["cam01", "cam02", "cam03", "cam04"]
    assert report["triangulation"] is not None  # the targets came from the videos
    # The triangulated keypoints are met: the mean residual of the tracked targets is below 3 cm.
    assert float(row["mean_residual_mm"]) < 30.0
    assert (outroot / "S00" / "T01" / "triangulated.trc").is_file()
