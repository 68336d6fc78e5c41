"""The tests' rendered real walking: 30 frames of CMU 35_01 posed on the scaled model and seen by
HumanEva-like cameras."""

import numpy as np

from ibik_pin.app.demo import DATA
from ibik_pin.evaluation import ESTIMATED
from ibik_pin.human import load_human
from ibik_pin.io.asf_amc import read_asf_amc
from ibik_pin.subject.scaling import scale_human, segment_lengths_from_keypoints
from ibik_pin.synthetic.mocap import keypoints_from_motion, pose_model_to_keypoints
from ibik_pin.synthetic.rig import humaneva_rig
from ibik_pin.synthetic.silhouettes import render_silhouettes


def walking_clip(views: int):
    """30 frames of CMU 35_01 (the demo's walking, every second frame at 60 Hz): the scaled model,
    `views` HumanEva-like cameras, the model's silhouettes posed on the mocap, the target names and
    positions (every keypoint but the elbows and knees) and the mocap's elbows and knees."""
    motion = read_asf_amc(DATA / "35.asf", DATA / "35_01_first240.amc").subset(slice(0, 60, 2))
    names, positions = keypoints_from_motion(motion, "asf")
    body = scale_human(load_human(), segment_lengths_from_keypoints(names, positions))
    q, _ = pose_model_to_keypoints(body, names, positions)
    cameras = humaneva_rig(views, np.nanmean(positions[:, names.index("Hip")], axis=0), seed=0)
    masks = [render_silhouettes(body, pose, cameras) for pose in q]
    kept = [k for k, name in enumerate(names) if name not in ESTIMATED]
    truth = positions[:, [names.index(name) for name in ESTIMATED]]
    return body, cameras, masks, [names[k] for k in kept], positions[:, kept], truth
