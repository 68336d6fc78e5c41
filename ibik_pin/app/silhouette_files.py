"""The silhouettes of `ibik track`: each calibrated camera paired with its mask folder or video
(by its whole name), the masks read lazily or the videos' silhouettes decoded, checked against the
targets' frame count before any solving."""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
from tqdm import tqdm

from ibik_pin.app.job import TrackJob
from ibik_pin.exceptions import FileFormatError, IbikWarning, InputError
from ibik_pin.io.files import PathLike
from ibik_pin.io.masks import IMAGE_SUFFIXES, list_mask_files, read_image, read_mask
from ibik_pin.io.video import VideoReader, read_frames
from ibik_pin.vision.mask_store import CroppedMasks
from ibik_pin.vision.segmentation import silhouettes_by_background_subtraction

if TYPE_CHECKING:
    from ibik_pin.vision.learned_pose import VideoPose

__all__ = ["Silhouettes", "camera_folder_entries", "check_video_size", "fit_to_size", "load_silhouettes",
           "silhouettes_from_video"]

VIDEO_SUFFIXES = {".mp4", ".avi", ".mov", ".mkv", ".m4v"}
# Encoders round frame sizes to macroblocks of 16 px: a video up to 15 px off its calibration's
# size (Pose2Sim's demo: 1080 px wide, calibrated at 1088) is the same sensor, anything more is not.
CODEC_ALIGNMENT_PX = 16


@dataclass
class Silhouettes:
    """Per camera, either mask files (read lazily) or decoded video silhouettes."""

    mask_files: list[list[Path]] | None
    video_masks: list[CroppedMasks] | None
    sizes: list[tuple[int, int]]

    @property
    def frame_count(self) -> int:
        source = self.mask_files if self.mask_files is not None else self.video_masks
        return len(source[0]) if source else 0

    def mask(self, index: int, camera: int) -> np.ndarray:
        """Frame `index`'s (H, W) bool silhouette in camera number `camera`."""
        if self.mask_files is not None:
            return read_mask(self.mask_files[camera][index], self.sizes[camera])
        if self.video_masks is None:
            raise InputError("silhouettes: neither mask files nor video masks were loaded")
        return self.video_masks[camera][index]

    def frame(self, index: int) -> list[np.ndarray]:
        """Frame `index`'s silhouettes, one per camera."""
        return [self.mask(index, camera) for camera in range(len(self.sizes))]


def _plain(name: str) -> str:
    """A name for matching files to cameras: lower case, without separators ("cam_01" ~ "Cam01")."""
    return "".join(character for character in name.lower() if character.isalnum())


def _starts_with_camera(stem: str, name: str) -> bool:
    """Whether a file name is the camera's name, whole, maybe followed by a separator and more
    (cam1_empty.png and cam1.png are cam1's backgrounds; cam10_empty.png is not)."""
    cuts = [index for index, character in enumerate(stem) if not character.isalnum()] + [len(stem)]
    return any(_plain(stem[:cut]) == _plain(name) for cut in cuts)


def camera_folder_entries(folder: Path, names: list[str], kind: str) -> dict[str, Path]:
    """Per camera, its mask sub-folder (--masks) or its video (--videos) in `folder`.

    A sub-folder or a video's file name (without its suffix) is the camera's whole name (for
    --videos, a sub-folder holding one video stands for that video); case and
    separators are ignored, so Pose2Sim's cam01.mp4 serves the calibration's cam_01, and cam1 never
    reads cam10.mp4. A camera with no entry, or with several, is an error listing them.
    """
    if not folder.is_dir():
        raise FileFormatError(f"--{kind} {folder}: not a folder")
    if kind == "masks":
        candidates = [p for p in sorted(folder.iterdir()) if p.is_dir()]
        what = "sub-folder"
    else:  # a camera's video, or its sub-folder holding one video (Pose2Sim's per-camera folders)
        candidates = [p for p in sorted(folder.iterdir()) if p.suffix.lower() in VIDEO_SUFFIXES and p.is_file()]
        candidates += [p for p in sorted(folder.iterdir()) if p.is_dir() and len(_videos_in(p)) == 1]
        what = "video"
    found: dict[str, Path] = {}
    for name in names:
        matches = [p for p in candidates if _plain(p.stem if kind != "masks" and p.is_file() else p.name)
                   == _plain(name)]
        if not matches:
            listed = ", ".join(p.name for p in candidates[:8]) or "none"
            raise FileFormatError(f"--{kind} {folder}: no {what} named after camera {name!r} (case and separators "
                                  f"ignored; found: {listed})")
        if len(matches) > 1:
            raise FileFormatError(f"--{kind} {folder}: camera {name!r} matches several entries: "
                                  f"{', '.join(p.name for p in matches)}; keep one")
        found[name] = matches[0] if kind == "masks" or matches[0].is_file() else _videos_in(matches[0])[0]
    return found


def _videos_in(folder: Path) -> list[Path]:
    return [p for p in sorted(folder.iterdir()) if p.suffix.lower() in VIDEO_SUFFIXES and p.is_file()]


