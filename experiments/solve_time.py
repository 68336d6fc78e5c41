"""Where the image solve's time goes, and what a change of settings saves, alternated in one run.

`ibik track` with the image (the readahead in its second process, as by default) on the
conditions of experiments/opensim_speed.py (real motion capture, 2 and 4 views, and the demo's 4
views). Each run is timed by parts of a frame's solve (Tracker._solve): the targets-only steps,
the swivel search (tracking.swivel), the image steps, the closing step; and its solver steps are
counted (HierarchicalQPSolver.compute_step calls), with the limbs the search looks at. Only the
run's own solve is counted: the subject calibration's tracks (`--trial-lengths images`, ibik
track's default) come before it and are left out (SolveParts). The timers are plain perf_counter calls around
those functions, a few microseconds a frame, not a profiler's cost on every call.

Variants (--variants): TrackingSettings overrides, run in turn in every round, e.g.
"every_target_step" (target_step_tolerance=None) and "tol02" (0.02, the default). Each variant's
solve frame rate over the first variant's is the median of the rounds' ratios; its judged error
(real motion: elbows on boxing, knees on walking) is beside it.

A benchmark, not a test. Usage:
    python experiments/solve_time.py --out out/solve_time [--rounds 5] [--variants every_target_step,tol02]
    python experiments/solve_time.py --out out/solve_time --accuracy [--variants ...]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see ibik_pin/cli.py

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from realdata.clips import CLIPS
from realdata.inputs import prepare_inputs
from realdata.runner import DEFAULT_DATA, code_revision, run_variant, single_threaded_math, summarize, variant

from ibik_pin.app.demo import prepare_demo_inputs
from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import run_track
from ibik_pin.io.files import strict_json
from ibik_pin.solvers.base import Solver
from ibik_pin.solvers.hqp import HierarchicalQPSolver
from ibik_pin.tracking import tracker as tracker_module
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.swivel import SwivelSearch
from ibik_pin.tracking.tracker import Tracker

VARIANTS = {"every_target_step": {"target_step_tolerance": None}, "tol01": {"target_step_tolerance": 0.01},
            "tol02": {"target_step_tolerance": 0.02}, "tol05": {"target_step_tolerance": 0.05}, "defaults": {},
            "image_step_0.1": {"image_step": 0.1},
            **{f"cadence{k}": {"swivel_cadence": k} for k in (1, 2, 3, 4)}}
PARTS = ("target steps", "swivel search", "image steps", "closing step", "first frame")


class SolveParts:
    """Seconds per part of the frames' solves, solver steps computed, the image solves that ended
    at the criterion's peak, and the limbs the swivel search looked at, while active: those of the
    last Tracker.track with the image, the run's own solve (the subject calibration's tracks,
    `--trial-lengths images`, come before it and are not counted)."""

    def __init__(self) -> None:
        self._first_frame = False
        self._clear()

    def _clear(self) -> None:
        self.seconds = dict.fromkeys(PARTS, 0.0)
        self.steps = 0
        self.image_solves = 0
        self.peaked = 0
        self.limbs_searched = 0

    @contextlib.contextmanager
    def active(self):
        solve, hints, step = Solver.solve, Tracker._swivel_hints, HierarchicalQPSolver.compute_step
        first_frame_solve, track, search = tracker_module.solve_first_frame, Tracker.track, SwivelSearch.hints
        parts = self

        def counted_track(tracker, *arguments, **keywords):
            if tracker.use_image:
                parts._clear()
            return track(tracker, *arguments, **keywords)

        def counted_search(swivel, configuration, free):
            parts.limbs_searched += 0 if parts._first_frame else len(free)
            return search(swivel, configuration, free)

        def timed_solve(solver, configuration, levels, iterations=15, tolerance=None, stop_at_peak=False):
            started = time.perf_counter()
            result = solve(solver, configuration, levels, iterations, tolerance, stop_at_peak)
            part = ("first frame" if parts._first_frame else "image steps" if stop_at_peak
                    else "closing step" if iterations == 1 else "target steps")
            parts.seconds[part] += time.perf_counter() - started
            if stop_at_peak and not parts._first_frame:
                parts.image_solves += 1
                parts.peaked += result.iterations < iterations
            return result

        def timed_hints(tracker, *arguments):
            started = time.perf_counter()
            found = hints(tracker, *arguments)
            parts.seconds["first frame" if parts._first_frame else "swivel search"] += time.perf_counter() - started
            return found

        def counted_step(solver, *arguments, **keywords):
            parts.steps += 1
            return step(solver, *arguments, **keywords)

        def first_frame(*arguments, **keywords):
            parts._first_frame = True
            try:
                return first_frame_solve(*arguments, **keywords)
            finally:
                parts._first_frame = False

        Solver.solve, Tracker._swivel_hints = timed_solve, timed_hints  # type: ignore[method-assign]
        HierarchicalQPSolver.compute_step, tracker_module.solve_first_frame = counted_step, first_frame  # type: ignore
        Tracker.track, SwivelSearch.hints = counted_track, counted_search  # type: ignore[method-assign]
        try:
            yield self
        finally:
            Solver.solve, Tracker._swivel_hints = solve, hints  # type: ignore[method-assign]
            HierarchicalQPSolver.compute_step, tracker_module.solve_first_frame = step, first_frame_solve  # type: ignore
            Tracker.track, SwivelSearch.hints = track, search  # type: ignore[method-assign]


def conditions(names: list[str], frames: int, cache: Path, out: Path, data: Path = DEFAULT_DATA) -> dict:
    """name -> a function (overrides, out) -> the run's figures."""
    runners: dict = {}
    for item in names:
        motion, _, views_text = item.partition(":")
        views = int(views_text or 4)
        if motion == "demo":
            paths = prepare_demo_inputs(out / "demo_input")

            def run_demo(overrides: dict, folder: Path, paths=paths) -> dict:
                single_threaded_math()
                report = run_track(TrackJob(targets=paths.targets, static=paths.folder / "static.trc",
                                            calibration=paths.calibration, masks=paths.masks, out=folder, quiet=True,
                                            settings=TrackingSettings(use_image=True, **overrides)))
                return {"solve_fps": float(report["solve_frames_per_second"]), "frames": int(report["frames"]),
                        "judged_error_mm": None}

            runners[f"demo_{views}v"] = run_demo
        else:
            inputs = prepare_inputs(CLIPS[motion], data, frames, cache)

            def run_clip(overrides: dict, folder: Path, inputs=inputs, views=views) -> dict:
                run = run_variant(inputs, variant(f"ibik{views}v"), "clean", overrides, out=folder)
                return {"solve_fps": run.solve_fps, "frames": int(run.errors.shape[0]),
                        "judged_error_mm": run.judged_mm}

            runners[f"{motion}_{views}v"] = run_clip
    return runners


