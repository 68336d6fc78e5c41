"""A 3D replay of the motion in one self-contained HTML file (no server, no network).

The page is the package file ``ibik_pin/viz/replay.html`` (its HTML, CSS and JavaScript); the
title and the motion's data, as JSON, take the places of its ``@TITLE@`` and ``@DATA@`` marks.
"""

from __future__ import annotations

import html
import os
import re
from importlib import resources

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.io.files import strict_json, write_text_atomically

__all__ = ["write_html_replay"]

# Positions in the HTML replay are integers of this many metres: 0.1 mm.
_HTML_UNIT = 1e-4


_HTML_COLORS = ("#1f6fb4", "#e0592a")  # blue, orange: told apart also by most colour-blind eyes


# Internal coordinates of the replay are Y up: (x, y, z) of a Z-up input become (x, z, -y).
_UP_AXIS_TO_Y_UP = {
    "y": np.eye(3),
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}


def write_html_replay(
    path: str | os.PathLike[str],
    keypoint_names: list[str],
    segments: list[tuple[int, int]],
    positions: np.ndarray,
    frame_rate: float,
    title: str,
    up_axis: str = "y",
    compare_positions: np.ndarray | None = None,
    label: str = "tracked",
    compare_label: str = "reference",
) -> None:
    """One self-contained HTML file that replays the 3D skeleton in a web browser, offline.

    The page draws the skeleton on a ``<canvas>`` with a perspective camera written in plain
    JavaScript (no library, no network): drag to orbit, shift-drag or right-drag to pan, wheel to
    zoom, double-click to reset; play/pause (space), frame slider (arrow keys step), frame
    counter and time, playback speed, a ground grid at the lowest point of the motion with the
    shadow of the skeleton, an axis gizmo, keypoint names on hover (or all of them), and a
    "follow" mode that keeps a travelling subject centred. An optional second skeleton (ground
    truth, or the baseline without images) is drawn dashed in another colour, with a legend.

    Positions are embedded as JSON integers of 0.1 mm (rounded), which keeps a file of 1000
    frames of 24 keypoints near 0.4 MB; a missing (NaN) keypoint is not drawn.

    Args:
        path: The .html file to write (atomically).
        keypoint_names: The K keypoint names.
        segments: Pairs of keypoint indices, each drawn as a line.
        positions: World keypoint positions, shape (F, K, 3) [m]; NaN for a missing keypoint.
        frame_rate: Frames per second [Hz].
        title: The page title.
        up_axis: The vertical axis of ``positions``: ``"y"`` (the human model, OpenSim, BVH)
            or ``"z"``.
        compare_positions: A second skeleton over the same frames, shape (F, K, 3) [m], or None.
        label: The legend label of ``positions``.
        compare_label: The legend label of ``compare_positions``.

    Raises:
        InputError: A shape, index or value is not as described (the message names it), no
            position is finite, or the file cannot be written.
    """
    names = [str(name) for name in keypoint_names]
    keypoint_count = len(names)
    skeletons = [("positions", positions, label)]
    if compare_positions is not None:
        skeletons.append(("compare_positions", compare_positions, compare_label))
    arrays = []
    for argument, array, _ in skeletons:
        array = np.asarray(array, dtype=float)
        if array.ndim != 3 or array.shape[1:] != (keypoint_count, 3) or array.shape[0] == 0:
            raise InputError(
                f"{argument}: expected shape (F, {keypoint_count}, 3) [m] with F >= 1 for "
                f"{keypoint_count} keypoint names, got {array.shape}"
            )
        arrays.append(array)
    if len(arrays) == 2 and arrays[1].shape != arrays[0].shape:
        raise InputError(
            f"compare_positions: expected the shape of positions {arrays[0].shape}, "
            f"got {arrays[1].shape}"
        )
    try:
        segment_array = np.asarray(segments, dtype=int).reshape(-1, 2)
    except (TypeError, ValueError):
        segment_array = np.empty((0, 2), int)  # ragged, or not numbers: refused below
    if segment_array.shape != (len(segments), 2) or np.any(
        (segment_array < 0) | (segment_array >= keypoint_count)
    ):
        raise InputError(
            f"segments: expected pairs of keypoint indices in [0, {keypoint_count - 1}], "
            f"got {list(segments)}"
        )
    if not np.isfinite(frame_rate) or frame_rate <= 0.0:
        raise InputError(f"frame_rate: expected a positive number [Hz], got {frame_rate}")
    if up_axis not in _UP_AXIS_TO_Y_UP:
        raise InputError(f"up_axis: expected 'y' or 'z', got {up_axis!r}")

    to_y_up = _UP_AXIS_TO_Y_UP[up_axis]
    # Rounded first, so the framing below is that of the numbers the page draws.
    points = [np.rint(array @ to_y_up.T / _HTML_UNIT) for array in arrays]
    finite = [np.isfinite(array).all(axis=-1) for array in points]
    all_points = np.concatenate(points, axis=1) * _HTML_UNIT
    all_finite = np.concatenate(finite, axis=1)
    if not np.any(all_finite):
        raise InputError("positions: expected at least one finite keypoint position, got none")
    lowest = np.where(all_finite[..., np.newaxis], all_points, np.inf).min(axis=1)
    highest = np.where(all_finite[..., np.newaxis], all_points, -np.inf).max(axis=1)
    seen = np.isfinite(lowest).all(axis=1)
    lowest, highest = lowest[seen], highest[seen]
    body_size = float(np.linalg.norm(highest - lowest, axis=1).max())
    bounds_min, bounds_max = lowest.min(axis=0), highest.max(axis=0)
    horizontal_extent = float(np.linalg.norm((bounds_max - bounds_min)[[0, 2]]))

    metadata = {
        "names": names,
        "segments": segment_array.tolist(),
        "frameCount": int(arrays[0].shape[0]),
        "frameRate": float(frame_rate),
        "unit": _HTML_UNIT,
        "bounds": {
            "min": bounds_min.tolist(),
            "max": bounds_max.tolist(),
            "bodySize": max(body_size, 0.5),
            "extent": float(np.linalg.norm(bounds_max - bounds_min)),
        },
        "follow": horizontal_extent > 2.0 * max(body_size, 0.5),
        # The input's X, Y, Z axes in the replay's Y-up coordinates, for the axis gizmo.
        "axes": to_y_up.T.tolist(),
        # Initial view: the human's ISB front (+X) three-quarter view, from slightly above.
        "view": {"yaw": float(np.pi / 2 - 0.6), "pitch": 0.25},
        "skeletons": [
            {"label": str(skeleton_label), "color": color, "positions": f"@POSITIONS{index}@"}
            for index, ((_, _, skeleton_label), color) in enumerate(zip(skeletons, _HTML_COLORS, strict=False))
        ],
    }
    # "<" escaped so that no name can close the <script> element holding the data.
    data_json = strict_json(metadata, indent=None).replace("<", "\\u003c")
    for index, (array, array_finite) in enumerate(zip(points, finite, strict=True)):
        data_json = data_json.replace(f'"@POSITIONS{index}@"', _json_integers(array, array_finite))
    # One pass, so that neither the title nor the data can bring in a placeholder.
    values = {"TITLE": html.escape(title), "DATA": data_json}
    template = resources.files(__package__).joinpath("replay.html").read_text(encoding="utf-8")
    page = re.sub(r"@(TITLE|DATA)@", lambda match: values[match.group(1)], template)
    write_text_atomically(path, page)


def _json_integers(points: np.ndarray, finite: np.ndarray) -> str:
    """A JSON array of the (F, K, 3) integer points, flat, a missing point as 3 nulls."""
    tokens = np.where(finite[..., np.newaxis], points, 0.0).astype(np.int64).astype(str)
    tokens[~finite] = "null"
    return "[" + ",".join(tokens.ravel().tolist()) + "]"
