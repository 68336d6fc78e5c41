"""From the Pose2Sim demo's four videos to motion, as a user runs it: `ibik track --videos` against
the previous release of the same path, and what the detection costs against its accuracy
(../shared/data/pose2sim_demo, 4 x 100 frames of 1080-1088 x 1920).

Variants, run alternated in each repeat (the machine's speed drifts within a day, so only ratios
within one run compare):

- `track_current`: the `ibik` command of this working tree, `ibik track --calibration ... --videos
  ... --out ... --quiet`, in its own process: its wall time from launch to exit is what the user
  waits for (interpreter start, imports, detection, association, triangulation, the subject's
  calibration, the solve and the outputs).
- `track_previous`: the same command of the package at --baseline (a git commit, default the last
  one before this round's video speed work), unpacked with `git archive` into --out (kept for the
  next run) and run through the same kind of `ibik` script.

Before the timed runs each command runs once, untimed, on the repository's 10-frame excerpt
(tests/data/pose2sim_video): numba compiles the package's kernels into its on-disk cache on first
use (about 100 s for a fresh copy of the package), which a user pays once, not per run.
- `people_<height>_2w`: the detection alone of this working tree (vision.people, up to 3 trackers
  per view, frames fed at <height> px, two worker processes), with the subject's landmarks
  triangulated (vision.triangulation).

Accuracy: elbows and knees (joints.trc of a track run, or the triangulated landmarks of a detection
run) against Pose2Sim's own triangulation (ref3d; agreement, not error).

Writes --out/video_speed.json (and copies it to experiments/results/video_speed.json with --keep),
with the machine's load average at the start and the end of the run.

Usage: python experiments/video_speed.py --out out/video_speed [--data ../shared/data] [--repeats 1]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ibik_pin.app.video_people import detect_people_in_videos
from ibik_pin.evaluation import ESTIMATED
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.trc import read_trc
from ibik_pin.readahead.view_workers import usable_cores
from ibik_pin.vision.camera import cameras_in_frame
from ibik_pin.vision.people import DetectionSettings
from ibik_pin.vision.person_views import person_pose
from ibik_pin.vision.triangulation import triangulate_landmarks

REFERENCE = "S00_P00_T01_BalancingTrial_0-100_filt_butterworth.trc"
CALIBRATION = "Calib_qualisys_converted.toml"
RESULTS = Path(__file__).resolve().parent / "results"
REPOSITORY = Path(__file__).resolve().parents[1]
# The last commit before the video path's speed work (restrict within crops, plain worker
# processes, thinner searches): the previous path's baseline.
BASELINE = "84228b7"
TRACK_VARIANTS = ("track_current", "track_previous")
DETECTION_VARIANTS = {"people_960_2w": 960, "people_640_2w": 640}
# The console script pip writes for `ibik`, for the baseline's package (its workers re-run it).
IBIK_SCRIPT = "import sys\nfrom ibik_pin.cli import main\nif __name__ == '__main__':\n    sys.exit(main())\n"


def agreement_mm(keypoints: dict[str, np.ndarray], reference) -> dict[str, float]:
    """Mean distance over frames of each of ESTIMATED to the reference [mm]."""
    return {name: 1000 * float(np.nanmean(np.linalg.norm(
        keypoints[name] - reference.positions[:, reference.marker_names.index(name)], axis=1))) for name in ESTIMATED}


def baseline_package(commit: str, folder: Path) -> Path:
    """The package at `commit` unpacked into `folder`, with an `ibik` script; returns the script.
    A folder unpacked by an earlier run is reused (with its numba cache)."""
    script = folder / "bin" / "ibik"
    if script.is_file():
        return script
    folder.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "-C", str(REPOSITORY), "archive", commit, "ibik_pin"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    script.parent.mkdir()
    script.write_text(IBIK_SCRIPT)
    return script


def warm_up(script: Path, package_root: Path | None, out: Path) -> None:
    """One untimed `ibik track --videos` on the repository's 10-frame excerpt (numba's cache filled)."""
    excerpt = REPOSITORY / "tests" / "data" / "pose2sim_video"
    environment = dict(os.environ)
    if package_root is not None:
        environment["PYTHONPATH"] = str(package_root)
    shutil.rmtree(out, ignore_errors=True)
    subprocess.run([sys.executable, str(script), "track", "--calibration", str(excerpt / "calibration.toml"),
                    "--videos", str(excerpt), "--out", str(out), "--quiet"], check=True, env=environment,
                   cwd=tempfile.gettempdir(), stderr=subprocess.DEVNULL)


def run_track_command(script: Path, package_root: Path | None, demo: Path, out: Path, reference) -> dict:
    """`ibik track --videos` in its own process: wall and processor time, report.json's figures, accuracy."""
    shutil.rmtree(out, ignore_errors=True)
    environment = dict(os.environ)
    if package_root is not None:
        environment["PYTHONPATH"] = str(package_root)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run([sys.executable, str(script), "track", "--calibration", str(demo / CALIBRATION), "--videos",
                    str(demo / "videos"), "--out", str(out), "--quiet"], check=True, env=environment,
                   cwd=tempfile.gettempdir(), stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    report = json.loads((out / "report.json").read_text())
    joints = read_trc(out / "joints.trc")
    frames = joints.positions.shape[0]
    return {"wall_seconds": wall, "frames_per_second": frames / wall,
            "processor_seconds": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "report_end_to_end_seconds": report["end_to_end_seconds"],
            "report_end_to_end_frames_per_second": report["end_to_end_frames_per_second"],
            "stage_seconds": report["stage_seconds"], "detection_seconds": report["detection_seconds"],
            "solve_frames_per_second": report["solve_frames_per_second"],
            "joints_mean_mm": agreement_mm({name: joints.positions[:, joints.marker_names.index(name)]
                                            for name in ESTIMATED}, reference),
            "people_found": report["people"]["found"]}


def run_detection(height: int, demo: Path, cameras: list, reference) -> dict:
    videos = {camera.name: demo / "videos" / f"cam0{index + 1}.mp4" for index, camera in enumerate(cameras)}
    started = time.perf_counter()
    detected = detect_people_in_videos(videos, cameras, 60.0, progress=False, workers=2,
                                       settings=DetectionSettings(detect_height=height))
    wall = time.perf_counter() - started
    poses = person_pose(cameras, detected.views, detected.tracks, 0)
    keypoints, _ = triangulate_landmarks(cameras, np.array([pose.keypoints for pose in poses]),
                                         np.array([pose.visibility for pose in poses]))
    frames = len(poses[0].masks)
    return {"wall_seconds": wall, "frames_per_second": frames / wall, "seconds": detected.seconds,
            "people_found": detected.tracks.count, "triangulated_mean_mm": agreement_mm(keypoints, reference)}


def _summary(rows: list[dict]) -> dict:
    walls = [row["wall_seconds"] for row in rows]
    return {"wall_seconds_median": float(np.median(walls)), "frames_per_second_median": float(100 / np.median(walls)),
            "runs": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--data", type=Path, default=REPOSITORY.parent / "shared" / "data")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--baseline", default=BASELINE, help="git commit of the previous path")
    parser.add_argument("--keep", action="store_true", help="copy the result to experiments/results")
    arguments = parser.parse_args()
    demo = arguments.data / "pose2sim_demo"
    arguments.out.mkdir(parents=True, exist_ok=True)
    cameras = cameras_in_frame(read_calibration(demo / CALIBRATION), POSE2SIM_TRC_TO_WORLD)
    reference = read_trc(demo / "ref3d" / REFERENCE)
    current_script = Path(sys.executable).parent / "ibik"
    previous_root = arguments.out / f"baseline_{arguments.baseline}"
    previous_script = baseline_package(arguments.baseline, previous_root)
    warm_up(current_script, None, arguments.out / "warm_up")
    warm_up(previous_script, previous_root, arguments.out / "warm_up")
    load_at_start = os.getloadavg()
    runs: dict[str, list[dict]] = {name: [] for name in (*TRACK_VARIANTS, *DETECTION_VARIANTS)}
    for repeat in range(arguments.repeats):
        order = list(runs) if repeat % 2 == 0 else list(reversed(runs))  # alternated
        for name in order:
            if name == "track_current":
                row = run_track_command(current_script, None, demo, arguments.out / name, reference)
            elif name == "track_previous":
                row = run_track_command(previous_script, previous_root, demo, arguments.out / name, reference)
            else:
                row = run_detection(DETECTION_VARIANTS[name], demo, cameras, reference)
            runs[name].append(row)
            print(name, json.dumps(row), flush=True)
    commit = subprocess.run(["git", "-C", str(REPOSITORY), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    summary: dict = {
        "conditions": {
            "machine": platform.machine(), "usable_cores": usable_cores(), "load_average_at_start": load_at_start,
            "load_average_at_end": os.getloadavg(), "frames": 100, "views": len(cameras), "repeats": arguments.repeats,
            "current": f"the working tree at HEAD {commit} (uncommitted changes included)",
            "previous": f"the package at {arguments.baseline}",
            "numba": "each command run once untimed before (its kernels compiled into numba's cache)",
            "wall_seconds": "track_*: from launching `ibik track --videos ... --quiet` to its exit (interpreter start, "
                            "imports, every stage, the outputs); people_*: the detection call alone",
            "note": "wall times on a machine shared with other jobs; compare the ratios within this run"},
        "variants": {name: _summary(rows) for name, rows in runs.items()},
    }
    summary["current_over_previous_speed"] = (summary["variants"]["track_previous"]["wall_seconds_median"]
                                              / summary["variants"]["track_current"]["wall_seconds_median"])
    text = json.dumps(summary, indent=1)
    (arguments.out / "video_speed.json").write_text(text)
    if arguments.keep:
        (RESULTS / "video_speed.json").write_text(text)
    print(json.dumps({name: {key: value for key, value in row.items() if key != "runs"}
                      for name, row in summary["variants"].items()}, indent=1))
    print("current over previous speed", summary["current_over_previous_speed"])


if __name__ == "__main__":
    main()
