"""Every person in every frame of one video, from MediaPipe Pose's single-person tracker.

MediaPipe 0.10.21's wheel ships the legacy Pose solution only, which detects one person and then
follows that person. Several people are found with several of its trackers, each given the frame
with the other trackers' people greyed out (their segmentation, dilated): a tracker then sees one
person only and cannot drift onto another, and an idle tracker searching the frame finds someone
nobody follows yet. A tracker that loses its person becomes idle. On the first frame, and then at
intervals (SearchSchedule: every SEARCH_EVERY frames while people come and go, less often while
searches keep finding nobody), the idle trackers search, one after the other until one finds
nobody (MediaPipe's detector costs about as much as a tracked frame). Of two trackers that end on
the same person (their landmarks within a few per cent of the frame's height), the first keeps it.

Frames may be fed at a reduced size (`detect_height`): BlazePose's networks see a 224 px (detector)
and 256 px (landmarks) crop, so a 1920 px frame carries little its landmarks need; the landmarks
are returned in the full frame's pixels and the masks at its size (kept as crops: a mask is never
built at the full frame's size).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import cv2
import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.native_output import captured_native_stderr
from ibik_pin.vision.learned_pose import LANDMARKS, MEDIAPIPE_INSTALL, VideoPose, learned_pose_available
from ibik_pin.vision.mask_store import CroppedMasks

__all__ = ["DetectionSettings", "SearchSchedule", "ViewPeople", "detect_people"]

# Idle trackers search the frame for a new person this often [frames] after the first frame, after
# a search that found someone and after a tracker lost its person (people come and go then) ...
SEARCH_EVERY = 6
# ... and the interval doubles after each search that finds nobody, up to this [frames] (0.8 s at
# 60 Hz): on the single-person demo the searches found nobody after the first frame.
SEARCH_EVERY_LONGEST = 48
# Grey drawn over the people other trackers follow (mid-grey: no edge a detector reads as a body).
GREY = 128
# The other people's silhouettes are greyed out dilated by this share of the frame's height: their
# segmentation lags a fast limb by a few pixels, and a sliver of arm left visible can seed a detection.
DILATION_SHARE = 0.01
# Two trackers on one person: their visible landmarks' median distance under this share of the frame's height.
SAME_PERSON_SHARE = 0.03


@dataclass(frozen=True)
class DetectionSettings:
    """How detect_people runs MediaPipe.

    Attributes:
        max_people: trackers per view: the most people followed at once.
        detect_height: frames taller than this are fed scaled down to this height [px]; 0 feeds
            them at full size.
        mask_threshold: segmentation probability above which a pixel is the person.
    """

    max_people: int = 3
    detect_height: int = 960
    mask_threshold: float = 0.5

    def __post_init__(self) -> None:
        if not 1 <= self.max_people <= 8:
            raise InputError(f"max_people: expected 1 to 8, found {self.max_people!r}", parameter="max_people")
        if self.detect_height < 0:
            raise InputError(f"detect_height: expected 0 or a height in px, found {self.detect_height!r}",
                             parameter="detect_height")
        if not 0.0 < self.mask_threshold < 1.0:
            raise InputError(f"mask_threshold: expected a probability in (0, 1), found {self.mask_threshold!r}",
                             parameter="mask_threshold")


@dataclass
class ViewPeople:
    """The people one video's trackers followed.

    Attributes:
        keypoints: (F, K, 33, 2) pixels of LANDMARKS per frame and tracker, NaN where the
            tracker followed no one.
        visibility: (F, K, 33) MediaPipe's visibility score, 0 where the tracker followed no one.
        masks: K CroppedMasks of F silhouettes each (empty where the tracker followed no one).
        size: the frames' (width, height) [px].
    """

    keypoints: np.ndarray
    visibility: np.ndarray
    masks: list[CroppedMasks]
    size: tuple[int, int]

    @property
    def frames(self) -> int:
        return int(self.keypoints.shape[0])

    def present(self) -> np.ndarray:
        """(F, K) bool: the tracker followed someone in the frame."""
        return np.isfinite(self.keypoints[..., 0]).any(axis=2)

    def single(self, slot: int = 0) -> VideoPose:
        """One tracker's person as a VideoPose."""
        return VideoPose(self.keypoints[:, slot].copy(), self.visibility[:, slot].copy(), self.masks[slot])


