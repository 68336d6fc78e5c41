"""`ibik track` on a real four-camera video: the Pose2Sim single-person demo (../shared/data).

Two kinds of run, each with the image (IBIK) and without (PIK), all 100 frames:

- **Pose2Sim's targets:** Pose2Sim's own triangulation of the demo (ref3d TRC) with the elbows and
  knees removed, the full triangulation as the static trial; silhouettes by background subtraction
  (`mog2`, the earlier default) or MediaPipe's learned segmentation (`mediapipe`).
- **From the videos alone:** no --targets; MediaPipe's keypoints are triangulated, the elbows and
  knees left to the image (or, `--triangulated-limbs`, targets below it).

The estimated elbows and knees are compared with Pose2Sim's triangulated ones; those are a
markerless estimate, not ground truth: the figures are agreement, not error. Also measured: the
triangulated end effectors against Pose2Sim's, and the share of Pose2Sim's keypoints (projected)
inside each camera's learned silhouette, the silhouettes cut to the subject by the triangulated
keypoints (never by the reference), with the cameras as calibrated and with cam_03 turned to meet
the other views (--refit-cameras cam_03, vision.extrinsics_refit); each camera's disagreement with
the others; and the tracking with cam_03 turned.

Writes into --out: one `ibik track` output folder per variant (overlays for two), agreement.json,
agreement.md, and overlay_frame.png (a frame of cam_01's overlay, from the videos alone).

Usage: python experiments/pose2sim_video.py --out out/pose2sim [--data ../shared/data]
"""

from __future__ import annotations

import os

# One OpenBLAS thread for the solvers' tiny factorisations, set before numpy is imported: see
# ibik_pin/cli.py (the library itself leaves the environment alone). A user's setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import time
import warnings
from pathlib import Path

import cv2
import numpy as np

from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import run_track
from ibik_pin.app.video_inputs import (
    points_inside,
    read_videos,
    refitted_cameras,
    restrict_to_subject,
    triangulated_trc,
)
from ibik_pin.evaluation import ESTIMATED
from ibik_pin.exceptions import IbikWarning
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.trc import TrcData, read_trc, write_trc
from ibik_pin.io.video import read_frames
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.vision.camera import cameras_in_frame
from ibik_pin.vision.mask_store import CroppedMasks

REFERENCE = "S00_P00_T01_BalancingTrial_0-100_filt_butterworth.trc"
# The camera whose calibration the other three views and Pose2Sim's own triangulation contradict
# (docs/method.md, "From video"): the variants marked refit turn it (--refit-cameras).
REFIT = ["cam_03"]
# name -> (Pose2Sim's targets, the image, segmenter, --triangulated-limbs, overlay, refit)
VARIANTS = {
    "pik": (True, False, "mog2", False, False, False),
    "ibik_mog2": (True, True, "mog2", False, False, False),
    "ibik_mediapipe": (True, True, "mediapipe", False, False, False),
    "ibik_mediapipe_refit": (True, True, "mediapipe", False, True, True),
    "pik_from_video": (False, False, "mediapipe", False, False, False),
    "pik_from_video_refit": (False, False, "mediapipe", False, False, True),
    "ibik_from_video": (False, True, "mediapipe", False, True, False),
    "ibik_from_video_refit": (False, True, "mediapipe", False, True, True),
    "ibik_from_video_limb_targets": (False, True, "mediapipe", True, False, False),
}
# The silhouette check: these keypoints of Pose2Sim's, projected, should fall inside.
SILHOUETTE_KEYPOINTS = ["RAnkle", "LAnkle", "RKnee", "LKnee", "RHip", "LHip", "RWrist", "LWrist", "RElbow",
                        "LElbow", "RShoulder", "LShoulder", "Head"]
END_EFFECTORS = ["LWrist", "RWrist", "LAnkle", "RAnkle", "LHip", "RHip", "Head"]


def median_distance_mm(estimate: TrcData, reference: TrcData, names: list[str]) -> dict[str, float]:
    """Per keypoint, the median over frames of the distance between the two TRCs [mm]."""
    return {name: 1000 * float(np.nanmedian(np.linalg.norm(
        estimate.positions[:, estimate.marker_names.index(name)]
        - reference.positions[:, reference.marker_names.index(name)], axis=1))) for name in names}


