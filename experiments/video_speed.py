"""From the Pose2Sim demo's four videos to motion: where the time goes, and what the detection
costs against its accuracy (../shared/data/pose2sim_demo, 4 x 100 frames of 1080-1088 x 1920).

Detection variants, run alternated in one process (the machine's speed drifts within a day, so
only ratios within one run compare):

- `single_sequential`: today's path before several people: MediaPipe Pose, one person per view,
  full-size frames, the views one after the other in this process (vision.learned_pose).
- `people_<height>_<workers>w`: every person (vision.people, up to 3 trackers per view), frames fed
  at <height> px (0 = full size), the views in <workers> spawned processes that decode their own
  video (app.video_people).

Each variant's accuracy: the subject's landmarks triangulated (vision.triangulation), elbows and
knees against Pose2Sim's own triangulation (ref3d; agreement, not error). Then one `ibik track
--videos` run with the default settings: its report.json's stage_seconds and end-to-end frame
rate, and its joints' elbows and knees against ref3d (experiments/results/pose2sim_agreement.json
holds the earlier figures of the same run).

Writes --out/video_speed.json (and copies it to experiments/results/video_speed.json with --keep).

Usage: python experiments/video_speed.py --out out/video_speed [--data ../shared/data] [--repeats 2]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import platform
import shutil
import time
from pathlib import Path

import numpy as np

from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import run_track
from ibik_pin.app.video_people import detect_people_in_videos, usable_cores
from ibik_pin.evaluation import ESTIMATED
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.trc import read_trc
from ibik_pin.io.video import read_frames
from ibik_pin.vision.camera import cameras_in_frame
from ibik_pin.vision.learned_pose import detect_pose_in_frames
from ibik_pin.vision.people import DetectionSettings
from ibik_pin.vision.person_views import person_pose
from ibik_pin.vision.triangulation import triangulate_landmarks

REFERENCE = "S00_P00_T01_BalancingTrial_0-100_filt_butterworth.trc"
RESULTS = Path(__file__).resolve().parent / "results"
# name -> (detect_height, workers); None: the single-person sequential path
VARIANTS = {
    "single_sequential": None,
    "people_0_2w": (0, 2),
    "people_960_2w": (960, 2),
    "people_960_1w": (960, 1),
    "people_640_2w": (640, 2),
}


def agreement_mm(keypoints: dict[str, np.ndarray], reference) -> dict[str, float]:
    """Mean distance over frames of each of ESTIMATED to the reference [mm]."""
    return {name: 1000 * float(np.nanmean(np.linalg.norm(
        keypoints[name] - reference.positions[:, reference.marker_names.index(name)], axis=1))) for name in ESTIMATED}


def run_variant(name: str, demo: Path, cameras: list, reference) -> dict:
    videos = {camera.name: demo / "videos" / f"cam0{index + 1}.mp4" for index, camera in enumerate(cameras)}
    started = time.perf_counter()
    setting = VARIANTS[name]
    if setting is None:
        poses = [detect_pose_in_frames(read_frames(videos[camera.name])) for camera in cameras]
        extra: dict = {}
    else:
        height, workers = setting
        detected = detect_people_in_videos(videos, cameras, 60.0, progress=False, workers=workers,
                                           settings=DetectionSettings(detect_height=height))
        poses = person_pose(cameras, detected.views, detected.tracks, 0)
        extra = {"seconds": detected.seconds, "people_found": detected.tracks.count,
                 "subject_frames": detected.tracks.frames[0]}
    wall = time.perf_counter() - started
    keypoints, _ = triangulate_landmarks(cameras, np.array([pose.keypoints for pose in poses]),
                                         np.array([pose.visibility for pose in poses]))
    frames = len(poses[0].masks)
    return {"wall_seconds": wall, "frames_per_second": frames / wall,
            "ms_per_view_frame_wall": 1000 * wall / (frames * len(cameras)),
            "triangulated_mean_mm": agreement_mm(keypoints, reference), **extra}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--keep", action="store_true", help="copy the result to experiments/results")
    arguments = parser.parse_args()
    demo = arguments.data / "pose2sim_demo"
    arguments.out.mkdir(parents=True, exist_ok=True)
    cameras = cameras_in_frame(read_calibration(demo / "Calib_qualisys_converted.toml"), POSE2SIM_TRC_TO_WORLD)
    reference = read_trc(demo / "ref3d" / REFERENCE)
    runs: dict[str, list[dict]] = {name: [] for name in VARIANTS}
    for repeat in range(arguments.repeats):
        order = list(VARIANTS) if repeat % 2 == 0 else list(reversed(VARIANTS))  # alternated
        for name in order:
            runs[name].append(run_variant(name, demo, cameras, reference))
            print(name, json.dumps(runs[name][-1]), flush=True)
    baseline = np.median([run["wall_seconds"] for run in runs["single_sequential"]])
    summary: dict = {
        "conditions": {"machine": platform.machine(), "usable_cores": usable_cores(),
                       "load_average_at_start": os.getloadavg(), "frames": 100, "views": len(cameras),
                       "repeats": arguments.repeats, "note": "wall times on a machine shared with other jobs; "
                       "compare the ratios within this run"},
        "variants": {name: {"wall_seconds_median": float(np.median([r["wall_seconds"] for r in rows])),
                            "speed_vs_single_sequential": float(baseline / np.median([r["wall_seconds"]
                                                                                      for r in rows])),
                            "runs": rows} for name, rows in runs.items()},
    }
    out = arguments.out / "track"
    shutil.rmtree(out, ignore_errors=True)
    started = time.perf_counter()
    report = run_track(TrackJob(targets=None, calibration=demo / "Calib_qualisys_converted.toml",
                                videos=demo / "videos", out=out, quiet=True))
    joints = read_trc(out / "joints.trc")
    summary["track"] = {"wall_seconds": time.perf_counter() - started,
                        "end_to_end_frames_per_second": report["end_to_end_frames_per_second"],
                        "stage_seconds": report["stage_seconds"], "detection_seconds": report["detection_seconds"],
                        "solve_frames_per_second": report["solve_frames_per_second"],
                        "end_effector_residual_mm": 1000 * report["end_effector_residual_m"]["mean"],
                        "joints_mean_mm": agreement_mm({name: joints.positions[:, joints.marker_names.index(name)]
                                                        for name in ESTIMATED}, reference),
                        "people": report["people"]}
    earlier = json.loads((RESULTS / "pose2sim_agreement.json").read_text())["variants"]["ibik_from_video"]
    summary["track"]["earlier_joints_mean_mm"] = earlier["mean_agreement_mm"]
    text = json.dumps(summary, indent=1)
    (arguments.out / "video_speed.json").write_text(text)
    if arguments.keep:
        (RESULTS / "video_speed.json").write_text(text)
    print(json.dumps({name: {k: v for k, v in row.items() if k != "runs"} for name, row in summary["variants"].items()},
                     indent=1))
    print(json.dumps(summary["track"], indent=1))


if __name__ == "__main__":
    main()
