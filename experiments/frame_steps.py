"""Where a frame's solver steps go: per condition, the steps of each of a frame's solves, the swivel
searches and their hints, and the limbs' round trip between the targets-only steps and the image
steps.

`ibik track` with the image (the defaults) on the conditions of experiments/opensim_speed.py (real
motion capture, 2 and 4 views; the demo, 4 views). Only the run's own solve is counted: the
subject calibration's solves (--trial-lengths images tracks on a few frames first) are left out.
Per frame of that solve:
- steps: the targets-only steps (with the posture prior), the image steps (stop at the
  criterion's peak; the undone step not counted), the closing step; swivel searches, the limbs
  they search (TrackingSettings.swivel_cadence) and their hints;
- round trip, on the limb coordinates (BodyModel.limb_coordinates): |a|, the move of frame t+1's
  targets-only steps, |b|, that of frame t's image steps, and cos(a, b). A cosine near -1 with
  |a| ~ |b| means each frame's targets-only steps take back what the image steps before gave: the
  posture prior (toward the neutral pose) pulls the limbs' free rotations back, and the image
  climbs back at its step norm (TrackingSettings.image_step) a step.
No timing: counts and moves, the same on any machine.

A benchmark, not a test. Usage:
    python experiments/frame_steps.py --out out/frame_steps [--conditions cmu35_01:2,boxing_a:2,demo:4]
        [--set swivel_cadence=1]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see ibik_pin/cli.py

import argparse
import contextlib
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parent))

from realdata.clips import CLIPS
from realdata.inputs import prepare_inputs
from realdata.runner import DEFAULT_DATA, code_revision, parse_settings, run_variant, single_threaded_math, variant

from ibik_pin.app.demo import prepare_demo_inputs
from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import run_track
from ibik_pin.io.files import strict_json
from ibik_pin.solvers.base import Solver
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.swivel import SwivelSearch
from ibik_pin.tracking.tracker import Tracker


class FrameSolves:
    """Each solve of the last Tracker.track with the image, while active: its kind ("targets",
    "image", "closing", by Tracker._solve's arguments), steps and move dq; and the searches' hints."""

    def __init__(self) -> None:
        self.solves: list[tuple[str, int, np.ndarray]] = []
        self.hints: list[int] = []
        self.searched: list[int] = []
        self.limbs: np.ndarray | None = None

    @contextlib.contextmanager
    def active(self):
        track, solve, hints = Tracker.track, Solver.solve, SwivelSearch.hints
        recording = {"on": False}
        parts = self

        def counted_track(tracker, names, targets, *arguments, **keywords):
            if not tracker.use_image:
                return track(tracker, names, targets, *arguments, **keywords)
            parts.solves, parts.hints, parts.searched = [], [], []
            parts.limbs = tracker.body.limb_coordinates
            recording["on"] = True
            try:
                return track(tracker, names, targets, *arguments, **keywords)
            finally:
                recording["on"] = False

        def counted_solve(solver, configuration, levels, iterations=15, tolerance=None, stop_at_peak=False):
            before = configuration.q.copy()
            result = solve(solver, configuration, levels, iterations, tolerance, stop_at_peak)
            if recording["on"]:
                kind = "image" if stop_at_peak else "closing" if iterations == 1 else "targets"
                parts.solves.append((kind, result.iterations, pin.difference(configuration.model, before,
                                                                                configuration.q)))
            return result

        def counted_hints(search, configuration, free):
            found = hints(search, configuration, free)
            if recording["on"]:
                parts.hints.append(len(found))
                parts.searched.append(len(free))
            return found

        Tracker.track, Solver.solve, SwivelSearch.hints = counted_track, counted_solve, counted_hints  # type: ignore
        try:
            yield self
        finally:
            Tracker.track, Solver.solve, SwivelSearch.hints = track, solve, hints  # type: ignore[method-assign]

    def figures(self) -> dict:
        """Per frame, the first left out (solve_first_frame's solves differ)."""
        frames: list[dict] = []
        for kind, steps, move in self.solves:
            if kind == "targets":
                frames.append({})
            if frames:
                frames[-1][kind] = (steps, move)
        complete = [frame for frame in frames if {"targets", "image", "closing"} <= frame.keys()]
        frames, searched = complete[1:], len(complete)
        limbs = self.limbs
        pull = np.array([frame["targets"][1][limbs] for frame in frames])
        climb = np.array([frame["image"][1][limbs] for frame in frames])
        # frame t + 1's targets-only move against frame t's image move
        after, before = pull[1:], climb[:-1]
        cosine = np.sum(after * before, axis=1) / np.maximum(
            np.linalg.norm(after, axis=1) * np.linalg.norm(before, axis=1), 1e-12)
        return {
            "frames": len(frames),
            "targets_steps_per_frame": float(np.mean([frame["targets"][0] for frame in frames])),
            "image_steps_per_frame": float(np.mean([frame["image"][0] for frame in frames])),
            "closing_steps_per_frame": float(np.mean([frame["closing"][0] for frame in frames])),
            "searches_per_frame": len(self.hints) / max(searched, 1),  # over every frame
            "limbs_searched_per_frame": sum(self.searched) / max(searched, 1),
            "hints_per_frame": sum(self.hints) / max(searched, 1),
            "targets_limb_move_median_rad": float(np.median(np.linalg.norm(pull, axis=1))),
            "image_limb_move_median_rad": float(np.median(np.linalg.norm(climb, axis=1))),
            "next_targets_against_image_cosine_median": float(np.median(cosine)),
        }


def run_condition(item: str, frames: int, cache: Path, data: Path, out: Path,
                  overrides: dict | None = None) -> tuple[str, dict]:
    motion, _, views_text = item.partition(":")
    views = int(views_text or 4)
    counter = FrameSolves()
    with counter.active():
        if motion == "demo":
            paths = prepare_demo_inputs(out / "demo_input")
            single_threaded_math()
            run_track(TrackJob(targets=paths.targets, static=paths.folder / "static.trc",
                               calibration=paths.calibration, masks=paths.masks, out=out / "runs" / "demo", quiet=True,
                               settings=TrackingSettings(use_image=True, **(overrides or {}))))
            judged = None
        else:
            inputs = prepare_inputs(CLIPS[motion], data, frames, cache)
            judged = run_variant(inputs, variant(f"ibik{views}v"), "clean", overrides or {},
                                 out=out / "runs" / f"{motion}_{views}v").judged_mm
    return f"{motion}_{views}v", {**counter.figures(), "judged_error_mm": judged}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--json", type=Path, help="default: OUT/frame_steps.json")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--cache", type=Path, help="where the rendered inputs are kept (default: OUT/cache)")
    parser.add_argument("--conditions", default="boxing_a:2,boxing_a:4,cmu35_01:2,cmu35_01:4,demo:4")
    parser.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE",
                        help="override a TrackingSettings field for every run (repeatable)")
    arguments = parser.parse_args()
    overrides = parse_settings(arguments.settings)
    arguments.out.mkdir(parents=True, exist_ok=True)
    cache = arguments.cache or arguments.out / "cache"
    results = {}
    for item in arguments.conditions.split(","):
        name, figures = run_condition(item.strip(), arguments.frames, cache, arguments.data, arguments.out, overrides)
        results[name] = figures
        print(f"{name}: " + ", ".join(f"{key} {value:.3g}" if isinstance(value, float) else f"{key} {value}"
                                      for key, value in figures.items()), flush=True)
    command = " ".join(["python experiments/frame_steps.py", *sys.argv[1:]])
    (arguments.json or arguments.out / "frame_steps.json").write_text(
        strict_json({"command": command, "revision": code_revision(), "conditions": results}))


if __name__ == "__main__":
    main()
