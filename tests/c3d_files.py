"""C3D files written for the tests, with ezc3d, as motion capture systems write them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ezc3d = pytest.importorskip("ezc3d")


def write_c3d(path: Path, names, positions_mm: np.ndarray, rate: float, up: str = "+Y") -> None:
    """A C3D file of points named `names`: positions_mm (F, M, 3), NaN for gaps (written with residual -1,
    as Vicon writes them); `up`, POINT:Y_SCREEN, the axis drawn upward ("+Y" for Pose2Sim's TRC axes)."""
    content = ezc3d.c3d()
    content["parameters"]["POINT"]["RATE"]["value"] = [rate]
    content["parameters"]["POINT"]["LABELS"]["value"] = tuple(names)
    content["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    content.add_parameter("POINT", "Y_SCREEN", up)
    points = np.ones((4, len(names), positions_mm.shape[0]))
    points[:3] = np.nan_to_num(np.transpose(positions_mm, (2, 1, 0)))
    content["data"]["points"] = points
    residuals = np.where(np.isnan(positions_mm).any(axis=2).T, -1.0, 0.5)[None]
    content["data"]["meta_points"]["residuals"] = residuals
    content.write(str(path))
