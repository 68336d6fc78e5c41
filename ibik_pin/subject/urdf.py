"""A calibrated subject as a URDF: the scaled joints, and every keypoint as a fixed link.

:func:`write_subject_urdf` rewrites the URDF the body was loaded from (example-robot-data's human
by default): every joint origin takes the body's placement, each link's visuals, collisions and
centre of mass are scaled like the segment it belongs to (masses and rotational inertias are kept:
the model is used for kinematics), and each keypoint becomes a massless link
``keypoint_<Name>`` fixed to its parent joint's link, so Pinocchio and any URDF viewer show it.
:func:`~ibik_pin.human.load_human` reads those links back as the keypoints, and a body with
keypoint links is a calibrated subject that tracking does not scale again.

Mesh paths: ``package://`` and relative file names of the source are written as absolute
``file://`` URIs when the file exists (the installed example-robot-data meshes do); a mesh that
cannot be found is dropped, and said so in the returned notes.
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pinocchio as pin

from ibik_pin.checks import require_instance
from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.human import KEYPOINT_LINK_PREFIX, human_urdf_path, human_urdf_tree
from ibik_pin.io.urdf import urdf_numbers, urdf_origin
from ibik_pin.model import BodyModel

__all__ = ["write_subject_urdf"]

_HEADER = (" ibik_pin calibrated subject. Links named {prefix}<Name> are the calibrated keypoints, fixed "
           "to their segments; ibik_pin.human.load_human reads them back and tracking does not re-scale "
           "this model. Written from {source}. ")


def write_subject_urdf(body: BodyModel, path: str | Path) -> list[str]:
    """Write the body as a URDF with one fixed link per keypoint.

    Args:
        body: a human loaded by :func:`~ibik_pin.human.load_human` (scaled or calibrated); its
            joint names must be the source URDF's.
        path: the URDF to write (its folder is created).

    Returns:
        Notes on what could not be carried over (meshes not found), one line each; empty if none.

    Raises:
        FileFormatError: the source URDF cannot be read, or the output cannot be written.
        InputError: a joint of the source URDF is missing from the body's model.
    """
    require_instance(body, BodyModel, "body", "a BodyModel (ibik_pin.human.load_human)")
    source = Path(body.urdf_path) if body.urdf_path is not None else human_urdf_path()
    tree = human_urdf_tree(source)
    robot = tree.getroot()
    _remove_keypoint_links(robot)
    model = body.model
    # joint name -> (parent link, child link, element)
    joints = {_required(element, ".", "name", source): (_required(element, "parent", "link", source),
                                                       _required(element, "child", "link", source), element)
              for element in robot.findall("joint")}
    parents = {child: parent for parent, child, _ in joints.values()}  # link -> its parent link
    root_links = [name for name in (_required(link, ".", "name", source) for link in robot.findall("link"))
                  if name not in parents]
    if len(root_links) != 1:
        raise FileFormatError(f"URDF {str(source)!r}: expected one root link, got {root_links}")
    root_link = root_links[0]

    def link_placement(link: str) -> pin.SE3:
        """Placement of a link in its supporting joint's frame, in the body's model."""
        if not model.existFrame(link, pin.FrameType.BODY):
            raise InputError(f"body: link {link!r} of {str(source)!r} is not in the model {model.name!r}")
        return model.frames[model.getFrameId(link, pin.FrameType.BODY)].placement

    old_lengths: dict[str, float] = {}
    new_lengths: dict[str, float] = {}
    for name, (parent, child, element) in joints.items():
        if element.get("type") == "fixed":
            placement = link_placement(parent).inverse() * link_placement(child)
        elif model.existJointName(name):
            placement = link_placement(parent).inverse() * model.jointPlacements[model.getJointId(name)]
        else:
            raise InputError(f"body: joint {name!r} of {str(source)!r} is not in the model {model.name!r}")
        old = urdf_origin(element)
        old_lengths[parent] = old_lengths.get(parent, 0.0) + float(np.linalg.norm(old.translation))
        new_lengths[parent] = new_lengths.get(parent, 0.0) + float(np.linalg.norm(placement.translation))
        _set_origin(element, placement)

    def link_factor(link: str | None) -> float:
        """How much a link grew: its child joints' distances, or its parent link's factor."""
        while link is not None:
            if old_lengths.get(link, 0.0) > 1e-6:
                return new_lengths[link] / old_lengths[link]
            link = parents.get(link)
        return 1.0

    notes: list[str] = []
    for link in robot.findall("link"):
        factor = link_factor(link.get("name"))
        for part in link.findall("inertial") + link.findall("visual") + link.findall("collision"):
            origin = part.find("origin")
            if origin is not None:
                xyz = np.array([float(v) for v in origin.get("xyz", "0 0 0").split()]) * factor
                origin.set("xyz", urdf_numbers(xyz))
            mesh = part.find("geometry/mesh")
            if mesh is None:
                continue
            resolved = _resolve_mesh(mesh.get("filename", ""), source)
            if resolved is None:
                notes.append(f"{link.get('name')}: mesh {mesh.get('filename')!r} not found, {part.tag} dropped")
                link.remove(part)
                continue
            mesh.set("filename", resolved.as_uri())
            scale = np.array([float(v) for v in mesh.get("scale", "1 1 1").split()]) * factor
            mesh.set("scale", urdf_numbers(scale))

    for keypoint, frame_name in body.keypoints.items():
        frame = model.frames[model.getFrameId(frame_name)]
        joint_name = model.names[frame.parentJoint]
        # the free-flyer (or the universe) carries the root link
        parent_link = joints[joint_name][1] if joint_name in joints else root_link
        placement = link_placement(parent_link).inverse() * frame.placement
        link_name = KEYPOINT_LINK_PREFIX + keypoint
        ElementTree.SubElement(robot, "link", name=link_name)
        joint = ElementTree.SubElement(robot, "joint", name=f"{link_name}_joint", type="fixed")
        ElementTree.SubElement(joint, "parent", link=parent_link)
        ElementTree.SubElement(joint, "child", link=link_name)
        ElementTree.SubElement(joint, "origin")
        _set_origin(joint, placement)

    robot.insert(0, ElementTree.Comment(_HEADER.format(prefix=KEYPOINT_LINK_PREFIX, source=source)))
    ElementTree.indent(tree, space="    ")
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tree.write(path, encoding="unicode", xml_declaration=False)
    except OSError as error:
        raise FileFormatError(f"{path}: cannot write the URDF: {error}") from error
    return notes


def _required(element: ElementTree.Element, path: str, attribute: str, source: Path) -> str:
    """An attribute the URDF must have (a joint's parent and child links, names)."""
    node = element.find(path)
    value = None if node is None else node.get(attribute)
    if value is None:
        raise FileFormatError(f"URDF {str(source)!r}: a {element.tag} {element.get('name', '')!r} lacks "
                              f"{attribute!r} in {path!r}")
    return value


def _remove_keypoint_links(robot: ElementTree.Element) -> None:
    """Drop the keypoint links (and their joints) of a URDF written before: they are rewritten."""
    for element in list(robot):
        child = element.find("child")
        link = element.get("name", "") if element.tag == "link" else (
            child.get("link", "") if element.tag == "joint" and child is not None else "")
        if link.startswith(KEYPOINT_LINK_PREFIX):
            robot.remove(element)


def _set_origin(element: ElementTree.Element, placement: pin.SE3) -> None:
    origin = element.find("origin")
    if origin is None:
        origin = ElementTree.SubElement(element, "origin")
    origin.set("xyz", urdf_numbers(placement.translation))
    origin.set("rpy", urdf_numbers(pin.rpy.matrixToRpy(placement.rotation)))


def _resolve_mesh(filename: str, source: Path) -> Path | None:
    """The absolute path of a URDF mesh reference (package://, file:// or relative), if it exists."""
    if filename.startswith("file://"):
        candidates = [Path(filename[len("file://"):])]
    elif filename.startswith("package://"):
        relative = filename[len("package://"):]
        roots = [Path(entry) / "cmeel.prefix" / "share" for entry in sys.path]
        roots += list(source.resolve().parents)  # a ROS-like tree: the package folder above the URDF
        package, _, rest = relative.partition("/")
        candidates = [root / relative for root in roots]
        candidates += [parent / rest for parent in source.resolve().parents if parent.name == package]
    else:
        path = Path(filename)
        candidates = [path if path.is_absolute() else source.parent / path]
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    return None
