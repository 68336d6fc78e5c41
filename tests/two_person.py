"""A two-person clip for the tests, composited from a real one-person multi-view clip (Pose2Sim's
demo): the subject's own pixels from another moment, pasted as a second person walking a circle
about the subject (ibik_pin.synthetic.people). The subject's reference triangulation stays valid."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.trc import read_trc
from ibik_pin.io.video import VideoReader, read_frames
from ibik_pin.synthetic.people import circle_path, composite_second_person
from ibik_pin.vision.camera import cameras_in_frame
from ibik_pin.vision.people import DetectionSettings, detect_people

# The walker: 1.3 m from the subject, at a walking pace, its pose the subject's half a clip later.
RADIUS_M = 1.3
START_DEG = 200.0
SPEED_M_S = 1.4
SHIFT_SHARE = 0.5


def write_two_person_clip(videos: Path, calibration: Path, reference_trc: Path, out: Path,
                          frames: int | None = None, start_deg: float = START_DEG) -> Path:
    """The composited clip's videos (mp4, same names and frame rate) in `out`; returns `out`.
    `start_deg`: where on its circle the walker starts."""
    out.mkdir(parents=True, exist_ok=True)
    names = sorted(path.name for path in videos.glob("cam*.mp4"))
    cameras = cameras_in_frame(read_calibration(calibration), POSE2SIM_TRC_TO_WORLD)
    trc = read_trc(reference_trc)
    index = {name: i for i, name in enumerate(trc.marker_names)}
    clips = [list(read_frames(videos / name, frames)) for name in names]
    count = min(len(clip) for clip in clips)
    clips = [clip[:count] for clip in clips]
    centres = 0.5 * (trc.positions[:count, index["LHip"]] + trc.positions[:count, index["RHip"]])
    masks = [detect_people(clip, DetectionSettings(max_people=1, detect_height=0)).masks[0] for clip in clips]
    with VideoReader(videos / names[0]) as reader:
        fps = reader.fps
    offsets = circle_path(count, RADIUS_M, start_deg, SPEED_M_S, fps)
    composited = composite_second_person(clips, [list(m) for m in masks], cameras, centres, offsets,
                                         int(round(SHIFT_SHARE * count)))
    for name, images in zip(names, composited, strict=True):
        height, width = images[0].shape[:2]
        writer = cv2.VideoWriter(str(out / name), cv2.VideoWriter_fourcc(*"mp4v"), fps, (width, height))
        for image in images:
            writer.write(np.ascontiguousarray(image))
        writer.release()
    return out
