"""What `ibik track` writes: the motion in the formats other programs read, report.json, and with
--overlay the videos, plot and replay that show it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ibik_pin.app.axes import AxesChoice
from ibik_pin.app.input_reports import SilhouetteQuality, TriangulationReport
from ibik_pin.app.job import TrackJob
from ibik_pin.app.outdir import overlay_file_names
from ibik_pin.app.report import TrackingReport
from ibik_pin.app.silhouette_files import Silhouettes, camera_folder_entries, fit_to_size
from ibik_pin.configuration import Configuration
from ibik_pin.human import with_hip_at_hip_joints_midpoint
from ibik_pin.io.export import write_model_bvh, write_model_mot, write_q_csv
from ibik_pin.io.mot import read_mot
from ibik_pin.io.osim import virtual_marker_positions, virtual_markers, write_osim_model
from ibik_pin.io.trc import METRES_PER_UNIT, TrcData, write_trc
from ibik_pin.io.video import VideoReader
from ibik_pin.model import BodyModel
from ibik_pin.subject.trial_lengths import TrialLengths
from ibik_pin.tracking.result import TrackingResult
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.vision.extrinsics_refit import ExtrinsicsRefit
from ibik_pin.viz.overlay import write_overlay_video
from ibik_pin.viz.plots import Panel, joint_angle_panels, plot_panels
from ibik_pin.viz.replay import write_html_replay

# The keypoints joints.trc always holds (estimated ones included), then any other of the model's.
OUTPUT_KEYPOINTS = ["Hip", "Neck", "Head", "LShoulder", "LElbow", "LWrist", "RShoulder", "RElbow",
                    "RWrist", "LHip", "LKnee", "LAnkle", "RHip", "RKnee", "RAnkle"]


def write_outputs(folder: Path, job: TrackJob, settings: TrackingSettings, name: str, trc: TrcData, body: BodyModel,
                  cameras: list, silhouettes: Silhouettes | None, result: TrackingResult, axes: AxesChoice,
                  outliers: np.ndarray | None = None, *, silhouette_report: SilhouetteQuality | None = None,
                  triangulation_report: TriangulationReport | None = None,
                  extrinsics: ExtrinsicsRefit | None = None,
                  trial_lengths: TrialLengths | None = None) -> TrackingReport:
    """joints.trc (in the TRC's own axis convention), q.csv, motion.mot, motion.bvh, model.osim
    (model frame, Y up), report.json (and the overlays) into `folder`. `settings`: the tracking's,
    as solved; `name`: the targets file's name without its suffix, to name what is written from it;
    `outliers`: (F, T) bool, the target values dropped as outliers, listed in report.json.

    Without a Hip target, the written Hip is HALPE_26's (Pose2Sim's): the midpoint of the hip
    joints, not the model's root above it (human.with_hip_at_hip_joints_midpoint)."""
    if "Hip" not in trc.marker_names and "Hip" in body.keypoints:
        body = with_hip_at_hip_joints_midpoint(body)
        hip = result.keypoint_names.index("Hip")
        hip_frame = body.frame_ids(["Hip"])
        result.keypoints[:, hip] = [Configuration(body.model, q).frame_positions(hip_frame)[0] for q in result.q]
    times = np.asarray(trc.times, dtype=float)
    frame_rate = float(trc.data_rate)
    keypoints = OUTPUT_KEYPOINTS + [n for n in result.keypoint_names if n not in OUTPUT_KEYPOINTS]
    indices = [result.keypoint_names.index(n) for n in keypoints]
    scale = 1.0 / METRES_PER_UNIT[trc.units]
    # The keypoints, then the virtual markers model.osim carries where they leave a body free to turn,
    # so that OpenSim's inverse kinematics on joints.trc finds motion.mot again.
    virtual = virtual_markers(body)
    positions = np.concatenate([result.keypoints[:, indices], virtual_marker_positions(body, virtual, result.q)],
                               axis=1)
    write_trc(folder / "joints.trc", TrcData(
        marker_names=keypoints + [marker.name for marker in virtual], times=times,
        positions=axes.to_trc(positions) * scale,
        units=trc.units, data_rate=frame_rate, frame_numbers=trc.frame_numbers,
    ))
    write_q_csv(folder / "q.csv", body.model, times, result.q)
    write_model_mot(folder / "motion.mot", body.model, times, result.q)
    write_model_bvh(folder / "motion.bvh", body, result.q, 1.0 / frame_rate)
    write_osim_model(folder / "model.osim", body, name=f"ibik_pin_{name}")
    report = TrackingReport.from_tracking(
        result, settings, result.camera_names,
        trc.frame_numbers, times, frame_rate, axes, outliers,
    )
    report.silhouettes, report.triangulation, report.extrinsics = silhouette_report, triangulation_report, extrinsics
    report.trial_lengths = None if trial_lengths is None else trial_lengths.report()
    report.write(folder / "report.json")
    if job.overlay:
        write_overlays(folder, job.videos, name, body, cameras, silhouettes, result, trc, frame_rate)
    return report


