"""A tree of small trials laid out as Pose2Sim lays out a session, for `ibik batch`.

The motion is the bundled CMU subject 35 walking (ibik_pin/data): the model is scaled to the
subject, posed on every frame once, and each trial is a different window of it, rendered into
the same small calibrated cameras. The tree::

    ROOT/calibration/Calib_synthetic.toml      the session's cameras, found by every trial
    ROOT/P1/static/static.trc                  a static trial: P1 is calibrated once from it
    ROOT/P1/walk_1/targets.trc, masks/cam1 ..  a trial: end-effector targets and silhouettes
    ROOT/P2/walk_1/ ...                        P2 has no static trial: scaled from its targets
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ibik_pin.evaluation import ESTIMATED
from ibik_pin.exceptions import InputError
from ibik_pin.human import load_human
from ibik_pin.io.asf_amc import read_asf_amc
from ibik_pin.io.trc import TrcData, read_trc, write_trc
from ibik_pin.subject.scaling import scale_human, segment_lengths_from_keypoints
from ibik_pin.synthetic.dataset import write_dataset
from ibik_pin.synthetic.mocap import keypoints_from_motion, pose_model_to_keypoints
from ibik_pin.synthetic.rig import humaneva_rig

__all__ = ["write_trial_tree"]

DATA = Path(__file__).resolve().parent.parent / "data"
# HumanEva's 700 px focal length at 640 px width, kept in proportion for smaller images.
FOCAL_PER_WIDTH = 700.0 / 640.0


def write_trial_tree(
    root: str | Path,
    trials_per_participant: Sequence[int] = (3, 3),
    frames: int = 5,
    views: int = 2,
    size: tuple[int, int] = (160, 120),
    frame_step: int = 8,
    static_participants: Sequence[int] = (0,),
    seed: int = 0,
) -> list[Path]:
    """Write the tree (see the module docstring) under `root`; returns the trial folders.

    Args:
        root: the session folder (created; files of the same names are replaced).
        trials_per_participant: number of trials of participant P1, P2, ...
        frames: frames per trial.
        views: number of cameras.
        size: (width, height) of every camera [px].
        frame_step: the motion (120 Hz) is sampled every `frame_step` frames.
        static_participants: indices (0 for P1) of the participants given a static trial.
        seed: seeds the cameras' placement.

    Raises:
        InputError: more frames asked than the bundled motion holds.
    """
    root = Path(root)
    motion = read_asf_amc(DATA / "35.asf", DATA / "35_01_first240.amc").subset(slice(0, None, frame_step))
    names, positions = keypoints_from_motion(motion, "asf")
    if frames > len(positions):
        raise InputError(f"frames: at most {len(positions)} at frame_step {frame_step}, got {frames}")
    total = sum(trials_per_participant)
    # Trials overlap when the motion is short: window k starts `stride` frames after window k-1.
    stride = max(1, (len(positions) - frames) // max(1, total - 1))
    body = scale_human(load_human(), segment_lengths_from_keypoints(names, positions))
    q, _ = pose_model_to_keypoints(body, names, positions)
    center = np.nanmean(positions[:, names.index("Hip")], axis=0)
    cameras = humaneva_rig(views, center, size=size, focal_px=FOCAL_PER_WIDTH * size[0], seed=seed)
    targets = [name for name in names if name not in ESTIMATED]

    trial_folders = []
    with tempfile.TemporaryDirectory() as scratch:
        index = 0
        for participant, count in enumerate(trials_per_participant):
            participant_folder = root / f"P{participant + 1}"
            for trial in range(count):
                start = min(index * stride, len(positions) - frames)
                dataset = write_dataset(Path(scratch) / f"{index}", body, q[start:start + frames], cameras,
                                        motion.frame_rate, targets, seed=seed)
                folder = participant_folder / f"walk_{trial + 1}"
                shutil.rmtree(folder, ignore_errors=True)
                folder.mkdir(parents=True)
                shutil.move(str(dataset.targets), folder / "targets.trc")
                shutil.move(str(dataset.masks), folder / "masks")
                if index == 0:
                    (root / "calibration").mkdir(parents=True, exist_ok=True)
                    shutil.copy(dataset.calibration, root / "calibration" / "Calib_synthetic.toml")
                if trial == 0 and participant in static_participants:
                    truth = read_trc(dataset.truth)
                    (participant_folder / "static").mkdir(exist_ok=True)
                    write_trc(participant_folder / "static" / "static.trc", TrcData(
                        marker_names=truth.marker_names, times=truth.times[:1], positions=truth.positions[:1],
                        units=truth.units, data_rate=truth.data_rate, frame_numbers=truth.frame_numbers[:1]))
                trial_folders.append(folder)
                index += 1
    return trial_folders
