"""A 3D replay of the motion in one self-contained HTML file (no server, no network).
"""

from __future__ import annotations

import html
import json
import os
import re

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.io.files import write_text_atomically

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
            for index, ((_, _, skeleton_label), color) in enumerate(zip(skeletons, _HTML_COLORS))
        ],
    }
    # "<" escaped so that no name can close the <script> element holding the data.
    data_json = json.dumps(metadata, separators=(",", ":")).replace("<", "\\u003c")
    for index, (array, array_finite) in enumerate(zip(points, finite)):
        data_json = data_json.replace(f'"@POSITIONS{index}@"', _json_integers(array, array_finite))
    # One pass, so that neither the title nor the data can bring in a placeholder.
    values = {"TITLE": html.escape(title), "DATA": data_json}
    page = re.sub(r"@(TITLE|DATA)@", lambda match: values[match.group(1)], _HTML_TEMPLATE)
    write_text_atomically(path, page)



def _json_integers(points: np.ndarray, finite: np.ndarray) -> str:
    """A JSON array of the (F, K, 3) integer points, flat, a missing point as 3 nulls."""
    tokens = np.where(finite[..., np.newaxis], points, 0.0).astype(np.int64).astype(str)
    tokens[~finite] = "null"
    return "[" + ",".join(tokens.ravel().tolist()) + "]"



_HTML_TEMPLATE = r"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>@TITLE@</title>
<style>
html, body { margin: 0; height: 100%; }
body {
  display: flex; flex-direction: column; background: #fafaf7; color: #222;
  font: 14px/1.4 system-ui, -apple-system, "Segoe UI", Roboto, Helvetica, Arial, sans-serif;
}
header { display: flex; align-items: baseline; gap: 16px; flex-wrap: wrap;
  padding: 8px 14px; border-bottom: 1px solid #ddd; }
header h1 { margin: 0; font-size: 16px; font-weight: 600; }
header .info { color: #666; font-size: 13px; }
#view { position: relative; flex: 1; min-height: 240px; overflow: hidden; }
#canvas { position: absolute; left: 0; top: 0; width: 100%; height: 100%;
  cursor: grab; touch-action: none; }
#canvas.dragging { cursor: grabbing; }
#legend { position: absolute; top: 10px; left: 12px; padding: 6px 10px; font-size: 13px;
  background: rgba(255, 255, 255, 0.85); border: 1px solid #ddd; border-radius: 4px;
  pointer-events: none; }
#legend .swatch { display: inline-block; width: 22px; margin-right: 8px;
  vertical-align: middle; border-top: 3px solid; }
#help { position: absolute; right: 12px; bottom: 8px; color: #777; font-size: 12px;
  pointer-events: none; text-align: right; }
#controls { display: flex; align-items: center; gap: 12px; flex-wrap: wrap;
  padding: 8px 14px; border-top: 1px solid #ddd; }
#controls button { font: inherit; min-width: 84px; padding: 3px 10px; }
#controls label { white-space: nowrap; }
#slider { flex: 1; min-width: 160px; }
#counter { min-width: 200px; font-variant-numeric: tabular-nums; }
</style>
</head>
<body>
<header><h1>@TITLE@</h1><span class="info" id="info"></span></header>
<div id="view">
  <canvas id="canvas"></canvas>
  <div id="legend"></div>
  <div id="help">drag: orbit &middot; shift+drag or right-drag: pan &middot; wheel: zoom &middot;
    double-click: reset view<br>space: play / pause &middot;
    &larr; &rarr;: previous / next frame</div>
</div>
<div id="controls">
  <button id="play" type="button">Play</button>
  <input id="slider" type="range" min="0" max="0" step="1" value="0" aria-label="frame">
  <span id="counter"></span>
  <label>speed <select id="speed">
    <option value="0.25">0.25&times;</option><option value="0.5">0.5&times;</option>
    <option value="1" selected>1&times;</option><option value="2">2&times;</option>
  </select></label>
  <label title="keep the subject centred"><input id="follow" type="checkbox"> follow</label>
  <label><input id="names" type="checkbox"> names</label>
  <button id="reset" type="button">Reset view</button>
