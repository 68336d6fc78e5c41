"""The benchmark's clips: which recordings, which windows, which static trials, at 60 Hz.

Walking: CMU ASF/AMC 35_01 and 39_01, CMU BVH 131_01. Boxing: three 2-s windows of Boxing_Toes.bvh
where the arms move most (:func:`arm_motion_windows`). A clip is resampled to 60 Hz (every other
frame of the 120 Hz CMU files; linear interpolation of the joint positions for the 100 Hz boxing
file, whose bones then shorten by at most about 0.1 % during the fastest punches) and expressed in
the frame of :func:`ibik_pin.synthetic.mocap.keypoints_from_motion` (Y up, the subject facing +X at
the first frame), every joint of the skeleton as well as the Pose2Sim keypoints.

The static trial comes from another trial of the same subject where one exists (35_02 for 35_01,
131_02 for 131_01: its first half second, standing still), else from frames of the same file
outside the evaluated window (39_01: its end; boxing: its first half second, in guard).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ibik_pin.exceptions import IbikWarning, InputError, UnknownNameError
from ibik_pin.io.asf_amc import read_asf_amc
from ibik_pin.io.bvh import CMU_BVH_SCALE, read_bvh
from ibik_pin.io.skeleton import SkeletonMotion
from ibik_pin.synthetic.mocap import facing_directions, keypoints_from_motion

RATE_HZ = 60.0
STATIC_FRAMES = 10  # frames of the static trial, 1/20 s apart (half a second)
STATIC_SPACING_S = 0.05
# The keypoints the tracker must estimate; every other keypoint is a target.
ESTIMATED = ("LElbow", "RElbow", "LKnee", "RKnee")


@dataclass(frozen=True)
class ClipSpec:
    """One evaluated window of a recording.

    Attributes:
        name: the clip's name in tables.
        kind: "walking" (the knees are what the paper judges) or "boxing" (the elbows).
        file: the motion file, relative to the data folder.
        source: the keypoints_from_motion source: "asf", "cmu_bvh" or "boxing".
        start_s: start of the window in the file [s].
        asf: the ASF skeleton of an AMC file, relative to the data folder.
        static_file: the static trial's file (another trial of the subject); None: the same file.
        static_start_s: where in it the static frames start [s].
    """

    name: str
    kind: str
    file: str
    source: str
    start_s: float
    asf: str | None = None
    static_file: str | None = None
    static_start_s: float = 0.0


# 131_01 walks from 4.2 s to 6.5 s (before: a start, a stride and kneeling on one knee at 3-3.5 s).
# Boxing windows: the three non-overlapping 2-s windows of highest mean speed of the elbows and
# wrists relative to the chest, with the subject upright (arm_motion_windows(motion, 3, 2.0);
# scores 7.9, 6.6 and 4.3 m/s summed over the four joints). The file's last third (a fall) is out.
CLIPS: dict[str, ClipSpec] = {spec.name: spec for spec in (
    ClipSpec("cmu35_01", "walking", "cmu/35_01.amc", "asf", 0.0, asf="cmu/35.asf",
             static_file="cmu/35_02.amc", static_start_s=0.0),
    ClipSpec("cmu39_01", "walking", "cmu/39_01.amc", "asf", 0.0, asf="cmu/39.asf",
             static_file=None, static_start_s=2.55),
    ClipSpec("cmu131_01", "walking", "bvh/131_01.bvh", "cmu_bvh", 4.3,
             static_file="bvh/131_02.bvh", static_start_s=0.0),
    ClipSpec("boxing_a", "boxing", "bvh/Boxing_Toes.bvh", "boxing", 3.3, static_start_s=0.0),
    ClipSpec("boxing_b", "boxing", "bvh/Boxing_Toes.bvh", "boxing", 5.4, static_start_s=0.0),
    ClipSpec("boxing_c", "boxing", "bvh/Boxing_Toes.bvh", "boxing", 8.5, static_start_s=0.0),
)}


@dataclass
class MocapClip:
    """A window of real motion capture at 60 Hz, in the keypoints' frame (Y up) [m].

    Attributes:
        spec: what it is.
        frame_rate: [Hz].
        joint_names, parents: the mocap skeleton (every joint, end sites included).
        joints: (F, J, 3) positions of every joint.
        keypoint_names: the Pose2Sim keypoints of the source; keypoints: (F, K, 3).
        static_joints: (S, J, 3), static_keypoints: (S, K, 3): the static trial's frames.
    """

    spec: ClipSpec
    frame_rate: float
    joint_names: list[str]
    parents: np.ndarray
    joints: np.ndarray
    keypoint_names: list[str]
    keypoints: np.ndarray
    static_joints: np.ndarray
    static_keypoints: np.ndarray

    @property
    def target_names(self) -> list[str]:
        """Every keypoint but the estimated elbows and knees."""
        return [name for name in self.keypoint_names if name not in ESTIMATED]

    def keypoint(self, name: str) -> np.ndarray:
        """(F, 3) positions of one keypoint [m]."""
        return self.keypoints[:, self.keypoint_names.index(name)]

    def facing(self) -> np.ndarray:
        """(3,) mean horizontal direction the subject faces over the window."""
        facing = np.nanmean(facing_directions(self.keypoint_names, self.keypoints), axis=0)
        return facing / np.linalg.norm(facing)


def load_motion(path: Path, source: str, asf: Path | None = None) -> SkeletonMotion:
    """Every joint of a recording [m]: ASF/AMC, a CMU BVH (CMU_BVH_SCALE) or the boxing BVH (cm)."""
    if source == "asf":
        if asf is None:
            raise InputError(f"{path}: an AMC file needs its ASF skeleton")
        return read_asf_amc(asf, path)
    scale = CMU_BVH_SCALE if source == "cmu_bvh" else 0.01
    with warnings.catch_warnings():  # Boxing_Toes.bvh holds one frame more than it declares
        warnings.simplefilter("ignore", IbikWarning)
        return read_bvh(path, scale=scale).to_skeleton_motion()


def resample(motion: SkeletonMotion, start_s: float, count: int, rate: float = RATE_HZ) -> SkeletonMotion:
    """`count` frames at `rate` from `start_s`: exact frames where the rates divide, else linear.

    Raises:
        InputError: the window runs past the recording's end.
    """
    times = float(start_s) + np.arange(int(count)) / rate
    position = times * motion.frame_rate
    last = motion.positions.shape[0] - 1
    if count < 1 or start_s < 0.0 or position[-1] > last + 1e-6:
        needed, available = position[-1] / motion.frame_rate, last / motion.frame_rate
        raise InputError(f"window: {count} frames at {rate:g} Hz from {start_s:g} s need {needed:.3f} s, "
                         f"the recording has {available:.3f} s")
    lower = np.clip(np.floor(position + 1e-6).astype(int), 0, max(last - 1, 0))
    fraction = np.clip(position - lower, 0.0, 1.0)
    fraction[np.abs(fraction) < 1e-6] = 0.0
    upper = np.minimum(lower + 1, last)
    positions = ((1.0 - fraction)[:, None, None] * motion.positions[lower]
                 + fraction[:, None, None] * motion.positions[upper])
    return SkeletonMotion(motion.names, motion.parents, positions, rate)


def keypoints_and_joints(motion: SkeletonMotion, source: str) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The Pose2Sim keypoints of a motion and every joint of it, in the keypoints' frame.

    keypoints_from_motion turns the motion about the vertical (its first frame facing +X); the same
    rotation is read back by passing it three extra frames with every joint at a unit vector, and
    applied to all joints.

    Returns:
        names (K), keypoints (F, K, 3), joints (F, J, 3) [m].
    """
    names, keypoints = keypoints_from_motion(motion, source)
    joint_count = len(motion.names)
    probe = np.concatenate([motion.positions[:1], np.repeat(np.eye(3)[:, None, :], joint_count, axis=1)])
    _, probed = keypoints_from_motion(SkeletonMotion(motion.names, motion.parents, probe, motion.frame_rate),
                                      source)
    rotation = probed[1:4, 0].T  # column i is the image of the unit vector e_i
    joints = motion.positions @ rotation.T
    gap = np.min(np.linalg.norm(keypoints[:, :, None] - joints[:, None], axis=3), axis=2)
    if np.max(gap) > 1e-9:  # every keypoint must be one of the rotated joints
        raise InputError(f"motion: keypoints and joints disagree by {np.max(gap):.3g} m after rotation")
    return list(names), keypoints, joints


