"""Body models: a Pinocchio model plus the named keypoints and skeleton segments the method needs.

A `BodyModel` says which model frame stands for each keypoint (Pose2Sim names on the human), which
keypoint pairs are the segments projected into the images (eq. 5), and how thick each segment is
(for rendering silhouettes). Keypoints that are not at a model joint are added as operational frames.
"""

from __future__ import annotations

import copy
import dataclasses
import sys
import xml.etree.ElementTree as ElementTree
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from itertools import pairwise
from pathlib import Path

import numpy as np
import pinocchio as pin

from ibik_pin.exceptions import FileFormatError, InputError, UnknownNameError
from ibik_pin.feet import add_foot_rotation
from ibik_pin.io.files import checked_input_file
from ibik_pin.io.native_output import captured_native_stderr

HUMAN_URDF_RELATIVE = Path("example-robot-data/robots/human_description/robots/human.urdf")
#: Links of this prefix in a URDF are keypoints (``keypoint_Neck`` is the Neck), see load_human.
KEYPOINT_LINK_PREFIX = "keypoint_"
# Joint names of the arms and legs (the human URDF's left_elbow_Z, the paper chains' elbow_Z, ...).
LIMB_JOINT_WORDS = ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")


@dataclass
class BodyModel:
    """A kinematic model with the keypoints and segments of the image criterion.

    Attributes:
        model: the Pinocchio model.
        keypoints: keypoint name -> model frame name.
        segments: pairs of keypoint names; each is a rigid segment between two keypoints.
        segment_radii: radius [m] of each segment's capsule, same order as `segments`.
        end_effectors: keypoints that are usually known targets (the rest are estimated).
        urdf_path: the URDF the model was loaded from (its meshes and inertias), if any.
        calibrated: the segments and keypoint placements are a subject's (fitted to a static
            trial, or read from a URDF with keypoint links): tracking must not scale it again.
    """

    model: pin.Model
    keypoints: dict[str, str]
    segments: list[tuple[str, str]]
    segment_radii: np.ndarray
    end_effectors: list[str] = field(default_factory=list)
    urdf_path: Path | None = None
    calibrated: bool = False

    def frame_id(self, keypoint: str) -> int:
        """Model frame index of a keypoint; UnknownNameError lists the known keypoints."""
        if keypoint not in self.keypoints:
            raise UnknownNameError(
                f"keypoint {keypoint!r} is not in model {self.model.name!r}; known keypoints: "
                + ", ".join(self.keypoints)
            )
        return self.model.getFrameId(self.keypoints[keypoint])

    def frame_ids(self, keypoints: list[str]) -> np.ndarray:
        """Frame indices of several keypoints, shape (K,)."""
        return np.array([self.frame_id(name) for name in keypoints], dtype=int)

    @property
    def segment_frame_ids(self) -> np.ndarray:
        """Frame indices of segment ends, shape (S, 2)."""
        return np.array([[self.frame_id(a), self.frame_id(b)] for a, b in self.segments], dtype=int)

    @property
    def limb_coordinates(self) -> np.ndarray:
        """(nv,) bool: the velocity coordinates of the arms and legs, the joints whose name holds
        one of LIMB_JOINT_WORDS (shoulder to wrist, hip to ankle); the root, spine, clavicles and
        neck are the rest."""
        mask = np.zeros(self.model.nv, dtype=bool)
        for joint_id in range(1, self.model.njoints):
            if any(word in self.model.names[joint_id].lower() for word in LIMB_JOINT_WORDS):
                joint = self.model.joints[joint_id]
                mask[joint.idx_v: joint.idx_v + joint.nv] = True
        return mask


def frame_id(model: pin.Model, frame_name: str) -> int:
    """Index of a model frame; UnknownNameError lists the available frames."""
    if not model.existFrame(frame_name):
        names = ", ".join(frame.name for frame in model.frames)
        raise UnknownNameError(
            f"frame {frame_name!r} does not exist in model {model.name!r}; available frames: {names}"
        )
    return model.getFrameId(frame_name)


