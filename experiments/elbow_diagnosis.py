"""Why IBIK's elbows can end worse than PIK's: each elbow per frame, decomposed, and what moved it.

On sweep conditions whose files a sweep run kept (``sweep.py --keep FOLDER``), runs PIK and IBIK
(2 views) as the sweep does (``ibik track``; the trial-refined statics the sweep wrote) and, per
frame and elbow:

- the error against the truth, split on the limb's circle as docs/sweep.md does: the distance from
  the shoulder-wrist line (estimated vs true: the lengths), the swivel about that line [deg] and its
  chord [mm], the position along the line;
- where the elbow was after the frame's targets-only steps, whether the swivel search hinted it
  (and how far), and where the image steps left it: which stage moved it away from the truth.

Usage:
    python experiments/elbow_diagnosis.py --keep /tmp/h4_inputs --conditions 8 22 36
    python experiments/elbow_diagnosis.py --keep /tmp/h4_inputs --conditions 22 --set swivel_search=false
"""

from __future__ import annotations

import argparse
import functools
import json
from pathlib import Path

import numpy as np
from realdata.runner import parse_settings
from sweepkit.conditions import draw_condition, load_condition
from sweepkit.runs import run_condition_variant

from ibik_pin.tracking import tracker as tracker_module
from ibik_pin.tracking.swivel import SwivelSearch

ELBOWS = {"LElbow": ("LShoulder", "LWrist"), "RElbow": ("RShoulder", "RWrist")}


class StageRecorder:
    """Records each frame's elbows after the targets-only steps and the swivel search's hints, by
    wrapping Tracker._swivel_hints (called once per frame solve, after those steps)."""

    def __init__(self) -> None:
        self.frames: list[dict] = []
        self._original = tracker_module.Tracker._swivel_hints

    def __enter__(self) -> StageRecorder:
        recorder, original = self, self._original

        def recording(tracker, configuration, free):
            ids = tracker.body.frame_ids(list(ELBOWS))
            before = configuration.frame_positions(ids).copy()
            hints = tracker.swivel.hints(configuration, free)
            recorder.frames.append({"before": before, "hints": {k: v.copy() for k, v in hints.items()}})
            return original(tracker, configuration, free)

        tracker_module.Tracker._swivel_hints = recording
        return self

    def __exit__(self, *exc) -> None:
        tracker_module.Tracker._swivel_hints = self._original


def _point(data, names: list[str], name: str) -> np.ndarray:
    return data[:, names.index(name)]


def decompose(shoulder, elbow, wrist, true_shoulder, true_elbow, true_wrist) -> dict[str, np.ndarray]:
    """Per frame (F, 3 each): total error, distance from the line (estimated minus true), swivel
    error [deg] and its chord on the true circle [m], along-the-line offset [m], the true radius."""
    def frame_of(start, middle, end):
        axis = end - start
        axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
        along = np.einsum("fi,fi->f", middle - start, axis)
        radial = middle - start - along[:, None] * axis
        return axis, along, radial

    axis, along, radial = frame_of(shoulder, elbow, wrist)
    _, true_along, true_radial = frame_of(true_shoulder, true_elbow, true_wrist)
    radius, true_radius = np.linalg.norm(radial, axis=1), np.linalg.norm(true_radial, axis=1)
    # The true radial direction seen about the estimated line (the two lines are nearly parallel).
    projected = true_radial - np.einsum("fi,fi->f", true_radial, axis)[:, None] * axis
    cosine = np.einsum("fi,fi->f", radial, projected) / np.maximum(radius * np.linalg.norm(projected, axis=1), 1e-12)
    swivel = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    return {"total": np.linalg.norm(elbow - true_elbow, axis=1), "radius_error": radius - true_radius,
            "swivel_deg": swivel, "chord": 2.0 * true_radius * np.sin(np.radians(swivel) / 2.0),
            "along_error": along - true_along, "true_radius": true_radius, "radius": radius}


