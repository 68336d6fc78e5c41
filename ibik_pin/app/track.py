"""`ibik track` as a function: read the user's files, check them, track, write every output.

Inputs are checked before any solving (names, frame counts, camera names, image sizes), and the
outputs are written into a temporary folder beside OUTDIR that replaces it only at the very end, so
a failure never leaves an OUTDIR that looks complete and never destroys a previous one half-way.
"""

from __future__ import annotations

import os
import shutil
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import FileFormatError, IbikWarning, InputError
from ibik_pin.human import load_human, with_hip_at_hip_joints_midpoint
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.export import write_model_bvh, write_model_mot, write_q_csv
from ibik_pin.io.osim import write_osim_model
from ibik_pin.io.trc import METRES_PER_UNIT, TrcData, read_trc, write_trc
from ibik_pin.io.video import VideoReader
from ibik_pin.model import BodyModel
from ibik_pin.subject.scaling import (
    FOOT_KEYPOINTS,
    scale_from_stature,
    scale_human,
    segment_lengths_from_keypoints,
)
from ibik_pin.tracking.axes import TRC_AXES, TRC_TO_MODEL, AxesChoice, choose_axes, sample_frames
from ibik_pin.tracking.input_checks import (
    check_cameras_see_targets,
    check_trc,
    drop_outlier_targets,
    silhouettes_all_empty,
)
from ibik_pin.tracking.outdir import check_outdir, make_staging, publish
from ibik_pin.tracking.report import TrackingReport
from ibik_pin.tracking.result import TrackingResult
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.silhouette_files import Silhouettes, camera_folder_entries, fit_to_size, load_silhouettes
from ibik_pin.tracking.tracker import Tracker
from ibik_pin.tracking.video_inputs import (
    SEGMENTERS,
    SilhouetteQuality,
    SilhouetteQualityReader,
    TriangulationReport,
    read_videos,
    restrict_to_subject,
)
from ibik_pin.vision.camera import cameras_in_frame, select_cameras
from ibik_pin.vision.extrinsics_refit import ExtrinsicsRefit
from ibik_pin.viz.overlay import write_overlay_video
from ibik_pin.viz.plots import Panel, plot_panels
from ibik_pin.viz.replay import write_html_replay

# The keypoints joints.trc always holds (estimated ones included), then any other of the model's.
OUTPUT_KEYPOINTS = ["Hip", "Neck", "Head", "LShoulder", "LElbow", "LWrist", "RShoulder", "RElbow",
                    "RWrist", "LHip", "LKnee", "LAnkle", "RHip", "RKnee", "RAnkle"]
# Bounds that keep a run finite: at 1000 steps a frame already takes seconds, and a majority vote
# over more than 61 frames (a second at 60 Hz) is no longer a filter of flicker.
MAX_ITERATIONS = 1000
MAX_MASK_FILTER_RADIUS = 30


def check_run_bounds(settings: TrackingSettings) -> None:
    """Refuse step counts and a mask filter outside the bounds above (InputError naming the option)."""
    for option, value, low, high in (("--iterations", settings.iterations, 1, MAX_ITERATIONS),
                                     ("--mask-filter", settings.mask_filter_radius, 0, MAX_MASK_FILTER_RADIUS)):
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise InputError(f"{option}: expected a whole number from {low} to {high}, found {value!r}")
    tolerance = settings.step_tolerance
    if tolerance is not None and not (isinstance(tolerance, (int, float)) and np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"--step-tolerance: expected a positive number of radians, found {tolerance!r}")


