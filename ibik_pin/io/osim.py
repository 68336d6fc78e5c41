"""An OpenSim model of a body (model.osim) that plays the .mot file :func:`write_model_mot` writes.

The model is written from the Pinocchio model itself, so it holds the subject's scaled segments
and calibrated keypoints, and its coordinate names are the .mot columns:

- Bodies: consecutive 1-DOF revolute joints about one origin (a hip's Z, X, Y) form one OpenSim
  body and one ``CustomJoint`` whose ``SpatialTransform`` rotates about their axes in order
  (OpenSim applies ``rotation1..3`` as body-fixed successive rotations, as Pinocchio composes a
  chain of joints). A joint starts a new body when it is placed away from its parent's origin or
  rotated, when its parent has another child joint or a keypoint off its origin, or when its
  parent's body already has three rotations. The body's frame is the group's last joint frame;
  its mass, centre of mass and inertia are the Pinocchio inertias of the group's joints.
- Root: a free flyer becomes the ``CustomJoint`` ``ground_pelvis`` with the coordinates
  ``pelvis_tilt, pelvis_list, pelvis_rotation`` (rotations about Z, X, Y) and ``pelvis_tx, _ty,
  _tz`` (translations in ground), exactly the root columns of motion.mot; its body is ``pelvis``.
- Markers: one per keypoint, on the body of its frame's joint, at the frame's position [m]; then
  the virtual markers (`virtual_markers`) that the keypoints leave a body's pose undetermined
  without, so that OpenSim's inverse kinematics on joints.trc finds motion.mot again.
- Coordinates: range from the URDF joint limits, not clamped (a motion that crosses a limit still
  plays), default 0.

The XML follows OpenSim 4.x's ``OpenSimDocument Version="40000"`` layout (``Ground``, ``BodySet``,
``JointSet`` with ``PhysicalOffsetFrame`` parent frames, ``MarkerSet``); tests load it with the
``opensim`` package and find the markers of the played motion on joints.trc.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ElementTree
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from ibik_pin.checks import require_instance
from ibik_pin.exceptions import InputError
from ibik_pin.io.files import write_text_atomically
from ibik_pin.io.skeleton import joint_group_name
from ibik_pin.model import BodyModel

__all__ = ["OSIM_VERSION", "OsimBody", "VirtualMarker", "osim_bodies", "virtual_marker_positions", "virtual_markers",
           "write_osim_model"]

#: The OpenSimDocument version written: OpenSim 4.0's format, which every 4.x release reads.
OSIM_VERSION = "40000"
ROOT_BODY = "pelvis"
_ROOT_ROTATIONS = (("pelvis_tilt", (0.0, 0.0, 1.0)), ("pelvis_list", (1.0, 0.0, 0.0)),
                   ("pelvis_rotation", (0.0, 1.0, 0.0)))
_ROOT_TRANSLATIONS = (("pelvis_tx", (1.0, 0.0, 0.0)), ("pelvis_ty", (0.0, 1.0, 0.0)),
                      ("pelvis_tz", (0.0, 0.0, 1.0)))
_REVOLUTE_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0),
                  "JointModelRUBX": (1.0, 0.0, 0.0), "JointModelRUBY": (0.0, 1.0, 0.0),
                  "JointModelRUBZ": (0.0, 0.0, 1.0)}
_UNALIGNED = {"JointModelRevoluteUnaligned", "JointModelRevoluteUnboundedUnaligned"}
# Closer than this to the origin, or to the identity rotation, counts as at it [m], [-].
_TOLERANCE = 1e-9
# A CustomJoint's SpatialTransform holds three rotations.
_MAX_ROTATIONS = 3
# Virtual markers sit this far from their body's origin along its frame's X and Z axes [m]: a
# limb's width, so that they stay near the body, far enough for a well-conditioned fit.
VIRTUAL_MARKER_OFFSET_M = 0.1
# A rotation that moves a body's keypoints less than this per radian is left to virtual markers
# [m/rad]: OpenSim's fit of it would rest on millimetres of lever.
MIN_LEVER_M = 0.02


@dataclass(frozen=True)
class OsimBody:
    """One OpenSim body and the joint that moves it.

    Attributes:
        name: The body name (``pelvis`` for a free-flyer root).
        joint_ids: The Pinocchio joints it merges, parent first (the free flyer alone for the root).
        parent: Index of the parent body in the list; -1 for a body on the ground.
    """

    name: str
    joint_ids: tuple[int, ...]
    parent: int


def _axis(model: pin.Model, joint_id: int) -> np.ndarray:
    kind = model.joints[joint_id].shortname()
    if kind in _REVOLUTE_AXES:
        return np.array(_REVOLUTE_AXES[kind])
    if kind in _UNALIGNED:
        return np.asarray(model.joints[joint_id].extract().axis, dtype=float)
    raise InputError(f"model {model.name!r}: joint {model.names[joint_id]!r} of type {kind} cannot be written "
                     "to an OpenSim model; expected revolute joints below an optional free-flyer root")


def osim_bodies(body: BodyModel) -> list[OsimBody]:
    """The OpenSim bodies of a model (module docstring), every parent before its children.

    Raises:
        InputError: The model holds a joint that is neither revolute nor a free-flyer root.
    """
    model = body.model
    has_free_flyer = model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer"
    child_counts = np.bincount(np.asarray(model.parents[1:], dtype=int), minlength=model.njoints)
    off_origin = {int(frame.parentJoint) for frame in model.frames
                  if frame.type == pin.FrameType.OP_FRAME and np.linalg.norm(frame.placement.translation) > _TOLERANCE}
    members: list[list[int]] = [[1]] if has_free_flyer else []
    parents: list[int] = [-1] if has_free_flyer else []
    body_of_joint: dict[int, int] = {1: 0} if has_free_flyer else {}
    for joint_id in range(2 if has_free_flyer else 1, model.njoints):
        axis = _axis(model, joint_id)
        parent_id = int(model.parents[joint_id])
        placement = model.jointPlacements[joint_id]
        parent_body = body_of_joint.get(parent_id, -1)
        mergeable = (
            parent_body >= 0 and not (has_free_flyer and parent_body == 0)
            and child_counts[parent_id] == 1 and parent_id not in off_origin
            and np.linalg.norm(placement.translation) < _TOLERANCE
            and np.allclose(placement.rotation, np.eye(3), atol=_TOLERANCE)
            and len(members[parent_body]) < _MAX_ROTATIONS
            and np.linalg.matrix_rank(np.array([_axis(model, j) for j in members[parent_body]] + [axis])) ==
            len(members[parent_body]) + 1
        )
        if mergeable:
            members[parent_body].append(joint_id)
            body_of_joint[joint_id] = parent_body
        else:
            members.append([joint_id])
            parents.append(parent_body)
            body_of_joint[joint_id] = len(members) - 1
    names = [ROOT_BODY] if has_free_flyer else []
    for joint_ids in members[len(names):]:
        name = joint_group_name([model.names[j] for j in joint_ids]) or model.names[joint_ids[0]]
        unique, suffix = name, 2
        while unique in names or unique == "ground":
            unique, suffix = f"{name}_{suffix}", suffix + 1
        names.append(unique)
    return [OsimBody(name, tuple(ids), parent) for name, ids, parent in zip(names, members, parents, strict=True)]


@dataclass(frozen=True)
class VirtualMarker:
    """A marker fixed to a body where no keypoint determines its pose.

    Attributes:
        name: ``<body>_axis_x`` or ``<body>_axis_z``: VIRTUAL_MARKER_OFFSET_M along that axis of the
            OpenSim body's frame; not an anatomical landmark.
        joint_id: The Pinocchio joint whose frame is the body's frame.
        location: (3,) position in that frame [m].
    """

    name: str
    joint_id: int
    location: np.ndarray


def _smallest_lever_m(axes: list[np.ndarray], origin: np.ndarray, points: list[np.ndarray]) -> float:
    """The smallest singular value of the points' velocities under unit rotations about the axes
    through the origin (columns axis x (p - origin)): how far [m] the least visible of those
    rotations moves the points per radian; 0 when one moves none."""
    if not points:
        return 0.0
    columns = [np.concatenate([np.cross(axis, point - origin) for point in points]) for axis in axes]
    return float(np.linalg.svd(np.stack(columns, axis=1), compute_uv=False)[-1])


def virtual_markers(body: BodyModel) -> list[VirtualMarker]:
    """Virtual markers for every body that its keypoints leave free to turn.

    OpenSim's inverse kinematics needs each body's rotations to move some marker: joint-centre
    keypoints leave a thigh free to turn about its hip-knee line, a pelvis known by its hip centres
    and their midpoint free to roll about them, a trunk segment without a keypoint free altogether.
    A body whose fixed keypoints (those on it, and those at its children's origins, which move with
    it) move less than MIN_LEVER_M per radian under one of its rotations (at the neutral pose) gets
    two virtual markers, along its frame's X and Z axes.
    """
    model = body.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    bodies = osim_bodies(body)
    body_of_joint = {joint_id: index for index, item in enumerate(bodies) for joint_id in item.joint_ids}
    fixed: list[list[np.ndarray]] = [[] for _ in bodies]
    for frame_name in body.keypoints.values():
        frame_id = model.getFrameId(frame_name)
        joint_id = int(model.frames[frame_id].parentJoint)
        if joint_id == 0:
            continue
        point = data.oMf[frame_id].translation.copy()
        index = body_of_joint[joint_id]
        fixed[index].append(point)
        # At its body's origin (every joint of a merged group has it), the keypoint is also fixed
        # on the parent body: a child's origin moves with its parent.
        at_origin = np.linalg.norm(model.frames[frame_id].placement.translation) < _TOLERANCE
        if at_origin and bodies[index].parent >= 0:
            fixed[bodies[index].parent].append(point)
    chosen: list[VirtualMarker] = []
    for index, item in enumerate(bodies):
        first = item.joint_ids[0]
        origin = data.oMi[first].translation
        if model.joints[first].shortname() == "JointModelFreeFlyer":
            # It translates too: a rotation about any axis, the points' mean moved back, is free.
            axes = list(data.oMi[first].rotation.T)
            origin = np.mean(fixed[index], axis=0) if fixed[index] else origin
        else:
            axes = [data.oMi[joint_id].rotation @ _axis(model, joint_id) for joint_id in item.joint_ids]
        if _smallest_lever_m(axes, origin, fixed[index]) >= MIN_LEVER_M:
            continue
        for axis_name, axis in (("x", (1.0, 0.0, 0.0)), ("z", (0.0, 0.0, 1.0))):
            chosen.append(VirtualMarker(f"{item.name}_axis_{axis_name}", item.joint_ids[-1],
                                        VIRTUAL_MARKER_OFFSET_M * np.array(axis)))
    return chosen


def virtual_marker_positions(body: BodyModel, markers: Sequence[VirtualMarker],
                             configurations: np.ndarray) -> np.ndarray:
    """The markers' world positions (F, V, 3) [m] at configurations (F, nq)."""
    model = body.model
    data = model.createData()
    positions = np.empty((len(configurations), len(markers), 3))
    for frame, q in enumerate(np.asarray(configurations, dtype=float)):
        pin.forwardKinematics(model, data, q)
        for index, marker in enumerate(markers):
            positions[frame, index] = data.oMi[marker.joint_id].act(marker.location)
    return positions


