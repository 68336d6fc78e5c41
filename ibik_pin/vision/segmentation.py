"""Silhouettes from images: background subtraction of videos, and temporal voting of masks.

:func:`silhouettes_by_background_subtraction` segments the moving person of a still camera's video
(its decoded frames; the files are opened by the caller) with OpenCV's MOG2 background model, learnt
on frames of the empty scene or, without them, on the video's own median plate;
:class:`TemporalMajority` votes each pixel of a mask sequence over neighbouring frames to remove
segmentation flicker.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Protocol

import cv2
import numpy as np

from ibik_pin.checks import as_mask
from ibik_pin.exceptions import InputError
from ibik_pin.vision.mask_store import CroppedMasks

__all__ = ["TemporalMajority", "VideoFrames", "silhouettes_by_background_subtraction"]


class VideoFrames(Protocol):
    """A video's frames, read again from the first one by each iteration (an io.video.VideoReader).

    Attributes:
        size: (width, height) [px].
        frame_count: the number of frames announced (0 or less: unknown).
    """

    size: tuple[int, int]
    frame_count: int

    def __iter__(self) -> Iterator[np.ndarray]: ...


class TemporalMajority:
    """Silhouettes with single-frame flicker voted away: each pixel of a camera's mask at frame t
    is the majority over frames t - radius .. t + radius (the first and last frames repeated at
    the ends of the sequence).

    Segmentation errors that last one or two frames (a hole, a passing shadow, a forearm lost
    against the background) are outvoted by the frames around them; a limb moves a few pixels at
    most between neighbouring frames at 50-120 Hz, so clean masks change little. Masks are read
    once each, in frame order, and only the 2 * radius + 1 frames of the window are kept.

    Args:
        source: frame index -> one (H, W) bool mask per camera.
        frame_count: number of frames of the sequence.
        radius: half window [frames], >= 1.
    """

    def __init__(self, source: Callable[[int], Sequence[np.ndarray]], frame_count: int, radius: int = 1) -> None:
        if isinstance(radius, bool) or int(radius) != radius or radius < 1:
            raise InputError(f"radius: expected a whole number of frames >= 1, got {radius!r}")
        if int(frame_count) != frame_count or frame_count < 1:
            raise InputError(f"frame_count: expected a positive whole number, got {frame_count!r}")
        self.source = source
        self.frame_count = int(frame_count)
        self.radius = int(radius)
        self._window: dict[int, list[np.ndarray]] = {}

    def __call__(self, frame: int) -> list[np.ndarray]:
        # The ends repeat the first and last frames (as a median filter's edge replication).
        indices = [min(max(index, 0), self.frame_count - 1)
                   for index in range(frame - self.radius, frame + self.radius + 1)]
        for old in [index for index in self._window if index not in indices]:
            del self._window[old]
        for index in indices:
            if index not in self._window:
                self._window[index] = [as_mask(mask) for mask in self.source(index)]
        window = [self._window[index] for index in indices]
        return [2 * np.sum([masks[camera] for masks in window], axis=0, dtype=np.int32) > len(window)
                for camera in range(len(window[0]))]


def _keep_largest_components(mask: np.ndarray, max_components: int, min_component_fraction: float) -> np.ndarray:
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if count <= 1:
        return mask.astype(bool)
    areas = stats[1:, cv2.CC_STAT_AREA]
    order = np.argsort(areas)[::-1][:max_components]
    order = order[areas[order] >= min_component_fraction * areas[order[0]]]
    keep = np.zeros(count, bool)
    keep[order + 1] = True
    return keep[labels]


def silhouettes_by_background_subtraction(
    video: VideoFrames,
    background: Iterable[np.ndarray] | None = None,
    *,
    max_frames: int | None = None,
    var_threshold: float = 16.0,
    median_frames: int = 31,
    foreground_threshold: int = 30,
    open_px: int = 3,
    close_px: int = 7,
    max_components: int = 3,
    min_component_fraction: float = 0.1,
) -> CroppedMasks:
    """Silhouettes of the moving person in a video, by OpenCV background subtraction (MOG2).

    With ``background`` (frames of the empty scene, the video's size),
    MOG2 learns the background on them, then is frozen while the video is segmented. Without,
    it learns on the video itself: the per-pixel temporal median of ``median_frames`` evenly
    spaced frames gives a background plate; MOG2 learns on these frames with the pixels far
    from the plate (``foreground_threshold`` grey levels in some channel) replaced by the
    plate, so that the person does not enter the model while MOG2 learns the noise of the real
    background. Shadows
    (MOG2's shadow label) count as background. Each mask is then cleaned by a morphological
    opening (``open_px``) and closing (``close_px``), and only the ``max_components`` largest
    connected components at least ``min_component_fraction`` of the largest are kept.

    Limits: the camera must be still and the lighting constant. Without a background, a part
    of the body that stays still over more than half of the frames is background (as in the
    Pose2Sim balancing demo, where the trunk barely moves); pass real background frames then.
    Parts whose colour matches the background behind them are lost; a second person or a
    moving object is kept if large enough. The video is decoded twice; besides the masks, only
    the median sample (``median_frames`` frames) is held in memory.

    Args:
        video: the video's frames, (H, W, 3) BGR uint8, read twice.
        background: (H, W, 3) BGR uint8 frames of the empty scene, or None.
        max_frames: segment only the first frames, or None for all.
        var_threshold: MOG2's squared Mahalanobis distance threshold.
        median_frames: number of frames in the median background plate (no background given).
        foreground_threshold: grey-level distance to the plate above which a pixel is kept out
            of MOG2's learning (no background given).
        open_px: diameter of the opening kernel [px]; 0 for none.
        close_px: diameter of the closing kernel [px]; 0 for none.
        max_components: number of connected components kept (the largest).
        min_component_fraction: smallest kept component, as a fraction of the largest's area.

    Returns:
        One (H, W) bool mask per frame, True = person (kept as bounding-box crops).

    Raises:
        InputError: the video has no frame, a background frame has another size than the video, or
            a parameter is out of range.
    """
    for name, value, smallest in (
        ("open_px", open_px, 0),
        ("close_px", close_px, 0),
        ("max_components", max_components, 1),
        ("median_frames", median_frames, 1),
        ("foreground_threshold", foreground_threshold, 0),
    ):
        if int(value) != value or value < smallest:
            raise InputError(f"{name}: expected an integer >= {smallest}, found {value!r}")
    if max_frames is not None and (int(max_frames) != max_frames or max_frames < 1):
        raise InputError(f"max_frames: expected a positive integer or None, found {max_frames!r}")
    if not 0.0 <= min_component_fraction <= 1.0:
        raise InputError(f"min_component_fraction: expected a number in [0, 1], found {min_component_fraction!r}")
    if not var_threshold > 0.0:
        raise InputError(f"var_threshold: expected a positive number, found {var_threshold!r}")

    size, frame_total = (int(video.size[0]), int(video.size[1])), video.frame_count
    if max_frames is not None:
        frame_total = min(frame_total, max_frames) if frame_total > 0 else max_frames
    subtractor = cv2.createBackgroundSubtractorMOG2(varThreshold=float(var_threshold), detectShadows=True)
    if background is not None:
        for index, frame in enumerate(background):
            found = (frame.shape[1], frame.shape[0])
            if found != size:
                raise InputError(f"background frame {index}: expected the video's size (w, h) = {size}, "
                                 f"found (w, h) = {found}")
            subtractor.apply(frame, learningRate=-1)
    else:
        # Without an announced frame count, the plate is the median of the first frames.
        stride = max(1, -(-frame_total // median_frames)) if frame_total > 0 else 1
        sample = []
        for index, frame in enumerate(itertools.islice(video, max_frames)):
            if index % stride == 0:
                sample.append(frame)
                if len(sample) == median_frames:
                    break
        if not sample:
            raise InputError("video: expected frames, found none")
        plate = np.median(np.stack(sample), axis=0).astype(np.uint8)
        for frame in sample:
            channels = cv2.split(cv2.absdiff(frame, plate))
            away = cv2.max(cv2.max(channels[0], channels[1]), channels[2]) > foreground_threshold
            np.copyto(frame, plate, where=away[:, :, np.newaxis])
            subtractor.apply(frame, learningRate=1.0 / len(sample))

    open_kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (open_px, open_px)) if open_px > 0 else None
    close_kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (close_px, close_px)) if close_px > 0 else None
    masks = CroppedMasks(size)
    for frame in itertools.islice(video, max_frames):
        mask = (subtractor.apply(frame, learningRate=0.0) == 255).astype(np.uint8)  # 127 = shadow
        if open_kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, open_kernel)
        if close_kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, close_kernel)
        masks.append(_keep_largest_components(mask, int(max_components), float(min_component_fraction)))
    if not len(masks):
        raise InputError("video: expected frames, found none")
    return masks