def accuracy(names: list[str], frames: int, cache: Path, out: Path, data: Path = DEFAULT_DATA) -> dict:
    """Every variant on every clip of the real-mocap benchmark, 2 and 4 views, clean and with
    defects, in this one process (the same code for all): the benchmark's aggregates per variant
    (elbows over the boxing clips, knees over the walking clips, all four joints) and, per run, the
    largest change from the first variant's of those judged joints [mm]."""
    results: dict = {name: [] for name in names}
    for clip in CLIPS:
        inputs = prepare_inputs(CLIPS[clip], data, frames, cache)
        for condition in ("clean", "defects"):
            for views in (2, 4):
                for name in names:
                    results[name].append(run_variant(inputs, variant(f"ibik{views}v"), condition, VARIANTS[name],
                                                     out=out / "accuracy" / clip / condition / f"{views}v" / name))
                print(f"{clip} {condition} {views}v: " + ", ".join(
                    f"{name} {results[name][-1].judged_mm:.2f} mm" for name in names), flush=True)
    figures: dict = {}
    for name in names:
        summary = summarize(results[name])
        figures[name] = {"summary": {condition: {views: {key: value for key, value in row.items() if key.endswith("_mm")
                                                         and not isinstance(value, dict)}
                                                 for views, row in rows.items()}
                                     for condition, rows in summary.items()},
                         "largest_judged_change_from_base_mm": max(
                             abs(run.judged_mm - base.judged_mm)
                             for run, base in zip(results[name], results[names[0]], strict=True)),
                         "mean_judged_change_from_base_mm": float(np.mean(
                             [run.judged_mm - base.judged_mm
                              for run, base in zip(results[name], results[names[0]], strict=True)]))}
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--json", type=Path, help="default: OUT/solve_time.json")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the shared data folder")
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--cache", type=Path)
    parser.add_argument("--conditions", default="boxing_a:2,boxing_a:4,cmu35_01:2,cmu35_01:4,demo:4")
    parser.add_argument("--variants", default="every_target_step,tol02",
                        help=f"among {', '.join(VARIANTS)}; the first is the base of the ratios")
    parser.add_argument("--accuracy", action="store_true",
                        help="the variants' errors on the whole real-mocap benchmark (2 and 4 views), no timing")
    arguments = parser.parse_args()
    names = [name.strip() for name in arguments.variants.split(",")]
    unknown = [name for name in names if name not in VARIANTS]
    if unknown:
        parser.error(f"--variants: unknown {unknown}; known: {', '.join(VARIANTS)}")
    arguments.out.mkdir(parents=True, exist_ok=True)
    if arguments.accuracy:
        figures = accuracy(names, arguments.frames, arguments.cache or arguments.out / "cache", arguments.out,
                           arguments.data)
        print(json.dumps(figures, indent=1))
        (arguments.json or arguments.out / "solve_time_accuracy.json").write_text(strict_json({
            "command": "python experiments/solve_time.py " + " ".join(sys.argv[1:]), "revision": code_revision(),
            "frames": arguments.frames, "variants": {name: VARIANTS[name] for name in names}, "accuracy": figures}))
        return
    runners = conditions(arguments.conditions.split(","), arguments.frames, arguments.cache or arguments.out / "cache",
                         arguments.out, arguments.data)
    started, load_before = time.perf_counter(), os.getloadavg()
    for key, run in runners.items():  # warm: compiled code loaded
        run({}, arguments.out / "runs" / key / "warm")
    rows: dict = {key: {name: [] for name in names} for key in runners}
    for round_index in range(arguments.rounds):
        for key, run in runners.items():
            for name in names:
                parts = SolveParts()
                with parts.active():
                    figures = run(VARIANTS[name], arguments.out / "runs" / key / name)
                frames = figures["frames"]
                figures.update({"seconds_per_frame_ms": {part: 1000.0 * seconds / frames
                                                         for part, seconds in parts.seconds.items()},
                                "steps_per_frame": parts.steps / frames,
                                "limbs_searched_per_frame": parts.limbs_searched / frames,
                                "peaked_fraction": parts.peaked / max(parts.image_solves, 1)})
                rows[key][name].append(figures)
                print(f"round {round_index + 1} {key} {name}: {figures['solve_fps']:.1f} frames/s, "
                      f"{figures['steps_per_frame']:.2f} steps a frame, "
                      f"{figures['limbs_searched_per_frame']:.2f} limbs searched a frame, parts [ms/frame] "
                      + ", ".join(f"{part} {ms:.2f}" for part, ms in figures["seconds_per_frame_ms"].items()),
                      flush=True)
    results: dict = {}
    lines = [f"# Where the image solve's time goes (`python experiments/solve_time.py "
             f"{' '.join(sys.argv[1:])}`)", "",
             f"code at {code_revision()}; load average {load_before[0]:.1f} before, {os.getloadavg()[0]:.1f} after; "
             f"medians of {arguments.rounds} rounds", "",
             "| condition | variant | solve [frames/s] | over base | share of the solve: " + " | ".join(PARTS)
             + " | steps a frame | old steps a frame | limbs searched a frame | judged error [mm] |",
             "| --- | --- |" + " ---: |" * (len(PARTS) + 7)]
    for key in runners:
        base = rows[key][names[0]]
        for name in names:
            runs = rows[key][name]
            ratios = [run["solve_fps"] / first["solve_fps"] for run, first in zip(runs, base, strict=True)]
            share = {part: float(np.median([run["seconds_per_frame_ms"][part]
                                            / sum(run["seconds_per_frame_ms"].values()) for run in runs]))
                     for part in PARTS}
            steps = float(np.median([run["steps_per_frame"] for run in runs]))
            searched = float(np.median([run["limbs_searched_per_frame"] for run in runs]))
            # Before Solver.solve read the criterion alone, an image solve that ended at the peak
            # computed one more step (whose criterion showed the fall).
            old_steps = steps + float(np.median([run["peaked_fraction"] for run in runs]))
            results.setdefault(key, {})[name] = {
                "overrides": VARIANTS[name], "solve_fps": float(np.median([run["solve_fps"] for run in runs])),
                "solve_fps_rounds": [run["solve_fps"] for run in runs], "over_base": float(np.median(ratios)),
                "over_base_rounds": ratios, "share": share, "steps_per_frame": steps,
                "steps_per_frame_before_peak_check": old_steps, "limbs_searched_per_frame": searched,
                "judged_error_mm": runs[0]["judged_error_mm"],
                "ms_per_frame": {part: float(np.median([run["seconds_per_frame_ms"][part] for run in runs]))
                                 for part in PARTS}}
            error = runs[0]["judged_error_mm"]
            lines.append(f"| {key} | {name} | {results[key][name]['solve_fps']:.1f} | {np.median(ratios):.2f} | "
                         + " | ".join(f"{100 * share[part]:.0f} %" for part in PARTS)
                         + f" | {steps:.2f} | {old_steps:.2f} | {searched:.2f} | "
                         + f"{'-' if error is None else f'{error:.2f}'} |")
    text = "\n".join(lines) + "\n"
    print(text)
    (arguments.out / "solve_time.md").write_text(text)
    (arguments.json or arguments.out / "solve_time.json").write_text(strict_json({
        "command": "python experiments/solve_time.py " + " ".join(sys.argv[1:]), "revision": code_revision(),
        "rounds": arguments.rounds, "load_average_before": list(load_before),
        "load_average_after": list(os.getloadavg()), "wall_s": time.perf_counter() - started, "conditions": results}))


if __name__ == "__main__":
    main()
