"""3D keypoints from the files users bring: an OpenSim/Pose2Sim TRC, or a C3D file (recognised by
its content, whatever its suffix) whose markers are mapped to keypoints (:mod:`ibik_pin.io.c3d`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from ibik_pin.io.c3d import is_c3d, read_c3d
from ibik_pin.io.files import PathLike
from ibik_pin.io.trc import TrcData, read_trc

__all__ = ["read_keypoints"]


def read_keypoints(path: PathLike, c3d_mapping: PathLike | Mapping[str, Sequence[str]] | None = None) -> TrcData:
    """The keypoints of a TRC file, or of a C3D file through `c3d_mapping` (a mapping file, a mapping,
    or None for io.c3d's default); in the file's units.

    Raises:
        FileFormatError: as read_trc or read_c3d.
    """
    return read_c3d(path, c3d_mapping) if is_c3d(path) else read_trc(path)
