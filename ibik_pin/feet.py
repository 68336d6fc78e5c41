"""The feet: a third ankle axis for the human model, and the joints that move a foot point.

example-robot-data's ankle has two axes; :func:`add_foot_rotation` gives it the third, and
:func:`foot_point_joints` says which joints a toe or heel target may move so that it does not
swivel the knee the image is there to place.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree

import numpy as np
import pinocchio as pin

from ibik_pin.exceptions import FileFormatError
from ibik_pin.io.urdf import urdf_numbers, urdf_origin
from ibik_pin.model import BodyModel

__all__ = ["FOOT_POINT_SIDES", "FOOT_ROTATION_LIMIT_RAD", "add_foot_rotation", "foot_point_joints"]

# Rotation of the foot about the shank's long axis [rad], both ways from neutral: the knee's axial
# rotation and the foot's abduction together reach about this range in adults (about 30 degrees).
FOOT_ROTATION_LIMIT_RAD = 0.52
#: Foot points and the side of their leg, as the human's joint names spell it.
FOOT_POINT_SIDES = {f"{letter}{point}": side for letter, side in (("L", "left"), ("R", "right"))
                    for point in ("BigToe", "SmallToe", "Heel")}


def add_foot_rotation(robot: ElementTree.Element) -> None:
    """Give each ankle a third degree of freedom: ``<side>_ankle_Y``, about the shank's long axis.

    example-robot-data's ankle flexes and inverts, and its knee is a hinge, so the direction a foot
    points is fixed to the plane of hip, knee and ankle. A real foot turns out of that plane by the
    knee's axial rotation and the foot's abduction: in CMU walking and boxing the toe leaves it by
    4 to 15 degrees (standard deviation over a clip, 16 to 47 mm at the toe), which a two-axis ankle
    can only meet by turning the hip, i.e. by swivelling the knee the image is there to place. The
    joint is inserted between the shank and ``<side>_ankle_Z`` at the ankle's centre, positive
    turning the toes outwards on both sides. A URDF that has it already (a calibrated subject
    written by ibik_pin) is left as it is, as is one without the human's ankles.
    """
    joints = {element.get("name"): element for element in robot.findall("joint")}
    for side, outwards in (("left", 1.0), ("right", -1.0)):
        ankle = joints.get(f"{side}_ankle_Z")
        parent = ankle.find("parent") if ankle is not None else None
        if f"{side}_ankle_Y" in joints or ankle is None or parent is None:
            continue
        shank_end = urdf_origin(ankle)
        if np.linalg.norm(shank_end.translation) < 1e-9:
            raise FileFormatError(f"URDF joint {side}_ankle_Z has no shank before it (its origin is at the knee)")
        # the shank's axis, ankle to knee, in the frame of the inserted joint
        axis = outwards * (shank_end.rotation.T @ -shank_end.translation) / np.linalg.norm(shank_end.translation)
        link = f"{side}_shank_rotation"
        limit = ankle.find("limit")
        strength = {key: limit.get(key, "0") if limit is not None else "0" for key in ("effort", "velocity")}
        ElementTree.SubElement(robot, "link", name=link)
        joint = ElementTree.SubElement(robot, "joint", name=f"{side}_ankle_Y", type="revolute")
        joint.append(ElementTree.Element("origin", xyz=urdf_numbers(shank_end.translation),
                                         rpy=urdf_numbers(pin.rpy.matrixToRpy(shank_end.rotation))))
        ElementTree.SubElement(joint, "axis", xyz=urdf_numbers(axis))
        ElementTree.SubElement(joint, "parent", link=parent.get("link", ""))
        ElementTree.SubElement(joint, "child", link=link)
        ElementTree.SubElement(joint, "limit", {**strength, "lower": repr(-FOOT_ROTATION_LIMIT_RAD),
                                                "upper": repr(FOOT_ROTATION_LIMIT_RAD)})
        for origin in ankle.findall("origin"):
            ankle.remove(origin)
        ElementTree.SubElement(ankle, "origin", xyz="0 0 0", rpy="0 0 0")
        parent.set("link", link)


def foot_point_joints(body: BodyModel, name: str) -> np.ndarray | None:
    """For a toe or heel keypoint: a mask of the ankle joints that carry it (``<side>_ankle_*``,
    three on the human); None for any other keypoint, or a model without such joints.

    A data set's toe is not exactly the model's; a toe target that may move the whole leg turns the
    hip and swivels the knee to meet it, and with the ankle target it pins every coordinate of the
    leg, leaving the knee nothing for the image to move. Driven by the ankle alone, the foot points
    keep to what they tell: how the foot is turned. Measured on the real-mocap benchmark (walking,
    2 views, 6 knees): IBIK knees 18.3 mm mean with the toes driving the whole leg, 10.7 mm driven
    by the two-axis ankle and the hip's axial rotation (before the ankle had its third axis). The
    joints are found by name, not by which keypoint they move: a calibrated ankle keypoint sits a
    little off the ankle's axes, and may be carried by the shank.
    """
    side = FOOT_POINT_SIDES.get(name)
    if side is None or name not in body.keypoints:
        return None
    model = body.model
    driven = np.zeros(model.nv, dtype=bool)
    for joint in model.supports[model.frames[body.frame_id(name)].parentJoint]:
        if model.names[joint].startswith(f"{side}_ankle"):
            driven[model.joints[joint].idx_v:model.joints[joint].idx_v + model.joints[joint].nv] = True
    return driven if driven.any() else None