def write_osim_model(path: str | os.PathLike[str], body: BodyModel, name: str = "ibik_pin_subject") -> None:
    """Write the body as an OpenSim 4.x model (.osim), atomically.

    Args:
        path: The .osim file to write.
        body: The (scaled or calibrated) model and its keypoints.
        name: The model's name in OpenSim.

    Raises:
        InputError: The model holds a joint an OpenSim model here cannot hold (module docstring),
            or the file cannot be written.
    """
    require_instance(body, BodyModel, "body", "a BodyModel (ibik_pin.human.load_human)")
    model = body.model
    bodies = osim_bodies(body)
    body_of_joint = {joint_id: index for index, item in enumerate(bodies) for joint_id in item.joint_ids}

    document = ElementTree.Element("OpenSimDocument", Version=OSIM_VERSION)
    root = ElementTree.SubElement(document, "Model", name=name)
    _text(root, "credits", "written by ibik_pin from the tracked subject; coordinates are motion.mot's columns")
    _text(root, "length_units", "meters")
    _text(root, "force_units", "N")
    _text(root, "gravity", "0 -9.8066499999999994 0")
    ElementTree.SubElement(root, "Ground", name="ground")
    body_objects = _set(root, "BodySet", "bodyset")
    joint_objects = _set(root, "JointSet", "jointset")
    for item in bodies:
        _write_body(body_objects, model, item)
        parent_name = "ground" if item.parent < 0 else bodies[item.parent].name
        _write_joint(joint_objects, model, item, parent_name)
    marker_objects = _set(root, "MarkerSet", "markerset")
    for keypoint, frame_name in body.keypoints.items():
        frame = model.frames[model.getFrameId(frame_name)]
        joint_id = int(frame.parentJoint)
        if joint_id == 0:
            socket, location = "/ground", frame.placement.translation
        else:
            osim_body = bodies[body_of_joint[joint_id]]
            # On a merged joint, a keypoint sits at the group's shared origin (osim_bodies saw to it).
            location = frame.placement.translation if joint_id == osim_body.joint_ids[-1] else np.zeros(3)
            socket = f"/bodyset/{osim_body.name}"
        _write_marker(marker_objects, keypoint, socket, location)
    for virtual in virtual_markers(body):
        _write_marker(marker_objects, virtual.name, f"/bodyset/{bodies[body_of_joint[virtual.joint_id]].name}",
                      virtual.location)
    ElementTree.indent(document, space="  ")
    text = '<?xml version="1.0" encoding="UTF-8" ?>\n' + ElementTree.tostring(document, encoding="unicode") + "\n"
    write_text_atomically(path, text)


