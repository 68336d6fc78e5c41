"""A tracked motion written for other programs: a spreadsheet (CSV), OpenSim (.mot), Blender (BVH).

The motion is a sequence of model configurations q, shape (F, nq), as the tracker returns them;
the CSV and MOT writers take it with the Pinocchio ``model`` it belongs to and the ``times`` of its
frames, shape (F,) [s]. Every writer raises an :class:`InputError` when the shapes disagree, a
value is not finite, a free-flyer quaternion is not of unit norm (within 1e-6), or the file cannot
be written. Supported joints: a free-flyer root (joint 1, child of the universe), 1-DOF revolute joints
(``RX``, ``RY``, ``RZ``, unaligned), 1-DOF prismatic joints (CSV and MOT only) and unbounded
revolute joints (``RUB*``, q = (cos, sin)). Any other joint type raises an :class:`InputError`
that names the joint.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from ibik_pin.checks import as_float_array, require_instance
from ibik_pin.exceptions import InputError
from ibik_pin.io.bvh_writer import write_bvh
from ibik_pin.io.files import write_text_atomically
from ibik_pin.io.mot import write_mot
from ibik_pin.io.skeleton import euler_angles, joint_group_name
from ibik_pin.model import BodyModel

__all__ = [
    "BvhJointGroup",
    "ROOT_EULER_AXES",
    "bvh_joint_groups",
    "q_column_names",
    "q_column_units",
    "write_model_bvh",
    "write_model_mot",
    "write_q_csv",
]

#: Intrinsic axes of the root's Euler angles in the .mot file:
#: R = R_z(tilt) R_x(list) R_y(rotation), the body-fixed sequence of OpenSim's ground-pelvis
#: joint (gait2392, Rajagopal 2015).
ROOT_EULER_AXES = "ZXY"
_ROOT_MOT_COLUMNS = [
    "pelvis_tx",
    "pelvis_ty",
    "pelvis_tz",
    "pelvis_tilt",
    "pelvis_list",
    "pelvis_rotation",
]
_FREE_FLYER_COLUMNS = ["root_tx", "root_ty", "root_tz", "root_qx", "root_qy", "root_qz", "root_qw"]
_REVOLUTE = {"JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned"}
_REVOLUTE_UNBOUNDED = {
    "JointModelRUBX",
    "JointModelRUBY",
    "JointModelRUBZ",
    "JointModelRevoluteUnboundedUnaligned",
}
_PRISMATIC = {"JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned"}
# A joint placed closer than this to its parent shares its origin [m].
_SAME_ORIGIN_TOLERANCE = 1e-9
# A free-flyer quaternion whose norm is farther than this from 1 is an error, not rounding.
_QUATERNION_NORM_TOLERANCE = 1e-6


@dataclass(frozen=True)
class BvhJointGroup:
    """One BVH joint: consecutive model joints that rotate about one origin.

    Attributes:
        name: The BVH joint name.
        joint_ids: The model joints of the group, parent first; the root group holds the free
            flyer (1) or, without one, the universe (0).
        parent: Index of the parent group in the list, -1 for the root.
    """

    name: str
    joint_ids: tuple[int, ...]
    parent: int


def q_column_names(model: pin.Model) -> list[str]:
    """One name per configuration coordinate, in the order of q.

    A free-flyer root gives ``root_tx, root_ty, root_tz`` [m] and ``root_qx, root_qy, root_qz,
    root_qw`` (the unit quaternion of its orientation, Pinocchio's order); a 1-DOF joint gives its
    URDF name [rad] or [m]; an unbounded revolute joint ``<name>_cos, <name>_sin``.

    Args:
        model: The Pinocchio model.

    Returns:
        nq names.

    Raises:
        InputError: The model holds a joint type listed as unsupported in the module docstring.
    """
    names = [""] * model.nq
    for joint_id in range(1, model.njoints):
        kind = _joint_kind(model, joint_id)
        name = model.names[joint_id]
        if kind == "free_flyer":
            joint_names = _FREE_FLYER_COLUMNS
        elif kind == "revolute_unbounded":
            joint_names = [f"{name}_cos", f"{name}_sin"]
        else:
            joint_names = [name]
        first = model.joints[joint_id].idx_q
        names[first : first + len(joint_names)] = joint_names
    return names


def q_column_units(model: pin.Model) -> list[str]:
    """The unit of each :func:`q_column_names` column: ``m`` for positions, ``1`` for the root's
    quaternion and an unbounded joint's (cos, sin), ``rad`` for revolute, ``m`` for prismatic joints."""
    per_kind = {"free_flyer": ["m"] * 3 + ["1"] * 4, "revolute_unbounded": ["1", "1"], "revolute": ["rad"],
                "prismatic": ["m"]}
    return [unit for joint_id in range(1, model.njoints) for unit in per_kind[_joint_kind(model, joint_id)]]


def write_q_csv(
    path: str | os.PathLike[str], model: pin.Model, times: np.ndarray, q: np.ndarray
) -> None:
    """Write configurations as CSV: header ``time [s],<name> [<unit>],...``, one row per frame.

    The header holds each column's :func:`q_column_names` name and :func:`q_column_units` unit
    (``root_tx [m]``, ``root_qw [1]``, ``left_hip_Z [rad]``).

    Values are written at full precision (shortest round-trip decimal), times [s], angles [rad],
    lengths [m]; ``np.loadtxt(path, delimiter=",", skiprows=1)`` gives back the exact numbers.
    The file is written atomically.

    Args:
        path: The .csv file to write.
        model, times, q: The motion (see the module docstring).

    Raises:
        InputError: For the reasons the module docstring lists, or an unsupported joint.
    """
    times, q = _check_motion(model, times, q, normalise=False)  # written as given
    table = np.column_stack([times, q])
    header = [f"{name} [{unit}]" for name, unit in zip(q_column_names(model), q_column_units(model), strict=True)]
    lines = [",".join(["time [s]", *header])]
    lines += [",".join(map(repr, row)) for row in table.tolist()]
    write_text_atomically(path, "\n".join(lines) + "\n")


def write_model_mot(
    path: str | os.PathLike[str], model: pin.Model, times: np.ndarray, q: np.ndarray
) -> None:
    """Write joint coordinates as an OpenSim storage file, angles in degrees.

    Columns: a free-flyer root as ``pelvis_tx, pelvis_ty, pelvis_tz`` [m] (the root position in
    the world) and ``pelvis_tilt, pelvis_list, pelvis_rotation`` [deg], the intrinsic Euler angles
    of the root orientation with R = R_z(tilt) @ R_x(list) @ R_y(rotation) (:data:`ROOT_EULER_AXES`,
    OpenSim's ground-pelvis sequence; the human's ISB axes, X forward, Y up, Z right, are
    OpenSim's). The angles are unwrapped over frames, so they may leave [-180, 180] but never
    jump by 360. Then each joint by its URDF name: revolute [deg], prismatic [m]. The names are
    those of the model: an OpenSim model must use the same coordinate names to load the file.

    Args:
        path: The .mot file to write.
        model, times, q: The motion (see the module docstring).

    Raises:
        InputError: For the reasons the module docstring lists, or an unsupported joint.
    """
    times, q = _check_motion(model, times, q)
    column_names: list[str] = []
    columns: list[np.ndarray] = []
    for joint_id in range(1, model.njoints):
        kind = _joint_kind(model, joint_id)
        first = model.joints[joint_id].idx_q
        if kind == "free_flyer":
            # Pinocchio's and scipy's quaternions are both in (x, y, z, w) order.
            rotations = Rotation.from_quat(q[:, first + 3 : first + 7]).as_matrix()
            angles = np.rad2deg(euler_angles(rotations, ROOT_EULER_AXES))
            column_names += _ROOT_MOT_COLUMNS
            columns += [q[:, first + 0], q[:, first + 1], q[:, first + 2]]
            columns += list(np.unwrap(angles, period=360.0, axis=0).T)
        elif kind == "revolute":
            column_names.append(model.names[joint_id])
            columns.append(np.rad2deg(q[:, first]))
        elif kind == "revolute_unbounded":
            column_names.append(model.names[joint_id])
            angle = np.arctan2(q[:, first + 1], q[:, first])
            columns.append(np.unwrap(np.rad2deg(angle), period=360.0))
        else:
            column_names.append(model.names[joint_id])
            columns.append(q[:, first])
    values = np.column_stack(columns) if columns else np.empty((len(times), 0))
    write_mot(path, times, column_names, values, in_degrees=True, name="Coordinates")


def bvh_joint_groups(model: pin.Model) -> list[BvhJointGroup]:
    """The BVH joints of a model: each a group of consecutive revolute joints about one origin.

    A revolute joint joins its parent's group when the parent is a revolute joint with this one
    child and the joint is placed at the parent's origin (zero translation), e.g.
    ``left_hip_Z, left_hip_X, left_hip_Y`` -> ``left_hip``. A group is named after the tokens
    (split at ``_``) its joints' names share, without a trailing axis letter or ``joint``
    (``left_clavicle_joint_X`` -> ``left_clavicle``); the first joint's name is used when that
    leaves nothing or a name already taken. The root group is ``root``: the free flyer, or the
    fixed universe if the model has none.

    Args:
        model: The Pinocchio model.

    Returns:
        The groups, every parent before its children.

    Raises:
        InputError: The model holds a joint that is neither revolute nor a free-flyer root.
    """
    has_free_flyer = model.njoints > 1 and _joint_kind(model, 1) == "free_flyer"
    child_counts = np.bincount(np.asarray(model.parents[1:], dtype=int), minlength=model.njoints)
    members: list[list[int]] = [[1 if has_free_flyer else 0]]
    parents = [-1]
    group_of_joint = {members[0][0]: 0}
    for joint_id in range(2 if has_free_flyer else 1, model.njoints):
        if _joint_kind(model, joint_id) not in ("revolute", "revolute_unbounded"):
            raise InputError(
                f"model {model.name!r}: joint {model.names[joint_id]!r} of type "
                f"{model.joints[joint_id].shortname()} cannot be written to BVH; expected revolute "
                f"joints below an optional free-flyer root"
            )
        parent_id = model.parents[joint_id]
        parent_group = group_of_joint[parent_id]
        same_origin = (
            np.linalg.norm(model.jointPlacements[joint_id].translation) < _SAME_ORIGIN_TOLERANCE
        )
        if parent_group != 0 and child_counts[parent_id] == 1 and same_origin:
            members[parent_group].append(joint_id)
            group_of_joint[joint_id] = parent_group
        else:
            members.append([joint_id])
            parents.append(parent_group)
            group_of_joint[joint_id] = len(members) - 1

    names = ["root"]
    for joint_ids in members[1:]:
        first_name = model.names[joint_ids[0]]
        name = joint_group_name([model.names[joint_id] for joint_id in joint_ids]) or first_name
        if name in names:
            name = first_name
        unique_name, suffix = name, 2
        while unique_name in names:
            unique_name, suffix = f"{name}_{suffix}", suffix + 1
        names.append(unique_name)
    return [
        BvhJointGroup(name, tuple(joint_ids), parent)
        for name, joint_ids, parent in zip(names, members, parents, strict=True)
    ]


def write_model_bvh(
    path: str | os.PathLike[str], body: BodyModel, q: np.ndarray, frame_time: float
) -> None:
    """Write a model's motion as a BVH file that Blender and MotionBuilder replay.

    BVH has no length unit: lengths are written in metres (import with scale 1 in Blender, read
    back with ``read_bvh(path, scale=1.0)``). The axes are the model's (the human's ISB axes:
    Y up, X forward), which is BVH's usual Y-up convention.

    - Hierarchy: one BVH joint per :func:`bvh_joint_groups` group; its OFFSET is the translation
      of the group's first model joint in its parent joint's frame, at the model's joint
      placements (rotation channels only, ``ZXY``; the root also has position channels).
    - Motion: the local rotation of each group is the rotation of its last joint frame relative
      to the parent group's last joint frame, from Pinocchio forward kinematics; the root's
      position and orientation are the free flyer's world placement (fixed at the world origin
      without a free flyer).
    - End sites: a group without children gets an End Site at the keypoint frame attached to
      its last joint that lies farthest from the joint (e.g. Head, LHand, LBigToe on the human),
      so the skeleton shows the head, hands and feet; a zero offset if there is none.

    Args:
        path: The .bvh file to write (atomically).
        body: The model and its keypoints.
        q: Configurations, shape (F, nq).
        frame_time: Time between frames [s].

    Raises:
        InputError: ``q`` has the wrong shape or a non-finite value, a free-flyer quaternion is
            not of unit norm, ``frame_time`` is not positive, the model holds a joint BVH cannot
            hold, or the file cannot be written.
    """
    require_instance(body, BodyModel, "body", "a BodyModel (ibik_pin.human.load_human)")
    model = body.model
    q = _check_configurations(model, q)
    if not np.isfinite(frame_time) or frame_time <= 0.0:
        raise InputError(f"frame_time: expected a positive number [s], got {frame_time}")
    groups = bvh_joint_groups(model)
    first_ids = [group.joint_ids[0] for group in groups]
    last_ids = [group.joint_ids[-1] for group in groups]
    parents = np.array([group.parent for group in groups])
    offsets = np.array([model.jointPlacements[joint_id].translation for joint_id in first_ids])
    offsets[0] = 0.0

    data = model.createData()
    frame_count = q.shape[0]
    rotations_world = np.empty((frame_count, len(groups), 3, 3))
    root_positions = np.empty((frame_count, 3))
    for frame, configuration in enumerate(q):
        pin.forwardKinematics(model, data, configuration)
        rotations_world[frame] = [data.oMi[joint_id].rotation for joint_id in last_ids]
        root_positions[frame] = data.oMi[last_ids[0]].translation
    local_rotations = rotations_world.copy()
    local_rotations[:, 1:] = (
        np.swapaxes(rotations_world[:, parents[1:]], -1, -2) @ rotations_world[:, 1:]
    )
    write_bvh(
        path,
        names=[group.name for group in groups],
        parents=parents,
        offsets=offsets,
        local_rotations=local_rotations,
        root_positions=root_positions,
        frame_time=frame_time,
        rotation_order="ZXY",
        end_sites=_end_sites(body, groups),
    )


def _end_sites(body: BodyModel, groups: list[BvhJointGroup]) -> dict[int, np.ndarray]:
    """Per leaf group, the farthest keypoint frame on its last joint, offset [m] in that joint."""
    model = body.model
    has_children = np.zeros(len(groups), dtype=bool)
    has_children[[group.parent for group in groups[1:]]] = True
    end_sites = {}
    for index, group in enumerate(groups):
        if has_children[index]:
            continue
        offsets = [
            model.frames[model.getFrameId(frame_name)].placement.translation
            for frame_name in body.keypoints.values()
            if model.existFrame(frame_name)
            and model.frames[model.getFrameId(frame_name)].parentJoint == group.joint_ids[-1]
        ]
        if offsets:
            end_sites[index] = np.array(max(offsets, key=np.linalg.norm))
    return end_sites


def _joint_kind(model: pin.Model, joint_id: int) -> str:
    """free_flyer (the root only), revolute, revolute_unbounded or prismatic; else InputError."""
    joint = model.joints[joint_id]
    type_name = joint.shortname()
    if type_name == "JointModelFreeFlyer" and joint_id == 1 and model.parents[1] == 0:
        return "free_flyer"
    if type_name in _REVOLUTE:
        return "revolute"
    if type_name in _REVOLUTE_UNBOUNDED:
        return "revolute_unbounded"
    if type_name in _PRISMATIC:
        return "prismatic"
    raise InputError(
        f"model {model.name!r}: joint {model.names[joint_id]!r} of type {type_name} is not "
        f"supported; expected a free-flyer root, revolute or prismatic joints"
    )


def _check_configurations(model: pin.Model, q: np.ndarray, normalise: bool = True) -> np.ndarray:
    """q as a finite (F, nq) float array, free-flyer quaternions normalised if asked."""
    require_instance(model, pin.Model, "model", "a Pinocchio model (pinocchio.Model; a BodyModel's .model)")
    q = as_float_array(q, "q")
    if q.ndim != 2 or q.shape[1] != model.nq:
        raise InputError(
            f"q: expected shape (F, {model.nq}) for model {model.name!r}, got {q.shape}"
        )
    if not np.all(np.isfinite(q)):
        frame = int(np.argwhere(~np.isfinite(q))[0, 0])
        raise InputError(f"q: expected finite values, got NaN or infinity at frame {frame}")
    if model.njoints > 1 and _joint_kind(model, 1) == "free_flyer":
        quaternions = q[:, 3:7]
        norms = np.linalg.norm(quaternions, axis=1)
        bad = np.abs(norms - 1.0) > _QUATERNION_NORM_TOLERANCE
        if np.any(bad):
            frame = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"q: expected a unit quaternion in columns 3:7 (root_qx..root_qw, tolerance "
                f"{_QUATERNION_NORM_TOLERANCE}), got norm {norms[frame]} at frame {frame}"
            )
        if normalise:
            q[:, 3:7] = quaternions / norms[:, np.newaxis]
    return q


def _check_motion(model: pin.Model, times: np.ndarray, q: np.ndarray, normalise: bool = True,
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Times (F,) and configurations (F, nq), checked (see :func:`_check_configurations`)."""
    q = _check_configurations(model, q, normalise)
    times = as_float_array(times, "times")
    if times.shape != (q.shape[0],) or not np.all(np.isfinite(times)):
        raise InputError(
            f"times: expected {q.shape[0]} finite times [s], shape ({q.shape[0]},), "
            f"got shape {times.shape}"
        )
    return times, q