def check_video_size(path: Path, camera) -> tuple[int, int]:
    """The video's (width, height), refused when it is not the camera's calibrated size; a size
    off by less than an encoder's alignment is accepted with a warning (masks are fitted to it)."""
    with VideoReader(path) as reader:
        video_size = (int(reader.size[0]), int(reader.size[1]))
    size = tuple(camera.size)
    if any(abs(a - b) >= CODEC_ALIGNMENT_PX for a, b in zip(video_size, size, strict=True)):
        raise InputError(f"--videos {path}: frames are {video_size[0]} x "
                         f"{video_size[1]} px but camera {camera.name!r} is {size[0]} x {size[1]} px")
    if video_size != size:
        warnings.warn(f"--videos {path}: frames are {video_size[0]} x {video_size[1]} px, "
                      f"camera {camera.name!r} {size[0]} x {size[1]} px: silhouettes padded or cropped "
                      "at the right and bottom (encoder alignment)", IbikWarning, stacklevel=2)
    return video_size


def load_silhouettes(job: TrackJob, cameras: list, frame_count: int, progress: bool,
                     learned: list[VideoPose] | None = None) -> Silhouettes:
    """Mask files or video silhouettes for every camera, checked against the targets' frame count.
    `learned`: MediaPipe's detections of the videos (app.video_inputs), whose masks are used
    instead of background subtraction."""
    names = [camera.name for camera in cameras]
    sizes = [tuple(camera.size) for camera in cameras]
    if job.masks is not None:
        folders = camera_folder_entries(job.masks, names, "masks")
        files = [list_mask_files(folders[name]) for name in names]
        for name, listed, size in zip(names, files, sizes, strict=True):
            if len(listed) != frame_count:
                raise InputError(f"--masks {folders[name]}: {len(listed)} masks for camera {name!r} "
                                 f"but the targets have {frame_count} frames")
            read_mask(listed[0], size)  # size and readability, before any solving
        return Silhouettes(files, None, sizes)
    if job.videos is None:
        raise InputError("the image criterion needs --masks or --videos (or pass --no-image)")
    videos = camera_folder_entries(job.videos, names, "videos")
    backgrounds: dict[str, list[Path]] = {name: [] for name in names}
    if job.background is not None:
        if not job.background.is_dir():
            raise FileFormatError(f"--background {job.background}: not a folder")
        for path in sorted(job.background.iterdir()):
            for name in names:
                if _starts_with_camera(path.stem, name) and path.suffix.lower() in IMAGE_SUFFIXES | VIDEO_SUFFIXES:
                    backgrounds[name].append(path)
    masks = []
    # disable=None draws the bar only when stderr is a terminal, so logs and pipes stay clean.
    with tqdm(total=len(names), desc="silhouettes", unit="camera", disable=None if progress else True) as bar:
        for index, (name, size) in enumerate(zip(names, sizes, strict=True)):
            if learned is not None:
                camera_masks = learned[index].masks
            else:
                video_size = check_video_size(videos[name], cameras[index])
                camera_masks = silhouettes_from_video(videos[name], backgrounds[name] or None)
                if video_size != size:
                    camera_masks = camera_masks.fitted(size)
            if len(camera_masks) != frame_count:
                raise InputError(f"--videos {videos[name]}: {len(camera_masks)} frames but the targets "
                                 f"have {frame_count} frames")
            masks.append(camera_masks)
            bar.update()
    return Silhouettes(None, masks, sizes)


def fit_to_size(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """The mask or image padded with zeros or cropped at the right and bottom to (width, height)."""
    width, height = size
    fitted = np.zeros((height, width) + image.shape[2:], dtype=image.dtype)
    rows, columns = min(height, image.shape[0]), min(width, image.shape[1])
    fitted[:rows, :columns] = image[:rows, :columns]
    return fitted


def silhouettes_from_video(video_path: PathLike, background_paths: Sequence[PathLike] | None = None,
                           **options) -> CroppedMasks:
    """The silhouettes of a video file by background subtraction
    (:func:`~ibik_pin.vision.segmentation.silhouettes_by_background_subtraction`, whose keyword
    `options` it takes), learnt on `background_paths`: images or videos of the empty scene, each
    checked against the video's size.

    Raises:
        FileFormatError: the video or a background file cannot be read.
        InputError: a background has another size than the video, or an option is out of range.
    """
    with VideoReader(video_path) as video:
        background = _background_frames(background_paths, video.size) if background_paths else None
        return silhouettes_by_background_subtraction(video, background, **options)


def _background_frames(paths: Sequence[PathLike], size: tuple[int, int]) -> Iterator[np.ndarray]:
    """Frames of background images and videos, each checked against the video size (w, h)."""
    for path in map(Path, paths):
        if path.suffix.lower() in IMAGE_SUFFIXES:
            frames: Iterator[np.ndarray] = iter([read_image(path, cv2.IMREAD_COLOR, "background")])
        else:
            frames = read_frames(path, None)
        for frame in frames:
            found = (frame.shape[1], frame.shape[0])
            if found != size:
                raise InputError(
                    f"background file '{path}': expected the video's size (w, h) = {size}, found (w, h) = {found}"
                )
            yield frame
