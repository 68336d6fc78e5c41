"""Body models: a Pinocchio model plus the named keypoints and skeleton segments the method needs.

A `BodyModel` says which model frame stands for each keypoint (Pose2Sim names on the human), which
keypoint pairs are the segments projected into the images (eq. 5), and how thick each segment is
(for rendering silhouettes). Keypoints that are not at a model joint are added as operational frames.
This module holds what any model shares and the paper's chains; the human is built on it in
:mod:`ibik_pin.human`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from itertools import pairwise
from pathlib import Path

import numpy as np
import pinocchio as pin

from ibik_pin.exceptions import FileFormatError, InputError, UnknownNameError
from ibik_pin.native_output import captured_native_stderr

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
        return built_from_urdf(path, lambda: pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()))
    return built_from_urdf(path, lambda: pin.buildModelFromUrdf(str(path)))


def built_from_urdf(path: Path, build: Callable[[], pin.Model]) -> pin.Model:
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
