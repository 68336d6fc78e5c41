"""2D detections written in OpenPose's JSON layout, one file per frame and camera, as Pose2Sim's
pose/ folder holds them: pose/<camera>_json/<camera>_<frame, 12 digits>_keypoints.json, each with
"people": [{"person_id": [...], "pose_keypoints_2d": [x0, y0, c0, x1, y1, c1, ...]}].

The keypoints are BlazePose's 33 landmarks in MediaPipe's order (Pose2Sim's `pose_model =
"BLAZEPOSE"`), in pixels of the full frame, the confidence MediaPipe's visibility; a landmark not
found is written 0, 0, 0 as OpenPose does.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ibik_pin.io.files import PathLike

__all__ = ["POSE_FOLDER", "read_openpose_frames", "write_openpose_frames"]

POSE_FOLDER = "pose"


def write_openpose_frames(folder: PathLike, camera: str, keypoints: np.ndarray, visibility: np.ndarray,
                          person_ids: np.ndarray | None = None) -> Path:
    """Write one camera's detections, one JSON file per frame; returns the camera's folder.

    Args:
        folder: the pose/ folder (made if missing).
        camera: the camera's name (the sub-folder is <camera>_json).
        keypoints: (F, K, L, 2) pixels of L keypoints of K people slots, NaN where absent.
        visibility: (F, K, L) confidence in [0, 1].
        person_ids: (F, K) each slot's person (-1 unknown), written as "person_id"; None: -1.
    """
    keypoints = np.asarray(keypoints, dtype=float)
    frames, slots = keypoints.shape[:2]
    out = Path(folder) / f"{camera}_json"
    out.mkdir(parents=True, exist_ok=True)
    for frame in range(frames):
        people = []
        for slot in range(slots):
            pixels = keypoints[frame, slot]
            if not np.isfinite(pixels).any():
                continue
            found = np.isfinite(pixels).all(axis=1)
            triples = np.column_stack((np.where(found[:, None], pixels, 0.0),
                                       np.where(found, visibility[frame, slot], 0.0)))
            person = -1 if person_ids is None else int(person_ids[frame, slot])
            people.append({"person_id": [person], "pose_keypoints_2d": [round(float(v), 3) for v in triples.ravel()],
                           "face_keypoints_2d": [], "hand_left_keypoints_2d": [], "hand_right_keypoints_2d": [],
                           "pose_keypoints_3d": [], "face_keypoints_3d": [], "hand_left_keypoints_3d": [],
                           "hand_right_keypoints_3d": []})
        (out / f"{camera}_{frame:012d}_keypoints.json").write_text(
            json.dumps({"version": 1.3, "people": people}), encoding="utf-8")
    return out


def read_openpose_frames(folder: PathLike) -> list[list[list[float]]]:
    """Each frame's people's pose_keypoints_2d, from a <camera>_json folder (files in name order)."""
    files = sorted(Path(folder).glob("*_keypoints.json"))
    return [[person["pose_keypoints_2d"] for person in json.loads(path.read_text(encoding="utf-8"))["people"]]
            for path in files]