def _write_marker(objects: ElementTree.Element, name: str, socket: str, location: np.ndarray) -> None:
    marker = ElementTree.SubElement(objects, "Marker", name=name)
    _text(marker, "socket_parent_frame", socket)
    _text(marker, "location", _vector(location))
    _text(marker, "fixed", "false")


def _text(parent: ElementTree.Element, tag: str, text: str) -> ElementTree.Element:
    element = ElementTree.SubElement(parent, tag)
    element.text = text
    return element


def _set(parent: ElementTree.Element, tag: str, name: str) -> ElementTree.Element:
    element = ElementTree.SubElement(parent, tag, name=name)
    objects = ElementTree.SubElement(element, "objects")
    ElementTree.SubElement(element, "groups")
    return objects


def _vector(values: np.ndarray | Sequence[float]) -> str:
    return " ".join(repr(float(value)) for value in values)


def _write_body(objects: ElementTree.Element, model: pin.Model, item: OsimBody) -> None:
    """Mass, centre of mass and inertia about it, in the body frame (the group's last joint)."""
    inertia = pin.Inertia.Zero()
    for joint_id in item.joint_ids:  # the merged joints share the last one's frame at q = 0
        inertia = inertia + model.inertias[joint_id]
    rotational = inertia.inertia
    element = ElementTree.SubElement(objects, "Body", name=item.name)
    _text(element, "mass", repr(float(inertia.mass)))
    _text(element, "mass_center", _vector(inertia.lever))
    _text(element, "inertia", _vector([rotational[0, 0], rotational[1, 1], rotational[2, 2],
                                       rotational[0, 1], rotational[0, 2], rotational[1, 2]]))


