"""`ibik track` as a function: read the user's files, check them, track, write every output.

Inputs are checked before any solving (names, frame counts, camera names, image sizes), and the
outputs are written into a temporary folder beside OUTDIR that replaces it only at the very end, so
a failure never leaves an OUTDIR that looks complete and never destroys a previous one half-way.
"""

from __future__ import annotations

import shutil
import sys
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ibik_pin.app.axes import TRC_AXES, TRC_TO_MODEL, choose_axes, sample_frames
from ibik_pin.app.diagnosis import (
    Diagnosis,
    ViewsLeftOut,
    add_jumps,
    axes_hint,
    check_axes,
    check_views,
    diagnose_result,
    view_evidence,
)
from ibik_pin.app.dropped_frames import SolvedFramesSource, expand_to_frames
from ibik_pin.app.input_checks import (
    check_camera_focal_lengths,
    check_cameras_see_targets,
    check_static_cells,
    check_trc,
    drop_jumping_frames,
    drop_outlier_targets,
    silhouettes_all_empty,
)
from ibik_pin.app.job import TrackJob
from ibik_pin.app.manifest import user_paths
from ibik_pin.app.options import as_options
from ibik_pin.app.outdir import check_outdir, kept_message, make_staging, overlay_file_names, publish
from ibik_pin.app.outputs import write_outputs
from ibik_pin.app.report import TrackingReport
from ibik_pin.app.silhouette_files import camera_folder_entries, load_silhouettes
from ibik_pin.app.trial_lengths_images import refine_lengths_on_images
from ibik_pin.app.video_inputs import SilhouetteQualityReader, detect_videos_people, read_videos, restrict_to_subject
from ibik_pin.app.video_people import DetectedPeople
from ibik_pin.exceptions import FileFormatError, IbikWarning, InputError, UnreconciledViewsError
from ibik_pin.human import FOOT_KEYPOINTS, load_human
from ibik_pin.io.c3d import c3d_axes, is_c3d
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.keypoints import read_keypoints
from ibik_pin.io.trc import METRES_PER_UNIT, TrcData
from ibik_pin.model import BodyModel
from ibik_pin.names import unknown_names_message
from ibik_pin.subject.calibration import calibrate_subject, check_subject_size
from ibik_pin.subject.scaling import (
    keypoint_lengths,
    scale_from_stature,
    scale_human,
    segment_lengths_from_keypoints,
)
from ibik_pin.subject.trial_lengths import apply_lengths, refine_from_reach
from ibik_pin.tracking.target_filter import filter_targets
from ibik_pin.tracking.tracker import Tracker
from ibik_pin.vision.camera import cameras_in_frame, select_cameras


def _trc_in_metres(option: str, path: Path, c3d_mapping: Path | None = None) -> tuple[TrcData, np.ndarray, np.ndarray]:
    """A TRC read and checked for plausibility (app.input_checks): the data, its positions in
    metres and (F, T) bool, the values dropped as outliers (only for --targets: a static trial is a
    few still frames, with no leap to drop)."""
    data = read_keypoints(path, c3d_mapping)
    if data.units not in METRES_PER_UNIT:
        raise FileFormatError(f"{path}: units {data.units!r} are not one of m, cm, mm")
    positions_m = data.positions * METRES_PER_UNIT[data.units]
    if option != "--targets":  # a static trial's lengths are measured: a corrupt cell is refused, named
        check_static_cells(option, path, data, positions_m)
    check_trc(option, path, data, positions_m)  # first: in the wrong unit, every target is an outlier
    outliers = np.zeros(positions_m.shape[:2], dtype=bool)
    if option == "--targets":
        positions_m, outliers = drop_outlier_targets(option, data.marker_names, positions_m)
    return data, positions_m, outliers


