"""The whole-body human: example-robot-data's ISB model with Pose2Sim keypoints and segments.

Built on the generic :class:`~ibik_pin.model.BodyModel`, with a third axis at each ankle
(:mod:`ibik_pin.feet`) and, for a calibrated subject, segment radii scaled by its stature.
"""

from __future__ import annotations

import copy
import dataclasses
import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pinocchio as pin

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.feet import add_foot_rotation
from ibik_pin.io.files import as_path, checked_input_file
from ibik_pin.model import BodyModel, add_keypoint_frame, built_from_urdf

HUMAN_URDF_RELATIVE = Path("example-robot-data/robots/human_description/robots/human.urdf")
#: Links of this prefix in a URDF are keypoints (``keypoint_Neck`` is the Neck), see load_human.
KEYPOINT_LINK_PREFIX = "keypoint_"

#: Head height above the lowest foot keypoint of example-robot-data's human at its neutral pose
#: [m], measured by :func:`neutral_stature` (Head 0.693 m above the root, toes 1.049 m below).
HUMAN_NEUTRAL_STATURE_M = 1.742

#: The keypoints a stature is measured down to: the lowest of them is the sole.
FOOT_KEYPOINTS = ("LAnkle", "RAnkle", "LHeel", "RHeel", "LBigToe", "RBigToe", "LSmallToe", "RSmallToe")


def human_urdf_path() -> Path:
    """Path of example-robot-data's human URDF inside the installed package (no network)."""
    for entry in sys.path:
        candidate = Path(entry) / "cmeel.prefix" / "share" / HUMAN_URDF_RELATIVE
        if candidate.is_file():
            return candidate
    raise FileFormatError(
        "example-robot-data's human.urdf was not found under any 'cmeel.prefix/share' of sys.path; "
        "install the package with: pip install example-robot-data"
    )


def human_urdf_tree(path: str | Path) -> ElementTree.ElementTree[ElementTree.Element[str]]:
    """A human URDF parsed, with the foot rotation joints added (see add_foot_rotation).

    Raises:
        FileFormatError: the file cannot be read or is not XML.
    """
    if not Path(path).exists():
        raise FileFormatError(f"URDF file {str(path)!r} does not exist")
    path = checked_input_file(path, "URDF")
    try:
        tree = ElementTree.parse(path)
    except (OSError, ElementTree.ParseError) as error:
        raise FileFormatError(f"URDF {str(path)!r} cannot be read: {error}") from error
    try:
        add_foot_rotation(tree.getroot())
    except FileFormatError as error:
        raise FileFormatError(f"URDF file {str(path)!r}: {error}") from error
    return tree


# Pose2Sim keypoint -> (parent joint, offset [m] in that joint's frame) on example-robot-data's
# human (ISB axes: X forward, Y up, Z to the right; the model's left side is at negative Z).
_HUMAN_KEYPOINTS: dict[str, tuple[str, tuple[float, float, float]]] = {
    "Hip": ("root_joint", (0.0, 0.0, 0.0)),
    "LHip": ("left_hip_Z", (0.0, 0.0, 0.0)),
    "LKnee": ("left_knee_Z", (0.0, 0.0, 0.0)),
    "LAnkle": ("left_ankle_Z", (0.0, 0.0, 0.0)),
    "LBigToe": ("left_ankle_X", (0.15, -0.07, 0.01)),
    "LSmallToe": ("left_ankle_X", (0.13, -0.07, -0.04)),
    "LHeel": ("left_ankle_X", (-0.05, -0.07, 0.0)),
    "RHip": ("right_hip_Z", (0.0, 0.0, 0.0)),
    "RKnee": ("right_knee_Z", (0.0, 0.0, 0.0)),
    "RAnkle": ("right_ankle_Z", (0.0, 0.0, 0.0)),
    "RBigToe": ("right_ankle_X", (0.15, -0.07, -0.01)),
    "RSmallToe": ("right_ankle_X", (0.13, -0.07, 0.04)),
    "RHeel": ("right_ankle_X", (-0.05, -0.07, 0.0)),
    "Neck": ("middle_cervical_Z", (0.0, 0.0, 0.0)),
    "Head": ("middle_cervical_Y", (0.0, 0.22, 0.0)),
    "Nose": ("middle_cervical_Y", (0.1, 0.12, 0.0)),
    "LShoulder": ("left_shoulder_Z", (0.0, 0.0, 0.0)),
    "LElbow": ("left_elbow_Z", (0.0, 0.0, 0.0)),
    "LWrist": ("left_wrist_Z", (0.0, 0.0, 0.0)),
    "LHand": ("left_wrist_X", (0.0, -0.12, 0.0)),
    "RShoulder": ("right_shoulder_Z", (0.0, 0.0, 0.0)),
    "RElbow": ("right_elbow_Z", (0.0, 0.0, 0.0)),
    "RWrist": ("right_wrist_Z", (0.0, 0.0, 0.0)),
    "RHand": ("right_wrist_X", (0.0, -0.12, 0.0)),
}