def keypoints_inside(camera, masks, points: np.ndarray) -> dict[str, float]:
    """Share of the keypoints (F, K, 3), projected, inside the camera's masks: all and per keypoint."""
    hits = np.array([points_inside(camera, mask, frame_points)
                     for mask, frame_points in zip(masks, points, strict=True)])
    shares = {name: float(hits[:, i].mean()) for i, name in enumerate(SILHOUETTE_KEYPOINTS)}
    return {"all": float(hits.mean()), **shares}


def silhouettes_and_triangulation(demo: Path, out: Path, reference: TrcData) -> dict:
    """The learned silhouettes' hold on Pose2Sim's keypoints, and the triangulated end effectors,
    with the cameras as calibrated and with REFIT turned (--refit-cameras)."""
    cameras = cameras_in_frame(read_calibration(demo / "Calib_qualisys_converted.toml"), POSE2SIM_TRC_TO_WORLD)
    folder = out / "silhouettes"
    folder.mkdir(parents=True, exist_ok=True)
    job = TrackJob(targets=None, videos=demo / "videos", calibration=demo / "Calib_qualisys_converted.toml",
                   out=out / "unused", quiet=True)
    sources = read_videos(folder, job, cameras)
    triangulated = {"as_calibrated": read_trc(folder / "triangulated.trc")}
    refit_cameras, refit = refitted_cameras(cameras, sources.poses, REFIT)
    triangulated["refit"] = triangulated_trc(refit_cameras, sources.poses, reference.data_rate)[0]
    points = np.stack([reference.positions[:, reference.marker_names.index(n)] for n in SILHOUETTE_KEYPOINTS], axis=1)
    inside: dict[str, dict] = {}
    for label, camera_set in (("as_calibrated", cameras), ("refit", refit_cameras)):
        masks = [CroppedMasks(pose.masks.size, pose.masks) for pose in sources.poses]
        restrict_to_subject(masks, camera_set, triangulated[label].positions)
        inside[label] = {camera.name: keypoints_inside(camera, camera_masks, points)
                         for camera, camera_masks in zip(camera_set, masks, strict=True)}
    limbs = {name: 1000 * float(np.nanmean(np.linalg.norm(
        triangulated["as_calibrated"].positions[:, triangulated["as_calibrated"].marker_names.index(name)]
        - reference.positions[:, reference.marker_names.index(name)], axis=1))) for name in ESTIMATED}
    return {"inside_share": inside,
            "triangulation_mm": {label: median_distance_mm(trc, reference, END_EFFECTORS)
                                 for label, trc in triangulated.items()},
            "triangulated_limbs_mean_mm": limbs,
            "triangulation": sources.triangulation.__dict__ if sources.triangulation else None,
            "extrinsics": refit.__dict__}