</div>
<script id="replay-data" type="application/json">@DATA@</script>
<script>
(function () {
  "use strict";
  var data = JSON.parse(document.getElementById("replay-data").textContent);
  var names = data.names, segments = data.segments, skeletons = data.skeletons;
  var K = names.length, F = data.frameCount, UNIT = data.unit, bounds = data.bounds;
  var FOV = 40 * Math.PI / 180, NEAR = 0.05, GRID_STEP = 0.5;
  var AXIS_COLORS = ["#d0342c", "#2e9e44", "#2c6fd0"], AXIS_NAMES = ["X", "Y", "Z"];
  var centre = [0, 1, 2].map(function (i) { return 0.5 * (bounds.min[i] + bounds.max[i]); });

  var canvas = document.getElementById("canvas"), context = canvas.getContext("2d");
  var slider = document.getElementById("slider"), playButton = document.getElementById("play");
  var counter = document.getElementById("counter"), speedSelect = document.getElementById("speed");
  var followBox = document.getElementById("follow"), namesBox = document.getElementById("names");

  var view = { yaw: 0, pitch: 0, distance: 1, pan: [0, 0, 0] };
  var camera = null, width = 1, height = 1, focal = 1;
  var frame = 0, time = 0, speed = 1, playing = false, lastStamp = null, dirty = true;
  var drag = null, hovered = null, screenPoints = [];

  function point(skeleton, f, k) {
    var values = skeletons[skeleton].positions, i = (f * K + k) * 3;
    if (values[i] === null) { return null; }
    return [values[i] * UNIT, values[i + 1] * UNIT, values[i + 2] * UNIT];
  }

  function target() {
    var base = centre.slice();
    if (followBox.checked) {
      var sum = [0, 0, 0], count = 0;
      for (var k = 0; k < K; k++) {
        var p = point(0, frame, k);
        if (p) { sum[0] += p[0]; sum[2] += p[2]; count++; }
      }
      if (count) { base[0] = sum[0] / count; base[2] = sum[2] / count; }
    }
    return [base[0] + view.pan[0], base[1] + view.pan[1], base[2] + view.pan[2]];
  }

  function setupCamera() {
    camera = { target: target(), cy: Math.cos(view.yaw), sy: Math.sin(view.yaw),
               cp: Math.cos(view.pitch), sp: Math.sin(view.pitch) };
  }

  // World (Y up) to camera coordinates: x right, y up, depth along the view direction.
  function toCamera(p) {
    var x = p[0] - camera.target[0], y = p[1] - camera.target[1], z = p[2] - camera.target[2];
    var x1 = camera.cy * x - camera.sy * z, z1 = camera.sy * x + camera.cy * z;
    var y2 = camera.cp * y - camera.sp * z1, z2 = camera.sp * y + camera.cp * z1;
    return [x1, y2, view.distance - z2];
  }

  function toScreen(c) {
    return [0.5 * width + focal * c[0] / c[2], 0.5 * height - focal * c[1] / c[2]];
  }

  // A segment in camera coordinates cut at the near plane, as two screen points, or null.
  function clip(a, b) {
    if (a[2] < NEAR && b[2] < NEAR) { return null; }
    if (a[2] < NEAR) { a = toNear(b, a); } else if (b[2] < NEAR) { b = toNear(a, b); }
    return [toScreen(a), toScreen(b)];
  }

  function toNear(inside, outside) {
    var s = (inside[2] - NEAR) / (inside[2] - outside[2]);
    return [inside[0] + s * (outside[0] - inside[0]),
            inside[1] + s * (outside[1] - inside[1]), NEAR];
  }

  // Grid cells around the target, fading with the distance from it (drawn in a few paths of
  // one opacity each); the lines x = 0 and z = 0 in the colours of the Z and X axes.
  function drawGrid() {
    var floor = bounds.min[1], t = camera.target, LEVELS = 8;
    var step = view.distance > 12 ? 2 * GRID_STEP : GRID_STEP;
    var count = Math.min(30, Math.max(6, Math.ceil(view.distance / step)));
    var radius = count * step;
    var x0 = Math.round(t[0] / step) * step, z0 = Math.round(t[2] / step) * step;
    var paths = [], axes = [[], []];
    for (var level = 0; level < LEVELS; level++) { paths.push([]); }
    for (var i = -count; i <= count; i++) {
      for (var j = -count; j < count; j++) {
        var u = i * step, v = (j + 0.5) * step;
        var fade = 1 - Math.sqrt(u * u + v * v) / radius;
        if (fade <= 0) { continue; }
        var x = x0 + u, z = z0 + u, from = j * step, to = (j + 1) * step;
        var along = [[x, floor, z0 + from], [x, floor, z0 + to]];
        var across = [[x0 + from, floor, z], [x0 + to, floor, z]];
        var bucket = paths[Math.min(LEVELS - 1, Math.floor(fade * LEVELS))];
        (Math.abs(x) < 1e-9 ? axes[0] : bucket).push(along);
        (Math.abs(z) < 1e-9 ? axes[1] : bucket).push(across);
      }
    }
    context.lineWidth = 1;
    paths.forEach(function (lines, level) {
      context.strokeStyle = "rgba(150, 150, 140, " + (0.5 * (level + 1) / LEVELS) + ")";
      strokePath(lines);
    });
    context.strokeStyle = "rgba(44, 111, 208, 0.5)";
    strokePath(axes[0]);
    context.strokeStyle = "rgba(208, 52, 44, 0.5)";
    strokePath(axes[1]);
  }

  function strokePath(lines) {
    context.beginPath();
    lines.forEach(function (line) {
      var ends = clip(toCamera(line[0]), toCamera(line[1]));
      if (ends) {
        context.moveTo(ends[0][0], ends[0][1]);
        context.lineTo(ends[1][0], ends[1][1]);
      }
    });
    context.stroke();
  }

  function drawShadows() {
    var floor = bounds.min[1];
    context.strokeStyle = "rgba(0, 0, 0, 0.10)";
    context.lineWidth = 5;
    context.lineCap = "round";
    var lines = [];
    for (var s = 0; s < skeletons.length; s++) {
      for (var i = 0; i < segments.length; i++) {
        var a = point(s, frame, segments[i][0]), b = point(s, frame, segments[i][1]);
        if (a && b) { lines.push([[a[0], floor, a[2]], [b[0], floor, b[2]]]); }
      }
    }
    strokePath(lines);
  }

  function drawSkeletons() {
    var items = [];
    screenPoints = [];
    for (var s = 0; s < skeletons.length; s++) {
      var cameraPoints = [];
      for (var k = 0; k < K; k++) {
        var p = point(s, frame, k);
        cameraPoints.push(p ? toCamera(p) : null);
      }
      for (var i = 0; i < segments.length; i++) {
        var a = cameraPoints[segments[i][0]], b = cameraPoints[segments[i][1]];
        if (a && b) { items.push({ skeleton: s, a: a, b: b, depth: 0.5 * (a[2] + b[2]) }); }
      }
      for (k = 0; k < K; k++) {
        var c = cameraPoints[k];
        if (c && c[2] > NEAR) {
          var q = toScreen(c);
          items.push({ skeleton: s, joint: k, point: q, depth: c[2] });
          screenPoints.push({ skeleton: s, joint: k, x: q[0], y: q[1] });
        }
      }
    }
    items.sort(function (u, v) { return v.depth - u.depth; });  // far first
    context.lineCap = "round";
    for (var j = 0; j < items.length; j++) {
      var item = items[j], color = skeletons[item.skeleton].color;
      context.setLineDash(item.skeleton === 0 ? [] : [7, 5]);
      if (item.point) {
        context.fillStyle = color;
        context.beginPath();
        context.arc(item.point[0], item.point[1], item.skeleton === 0 ? 3.5 : 3, 0, 2 * Math.PI);
        context.fill();
      } else {
        var ends = clip(item.a, item.b);
        if (!ends) { continue; }
        context.strokeStyle = color;
        context.lineWidth = item.skeleton === 0 ? 3 : 2.5;
        context.beginPath();
        context.moveTo(ends[0][0], ends[0][1]);
        context.lineTo(ends[1][0], ends[1][1]);
        context.stroke();
      }
    }
    context.setLineDash([]);
  }

  function drawLabel(text, x, y, bold) {
    context.font = (bold ? "600 13px " : "11px ") + "system-ui, sans-serif";
    var w = context.measureText(text).width;
    context.fillStyle = bold ? "rgba(255, 255, 255, 0.92)" : "rgba(255, 255, 255, 0.7)";
    context.fillRect(x + 6, y - 16, w + 8, 18);
    context.fillStyle = bold ? "#111" : "#555";
    context.fillText(text, x + 10, y - 3);
  }

  function drawLabels() {
    if (namesBox.checked) {
      screenPoints.forEach(function (p) {
        if (p.skeleton === 0) { drawLabel(names[p.joint], p.x, p.y, false); }
      });
    }
    if (hovered) {
      var p = screenPoints.filter(function (q) {
        return q.skeleton === hovered.skeleton && q.joint === hovered.joint;
      })[0];
      if (p) {
        var suffix = skeletons.length > 1 ? " (" + skeletons[p.skeleton].label + ")" : "";
        drawLabel(names[p.joint] + suffix, p.x, p.y, true);
      }
    }
  }

  function drawAxes() {
    var origin = [44, height - 44], length = 28;
    context.lineWidth = 2;
    context.font = "600 12px system-ui, sans-serif";
    for (var i = 0; i < 3; i++) {
      var v = data.axes[i];
      var x1 = camera.cy * v[0] - camera.sy * v[2], z1 = camera.sy * v[0] + camera.cy * v[2];
      var y2 = camera.cp * v[1] - camera.sp * z1;
      var end = [origin[0] + length * x1, origin[1] - length * y2];
      context.strokeStyle = AXIS_COLORS[i];
      context.fillStyle = AXIS_COLORS[i];
      context.beginPath();
      context.moveTo(origin[0], origin[1]);
      context.lineTo(end[0], end[1]);
      context.stroke();
      context.fillText(AXIS_NAMES[i], end[0] + 4 * x1 - 4, end[1] - 4 * y2 + 4);
    }
  }

  function draw() {
    setupCamera();
    context.clearRect(0, 0, width, height);
    drawGrid();
    drawShadows();
    drawSkeletons();
    drawLabels();
    drawAxes();
  }

  function resize() {
    var box = canvas.parentElement.getBoundingClientRect(), ratio = window.devicePixelRatio || 1;
    width = Math.max(1, box.width);
    height = Math.max(1, box.height);
    canvas.width = Math.round(width * ratio);
    canvas.height = Math.round(height * ratio);
    context.setTransform(ratio, 0, 0, ratio, 0, 0);
    focal = 0.5 * height / Math.tan(0.5 * FOV);
    dirty = true;
  }

  function resetView() {
    view.yaw = data.view.yaw;
    view.pitch = data.view.pitch;
    var size = followBox.checked ? bounds.bodySize : Math.max(bounds.bodySize, bounds.extent);
    view.distance = 0.55 * size / Math.tan(0.5 * FOV) + 0.3 * size;
    view.pan = [0, 0, 0];
    dirty = true;
  }

  function updateCounter() {
    counter.textContent = "frame " + (frame + 1) + " / " + F + " \u00b7 " +
      (frame / data.frameRate).toFixed(3) + " s";
    slider.value = String(frame);
  }

  function setFrame(f) {
    frame = ((f % F) + F) % F;
    time = frame / data.frameRate;
    updateCounter();
    dirty = true;
  }

  function setPlaying(on) {
    playing = on && F > 1;
    lastStamp = null;
    playButton.textContent = playing ? "\u275a\u275a Pause" : "\u25b6 Play";
  }

  function tick(stamp) {
    if (playing) {
      if (lastStamp !== null) {
        var duration = F / data.frameRate;
        time = (time + speed * (stamp - lastStamp) / 1000) % duration;
        var f = Math.min(F - 1, Math.floor(time * data.frameRate + 1e-9));
        if (f !== frame) { frame = f; updateCounter(); dirty = true; }
      }
      lastStamp = stamp;
    }
    if (dirty) { dirty = false; draw(); }
    window.requestAnimationFrame(tick);
  }

  canvas.addEventListener("pointerdown", function (event) {
    drag = { x: event.clientX, y: event.clientY, pan: event.shiftKey || event.button === 2 };
    canvas.setPointerCapture(event.pointerId);
    canvas.classList.add("dragging");
  });
  canvas.addEventListener("pointermove", function (event) {
    if (drag) {
      var dx = event.clientX - drag.x, dy = event.clientY - drag.y;
      drag.x = event.clientX;
      drag.y = event.clientY;
      if (drag.pan) {
        var scale = view.distance / focal;
        var right = [camera.cy, 0, -camera.sy];
        var up = [-camera.sp * camera.sy, camera.cp, -camera.sp * camera.cy];
        for (var i = 0; i < 3; i++) { view.pan[i] += scale * (up[i] * dy - right[i] * dx); }
      } else {
        view.yaw -= 0.008 * dx;
        view.pitch = Math.max(-1.45, Math.min(1.45, view.pitch + 0.008 * dy));
      }
      dirty = true;
      return;
    }
    var box = canvas.getBoundingClientRect();
    var x = event.clientX - box.left, y = event.clientY - box.top, best = null, bestDistance = 100;
    screenPoints.forEach(function (p) {
      var d = (p.x - x) * (p.x - x) + (p.y - y) * (p.y - y);
      if (d < bestDistance) { bestDistance = d; best = p; }
    });
    var changed = (best === null) !== (hovered === null) || (best && hovered &&
      (best.skeleton !== hovered.skeleton || best.joint !== hovered.joint));
    if (changed) { hovered = best; dirty = true; }
  });
  function endDrag() { drag = null; canvas.classList.remove("dragging"); }
  canvas.addEventListener("pointerup", endDrag);
  canvas.addEventListener("pointercancel", endDrag);
  canvas.addEventListener("pointerleave", function () {
    if (hovered) { hovered = null; dirty = true; }
  });
  canvas.addEventListener("contextmenu", function (event) { event.preventDefault(); });
  canvas.addEventListener("wheel", function (event) {
    event.preventDefault();
    var step = event.deltaMode === 1 ? 33 * event.deltaY : event.deltaY;
    view.distance = Math.max(0.1, Math.min(1000, view.distance * Math.exp(0.001 * step)));
    dirty = true;
  }, { passive: false });
  canvas.addEventListener("dblclick", resetView);

  playButton.addEventListener("click", function () { setPlaying(!playing); });
  document.getElementById("reset").addEventListener("click", resetView);
  slider.addEventListener("input", function () {
    setPlaying(false);
    setFrame(Number(slider.value));
  });
  speedSelect.addEventListener("change", function () { speed = Number(speedSelect.value); });
  followBox.addEventListener("change", function () { view.pan = [0, 0, 0]; dirty = true; });
  namesBox.addEventListener("change", function () { dirty = true; });
  window.addEventListener("keydown", function (event) {
    var tag = event.target && event.target.tagName;
    if (tag === "BUTTON" || tag === "SELECT") { return; }
    if (event.code === "Space" || event.key === " ") {
      event.preventDefault();
      setPlaying(!playing);
    } else if (event.key === "ArrowRight" || event.key === "ArrowLeft") {
      event.preventDefault();
      setPlaying(false);
      setFrame(frame + (event.key === "ArrowRight" ? 1 : -1));
    }
  });
  window.addEventListener("resize", resize);

  document.getElementById("info").textContent = K + " keypoints \u00b7 " + F + " frames at " +
    data.frameRate + " Hz \u00b7 " + (F / data.frameRate).toFixed(2) + " s";
  var legend = document.getElementById("legend");
  skeletons.forEach(function (skeleton, index) {
    var row = document.createElement("div"), swatch = document.createElement("span");
    swatch.className = "swatch";
    swatch.style.borderTopColor = skeleton.color;
    swatch.style.borderTopStyle = index === 0 ? "solid" : "dashed";
    row.appendChild(swatch);
    row.appendChild(document.createTextNode(skeleton.label));
    legend.appendChild(row);
  });
  slider.max = String(F - 1);
  slider.disabled = F < 2;
  playButton.disabled = F < 2;
  followBox.checked = data.follow;
  resize();
  resetView();
  setFrame(0);
  setPlaying(true);
  draw();
  window.requestAnimationFrame(tick);
})();
</script>
</body>
</html>
"""