def diagnose(inputs, kind: str, overrides: dict) -> dict:
    """PIK and IBIK 2v on one condition; per elbow the decomposition of both and IBIK's stages."""
    folder = inputs.folder
    refined = folder / f"static_images2v_{kind}.trc"
    reach = folder / "static_reach.trc"
    pik = run_condition_variant(inputs, "pik", kind, overrides, reach if reach.exists() else None)
    with StageRecorder() as recorder:
        ibik = run_condition_variant(inputs, "ibik2v", kind, overrides, refined if refined.exists() else None)
    frames = inputs.truth.shape[0]
    stages = recorder.frames[-frames:]
    truth_names = inputs.truth_names
    out: dict = {"index": inputs.condition.index, "motion": inputs.condition.motion, "silhouettes": kind, "elbows": {}}
    for k, (elbow, (shoulder, wrist)) in enumerate(ELBOWS.items()):
        true = [_point(inputs.truth, truth_names, n) for n in (shoulder, elbow, wrist)]
        rows = {}
        for name, run in (("pik", pik), ("ibik", ibik)):
            names = run.estimate.marker_names
            estimate = [_point(run.estimate.positions, names, n) for n in (shoulder, elbow, wrist)]
            rows[name] = decompose(*estimate, *true)
        # Without the swivel search (or the image) nothing was recorded: NaN before the image steps.
        before = (np.array([stage["before"][k] for stage in stages]) if len(stages) == frames
                  else np.full((frames, 3), np.nan))
        hinted = np.array([elbow in stage["hints"] for stage in stages]) if len(stages) == frames \
            else np.zeros(frames, dtype=bool)
        hint_error = np.array([np.linalg.norm(stage["hints"][elbow] - true[1][f]) if elbow in stage["hints"]
                               else np.nan for f, stage in enumerate(stages)]) if len(stages) == frames \
            else np.full(frames, np.nan)
        rows["ibik"]["before_image"] = np.linalg.norm(before - true[1], axis=1)
        rows["ibik"]["hinted"] = hinted
        rows["ibik"]["hint_error"] = hint_error
        out["elbows"][elbow] = {run: {key: value.tolist() for key, value in columns.items()}
                                for run, columns in rows.items()}
    return out


def summary_lines(result: dict) -> list[str]:
    lines = []
    for elbow, runs in result["elbows"].items():
        pik, ibik = runs["pik"], runs["ibik"]
        med = {key: float(np.median(value)) for key, value in ibik.items() if key not in ("hinted", "hint_error")}
        lines.append(
            f"{result['index']:3d} {result['motion']:15s} {result['silhouettes']:7s} {elbow}: "
            f"PIK {np.mean(pik['total'])*1e3:5.1f}"
            f" IBIK {np.mean(ibik['total'])*1e3:5.1f} mm (before image {np.mean(ibik['before_image'])*1e3:5.1f}); "
            f"IBIK radius {med['radius']*1e3:4.0f} (true {med['true_radius']*1e3:4.0f}) radius err "
            f"{np.mean(np.abs(ibik['radius_error']))*1e3:4.1f}, swivel {med['swivel_deg']:5.1f} deg "
            f"(PIK {np.median(pik['swivel_deg']):5.1f}), chord {np.mean(ibik['chord'])*1e3:5.1f}, along "
            f"{np.mean(np.abs(ibik['along_error']))*1e3:4.1f}; hinted {int(np.sum(ibik['hinted']))} frames")
    return lines


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, required=True, help="the folder sweep.py --keep wrote")
    parser.add_argument("--conditions", type=int, nargs="+", required=True)
    parser.add_argument("--silhouettes", default="clean")
    parser.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="a JSON of every frame's figures")
    parser.add_argument("--hint-unrefuted", action="store_true",
                        help="the swivel search hints limbs the silhouettes do not refute too (the earlier rule: "
                             "SwivelSearch.keep_unrefuted=False)")
    arguments = parser.parse_args(argv)
    if arguments.hint_unrefuted:  # the Tracker builds its SwivelSearch from its module's name
        tracker_module.SwivelSearch = functools.partial(SwivelSearch, keep_unrefuted=False)  # type: ignore[misc]
    overrides = parse_settings(arguments.settings)
    results = []
    for index in arguments.conditions:
        inputs = load_condition(draw_condition(index, arguments.seed), arguments.keep / f"condition_{index:03d}")
        if inputs is None:
            raise SystemExit(f"condition {index}: no kept files under {arguments.keep}; run sweep.py --keep first")
        for kind in arguments.silhouettes.split(","):
            result = diagnose(inputs, kind, overrides)
            results.append(result)
            print("\n".join(summary_lines(result)), flush=True)
    if arguments.out is not None:
        arguments.out.write_text(json.dumps(results) + "\n")


if __name__ == "__main__":
    main()