@dataclass
class TrackJob:
    """Everything `ibik track` was asked to do (paths as given on the command line).

    `trc_axes` is the TRC files' axis convention: "auto" (detected against the calibration's
    cameras; y-up without a calibration), "y-up" (Pose2Sim, OpenSim) or "z-up" (the calibration's
    own world); see tracking.axes.
    """

    targets: Path | None
    out: Path
    static: Path | None = None
    calibration: Path | None = None
    masks: Path | None = None
    videos: Path | None = None
    background: Path | None = None
    cameras: list[str] | None = None
    model: Path | None = None
    settings: TrackingSettings = field(default_factory=TrackingSettings)
    overlay: bool = False
    quiet: bool = False
    trc_axes: str = "auto"
    segmenter: str = "auto"
    triangulated_limbs: bool = False
    refit_cameras: list[str] | None = None

    def __post_init__(self) -> None:
        """Paths given as str become Paths; what the CLI refuses, the API refuses too (InputError)."""
        for name in ("targets", "out", "static", "calibration", "masks", "videos", "background", "model"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, Path):
                if isinstance(value, str) and not value.strip():
                    raise InputError(f"--{name} {value!r}: expected a path, found an empty name")
                if not isinstance(value, (str, os.PathLike)):
                    raise InputError(f"TrackJob.{name}: expected a path (str or Path), found {type(value).__name__}")
                setattr(self, name, Path(value))
        if self.masks is not None and self.videos is not None:
            raise InputError("--masks and --videos: give one source of silhouettes, not both")
        if self.background is not None and self.videos is None:
            raise InputError("--background goes with --videos")
        if self.targets is None and (self.videos is None or self.calibration is None):
            raise InputError("--targets: needed unless --videos and --calibration are given (then the end "
                             "effectors are triangulated from the videos)")
        if self.triangulated_limbs and self.targets is not None:
            raise InputError("--triangulated-limbs goes with --videos without --targets")
        if self.triangulated_limbs and self.settings.stack is not None:
            raise InputError("--triangulated-limbs and --stack: give the elbows and knees a level in your "
                             "stack instead")
        if self.segmenter not in SEGMENTERS:
            raise InputError(f"--segmenter: expected one of {', '.join(SEGMENTERS)}, found {self.segmenter!r}")
        if self.trc_axes not in ("auto", *TRC_AXES):
            raise InputError(f"--trc-axes: expected auto, {', '.join(TRC_AXES)}, found {self.trc_axes!r}")
        check_run_bounds(self.settings)

    @property
    def inputs(self) -> list[Path | None]:
        """Every input path of the job (None for those not given)."""
        return [self.targets, self.static, self.calibration, self.masks, self.videos, self.background, self.model]


def trc_stem(job: TrackJob) -> str:
    """The targets file's name without its suffix, to name what is written from it."""
    return job.targets.stem if job.targets is not None else "targets"


def _trc_in_metres(option: str, path: Path) -> tuple[TrcData, np.ndarray, np.ndarray]:
    """A TRC read and checked for plausibility (tracking.input_checks): the data, its positions in
    metres and (F, T) bool, the values dropped as outliers (only for --targets: a static trial is a
    few still frames, with no leap to drop)."""
    data = read_trc(path)
    if data.units not in METRES_PER_UNIT:
        raise FileFormatError(f"{path}: units {data.units!r} are not one of m, cm, mm")
    positions_m = data.positions * METRES_PER_UNIT[data.units]
    check_trc(option, path, data, positions_m)  # first: in the wrong unit, every target is an outlier
    outliers = np.zeros(positions_m.shape[:2], dtype=bool)
    if option == "--targets":
        positions_m, outliers = drop_outlier_targets(option, data.marker_names, positions_m)
    return data, positions_m, outliers


def _check_names(path: Path | None, names: Sequence[str], body: BodyModel) -> None:
    unknown = [name for name in names if name not in body.keypoints]
    if unknown:
        raise InputError(
            f"{path}: unknown keypoint name(s) {', '.join(unknown)}; known keypoints: "
            + ", ".join(body.keypoints)
        )


def prepare_body(job: TrackJob, names: list[str], targets_m: np.ndarray,
                 calibrate_on_targets: bool = False) -> BodyModel:
    """The human (or --model) fitted to the subject.

    With --static: calibrated on the static trial (segment scales and keypoint placements,
    subject.calibration). Without, a --model that is already a calibrated subject (a URDF with
    keypoint links, as `ibik calibrate` writes) is used as it is: scaling it again would move its
    joints away from the keypoint placements fitted with them. With `calibrate_on_targets` (targets
    triangulated from the videos), calibrated on the targets themselves, elbows and knees included:
    the detector places the head's and feet's keypoints otherwise than the model does (on the
    Pose2Sim demo the tracked Nose stayed 61 mm off its target, 10 mm once calibrated). Otherwise the
    segments are scaled from the targets' own distances, or the stature.
    """
    from ibik_pin.subject.calibration import calibrate_subject, check_subject_size

    body = load_human(job.model) if job.model is not None else load_human()
    _check_names(job.targets, names, body)
    if job.static is not None:
        static, static_m, _ = _trc_in_metres("--static", job.static)
        _check_names(job.static, static.marker_names, body)
        return calibrate_subject(body, static.marker_names, static_m, source=f"--static {job.static}").body
    if body.calibrated:
        return body
    if calibrate_on_targets:
        return calibrate_subject(body, names, targets_m, source=f"the keypoints triangulated from --videos "
                                 f"{job.videos}").body
    lengths = segment_lengths_from_keypoints(names, targets_m)
    if lengths:
        check_subject_size(body, lengths, f"--targets {job.targets}")
        return scale_human(body, lengths)
    stature = _stature(names, targets_m)
    return scale_from_stature(body, stature) if np.isfinite(stature) else body