def load_clip(spec: ClipSpec, data: Path, frames: int, rate: float = RATE_HZ) -> MocapClip:
    """A clip's window (`frames` frames at `rate`) and its static trial, read from `data`."""
    data = Path(data)
    motion = load_motion(data / spec.file, spec.source, data / spec.asf if spec.asf else None)
    window = resample(motion, spec.start_s, frames, rate)
    names, keypoints, joints = keypoints_and_joints(window, spec.source)
    static_motion = motion if spec.static_file is None else load_motion(
        data / spec.static_file, spec.source, data / spec.asf if spec.asf else None)
    static = resample(static_motion, spec.static_start_s, STATIC_FRAMES, 1.0 / STATIC_SPACING_S)
    static_names, static_keypoints, static_joints = keypoints_and_joints(static, spec.source)
    if static_names != names or static.names != window.names:
        raise UnknownNameError(f"{spec.static_file}: its skeleton differs from {spec.file}'s")
    return MocapClip(spec, rate, list(window.names), window.parents.copy(), joints, names, keypoints,
                     static_joints, static_keypoints)


def arm_motion_windows(
    motion: SkeletonMotion,
    count: int,
    seconds: float,
    chest: str = "Chest",
    arm_joints: tuple[str, ...] = ("LeftElbow", "RightElbow", "LeftWrist", "RightWrist"),
    pelvis: str = "Hips",
    upright_height_m: float = 0.7,
    step_s: float = 0.1,
) -> list[tuple[float, float]]:
    """The `count` non-overlapping windows where the arms move most relative to the chest.

    Score: the mean over the window of the summed speeds of `arm_joints` relative to `chest`
    [m/s]; only windows where `pelvis` stays above `upright_height_m` (the subject upright).

    Returns:
        (start [s], score [m/s]) per window, best first.
    """
    positions = motion.positions
    relative = positions[:, [motion.index(name) for name in arm_joints]] - positions[:, [motion.index(chest)]]
    speed = np.linalg.norm(np.diff(relative, axis=0), axis=2).sum(axis=1) * motion.frame_rate
    upright = positions[:, motion.index(pelvis), 1] > upright_height_m
    length = int(round(seconds * motion.frame_rate))
    step = max(int(round(step_s * motion.frame_rate)), 1)
    candidates = sorted(((float(speed[s:s + length].mean()), s) for s in range(0, len(speed) - length, step)
                         if upright[s:s + length + 1].all()), reverse=True)
    chosen: list[tuple[float, int]] = []
    for score, start in candidates:
        if all(abs(start - other) >= length for _, other in chosen):
            chosen.append((score, start))
        if len(chosen) == count:
            break
    return [(start / motion.frame_rate, score) for score, start in chosen]
