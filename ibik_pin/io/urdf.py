"""Reading and writing the numbers of URDF elements (ElementTree): origins and number lists."""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree

import numpy as np
import pinocchio as pin

__all__ = ["urdf_numbers", "urdf_origin"]


def urdf_origin(element: ElementTree.Element) -> pin.SE3:
    """The placement a URDF element's <origin> gives (identity without one)."""
    origin = element.find("origin")
    xyz = np.array([float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()])
    rpy = np.array([float(v) for v in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()])
    return pin.SE3(pin.rpy.rpyToMatrix(rpy), xyz)


def urdf_numbers(values: np.ndarray) -> str:
    """Space-separated, exact to the double (repr), with -0 written as 0."""
    return " ".join(repr(float(value) + 0.0) for value in values)