def overlay_frame(video: Path, destination: Path, frame: int = 50) -> None:
    """One frame of an overlay video, at half size, as PNG."""
    image = next(image for index, image in enumerate(read_frames(video)) if index == frame)
    cv2.imwrite(str(destination), cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2),
                                             interpolation=cv2.INTER_AREA))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parent.parent.parent / "shared" / "data")
    arguments = parser.parse_args()
    warnings.simplefilter("ignore", IbikWarning)  # the demo's 1080 px videos calibrated at 1088: known
    demo = arguments.data / "pose2sim_demo"
    reference = read_trc(demo / "ref3d" / REFERENCE)
    kept = [i for i, name in enumerate(reference.marker_names) if name not in ESTIMATED]
    targets = TrcData(marker_names=[reference.marker_names[i] for i in kept], times=reference.times,
                      positions=reference.positions[:, kept], units=reference.units,
                      data_rate=reference.data_rate, frame_numbers=reference.frame_numbers)
    (arguments.out / "input").mkdir(parents=True, exist_ok=True)
    write_trc(arguments.out / "input" / "targets.trc", targets)
    started = time.perf_counter()
    summary = silhouettes_and_triangulation(demo, arguments.out, reference)
    summary["silhouettes_seconds"] = time.perf_counter() - started
    print(json.dumps(summary["inside_share"]), json.dumps(summary["triangulation_mm"]), flush=True)
    rows = {}
    for variant, (given, use_image, segmenter, limb_targets, overlay, refit) in VARIANTS.items():
        started = time.perf_counter()
        report = run_track(TrackJob(
            targets=arguments.out / "input" / "targets.trc" if given else None,
            static=demo / "ref3d" / REFERENCE if given else None,
            calibration=demo / "Calib_qualisys_converted.toml", videos=demo / "videos", out=arguments.out / variant,
            overlay=overlay, quiet=True, segmenter=segmenter, triangulated_limbs=limb_targets,
            refit_cameras=REFIT if refit else None, settings=TrackingSettings(use_image=use_image),
        ))
        estimate = read_trc(arguments.out / variant / "joints.trc")
        agreement = median_distance_mm(estimate, reference, list(ESTIMATED))
        mean_agreement = {name: 1000 * float(np.nanmean(np.linalg.norm(
            estimate.positions[:, estimate.marker_names.index(name)]
            - reference.positions[:, reference.marker_names.index(name)], axis=1))) for name in ESTIMATED}
        rows[variant] = {"mean_agreement_mm": mean_agreement, "median_agreement_mm": agreement,
                         "mean_mm": float(np.mean(list(mean_agreement.values()))),
                         "solve_frames_per_second": report["solve_frames_per_second"],
                         "end_effector_residual_mm": 1000 * report["end_effector_residual_m"]["mean"],
                         "targets_inside": (report["silhouettes"] or {}).get("targets_inside_mean"),
                         "wall_seconds": time.perf_counter() - started}
        print(variant, json.dumps(rows[variant]), flush=True)
    summary["variants"] = rows
    overlay_frame(arguments.out / "ibik_from_video" / "overlay_cam_01.mp4", arguments.out / "overlay_frame.png")
    lines = ["| variant | targets | silhouettes | " + " | ".join(ESTIMATED) + " | mean | solve fps |",
             "| --- | --- | --- |" + " ---: |" * 6]
    for name, row in rows.items():
        given, use_image, segmenter, limb_targets, _, refit = VARIANTS[name]
        source = "Pose2Sim's" if given else "triangulated" + (", limbs below the image" if limb_targets else "")
        source += f", {' '.join(REFIT)} turned" if refit else ""
        lines.append(f"| {name} | {source} | {segmenter if use_image else 'none'} | "
                     + " | ".join(f"{row['mean_agreement_mm'][j]:.1f}" for j in ESTIMATED)
                     + f" | {row['mean_mm']:.1f} | {row['solve_frames_per_second']:.1f} |")
    limbs = summary["triangulated_limbs_mean_mm"]
    lines.append("| triangulation alone (no model) | triangulated | none | "
                 + " | ".join(f"{limbs[j]:.1f}" for j in ESTIMATED) + f" | {np.mean(list(limbs.values())):.1f} | |")
    lines += ["", "| camera | cameras | " + " | ".join(SILHOUETTE_KEYPOINTS) + " | all |",
              "| --- | --- |" + " ---: |" * 14]
    for label, per_camera in summary["inside_share"].items():
        for camera, shares in per_camera.items():
            lines.append(f"| {camera} | {label.replace('_', ' ')} | "
                         + " | ".join(f"{100 * shares[n]:.0f}" for n in SILHOUETTE_KEYPOINTS)
                         + f" | {100 * shares['all']:.1f} |")
    refit = summary["extrinsics"]
    lines += ["", "| each camera's detections to the others' triangulation, median [px] | "
              + " | ".join(refit["reprojection_px"]) + " |", "| --- |" + " ---: |" * len(refit["reprojection_px"]),
              "| as calibrated | " + " | ".join(f"{v:.1f}" for v in refit["reprojection_px"].values()) + " |",
              f"| {' '.join(REFIT)} turned by {', '.join(f'{v:.2f}' for v in refit['turn_deg'].values())} deg | "
              + " | ".join(f"{v:.1f}" for v in refit["reprojection_after_px"].values()) + " |"]
    lines += ["", "| triangulated, median distance to Pose2Sim's [mm] | " + " | ".join(END_EFFECTORS) + " |",
              "| --- |" + " ---: |" * 7]
    for label, distances in summary["triangulation_mm"].items():
        lines.append(f"| {label.replace('_', ' ')} | " + " | ".join(f"{distances[n]:.1f}" for n in END_EFFECTORS)
                     + " |")
    (arguments.out / "agreement.md").write_text("\n".join(lines) + "\n")
    (arguments.out / "agreement.json").write_text(json.dumps(summary, indent=2))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
