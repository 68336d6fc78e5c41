"""2D body keypoints and the person's silhouette in every frame of a video, from MediaPipe Pose.

MediaPipe Pose (BlazePose, Apache 2.0) detects one person, then tracks that person from frame to
frame: 33 landmarks with a visibility score, and a segmentation of the same person (the people
behind, a mannequin or a skeleton on a stand are not in it). It is optional: release 0.10.21 is the
last whose wheel carries its models (later ones fetch them at run time, which fails offline), and it
declares numpy < 2, which this package does not need: `MEDIAPIPE_INSTALL` installs it without its
declared dependencies beside the `video` extra, which supplies the ones it really imports (it runs
with numpy 2; tests/test_learned_pose.py runs it wherever it is installed).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from importlib import util

import cv2
import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.native_output import captured_native_stderr
from ibik_pin.vision.mask_store import CroppedMasks

__all__ = ["LANDMARKS", "MEDIAPIPE_INSTALL", "VideoPose", "detect_pose_in_frames", "learned_pose_available"]

MEDIAPIPE_INSTALL = "pip install 'ibik_pin[video]' && pip install --no-deps mediapipe==0.10.21"

# BlazePose's 33 landmarks, in its output order (MediaPipe's PoseLandmark enum).
LANDMARKS = (
    "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye", "right_eye_outer",
    "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder", "right_shoulder", "left_elbow",
    "right_elbow", "left_wrist", "right_wrist", "left_pinky", "right_pinky", "left_index", "right_index",
    "left_thumb", "right_thumb", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
    "left_heel", "right_heel", "left_foot_index", "right_foot_index",
)


def learned_pose_available() -> bool:
    """Whether MediaPipe is installed (see MEDIAPIPE_INSTALL)."""
    return util.find_spec("mediapipe") is not None


@dataclass
class VideoPose:
    """What MediaPipe Pose found in each frame of one video.

    Attributes:
        keypoints: (F, 33, 2) pixel positions (u right, v down) of LANDMARKS, NaN in a frame where
            no person was found.
        visibility: (F, 33) MediaPipe's visibility score in [0, 1] (0 where no person was found).
        masks: F (H, W) bool silhouettes of the person it tracks.
    """

    keypoints: np.ndarray
    visibility: np.ndarray
    masks: CroppedMasks


def _solution(model_complexity: int):
    """MediaPipe's Pose solution in tracking mode with its segmentation, its log lines silenced."""
    os.environ.setdefault("GLOG_minloglevel", "2")  # MediaPipe's C++ INFO and WARNING lines
    if not learned_pose_available():
        raise InputError(f"learned silhouettes need MediaPipe: {MEDIAPIPE_INSTALL}")
    with captured_native_stderr():  # TensorFlow Lite's delegate banner
        import mediapipe as mp

        # No landmark smoothing: MediaPipe's filter lags the motion by about a frame at 60 fps (on the
        # Pose2Sim demo its landmarks matched Pose2Sim's of the frame before; unsmoothed, the same
        # frame, and the triangulated wrists came 2-6 mm closer). Its segmentation smoothing changed
        # no share of keypoints inside the silhouettes there, and stays.
        return mp.solutions.pose.Pose(static_image_mode=False, model_complexity=model_complexity,
                                      smooth_landmarks=False, enable_segmentation=True, smooth_segmentation=True,
                                      min_detection_confidence=0.5, min_tracking_confidence=0.5)


def detect_pose_in_frames(frames: Iterable[np.ndarray], *, mask_threshold: float = 0.5, model_complexity: int = 1,
                          progress: Callable[[int], object] | None = None) -> VideoPose:
    """MediaPipe Pose's landmarks and person segmentation in every frame of a video.

    Args:
        frames: the video's frames in order, (H, W, 3) BGR uint8 (io.video.read_frames).
        mask_threshold: segmentation probability above which a pixel is the person.
        model_complexity: 1 (BlazePose full, the default) is the model the 0.10.21 wheel ships;
            0 and 2 are downloaded on first use.
        progress: called with 1 after each frame (a progress bar's update).

    Raises:
        InputError: MediaPipe is not installed (the message gives the install command),
            `mask_threshold` is outside (0, 1), or `frames` holds none.
    """
    if not 0.0 < mask_threshold < 1.0:
        raise InputError(f"mask_threshold: expected a probability in (0, 1), found {mask_threshold!r}")
    keypoints, visibility = [], []
    masks: CroppedMasks | None = None
    with _solution(model_complexity) as pose, captured_native_stderr():
        for frame in frames:
            height, width = frame.shape[:2]
            masks = masks if masks is not None else CroppedMasks((width, height))
            found = pose.process(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
            if found.pose_landmarks is None:
                keypoints.append(np.full((len(LANDMARKS), 2), np.nan))
                visibility.append(np.zeros(len(LANDMARKS)))
            else:
                marks = found.pose_landmarks.landmark
                keypoints.append(np.array([(m.x * width, m.y * height) for m in marks]))
                visibility.append(np.array([m.visibility for m in marks]))
            probability = found.segmentation_mask
            masks.append(probability > mask_threshold if probability is not None
                         else np.zeros((height, width), bool))
            if progress is not None:
                progress(1)
    if masks is None:
        raise InputError("frames: expected at least one frame, found none")
    return VideoPose(np.array(keypoints), np.array(visibility), masks)