def _tracker():
    """A MediaPipe Pose tracker with its segmentation, unsmoothed landmarks (learned_pose._solution)."""
    os.environ.setdefault("GLOG_minloglevel", "2")
    if not learned_pose_available():
        raise InputError(f"several people's keypoints need MediaPipe: {MEDIAPIPE_INSTALL}")
    with captured_native_stderr():
        import mediapipe as mp

        return mp.solutions.pose.Pose(static_image_mode=False, model_complexity=1, smooth_landmarks=False,
                                      enable_segmentation=True, smooth_segmentation=True,
                                      min_detection_confidence=0.5, min_tracking_confidence=0.5)


class SearchSchedule:
    """When the idle trackers search a frame for someone nobody follows: the first frame; then every
    SEARCH_EVERY frames, the interval doubling after each search that finds nobody up to
    SEARCH_EVERY_LONGEST, and back to SEARCH_EVERY once a search finds someone or a tracker loses
    its person."""

    def __init__(self) -> None:
        self.interval = SEARCH_EVERY
        self.next_frame = 0

    def due(self, frame: int) -> bool:
        """Whether the idle trackers search `frame` (each frame from a due one until a search runs)."""
        return frame >= self.next_frame

    def update(self, frame: int, searched: bool, found: bool, lost: bool) -> None:
        """After `frame`: whether a search ran on it, found someone, and whether a tracker lost its person."""
        if found or lost:
            self.interval = SEARCH_EVERY
        elif searched:
            self.interval = min(2 * self.interval, SEARCH_EVERY_LONGEST) if frame > 0 else SEARCH_EVERY
        if searched or lost:
            self.next_frame = frame + self.interval


_EMPTY_CROP = (0, 0, np.zeros((0, 0), bool))


def _mask_crop(probability: np.ndarray, threshold: float, size: tuple[int, int]) -> tuple[int, int, np.ndarray]:
    """The segmentation (h, w) probability at the frame's size (W, H), thresholded, as the crop of
    its bounding box: (top, left, crop); only that box is resized."""
    small = probability > threshold
    width, height = size
    rows, columns = np.flatnonzero(small.any(axis=1)), np.flatnonzero(small.any(axis=0))
    if rows.size == 0:
        return _EMPTY_CROP
    sy, sx = height / probability.shape[0], width / probability.shape[1]
    top, bottom = max(rows[0] - 1, 0), min(rows[-1] + 2, probability.shape[0])
    left, right = max(columns[0] - 1, 0), min(columns[-1] + 2, probability.shape[1])
    y0, y1 = int(round(top * sy)), min(int(round(bottom * sy)), height)
    x0, x1 = int(round(left * sx)), min(int(round(right * sx)), width)
    if y1 <= y0 or x1 <= x0:
        return _EMPTY_CROP
    crop = cv2.resize(np.ascontiguousarray(probability[top:bottom, left:right]), (x1 - x0, y1 - y0),
                      interpolation=cv2.INTER_LINEAR)
    return y0, x0, crop > threshold


class _Slot:
    """One tracker, the person it follows and that person's last silhouette (at the fed size)."""

    def __init__(self) -> None:
        self.tracker = _tracker()
        self.active = False
        self.silhouette: np.ndarray | None = None  # uint8, at the fed size
        self._hidden: np.ndarray | None = None

    def follows(self, silhouette: np.ndarray | None) -> None:
        """The person's silhouette in this frame (None: not segmented)."""
        self.active, self.silhouette, self._hidden = True, silhouette, None

    def idle(self) -> None:
        self.active, self.silhouette, self._hidden = False, None, None

    def hidden(self, kernel: np.ndarray) -> np.ndarray | None:
        """The silhouette dilated by `kernel`, greyed out for the other trackers; made when first
        asked for (with one person followed nobody asks, but on a search frame)."""
        if self._hidden is None and self.silhouette is not None:
            self._hidden = cv2.dilate(self.silhouette, kernel).astype(bool)
        return self._hidden

    def reset(self) -> None:
        self.tracker.close()
        self.tracker = _tracker()
        self.idle()