# (segment, capsule radius [m]): limbs, trunk and head, the parts a silhouette really covers.
_HUMAN_SEGMENTS: list[tuple[tuple[str, str], float]] = [
    (("Hip", "Neck"), 0.13),
    (("LHip", "RHip"), 0.09),
    (("LShoulder", "RShoulder"), 0.06),
    (("Neck", "Head"), 0.08),
    (("LHip", "LKnee"), 0.07),
    (("LKnee", "LAnkle"), 0.05),
    (("LHeel", "LBigToe"), 0.035),
    (("RHip", "RKnee"), 0.07),
    (("RKnee", "RAnkle"), 0.05),
    (("RHeel", "RBigToe"), 0.035),
    (("LShoulder", "LElbow"), 0.045),
    (("LElbow", "LWrist"), 0.035),
    (("LWrist", "LHand"), 0.035),
    (("RShoulder", "RElbow"), 0.045),
    (("RElbow", "RWrist"), 0.035),
    (("RWrist", "RHand"), 0.035),
]

HUMAN_END_EFFECTORS = ["Hip", "LAnkle", "RAnkle", "LWrist", "RWrist", "Head"]


def load_human(urdf_path: str | Path | None = None, free_flyer: bool = True) -> BodyModel:
    """The whole-body human: example-robot-data's 36-DOF ISB model with Pose2Sim keypoints, and a
    third degree of freedom at each ankle (:func:`add_foot_rotation`): 38 in all.

    A URDF with keypoint links (links named ``keypoint_<Name>``, as
    :func:`ibik_pin.subject.urdf.write_subject_urdf` writes a calibrated subject) gives its
    keypoints there instead of at the default placements, keypoints of other names included, and
    the body is marked ``calibrated``; its segment radii are the default ones scaled by its
    stature.

    Args:
        urdf_path: another URDF with the same joint names; default the installed human.urdf.
        free_flyer: add the 6-DOF floating base (45 coordinates, 44 velocities).
    """
    path = as_path(urdf_path, "urdf_path") if urdf_path is not None else human_urdf_path()
    xml = ElementTree.tostring(human_urdf_tree(path).getroot(), encoding="unicode")
    model = built_from_urdf(path, lambda: pin.buildModelFromXML(xml, pin.JointModelFreeFlyer()) if free_flyer
                             else pin.buildModelFromXML(xml))
    model.name = "human"
    lacking = sorted({joint for joint, _ in _HUMAN_KEYPOINTS.values()
                      if joint not in ("root_joint", "universe") and not model.existJointName(joint)})
    if lacking:
        raise FileFormatError(f"URDF file {str(path)!r}: not the human model: it lacks the joint(s) "
                              f"{', '.join(lacking[:4])}{' and more' if len(lacking) > 4 else ''} that carry "
                              "the keypoints (example-robot-data's human joint names are needed)")
    # name -> (link frame index, parent joint, placement), copied: addFrame reallocates the frames
    calibrated = {frame.name[len(KEYPOINT_LINK_PREFIX):]: (index, int(frame.parentJoint), frame.placement.copy())
                  for index, frame in enumerate(model.frames)
                  if frame.type == pin.FrameType.BODY and frame.name.startswith(KEYPOINT_LINK_PREFIX)}
    for name, (joint, offset) in _HUMAN_KEYPOINTS.items():
        if name in calibrated:
            continue
        if joint == "root_joint" and not free_flyer:
            joint = "universe"
        add_keypoint_frame(model, name, joint, np.array(offset))
    for name, (link, joint_index, placement) in calibrated.items():
        if not name or model.existFrame(name):
            raise FileFormatError(f"URDF file {str(path)!r}: keypoint link {KEYPOINT_LINK_PREFIX + name!r} names "
                                  "no keypoint or one that is already a frame of the model")
        model.addFrame(pin.Frame(name, joint_index, link, placement, pin.FrameType.OP_FRAME))
    body = BodyModel(
        model=model,
        keypoints={name: name for name in [*_HUMAN_KEYPOINTS, *(n for n in calibrated if n not in _HUMAN_KEYPOINTS)]},
        segments=[segment for segment, _ in _HUMAN_SEGMENTS],
        segment_radii=np.array([radius for _, radius in _HUMAN_SEGMENTS]),
        end_effectors=list(HUMAN_END_EFFECTORS),
        urdf_path=path,
        calibrated=bool(calibrated),
    )
    if calibrated:
        body.segment_radii = body.segment_radii * (neutral_stature(body) / HUMAN_NEUTRAL_STATURE_M)
    return body


