"""The subject calibration's joint groups, keypoint stiffness classes and cost weights.

The groups (:data:`SCALE_GROUPS`, :data:`SHIFT_GROUPS`) are the calibration's segment unknowns, one
parameter each; the keypoint sets say which offsets are stiff; :class:`CalibrationSettings` holds
the weights of the cost that :mod:`ibik_pin.subject.calibration` minimises (its docstring gives the
cost and what each weight decides).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ibik_pin.exceptions import InputError

__all__ = [
    "JOINT_CENTRE_KEYPOINTS",
    "SCALE_GROUPS",
    "SHIFT_GROUPS",
    "SHOULDER_KEYPOINTS",
    "CalibrationSettings",
]

_ALL = (1.0, 1.0, 1.0)
_SAGITTAL = (1.0, 1.0, 0.0)
_LATERAL = (0.0, 0.0, 1.0)

#: Segment group -> (joint, axes) whose placement translation in its parent the group scales.
#: Together they cover every joint placement of example-robot-data's human; the trunk holds the
#: pelvis (the hip joints' height and depth below the spine base) with the spine and clavicles.
SCALE_GROUPS: dict[str, tuple[tuple[str, tuple[float, float, float]], ...]] = {
    "pelvis_width": (("left_hip_Z", _LATERAL), ("right_hip_Z", _LATERAL)),
    "left_thigh": (("left_knee_Z", _ALL),),
    "right_thigh": (("right_knee_Z", _ALL),),
    "left_shank": (("left_ankle_Y", _ALL),),
    "right_shank": (("right_ankle_Y", _ALL),),
    "trunk": (
        ("left_hip_Z", _SAGITTAL),
        ("right_hip_Z", _SAGITTAL),
        ("middle_thoracic_Z", _ALL),
        ("middle_cervical_Z", _ALL),
        ("left_clavicle_joint_X", _ALL),
        ("right_clavicle_joint_X", _ALL),
        ("left_shoulder_Z", _SAGITTAL),
        ("right_shoulder_Z", _SAGITTAL),
    ),
    "shoulder_width": (("left_shoulder_Z", _LATERAL), ("right_shoulder_Z", _LATERAL)),
    "left_upper_arm": (("left_elbow_Z", _ALL),),
    "right_upper_arm": (("right_elbow_Z", _ALL),),
    "left_forearm": (("left_wrist_Z", _ALL),),
    "right_forearm": (("right_wrist_Z", _ALL),),
}

#: Joint shift -> (joint, unit direction in its parent's frame) moved together by one distance [m]:
#: how high the shoulders sit on the trunk, which no segment's length says.
SHIFT_GROUPS: dict[str, tuple[tuple[str, tuple[float, float, float]], ...]] = {
    "shoulder_height": (("left_shoulder_Z", (0.0, 1.0, 0.0)), ("right_shoulder_Z", (0.0, 1.0, 0.0))),
}

#: Keypoints at a joint centre of the model: their offsets are stiff (see
#: :mod:`ibik_pin.subject.calibration`).
JOINT_CENTRE_KEYPOINTS = frozenset(
    {"LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle", "LElbow", "RElbow", "LWrist", "RWrist"}
)

#: The shoulders, less stiff: where a data set puts its shoulder (the joint centre, the top of the
#: humeral head, the acromion) varies more, and the joint itself moves with :data:`SHIFT_GROUPS`.
SHOULDER_KEYPOINTS = frozenset({"LShoulder", "RShoulder"})


@dataclasses.dataclass(frozen=True)
class CalibrationSettings:
    """Weights of the calibration cost (:mod:`ibik_pin.subject.calibration`) and how hard to solve it.

    Attributes:
        offset_weight: cost of moving a keypoint from the start's placement, per metre, relative
            to a keypoint missed in one frame (dimensionless). 0.1: a 4 cm move costs what a 4 mm
            miss does in one frame.
        joint_centre_stiffness: factor on ``offset_weight`` for :data:`JOINT_CENTRE_KEYPOINTS`.
        shoulder_stiffness: factor on ``offset_weight`` for :data:`SHOULDER_KEYPOINTS`.
        scale_weight: cost of moving a joint by a segment scale or a shift, per metre of the
            joints' displacement (dimensionless).
        fit_scales: False keeps the start model's segments (scale_human's lengths, no shift) and
            fits only the keypoint placements and poses.
        spine_posture_weight: pull of the lumbar and thoracic angles toward neutral [m/rad].
        clavicle_posture_weight: pull of the clavicles' elevation toward neutral [m/rad].
            Stronger than the shoulder-height shift's cost: shoulders higher than the model's in
            the static trial are the subject's build more often than a shrug.
        neck_posture_weight: pull of the neck's angles toward neutral [m/rad]. Weak: a Head and
            a Nose a few centimetres forward of the model's are a bowed head more often than
            another head shape.
        limb_posture_weight: pull of every other joint angle toward neutral [m/rad].
        max_offset: bound on each coordinate of a keypoint's move from the start's placement [m].
        max_shift: bound on a joint shift of :data:`SHIFT_GROUPS` [m].
        max_frames: at most this many static frames, evenly spread, are fitted.
        robust_scale: keypoint distance [m] beyond which a miss counts linearly, not squared
            (Huber's loss), so that a few inconsistent keypoints of a markerless triangulation
            do not bend the placements of all the others; 0 for plain least squares.
        iterations: Levenberg-Marquardt steps of the joint fit.
        pose_iterations: Levenberg-Marquardt steps of the first stage (poses alone).
    """

    offset_weight: float = 0.1
    joint_centre_stiffness: float = 10.0
    shoulder_stiffness: float = 3.0
    scale_weight: float = 0.1
    fit_scales: bool = True
    spine_posture_weight: float = 0.005
    clavicle_posture_weight: float = 0.05
    neck_posture_weight: float = 0.01
    limb_posture_weight: float = 0.001
    max_offset: float = 0.3
    max_shift: float = 0.15
    max_frames: int = 10
    robust_scale: float = 0.02
    iterations: int = 100
    pose_iterations: int = 60

    def __post_init__(self) -> None:
        for name in ("offset_weight", "joint_centre_stiffness", "shoulder_stiffness", "scale_weight",
                     "spine_posture_weight", "clavicle_posture_weight", "neck_posture_weight",
                     "limb_posture_weight", "max_offset", "max_shift", "robust_scale"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise InputError(f"CalibrationSettings.{name}: expected a finite value >= 0, got {value}")
        for name in ("max_frames", "iterations", "pose_iterations"):
            if int(getattr(self, name)) < 1:
                raise InputError(f"CalibrationSettings.{name}: expected >= 1, got {getattr(self, name)}")