def _check_names(path: Path | None, names: Sequence[str], body: BodyModel) -> None:
    unknown = [name for name in names if name not in body.keypoints]
    if unknown:
        raise InputError(
            f"{path}: unknown keypoint name(s) {unknown_names_message(unknown, list(body.keypoints))}; "
            "known keypoints: " + ", ".join(body.keypoints)
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
    body = load_human(job.model) if job.model is not None else load_human()
    _check_names(job.targets, names, body)
    if job.static is not None:
        static, static_m, _ = _trc_in_metres("--static", job.static, job.c3d_mapping)
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


def run_track(job: TrackJob, detected: DetectedPeople | None = None, started: float | None = None) -> TrackingReport:
    """Run the whole job; returns the report that was written to OUTDIR/report.json.

    With --person all, each person the views agree on is tracked into OUT/person_N (the detection
    made once) and the first one's report is returned. `detected`: the videos' people, if already
    detected (app.video_people). `started`: the time.perf_counter() at which the user's command
    started (the `ibik` command's, before its imports), from which the end-to-end time counts;
    default: this call.

    OUTDIR is checked first (app.outdir), and the outputs go to a staging folder made before
    any work, so that an OUTDIR that cannot be written is found at once. An earlier output's files
    that ibik did not write (not in its manifest) are kept, and a warning says so."""
    if not isinstance(job, TrackJob):
        raise InputError(f"run_track: expected a TrackJob (ibik_pin.app.job), found {type(job).__name__}")
    if job.person == "all":
        return _track_everyone(job)
    out = check_outdir(job.out, job.inputs)
    staging = make_staging(out)
    try:
        with _warnings_recorded() as said:
            report = _run_into(staging, job, detected, started)
            kept_ahead = user_paths(out) if out.is_dir() else []
            if kept_ahead:  # said before publishing, so that report.json lists it too
                warnings.warn(kept_message(out, kept_ahead), IbikWarning, stacklevel=2)
        report.warnings, report.kept_user_files = said, kept_ahead
        report.write(staging / "report.json")
        kept = publish(staging, out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if set(kept) - set(kept_ahead):  # the user added files while the run went on
        warnings.warn(kept_message(out, kept), IbikWarning, stacklevel=2)
    return report


@contextmanager
def _warnings_recorded() -> Iterator[list[str]]:
    """Every IbikWarning shown inside, each once and in order, for report.json's `warnings`; each is
    still shown as it comes."""
    said: list[str] = []
    with warnings.catch_warnings():
        shown = warnings.showwarning

        def record(message, category, *args, **kwargs):
            if issubclass(category, IbikWarning) and str(message) not in said:
                said.append(str(message))
            shown(message, category, *args, **kwargs)

        warnings.showwarning = record
        yield said


def _track_everyone(job: TrackJob) -> TrackingReport:
    """--person all: each person the views reconcile, tracked into OUT/person_N."""
    cameras = _job_cameras(job)
    if job.videos is None or not cameras:
        raise InputError("--person all: needs --videos and --calibration")
    entries = camera_folder_entries(job.videos, [camera.name for camera in cameras], "videos")
    detected = detect_videos_people(entries, cameras, not job.quiet)
    reports: list[TrackingReport] = []
    skipped = []
    for number in range(1, detected.tracks.count + 1):
        try:
            reports.append(run_track(replace(job, person=number, out=job.out / f"person_{number}"), detected))
        except UnreconciledViewsError:
            skipped.append(number)
    if not reports:
        raise UnreconciledViewsError("--person all: the views cannot be reconciled on anyone (a wrong calibration, "
                         "unsynchronised videos, or nobody seen by two cameras)")
    if skipped:
        warnings.warn(f"--person all: person(s) {', '.join(map(str, skipped))} seen in too few frames or views "
                      f"to track; {len(reports)} tracked into {job.out}/person_N", IbikWarning, stacklevel=2)
    return reports[0]


def _job_cameras(job: TrackJob) -> list:
    """The calibration's cameras seeing the TRC's frame (--cameras applied), or none."""
    if job.calibration is None:
        return []
    cameras = cameras_in_frame(read_calibration(job.calibration), POSE2SIM_TRC_TO_WORLD)
    if job.cameras:
        with as_options({"names": "--cameras"}):
            cameras = select_cameras(cameras, job.cameras)
    return cameras


def _run_into(staging: Path, job: TrackJob, detected: DetectedPeople | None = None,
              command_started: float | None = None) -> TrackingReport:
    """Read, check, track and write every output into `staging`."""
    started = time.perf_counter()
    startup = started - command_started if command_started is not None else None
    started = command_started if command_started is not None else started
    cameras = _job_cameras(job)
    if job.calibration is not None:
        check_camera_focal_lengths(cameras)
        if job.overlay:  # said now, not after the solve: a camera's name names its overlay video
            renamed = {name: file for name, file in overlay_file_names([c.name for c in cameras]).items()
                       if file != f"overlay_{name}.mp4"}
            if renamed:
                name, file = next(iter(renamed.items()))
                warnings.warn(f"--calibration {job.calibration}: camera {name!r} cannot name a file as it is; "
                              f"its overlay video is {file}" + (f" ({len(renamed) - 1} more renamed so)"
                                                                if len(renamed) > 1 else ""),
                              IbikWarning, stacklevel=2)
    # Without --targets the videos' keypoints are triangulated into staging and read back as targets.
    videos = read_videos(staging, job, cameras, detected)
    cameras = videos.cameras
    targets = videos.targets if videos.targets is not None else job.targets
    if targets is None:  # TrackJob refuses this unless the videos give the targets
        raise InputError("--targets: expected a TRC, or --videos and --calibration to triangulate one")
    trc_axes = "y-up" if videos.targets is not None else job.trc_axes  # triangulated in the cameras' Y-up frame
    declared = c3d_axes(targets) if trc_axes == "auto" and is_c3d(targets) else None
    trc_axes = declared or trc_axes
    settings = job.settings if videos.stack is None else replace(job.settings, stack=videos.stack)
    trc, targets_trc_m, outliers = _trc_in_metres("--targets", targets, job.c3d_mapping)
    names = list(trc.marker_names)
    frame_count = targets_trc_m.shape[0]
    if frame_count == 0:
        raise InputError(f"--targets {targets}: no frame")
    # Frames whose targets all leap away and back are left unsolved, their poses interpolated.
    targets_trc_m, jumps = drop_jumping_frames("--targets", trc.frame_numbers, targets_trc_m, trc.times)
    silhouettes = None
    if settings.use_image:
        if not cameras:
            raise InputError("the image criterion needs --calibration with --masks or --videos "
                             "(or pass --no-image for the blind baseline)")
        if job.masks is None and job.videos is None:
            raise InputError("the image criterion needs --masks or --videos (or pass --no-image)")
        conventions = TRC_AXES if trc_axes == "auto" else (trc_axes,)
        check_cameras_see_targets(cameras, targets_trc_m, sample_frames(targets_trc_m),
                                  [TRC_TO_MODEL[axes] for axes in conventions])
        silhouettes = load_silhouettes(job, cameras, frame_count, not job.quiet, videos.poses)
        if silhouettes_all_empty(silhouettes.frame, frame_count):
            warnings.warn(f"--{'masks' if job.masks is not None else 'videos'}: every silhouette is empty; "
                          "tracking without the image (as --no-image)", IbikWarning, stacklevel=2)
            settings = replace(settings, use_image=False)
    elif job.overlay and cameras and (job.masks is not None or job.videos is not None):
        silhouettes = load_silhouettes(job, cameras, frame_count, not job.quiet, videos.poses)
    # The cameras project model-frame points whatever the TRC's convention: only the targets turn.
    axes = choose_axes(trc_axes, names, targets_trc_m, cameras,
                       silhouettes.frame if silhouettes is not None else None)
    if videos.targets is not None:  # y-up because ibik triangulated them so, not because the user said
        axes = replace(axes, how="triangulated")
    elif declared is not None:
        axes = replace(axes, how="declared by the C3D file")
    if not job.quiet:
        print(f"ibik: TRC axes: {axes.describe()}", file=sys.stderr)
    targets_m = axes.to_model(targets_trc_m)
    # Target noise goes into the joints as it is: each keypoint low-passed over time, if asked.
    target_filter = filter_targets(names, targets_m, float(trc.data_rate), job.target_filter)
    targets_m = target_filter.positions
    if silhouettes is not None and silhouettes.video_masks is not None:
        restrict_to_subject(silhouettes.video_masks, cameras, targets_m)
    diagnosis = Diagnosis()  # the views' evidence judged before any solving (app.diagnosis)
    if silhouettes is not None and settings.use_image:
        diagnosis = check_views(view_evidence(cameras, silhouettes.frame, targets_m),
                                "--masks" if job.masks is not None else "--videos", trc.frame_numbers,
                                axes_hint(axes))
    add_jumps(diagnosis, jumps, trc.frame_numbers)
    check_axes(diagnosis, axes)
    # Every keypoint scales the segments, tracked or not.
    stages = dict(videos.stage_seconds) if startup is None else {"startup": startup, **videos.stage_seconds}
    calibration_started = time.perf_counter()
    body = prepare_body(job, names, targets_m, calibrate_on_targets=videos.triangulation is not None)
    trial_lengths = None
    if job.trial_lengths == "images" and silhouettes is not None and settings.use_image:
        kept = [k for k, name in enumerate(names) if name not in videos.left_to_image]
        frames = np.flatnonzero(~jumps.dropped)
        frame_masks = silhouettes.frame
        trial_lengths = refine_lengths_on_images(body, [names[k] for k in kept], targets_m[frames][:, kept], cameras,
                                                 lambda index: frame_masks(int(frames[index])), settings)
        body = apply_lengths(body, trial_lengths)
    elif job.trial_lengths != "off":  # a static take's joint centres are not rigid across takes
        trial_lengths = refine_from_reach(keypoint_lengths(body), names, targets_m)
        body = apply_lengths(body, trial_lengths)
    stages["calibration"] = time.perf_counter() - calibration_started
    reader = None  # the silhouettes, each frame's read once for the tracker and the report
    if silhouettes is not None:
        reader = SilhouetteQualityReader(silhouettes.frame, cameras, targets_m)
    tracked = [index for index, name in enumerate(names) if name not in videos.left_to_image]

    use_image = settings.use_image
    tracker = Tracker(body, cameras if use_image else [], settings)
    solved = np.flatnonzero(~jumps.dropped)  # the frames of whole-body jumps are not solved
    source: Callable[[int], Sequence[np.ndarray]] | None = (
        reader if reader is None or len(solved) == frame_count else SolvedFramesSource(reader, solved))
    if source is not None and diagnosis.views_left_out:  # suspect views (app.diagnosis) pull nothing
        source = ViewsLeftOut(source, [index for index, camera in enumerate(cameras)
                                       if camera.name in diagnosis.views_left_out])
    solve_started = time.perf_counter()
    with tqdm(total=len(solved), desc="tracking", unit="frame", disable=True if job.quiet else None) as bar:
        result = tracker.track([names[index] for index in tracked], targets_m[solved][:, tracked],
                               source if use_image else None, progress=bar.update,
                               frame_rate_hz=float(trc.data_rate))
    stages["solve"] = time.perf_counter() - solve_started
    if len(solved) < frame_count:
        result = expand_to_frames(result, body, solved, np.asarray(trc.times, dtype=float))
    diagnose_result(diagnosis, trc.frame_numbers, result.target_residuals, result.camera_names,
                    result.inside_fraction)
    silhouette_report = reader.quality(videos.segmenter) if reader is not None else None

    outputs_started = time.perf_counter()
    # tracker.settings: as solved (a stack's image task may set the criterion)
    report = write_outputs(staging, job, tracker.settings, targets.stem, trc, body, cameras, silhouettes, result,
                           axes, outliers[:, tracked], silhouette_report=silhouette_report,
                           triangulation_report=videos.triangulation, extrinsics=videos.extrinsics,
                           trial_lengths=trial_lengths)
    stages["outputs"] = time.perf_counter() - outputs_started
    report.diagnosis = diagnosis.to_report()
    report.target_filter = target_filter.report()
    report.people, report.stage_seconds = videos.people, stages
    report.detection_seconds = videos.detection_seconds or None
    report.end_to_end_seconds = time.perf_counter() - started
    report.end_to_end_frames_per_second = frame_count / report.end_to_end_seconds
    return report  # run_track writes report.json again, with these and the run's warnings
