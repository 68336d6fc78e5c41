"""What `ibik track --videos` takes from the videos themselves: learned silhouettes of the subject,
and, without --targets, the end effectors triangulated from the same detections.

MediaPipe Pose's trackers find every person in every camera (app.video_people, vision.people): their
segmentations and 2D landmarks, associated across the views into people, of whom --person names the
one to track (vision.person_association, vision.person_views); that person's landmarks in all
cameras triangulate into Pose2Sim's keypoints (vision.triangulation). A mask is then cut down to
the subject: only the connected parts that hold a projected target (given or triangulated) are
kept, so that a stray blob the other views deny never pulls the skeleton.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import cv2
import numpy as np

from ibik_pin.app.input_reports import SilhouetteQuality, TriangulationReport
from ibik_pin.app.job import SEGMENTERS, TrackJob
from ibik_pin.app.options import as_options
from ibik_pin.app.silhouette_files import camera_folder_entries, check_video_size
from ibik_pin.app.video_people import DetectedPeople, PeopleReport, chosen_person, detect_people_in_videos
from ibik_pin.exceptions import IbikWarning, InputError
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, write_calibration
from ibik_pin.io.openpose import POSE_FOLDER, write_openpose_frames
from ibik_pin.io.trc import TrcData, write_trc
from ibik_pin.io.video import VideoReader
from ibik_pin.tracking.stack import Stack
from ibik_pin.vision.camera_diagnosis import diagnose_cameras
from ibik_pin.vision.extrinsics_refit import ExtrinsicsRefit, in_calibration_world, refit_extrinsics
from ibik_pin.vision.learned_pose import MEDIAPIPE_INSTALL, VideoPose, learned_pose_available
from ibik_pin.vision.mask_store import CroppedMasks
from ibik_pin.vision.person_views import person_pose
from ibik_pin.vision.triangulation import labelled_landmarks, triangulate_landmarks

__all__ = ["LIMB_KEYPOINTS", "REFITTED_CALIBRATION", "TRIANGULATED_TRC", "SilhouetteQualityReader", "VideoSources",
           "detect_videos_people", "keep_subject",
           "points_inside", "read_videos", "refitted_cameras", "resolve_segmenter", "restrict_to_subject",
           "triangulated_trc"]

# How far outside a mask a projected target may fall and still claim the part it touches [m]:
# a keypoint sits inside its limb, so a few centimetres of calibration and detection error.
SUBJECT_MARGIN_M = 0.05
TRIANGULATED_TRC = "triangulated.trc"
# Left to the image term when the targets are triangulated (the paper's split: IK places the end
# effectors, the silhouettes the internal joints); --triangulated-limbs makes them low-priority targets.
LIMB_KEYPOINTS = ("LElbow", "RElbow", "LKnee", "RKnee")
LIMB_STACK_FILE = "limb_targets_stack.toml"
REFITTED_CALIBRATION = "calibration_refitted.toml"
# The extrinsics re-fit uses only the landmarks the detector is sure of.
REFIT_MIN_VISIBILITY = 0.5


@dataclass
class VideoSources:
    """What `ibik track` read from --videos before tracking.

    Attributes:
        cameras: the cameras to track with: as calibrated, or with re-fitted poses (extrinsics).
        poses: MediaPipe's detections per camera, or None (MOG2, masks, no videos).
        segmenter: "mediapipe", "mog2", "masks" (given by --masks) or "none".
        triangulation: how the targets were triangulated, or None when they were given.
        left_to_image: target keypoints not tracked (the limbs of a triangulated TRC).
        extrinsics: what the re-fit of the cameras' poses found, or None when it did not run.
        targets: the TRC triangulated from the videos (in the staging folder, Y up), or None when
            the job gives the targets.
        stack: the stack to track the triangulated targets with (--triangulated-limbs), or None:
            the job's own.
        people: who was in the videos and whom the detections follow (MediaPipe only).
        stage_seconds: wall time of the steps run here [s]: "detection" (decoding and detecting,
            in parallel processes), "association", "triangulation" (with the cameras' check).
        detection_seconds: "decode" and "detection" summed over the views (processor seconds in
            the worker processes).
    """

    cameras: list
    poses: list[VideoPose] | None = None
    segmenter: str = "none"
    triangulation: TriangulationReport | None = None
    left_to_image: tuple[str, ...] = ()
    extrinsics: ExtrinsicsRefit | None = None
    targets: Path | None = None
    stack: Stack | None = None
    people: PeopleReport | None = None
    stage_seconds: dict[str, float] = field(default_factory=dict)
    detection_seconds: dict[str, float] = field(default_factory=dict)


def read_videos(staging: Path, job: TrackJob, cameras: Sequence, detected: DetectedPeople | None = None
                ) -> VideoSources:
    """Run the videos' segmenter once; with MediaPipe, follow the person --person names among
    those the views agree on (app.video_people; `detected`: its detections, if already made); with
    MediaPipe's landmarks and three cameras or more, measure each camera's disagreement with the
    others and turn those of --refit-cameras (written to staging/REFITTED_CALIBRATION); without
    --targets, triangulate the targets into staging/TRIANGULATED_TRC (VideoSources.targets)."""
    cameras = list(cameras)
    if job.refit_cameras is not None and (job.videos is None or len(cameras) < 3 or job.segmenter == "mog2"
                                          or not learned_pose_available()):
        raise InputError("--refit-cameras: needs --videos, --calibration with three cameras or more, and "
                         f"MediaPipe's keypoints (--segmenter mediapipe or auto, the video extra: {MEDIAPIPE_INSTALL})")
    unknown = sorted(set(job.refit_cameras or ()) - {camera.name for camera in cameras})
    if unknown:
        raise InputError(f"--refit-cameras: {', '.join(unknown)} not among the cameras "
                         f"{', '.join(camera.name for camera in cameras)}")
    if job.masks is not None:
        return VideoSources(cameras, segmenter="masks")
    keypoints_needed = job.targets is None
    wanted = keypoints_needed or job.settings.use_image or job.overlay or job.refit_cameras
    if job.videos is None or not cameras or not wanted:
        return VideoSources(cameras)
    segmenter = resolve_segmenter(job.segmenter, keypoints_needed)
    if segmenter == "mog2":
        return VideoSources(cameras, segmenter=segmenter)
    if job.background is not None:
        warnings.warn("--background is used by --segmenter mog2 only; MediaPipe's silhouettes need none",
                      IbikWarning, stacklevel=2)
    if keypoints_needed and len(cameras) < 2:
        raise InputError(f"without --targets the end effectors are triangulated: that needs two cameras or more, "
                         f"found {len(cameras)}")
    entries = camera_folder_entries(job.videos, [camera.name for camera in cameras], "videos")
    if detected is None:
        detected = detect_videos_people(entries, cameras, not job.quiet)
    person = chosen_person(getattr(job, "person", "auto"), detected.tracks)
    poses = person_pose(cameras, detected.views, detected.tracks, person)
    for camera, pose in zip(cameras, poses, strict=True):
        if pose.masks.size != tuple(camera.size):
            pose.masks = pose.masks.fitted(tuple(camera.size))
    timing = {"detection": detected.seconds["detection_wall"], "association": detected.seconds["association"]}
    people_report = detected.report(person)
    for camera, people in zip(cameras, detected.views, strict=True):  # Pose2Sim's pose/ layout, for reuse
        view = detected.names.index(camera.name)
        write_openpose_frames(staging / POSE_FOLDER, camera.name, people.keypoints, people.visibility,
                              detected.tracks.identity[view, :, : people.keypoints.shape[1]] + 1)
    worker_seconds = {key: detected.seconds[key] for key in ("decode", "detection")}
    start = time.perf_counter()
    extrinsics = None
    # One triangulation serves the extrinsics check and the targets, unless a camera is turned.
    triangulated = _triangulate(cameras, poses) if keypoints_needed or len(cameras) >= 3 else None
    if triangulated is not None and len(cameras) >= 3:
        cameras, extrinsics = refitted_cameras(cameras, poses, job.refit_cameras or (),
                                               triangulated[1]["views_swapped"])
        extrinsics.diagnosis = diagnose_cameras([camera.name for camera in cameras], extrinsics.reprojection_px,
                                                detected.views, detected.tracks, person)
        if extrinsics.refitted:
            write_calibration(staging / REFITTED_CALIBRATION, in_calibration_world(cameras, POSE2SIM_TRC_TO_WORLD))
            triangulated = None
    if not keypoints_needed:
        timing["triangulation"] = time.perf_counter() - start
        return VideoSources(cameras, poses, segmenter, extrinsics=extrinsics, people=people_report,
                            stage_seconds=timing, detection_seconds=worker_seconds)
    trc, figures = triangulated_trc(cameras, poses, video_frame_rate(entries[cameras[0].name]), triangulated)
    timing["triangulation"] = time.perf_counter() - start
    write_trc(staging / TRIANGULATED_TRC, trc)
    left_out = () if job.triangulated_limbs else LIMB_KEYPOINTS
    report = TriangulationReport(file=TRIANGULATED_TRC, keypoints=list(trc.marker_names),
                                 tracked_keypoints=[name for name in trc.marker_names if name not in left_out],
                                 **figures)
    stack = Stack.packaged(LIMB_STACK_FILE) if job.triangulated_limbs else None
    return VideoSources(cameras, poses, segmenter, report, left_out, extrinsics, staging / TRIANGULATED_TRC, stack,
                        people_report, timing, worker_seconds)


def _triangulate(cameras: Sequence, poses: Sequence[VideoPose]) -> tuple[dict, dict]:
    """triangulate_landmarks on every camera's detections."""
    return triangulate_landmarks(cameras, np.array([pose.keypoints for pose in poses]),
                                 np.array([pose.visibility for pose in poses]))


def refitted_cameras(cameras: Sequence, poses: Sequence[VideoPose], refit: Sequence[str],
                     swapped: np.ndarray | None = None) -> tuple[list, ExtrinsicsRefit]:
    """Each camera's disagreement with the others, and the cameras with those named in `refit`
    turned to meet them (vision.extrinsics_refit), from the detections with left and right agreed
    across views (`swapped`: the (F, V) side swaps of a triangulation with these cameras, else one
    is made)."""
    landmarks = np.array([pose.keypoints for pose in poses])
    visibility = np.array([pose.visibility for pose in poses])
    if swapped is None:
        swapped = _triangulate(cameras, poses)[1]["views_swapped"]
    confidence = labelled_landmarks(visibility[..., None], swapped)[..., 0]
    with as_options({"refit": "--refit-cameras"}):
        return refit_extrinsics(cameras, labelled_landmarks(landmarks, swapped),
                                np.where(confidence >= REFIT_MIN_VISIBILITY, confidence, 0.0), refit)


def restrict_to_subject(video_masks: Sequence[CroppedMasks], cameras: Sequence, targets_m: np.ndarray) -> None:
    """Cut every video mask down to the subject in place (keep_subject): the parts that hold one of
    the frame's targets (F, T, 3), projected, within SUBJECT_MARGIN_M. Each mask is cut within its
    stored crop (a person fills a few per cent of a frame), never rebuilt at the frame's size."""
    for camera, masks in zip(cameras, video_masks, strict=True):
        for frame, points in enumerate(targets_m):
            present = points[np.isfinite(points).all(axis=1)]
            top, left, crop = masks.crop(frame)
            if len(present) and crop.size:
                kept = keep_subject(crop, camera.project(present) - (left, top),
                                    camera.pixel_radius(present, SUBJECT_MARGIN_M))
                if kept is not crop:  # a part was cut
                    masks.set_crop(frame, top, left, kept)


def resolve_segmenter(requested: str, keypoints_needed: bool) -> str:
    """The segmenter to run: "mediapipe" or "mog2".

    "auto" takes MediaPipe where it is installed and otherwise falls back, with a warning that
    gives the install command, to background subtraction. Triangulating the targets (no --targets)
    needs MediaPipe's keypoints."""
    if requested not in SEGMENTERS:
        raise InputError(f"--segmenter: expected one of {', '.join(SEGMENTERS)}, found {requested!r}")
    available = learned_pose_available()
    if keypoints_needed and (requested == "mog2" or not available):
        raise InputError("without --targets the end effectors are triangulated from MediaPipe Pose's keypoints"
                         + (": install it with " + MEDIAPIPE_INSTALL if not available
                            else "; --segmenter mog2 gives none"))
    if requested == "mediapipe" and not available:
        raise InputError(f"--segmenter mediapipe: MediaPipe is not installed ({MEDIAPIPE_INSTALL})")
    if requested == "auto" and not available:
        warnings.warn("silhouettes by background subtraction (MOG2), which loses a person who stands still; "
                      f"for learned silhouettes: {MEDIAPIPE_INSTALL}", IbikWarning, stacklevel=2)
        return "mog2"
    return "mediapipe" if requested == "auto" else requested


def detect_videos_people(videos: dict[str, Path], cameras: Sequence, progress: bool) -> DetectedPeople:
    """Every camera's people, in parallel, associated across views (app.video_people)."""
    for camera in cameras:  # a size unlike the calibration's is refused, or warned of (the masks are fitted)
        check_video_size(videos[camera.name], camera)
    frames = 0
    for camera in cameras:
        with VideoReader(videos[camera.name]) as reader:
            frames += max(reader.frame_count, 0)
    with VideoReader(videos[cameras[0].name]) as reader:
        fps = reader.fps
    # Without a frame rate the association's speed bound assumes 30 Hz: looser at a higher rate.
    rate = float(fps) if np.isfinite(fps) and fps > 0 else 30.0
    return detect_people_in_videos(videos, cameras, rate, progress=progress, total_frames=frames or None)


def triangulated_trc(cameras: Sequence, poses: Sequence[VideoPose], frame_rate: float,
                     triangulated: tuple[dict, dict] | None = None) -> tuple[TrcData, dict]:
    """Pose2Sim keypoints triangulated from the detections, as a TRC in metres (Y up, the frame the
    cameras project), and the per-camera quality figures of TriangulationReport (`triangulated`:
    triangulate_landmarks' answer for these cameras and poses, if already made)."""
    keypoints, quality = triangulated if triangulated is not None else _triangulate(cameras, poses)
    names = list(keypoints)
    frames = len(poses[0].masks)
    trc = TrcData(marker_names=names, times=np.arange(frames) / frame_rate,
                  positions=np.stack([keypoints[name] for name in names], axis=1), units="m",
                  data_rate=frame_rate, frame_numbers=np.arange(1, frames + 1))
    errors = quality["reprojection_m"]
    figures = {
        "frames_swapped_per_view": {camera.name: int(quality["views_swapped"][:, index].sum())
                                    for index, camera in enumerate(cameras)},
        "landmarks_used_per_view": {camera.name: float(quality["views_used"][:, index].mean())
                                    for index, camera in enumerate(cameras)},
        "reprojection_median_m": float(np.nanmedian(errors)) if np.isfinite(errors).any() else None,
    }
    return trc, figures


def video_frame_rate(path: Path) -> float:
    """The frame rate the video announces [Hz]; InputError when it announces none."""
    with VideoReader(path) as reader:
        fps = reader.fps
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(f"--videos {path}: the video announces no frame rate; give --targets instead")
    return float(fps)


def keep_subject(mask: np.ndarray, pixels: np.ndarray, radius_px: np.ndarray) -> np.ndarray:
    """The parts of a mask (8-connected) that hold a target pixel or lie within its radius; the
    bool `mask` itself, not a copy, when every part is kept.

    Args:
        mask: (H, W) bool.
        pixels: (N, 2) projected targets [px] (NaN rows ignored).
        radius_px: (N,) how far outside a part each target may fall and still claim it [px].
    """
    count, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    if count <= 1:
        return np.asarray(mask, bool)  # `mask` itself when it is bool: nothing to cut
    height, width = mask.shape
    keep = np.zeros(count, bool)
    for (u, v), radius in zip(pixels, radius_px, strict=True):
        if not (np.isfinite(u) and np.isfinite(v) and np.isfinite(radius)):
            continue
        r = int(np.ceil(radius))
        u0, u1 = max(int(round(u)) - r, 0), min(int(round(u)) + r + 1, width)
        v0, v1 = max(int(round(v)) - r, 0), min(int(round(v)) + r + 1, height)
        if u0 < u1 and v0 < v1:
            keep[labels[v0:v1, u0:u1]] = True
    keep[0] = False
    if keep[1:].all():  # the usual case: the subject alone, in one part or several
        return np.asarray(mask, bool)
    return keep[labels]


def points_inside(camera, mask: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) bool: each point (N, 3), projected to its nearest pixel, falls inside the camera's mask
    (False outside the image or behind the camera; a camera far off, as a broken calibration gives,
    projects to no pixel rather than overflowing)."""
    projection = camera.project_with_jacobian(points)
    with np.errstate(invalid="ignore", over="ignore"):
        pixels = np.rint(projection.pixels)
        height, width = mask.shape
        seen = (projection.depth > 0) & (pixels[:, 0] >= 0) & (pixels[:, 0] < width) \
            & (pixels[:, 1] >= 0) & (pixels[:, 1] < height)
    hits = np.zeros(len(points), dtype=bool)
    taken = pixels[seen].astype(int)
    hits[seen] = mask[taken[:, 1], taken[:, 0]]
    return hits


class SilhouetteQualityReader:
    """Reads frames' silhouettes for the tracker and keeps, from the first reading of each frame,
    what SilhouetteQuality reports of it: each mask file is then decoded once, not once for the
    report and again for the tracking.

    Args:
        masks_of_frame: frame index -> its masks, one per camera.
        cameras: the cameras, in the masks' order.
        targets_m: (F, T, 3) the targets in the frame the cameras project [m].
    """

    def __init__(self, masks_of_frame, cameras: Sequence, targets_m: np.ndarray) -> None:
        self._masks_of_frame = masks_of_frame
        self._cameras = list(cameras)
        self._targets_m = targets_m
        self._inside = np.full((len(targets_m), len(self._cameras)), np.nan)
        self._areas = np.zeros((len(targets_m), len(self._cameras)), dtype=int)
        self._read = np.zeros(len(targets_m), dtype=bool)
        self._read_elsewhere = np.zeros(len(targets_m), dtype=bool)  # by the other process, figures there

    def __call__(self, frame: int) -> list[np.ndarray]:
        """Frame `frame`'s masks, one per camera."""
        masks = self._masks_of_frame(frame)
        if not self._read[frame]:
            points = self._targets_m[frame]
            present = np.isfinite(points).all(axis=1)
            for index, (camera, mask) in enumerate(zip(self._cameras, masks, strict=True)):
                self._areas[frame, index] = int(np.count_nonzero(mask))
                if present.any():
                    self._inside[frame, index] = points_inside(camera, mask, points[present]).mean()
            self._read[frame] = True
        return masks

    # Its figures, for a reader in another process (readahead.image_process.FrameRecords).
    def recorded_frames(self) -> int:
        """How many frames, from frame 0 on, have been read (their figures kept), here or elsewhere."""
        unread = np.flatnonzero(~(self._read | self._read_elsewhere))
        return int(unread[0]) if unread.size else len(self._read)

    def records(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._inside[start:stop].copy(), self._areas[start:stop].copy(), self._read[start:stop].copy()

    def add_records(self, start: int, records: object) -> None:
        inside, areas, read = cast(tuple[np.ndarray, np.ndarray, np.ndarray], records)
        taken = start + np.flatnonzero(read)  # a frame the other process did not read keeps its figures here
        self._inside[taken], self._areas[taken], self._read[taken] = inside[read], areas[read], True

    def read_elsewhere(self, frame: int) -> None:
        self._read_elsewhere[frame] = True

    def quality(self, segmenter: str) -> SilhouetteQuality:
        """SilhouetteQuality over every frame (those not read yet are read now)."""
        for frame in np.flatnonzero(~self._read):
            self(int(frame))
        quality = SilhouetteQuality(segmenter)
        for index, camera in enumerate(self._cameras):
            column = self._inside[:, index]
            quality.targets_inside_per_view[camera.name] = [None if np.isnan(v) else float(v) for v in column]
            quality.targets_inside_mean[camera.name] = (float(np.nanmean(column)) if np.isfinite(column).any()
                                                        else None)
            quality.mask_area_per_view[camera.name] = [int(area) for area in self._areas[:, index]]
        return quality