def load_urdf(path: str | Path, free_flyer: bool = False) -> pin.Model:
    """Load a URDF file into a Pinocchio model.

    Args:
        path: the URDF file.
        free_flyer: add a 6-DOF free-flyer root joint (floating base).
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"URDF file {str(path)!r} does not exist")
    if free_flyer:
        return _built_from_urdf(path, lambda: pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()))
    return _built_from_urdf(path, lambda: pin.buildModelFromUrdf(str(path)))


def _built_from_urdf(path: Path, build: Callable[[], pin.Model]) -> pin.Model:
    """`build()`'s model; its failure a FileFormatError naming the URDF, with Pinocchio's error and
    urdfdom's first line ("Joint [j] is of type REVOLUTE but it does not specify limits"), which
    urdfdom prints to stderr and says what is wrong."""
    with captured_native_stderr() as parser:
        try:
            return build()
        except (RuntimeError, ValueError) as error:
            failure = error
    said = parser.first_line().removeprefix("Error:").strip()
    reason = f"{failure} ({said})" if said else str(failure)
    raise FileFormatError(f"URDF file {str(path)!r} cannot be parsed: {reason}") from failure


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


def add_keypoint_frame(model: pin.Model, name: str, parent_joint: str, offset: np.ndarray) -> None:
    """Add an operational frame `name` at `offset` [m] in the frame of joint `parent_joint`."""
    if not model.existJointName(parent_joint):
        raise UnknownNameError(
            f"joint {parent_joint!r} does not exist in model {model.name!r}; joints: "
            + ", ".join(model.names)
        )
    joint_index = model.getJointId(parent_joint)
    placement = pin.SE3(np.eye(3), np.asarray(offset, dtype=float))
    parent_frame = model.getFrameId(parent_joint)
    model.addFrame(pin.Frame(name, joint_index, parent_frame, placement, pin.FrameType.OP_FRAME))


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
    path = Path(urdf_path) if urdf_path is not None else human_urdf_path()
    xml = ElementTree.tostring(human_urdf_tree(path).getroot(), encoding="unicode")
    model = _built_from_urdf(path, lambda: pin.buildModelFromXML(xml, pin.JointModelFreeFlyer()) if free_flyer
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
        from ibik_pin.subject.scaling import HUMAN_NEUTRAL_STATURE_M, neutral_stature  # scaling imports model

        body.segment_radii = body.segment_radii * (neutral_stature(body) / HUMAN_NEUTRAL_STATURE_M)
    return body


def _project_model(file_name: str) -> Path:
    """Path of one of the project's URDFs (models/ in the repository, ibik_pin.models installed)."""
    return Path(str(resources.files("ibik_pin.models").joinpath(file_name)))


def load_planar_chain() -> BodyModel:
    """The paper's planar chain (Figs. 6-8): 4 segments of 0.25 m, 4 revolute joints about Z."""
    model = load_urdf(_project_model("planar_chain.urdf"))
    keypoints = {f"joint_{i}": f"joint_{i}" for i in range(1, 5)}
    keypoints["end_effector"] = "end_effector"
    names = list(keypoints)
    return BodyModel(
        model=model,
        keypoints=keypoints,
        segments=list(pairwise(names)),
        segment_radii=np.full(4, 0.02),
        end_effectors=["end_effector"],
    )


def load_arm() -> BodyModel:
    """The paper's 3D arm: shoulder and elbow of 3 DOF each, end effector at the wrist."""
    return _paper_chain("arm.urdf", [("Shoulder", "shoulder_Z"), ("Elbow", "elbow_Z"), ("Wrist", "wrist")],
                        radii=(0.045, 0.035))


def load_leg() -> BodyModel:
    """The paper's 3D leg: hip and knee of 3 DOF each, end effector at the ankle."""
    return _paper_chain("leg.urdf", [("Hip", "hip_Z"), ("Knee", "knee_Z"), ("Ankle", "ankle")], radii=(0.07, 0.05))


def _paper_chain(file_name: str, keypoint_frames: list[tuple[str, str]], radii: tuple[float, float]) -> BodyModel:
    """A two-segment chain of the project's models: keypoints (name, frame) from root to end effector."""
    names = [name for name, _ in keypoint_frames]
    return BodyModel(
        model=load_urdf(_project_model(file_name)),
        keypoints=dict(keypoint_frames),
        segments=list(pairwise(names)),
        segment_radii=np.array(radii),
        end_effectors=[names[-1]],
    )


def set_segment_length(model: pin.Model, joint_name: str, length: float) -> None:
    """Scale the placement of `joint_name` in its parent so that it lies `length` [m] away.

    The direction of the joint's offset from its parent joint is kept; frames attached to the
    parent are not moved.
    """
    if length <= 0 or not np.isfinite(length):
        raise InputError(f"segment length for joint {joint_name!r} must be positive, got {length}")
    joint_index = model.getJointId(joint_name)
    if joint_index >= model.njoints:
        raise UnknownNameError(f"joint {joint_name!r} does not exist in model {model.name!r}")
    offset = model.jointPlacements[joint_index].translation
    norm = np.linalg.norm(offset)
    if norm == 0:
        raise InputError(f"joint {joint_name!r} has no offset from its parent: it cannot be scaled")
    placement = model.jointPlacements[joint_index].copy()
    placement.translation = offset * (length / norm)
    model.jointPlacements[joint_index] = placement


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