def _write_joint(objects: ElementTree.Element, model: pin.Model, item: OsimBody, parent_name: str) -> None:
    """A CustomJoint: parent offset frame at the first joint's placement, child frame the body."""
    joint = ElementTree.SubElement(objects, "CustomJoint", name=f"{parent_name}_{item.name}")
    _text(joint, "socket_parent_frame", f"{parent_name}_offset")
    _text(joint, "socket_child_frame", f"{item.name}_offset")
    free_flyer = model.joints[item.joint_ids[0]].shortname() == "JointModelFreeFlyer"
    if free_flyer:
        rotations = list(_ROOT_ROTATIONS)
        translations = list(_ROOT_TRANSLATIONS)
        placement = pin.SE3.Identity()
    else:
        rotations = [(model.names[j], tuple(_axis(model, j))) for j in item.joint_ids]
        translations = []
        placement = model.jointPlacements[item.joint_ids[0]]
    coordinates = ElementTree.SubElement(joint, "coordinates")
    limits = {model.names[j]: (model.lowerPositionLimit[model.joints[j].idx_q],
                               model.upperPositionLimit[model.joints[j].idx_q]) for j in item.joint_ids}
    for coordinate_name, _ in rotations + translations:
        lower, upper = limits.get(coordinate_name, (-np.pi, np.pi))
        if coordinate_name in dict(_ROOT_TRANSLATIONS):
            lower, upper = -10.0, 10.0
        if not (np.isfinite(lower) and np.isfinite(upper)) or model.joints[item.joint_ids[0]].nq == 2:
            lower, upper = -np.pi, np.pi
        coordinate = ElementTree.SubElement(coordinates, "Coordinate", name=coordinate_name)
        _text(coordinate, "default_value", "0")
        _text(coordinate, "range", _vector((lower, upper)))
        _text(coordinate, "clamped", "false")
        _text(coordinate, "locked", "false")
    frames = ElementTree.SubElement(joint, "frames")
    parent_socket = "/ground" if parent_name == "ground" else f"/bodyset/{parent_name}"
    _offset_frame(frames, f"{parent_name}_offset", parent_socket, placement)
    _offset_frame(frames, f"{item.name}_offset", f"/bodyset/{item.name}", pin.SE3.Identity())
    transform = ElementTree.SubElement(joint, "SpatialTransform")
    rotation_axes = _completed_axes([np.array(axis) for _, axis in rotations])
    for index, axis in enumerate(rotation_axes):
        used = rotations[index][0] if index < len(rotations) else ""
        _transform_axis(transform, f"rotation{index + 1}", used, axis)
    for index in range(3):
        used = translations[index][0] if translations else ""
        _transform_axis(transform, f"translation{index + 1}", used, np.eye(3)[index])