def detect_people(frames: Iterable[np.ndarray], settings: DetectionSettings = DetectionSettings(),
                  progress: Callable[[int], object] | None = None) -> ViewPeople:
    """Every person MediaPipe Pose finds in a video's frames, up to settings.max_people at once.

    Args:
        frames: the video's frames in order, (H, W, 3) BGR uint8.
        settings: see DetectionSettings.
        progress: called with 1 after each frame.

    Raises:
        InputError: MediaPipe is not installed, or `frames` holds none.
    """
    slots = [_Slot() for _ in range(settings.max_people)]
    schedule = SearchSchedule()
    keypoints: list[np.ndarray] = []
    visibility: list[np.ndarray] = []
    masks: list[CroppedMasks] = []
    size = (0, 0)
    try:
        with captured_native_stderr():
            for index, frame in enumerate(frames):
                height, width = frame.shape[:2]
                if not masks:
                    size = (width, height)
                    masks = [CroppedMasks(size) for _ in slots]
                scale = min(1.0, settings.detect_height / height) if settings.detect_height else 1.0
                fed = (cv2.resize(frame, (max(int(round(width * scale)), 1), max(int(round(height * scale)), 1)),
                                  interpolation=cv2.INTER_AREA) if scale < 1.0 else frame)
                rgb = cv2.cvtColor(fed, cv2.COLOR_BGR2RGB)
                marks, seen = _frame_people(slots, rgb, (width, height), index, schedule, settings, masks)
                keypoints.append(marks)
                visibility.append(seen)
                if progress is not None:
                    progress(1)
    finally:
        for slot in slots:
            slot.tracker.close()
    if not keypoints:
        raise InputError("frames: expected at least one frame, found none")
    return ViewPeople(np.array(keypoints), np.array(visibility), masks, size)


def _frame_people(slots: list[_Slot], rgb: np.ndarray, size: tuple[int, int], frame: int, schedule: SearchSchedule,
                  settings: DetectionSettings, masks: list[CroppedMasks]) -> tuple[np.ndarray, np.ndarray]:
    """Run the active trackers (and, when the schedule says, the idle ones in turn) on one frame;
    append each slot's mask to `masks`; return its (K, 33, 2) landmarks and (K, 33) visibility."""
    width, height = size
    marks = np.full((len(slots), len(LANDMARKS), 2), np.nan)
    seen = np.zeros((len(slots), len(LANDMARKS)))
    found_masks = [_EMPTY_CROP] * len(slots)
    radius = max(int(round(DILATION_SHARE * rgb.shape[0])), 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    searching = schedule.due(frame)
    searched = found = lost = False
    for k, slot in enumerate(slots):
        was_active = slot.active
        if not was_active:
            if not searching:
                continue
            # Idle trackers search one after the other, each with the people found so far greyed
            # out, until one finds nobody.
            searching, searched = False, True
        fed = rgb
        others = [hidden for j, other in enumerate(slots) if j != k and (hidden := other.hidden(kernel)) is not None]
        if others:
            fed = rgb.copy()
            for hidden in others:
                fed[hidden] = GREY
        result = slot.tracker.process(fed)
        if result.pose_landmarks is None:
            lost = lost or was_active
            slot.idle()
            continue
        landmarks = result.pose_landmarks.landmark
        points = np.array([(m.x * width, m.y * height) for m in landmarks])
        scores = np.array([m.visibility for m in landmarks])
        if _duplicate(points, scores, marks, seen, height):
            lost = lost or was_active
            slot.reset()
            continue
        marks[k], seen[k] = points, scores
        if not was_active:  # this search found someone: the next idle tracker tries
            searching, found = True, True
        probability = result.segmentation_mask
        if probability is None:
            slot.follows(None)
            continue
        slot.follows((probability > settings.mask_threshold).astype(np.uint8))
        found_masks[k] = _mask_crop(probability, settings.mask_threshold, size)
    schedule.update(frame, searched, found, lost)
    for store, (top, left, crop) in zip(masks, found_masks, strict=True):
        store.append_crop(top, left, crop)
    return marks, seen


def _duplicate(points: np.ndarray, scores: np.ndarray, marks: np.ndarray, seen: np.ndarray, height: int) -> bool:
    """Whether a tracker's person is one another tracker already holds in this frame."""
    for other_points, other_scores in zip(marks, seen, strict=True):
        both = (scores > 0.5) & (other_scores > 0.5) & np.isfinite(other_points[:, 0])
        if both.sum() >= 5 and np.median(np.linalg.norm(points[both] - other_points[both], axis=1)) \
                < SAME_PERSON_SHARE * height:
            return True
    return False