def with_hip_at_hip_joints_midpoint(body: BodyModel) -> BodyModel:
    """A copy of the body whose ``Hip`` keypoint is HALPE_26's: the midpoint of LHip and RHip.

    The model's own ``Hip`` is its root, about 0.1 m above the hip joints; Pose2Sim's HALPE_26
    (and its OpenSim model's ``Hip`` marker) is the LHip/RHip midpoint. The new Hip is fixed to the
    root at that midpoint in the neutral pose (exactly the midpoint in every pose when LHip and
    RHip move with the root, as they do on this project's human, scaled or calibrated).

    Raises:
        UnknownNameError: The body lacks a Hip, LHip or RHip keypoint.
    """
    model = copy.deepcopy(body.model)
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    root = pin.SE3(data.oMi[1]) if model.njoints > 1 else pin.SE3.Identity()
    hips = [data.oMf[body.frame_id(name)].translation for name in ("LHip", "RHip")]
    hip_id = body.frame_id("Hip")
    frame = model.frames[hip_id]
    frame.parentJoint = 1 if model.njoints > 1 else 0
    frame.parentFrame = model.getFrameId(model.names[frame.parentJoint])
    frame.placement = pin.SE3(np.eye(3), root.actInv(0.5 * (hips[0] + hips[1])))
    model.frames[hip_id] = frame
    return dataclasses.replace(body, model=model, keypoints=dict(body.keypoints), segments=list(body.segments),
                               end_effectors=list(body.end_effectors))


def neutral_stature(body: BodyModel) -> float:
    """Head height above the lowest foot keypoint at the neutral pose [m] (Y up).

    The default human measures :data:`HUMAN_NEUTRAL_STATURE_M` = 1.742 m.
    """
    feet = [name for name in FOOT_KEYPOINTS if name in body.keypoints]
    if "Head" not in body.keypoints or not feet:
        raise InputError(
            f"body: expected keypoints Head and at least one of {list(FOOT_KEYPOINTS)} to measure a "
            f"stature, got {list(body.keypoints)}"
        )
    model = body.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    lowest = min(data.oMf[body.frame_id(name)].translation[1] for name in feet)
    return float(data.oMf[body.frame_id("Head")].translation[1] - lowest)