def _completed_axes(axes: list[np.ndarray]) -> list[np.ndarray]:
    """The given rotation axes, completed to three independent ones (OpenSim requires three)."""
    completed = list(axes)
    for candidate in np.eye(3):
        if len(completed) == _MAX_ROTATIONS:
            break
        if np.linalg.matrix_rank(np.array(completed + [candidate])) == len(completed) + 1:
            completed.append(candidate)
    return completed


def _offset_frame(frames: ElementTree.Element, name: str, socket: str, placement: pin.SE3) -> None:
    frame = ElementTree.SubElement(frames, "PhysicalOffsetFrame", name=name)
    _text(frame, "socket_parent", socket)
    _text(frame, "translation", _vector(placement.translation))
    # OpenSim's orientation: body-fixed X-Y-Z Euler angles [rad].
    _text(frame, "orientation", _vector(Rotation.from_matrix(placement.rotation).as_euler("XYZ")))


def _transform_axis(transform: ElementTree.Element, name: str, coordinate: str, axis: np.ndarray) -> None:
    element = ElementTree.SubElement(transform, "TransformAxis", name=name)
    _text(element, "coordinates", coordinate)
    _text(element, "axis", _vector(axis))
    if coordinate:
        function = ElementTree.SubElement(element, "LinearFunction", name="function")
        _text(function, "coefficients", "1 0")
    else:
        function = ElementTree.SubElement(element, "Constant", name="function")
        _text(function, "value", "0")