def _stature(names: list[str], targets_m: np.ndarray) -> float:
    """Head height above the lowest foot point, median over frames [m] (NaN if not measurable)."""
    if "Head" not in names:
        return float("nan")
    head = targets_m[:, names.index("Head"), 1]
    feet = [names.index(n) for n in names if n in FOOT_KEYPOINTS]
    if not feet:
        return float("nan")
    lowest = np.nanmin(targets_m[:, feet, 1], axis=1)
    return float(np.nanmedian(head - lowest))


def run_track(job: TrackJob) -> TrackingReport:
    """Run the whole job; returns the report that was written to OUTDIR/report.json.

    OUTDIR is checked first (tracking.outdir), and the outputs go to a staging folder made before
    any work, so that an OUTDIR that cannot be written is found at once."""
    out = check_outdir(job.out, job.inputs)
    staging = make_staging(out)
    try:
        report = _run_into(staging, job)
        publish(staging, out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return report


def _run_into(staging: Path, job: TrackJob) -> TrackingReport:
    """Read, check, track and write every output into `staging`."""
    cameras: list = []
    if job.calibration is not None:
        cameras = cameras_in_frame(read_calibration(job.calibration), POSE2SIM_TRC_TO_WORLD)
        if job.cameras:
            cameras = select_cameras(cameras, job.cameras)
    # Without --targets the videos' keypoints are triangulated into staging and read back as targets.
    videos = read_videos(staging, job, cameras)
    job, cameras = videos.job, videos.cameras
    if job.targets is None:  # TrackJob refuses this unless the videos give the targets
        raise InputError("--targets: expected a TRC, or --videos and --calibration to triangulate one")
    trc, targets_trc_m, outliers = _trc_in_metres("--targets", job.targets)
    names = list(trc.marker_names)
    frame_count = targets_trc_m.shape[0]
    if frame_count == 0:
        raise InputError(f"--targets {job.targets}: no frame")
    silhouettes = None
    use_image = job.settings.use_image
    if use_image:
        if not cameras:
            raise InputError("the image criterion needs --calibration with --masks or --videos "
                             "(or pass --no-image for the blind baseline)")
        if job.masks is None and job.videos is None:
            raise InputError("the image criterion needs --masks or --videos (or pass --no-image)")
        conventions = TRC_AXES if job.trc_axes == "auto" else (job.trc_axes,)
        check_cameras_see_targets(cameras, targets_trc_m, sample_frames(targets_trc_m),
                                  [TRC_TO_MODEL[axes] for axes in conventions])
        silhouettes = load_silhouettes(job, cameras, frame_count, not job.quiet, videos.poses)
        if silhouettes_all_empty(silhouettes.frame, frame_count):
            warnings.warn(f"--{'masks' if job.masks is not None else 'videos'}: every silhouette is empty; "
                          "tracking without the image (as --no-image)", IbikWarning, stacklevel=2)
            use_image = False
            job = replace(job, settings=replace(job.settings, use_image=False))
    elif job.overlay and cameras and (job.masks is not None or job.videos is not None):
        silhouettes = load_silhouettes(job, cameras, frame_count, not job.quiet, videos.poses)
    # The cameras project model-frame points whatever the TRC's convention: only the targets turn.
    axes = choose_axes(job.trc_axes, names, targets_trc_m, cameras,
                       silhouettes.frame if silhouettes is not None else None)
    if not job.quiet:
        print(f"ibik: TRC axes: {axes.describe()}", file=sys.stderr)
    targets_m = axes.to_model(targets_trc_m)
    # Every keypoint scales the segments, tracked or not.
    body = prepare_body(job, names, targets_m, calibrate_on_targets=videos.triangulation is not None)
    reader = None  # the silhouettes, each frame's read once for the tracker and the report
    if silhouettes is not None:
        if silhouettes.video_masks is not None:
            restrict_to_subject(silhouettes.video_masks, cameras, targets_m)
        reader = SilhouetteQualityReader(silhouettes.frame, cameras, targets_m)
    tracked = [index for index, name in enumerate(names) if name not in videos.left_to_image]

    tracker = Tracker(body, cameras if use_image else [], job.settings)
    job = replace(job, settings=tracker.settings)  # as solved: a stack's image task may set the criterion
    with tqdm(total=frame_count, desc="tracking", unit="frame", disable=True if job.quiet else None) as bar:
        result = tracker.track([names[index] for index in tracked], targets_m[:, tracked],
                               reader if use_image else None, progress=bar.update)
    silhouette_report = reader.quality(videos.segmenter) if reader is not None else None

    return write_outputs(staging, job, trc, body, cameras, silhouettes, result, axes, outliers[:, tracked],
                         silhouette_report=silhouette_report, triangulation_report=videos.triangulation,
                         extrinsics=videos.extrinsics)


def write_outputs(folder: Path, job: TrackJob, trc: TrcData, body: BodyModel, cameras: list,
                  silhouettes: Silhouettes | None, result: TrackingResult, axes: AxesChoice,
                  outliers: np.ndarray | None = None, *, silhouette_report: SilhouetteQuality | None = None,
                  triangulation_report: TriangulationReport | None = None,
                  extrinsics: ExtrinsicsRefit | None = None) -> TrackingReport:
    """joints.trc (in the TRC's own axis convention), q.csv, motion.mot, motion.bvh, model.osim
    (model frame, Y up), report.json (and the overlays) into `folder`. `outliers`: (F, T) bool,
    the target values dropped as outliers, listed in report.json.

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
    write_trc(folder / "joints.trc", TrcData(
        marker_names=keypoints, times=times, positions=axes.to_trc(result.keypoints[:, indices]) * scale,
        units=trc.units, data_rate=frame_rate, frame_numbers=trc.frame_numbers,
    ))
    write_q_csv(folder / "q.csv", body.model, times, result.q)
    write_model_mot(folder / "motion.mot", body.model, times, result.q)
    write_model_bvh(folder / "motion.bvh", body, result.q, 1.0 / frame_rate)
    write_osim_model(folder / "model.osim", body, name=f"ibik_pin_{trc_stem(job)}")
    report = TrackingReport.from_tracking(
        result, job.settings, result.camera_names,
        trc.frame_numbers, times, frame_rate, axes, outliers,
    )
    report.silhouettes, report.triangulation, report.extrinsics = silhouette_report, triangulation_report, extrinsics
    report.write(folder / "report.json")
    if job.overlay:
        write_overlays(folder, job, body, cameras, silhouettes, result, trc, frame_rate)
    return report


def write_overlays(folder: Path, job: TrackJob, body: BodyModel, cameras: list,
                   silhouettes: Silhouettes | None, result: TrackingResult, trc: TrcData,
                   frame_rate: float) -> None:
    """Per camera an MP4 of the projected skeleton, a residual plot and an HTML 3D replay."""
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
    segment_indices = [(result.keypoint_names.index(a), result.keypoint_names.index(b))
                       for a, b in body.segments]
    write_html_replay(folder / "replay.html", result.keypoint_names, segment_indices,
                      result.keypoints, frame_rate, title=f"ibik_pin: {trc_stem(job)}")
    starts = result.keypoints[:, [a for a, _ in segment_indices]]
    ends = result.keypoints[:, [b for _, b in segment_indices]]
    for index, camera in enumerate(cameras):
        skeletons = ((camera.project(starts[f]), camera.project(ends[f])) for f in range(len(times)))
        if job.videos is not None:
            reader = VideoReader(camera_folder_entries(job.videos, [camera.name], "videos")[camera.name])
            frames = (fit_to_size(frame, tuple(camera.size)) for frame in reader)
        else:
            reader = None
            width, height = camera.size
            frames = (np.zeros((height, width, 3), np.uint8) for _ in range(len(times)))
        masks = (silhouettes.mask(f, index) for f in range(len(times))) if silhouettes else None
        try:
            write_overlay_video(folder / f"overlay_{camera.name}.mp4", frames, skeletons,
                                frame_rate, masks=masks, frame_numbers=trc.frame_numbers, times=times)
        finally:
            if reader is not None:
                reader.close()