def write_overlays(folder: Path, videos: Path | None, name: str, body: BodyModel, cameras: list,
                   silhouettes: Silhouettes | None, result: TrackingResult, trc: TrcData,
                   frame_rate: float) -> None:
    """Per camera an MP4 of the projected skeleton (over its frame of `videos`, the --videos folder,
    if given), a residual plot, the joint angles of motion.mot (angles.png; written before) and an
    HTML 3D replay titled with `name`."""
    times = np.asarray(trc.times, dtype=float)
    residuals = {"mean of the targets": result.target_residuals * 1000.0}
    residuals |= {name: result.target_distances[:, index] * 1000.0 for index, name in enumerate(result.target_names)}
    panels = [Panel(residuals, "residual [mm]", "distance of each target keypoint to its target",
                    highlight="mean of the targets")]
    if result.inside_fraction.shape == result.overlap.shape and result.overlap.shape[1] > 0:
        inside = {camera.name: result.inside_fraction[:, index] for index, camera in enumerate(cameras)}
        panels.append(Panel(inside, "inside the silhouette [0-1]", "fraction of the skeleton inside each view's "
                            "silhouette", ylim=(0.0, 1.02)))
    plot_panels(folder / "residuals.png", times, panels)
    # Read back from motion.mot, so that each curve is the column its panel names.
    motion = read_mot(folder / "motion.mot")
    degrees = motion.values if motion.in_degrees else np.degrees(motion.values)
    angle_panels = joint_angle_panels(dict(zip(motion.column_names, degrees.T, strict=True)))
    if angle_panels:  # none for a --model without the human's joints
        plot_panels(folder / "angles.png", motion.times, angle_panels)
    segment_indices = [(result.keypoint_names.index(a), result.keypoint_names.index(b))
                       for a, b in body.segments]
    write_html_replay(folder / "replay.html", result.keypoint_names, segment_indices,
                      result.keypoints, frame_rate, title=f"ibik_pin: {name}")
    file_names = overlay_file_names([camera.name for camera in cameras])
    starts = result.keypoints[:, [a for a, _ in segment_indices]]
    ends = result.keypoints[:, [b for _, b in segment_indices]]
    for index, camera in enumerate(cameras):
        skeletons = ((camera.project(starts[f]), camera.project(ends[f])) for f in range(len(times)))
        if videos is not None:
            reader = VideoReader(camera_folder_entries(videos, [camera.name], "videos")[camera.name])
            frames = (fit_to_size(frame, tuple(camera.size)) for frame in reader)
        else:
            reader = None
            width, height = camera.size
            frames = (np.zeros((height, width, 3), np.uint8) for _ in range(len(times)))
        masks = (silhouettes.mask(f, index) for f in range(len(times))) if silhouettes else None
        try:
            write_overlay_video(folder / file_names[camera.name], frames, skeletons,
                                frame_rate, masks=masks, frame_numbers=trc.frame_numbers, times=times)
        finally:
            if reader is not None:
                reader.close()
