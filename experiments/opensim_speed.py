"""Speed against OpenSim on the same model and targets: `ibik track` with the image and blind,
alternated with OpenSim's InverseKinematicsTool (blind) on the model.osim `ibik track` wrote.

Conditions: real motion capture as the real-mocap benchmark renders it (experiments/realdata:
CMU walking 35_01 and the boxing BVH's first window, 640 x 480 silhouettes of another body, the
subject calibrated on a static trial), 2 and 4 views; and the demo's inputs (`ibik demo`: CMU 35_01
rendered on the scaled model, 4 views). Every condition has --frames frames at 60 Hz (the demo:
its 120).

In each of --rounds rounds, each condition runs in turn: `ibik track` with the image, OpenSim's IK,
`ibik track` blind (PIK), `ibik track` with the image on one thread (--read-ahead off). Figures:
- ibik: report.json's frame rate of the solves alone (solve_frames_per_second), of the whole
  frame loop, and the whole run_track call's wall time (subject calibration, reading, writing
  every output). By default the support images are built in a second process (the readahead)
  while the frame before is solved; on one thread they are built between the solves. On a
  shared machine the two differ: the process and its child share the session's slice of the
  cores (measured here at load 12 on 2 cores: the solves 2x faster with the child off), where on
  a quiet machine the child takes the idle core;
- OpenSim: frames over InverseKinematicsTool.run()'s time (reading the TRC, the solves, writing
  the .mot; one thread), and over the whole of loading model.osim, setting up the tool and
  running it. Its tasks: every target keypoint, weight 1 (the targets file has no virtual marker);
  the tool's defaults otherwise (accuracy 1e-5, no constraint).
Each ratio is the median over the rounds of the ratio of the two runs of that round (the
machine's speed drifts 3x within a day: figures of one run are comparable, across runs not).

A benchmark, not a test. Usage:
    python experiments/opensim_speed.py --out out/opensim_speed [--json PATH] [--rounds 5]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see ibik_pin/cli.py

import argparse
import dataclasses
import os.path
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from realdata.clips import CLIPS
from realdata.inputs import prepare_inputs
from realdata.runner import code_revision, run_variant, single_threaded_math, variant

from ibik_pin.app.demo import prepare_demo_inputs
from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import run_track
from ibik_pin.io.files import strict_json
from ibik_pin.io.trc import read_trc
from ibik_pin.tracking.settings import TrackingSettings

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@dataclasses.dataclass
class Condition:
    """One motion and view count: `track(use_image, out, read_ahead)` runs `ibik track` and returns
    its report's frame rates and its wall time; `targets` is the targets file both tools follow."""

    name: str
    views: int
    targets: Path
    frames: int
    track: Callable[[bool, Path, str], dict]


def realdata_condition(clip: str, views: int, frames: int, cache: Path) -> Condition:
    inputs = prepare_inputs(CLIPS[clip], DATA, frames, cache)

    def track(use_image: bool, out: Path, read_ahead: str = "process") -> dict:
        run = run_variant(inputs, variant(f"ibik{views}v" if use_image else "pik"), "clean",
                          {"read_ahead": read_ahead}, out=out)
        return {"solve_fps": run.solve_fps, "loop_fps": run.loop_fps, "wall_s": run.wall_seconds,
                "judged_error_mm": run.judged_mm}

    return Condition(clip, views, inputs.targets("clean"), frames, track)


def demo_condition(folder: Path) -> Condition:
    paths = prepare_demo_inputs(folder)

    def track(use_image: bool, out: Path, read_ahead: str = "process") -> dict:
        single_threaded_math()
        started = time.perf_counter()
        report = run_track(TrackJob(targets=paths.targets, static=paths.folder / "static.trc",
                                    calibration=paths.calibration, masks=paths.masks, out=out, quiet=True,
                                    settings=TrackingSettings(use_image=use_image, read_ahead=read_ahead)))
        return {"solve_fps": float(report["solve_frames_per_second"]), "loop_fps": float(report["frames_per_second"]),
                "wall_s": time.perf_counter() - started}

    return Condition("demo", 4, paths.targets, len(read_trc(paths.targets).times), track)


def _ik_tool(opensim, model_path: Path, targets: Path, work: Path, output: str, report_errors: bool):
    """OpenSim's InverseKinematicsTool set up on `targets` with `model_path`, every marker a task of
    weight 1 over the whole take; returns the tool, its model and the number of frames. The caller
    holds the model while the tool runs: the tool only points to it (freed, the run crashes)."""
    model = opensim.Model(str(model_path))
    markers = opensim.TimeSeriesTableVec3(str(targets))
    tool = opensim.InverseKinematicsTool()
    tool.setModel(model)
    tool.setMarkerDataFileName(str(targets))
    times = markers.getIndependentColumn()
    tool.setStartTime(times[0])
    tool.setEndTime(times[-1])
    tool.setResultsDir(str(work))
    tool.setOutputMotionFileName(str(work / output))
    tool.set_report_errors(report_errors)
    for name in markers.getColumnLabels():
        task = opensim.IKMarkerTask()
        task.setName(name)
        task.setWeight(1.0)
        task.setApply(True)
        tool.getIKTaskSet().cloneAndAppend(task)
    return tool, model, len(times)


def opensim_ik(model_path: Path, targets: Path, work: Path) -> dict:
    """OpenSim's InverseKinematicsTool on `targets` with `model_path`: seconds of tool.run() and of
    the whole (model loaded, tool set up, run), and the number of frames."""
    import opensim

    opensim.Logger.setLevelString("warn")
    opensim.Logger.removeFileSink()  # else opensim.log in the working directory
    started = time.perf_counter()
    # The marker-error file is written apart, once (opensim_marker_rms_mm).
    tool, _model, frames = _ik_tool(opensim, model_path, targets, work, "ik.mot", report_errors=False)
    running = time.perf_counter()
    if not tool.run():
        raise RuntimeError(f"OpenSim's IK failed on {targets} with {model_path}")
    ended = time.perf_counter()
    return {"run_s": ended - running, "whole_s": ended - started, "frames": frames}


def opensim_marker_rms_mm(model_path: Path, targets: Path, work: Path) -> float:
    """The mean over frames of OpenSim's RMS marker error [mm] (its _ik_marker_errors.sto), once."""
    import opensim

    tool, _model, _ = _ik_tool(opensim, model_path, targets, work, "ik_errors.mot", report_errors=True)
    tool.run()
    table = opensim.TimeSeriesTable(str(work / "_ik_marker_errors.sto"))
    return float(np.mean(table.getDependentColumn("marker_error_RMS").to_numpy()) * 1000.0)


def median_ratio(pairs: list[float]) -> float:
    return float(np.median(pairs))


def measure(conditions: list[Condition], rounds: int, out: Path) -> dict:
    """The alternated runs: per round, per condition, ibik with the image, OpenSim, ibik blind."""
    runs: dict = {c.name + f"_{c.views}v": {"image": [], "image_one_thread": [], "blind": [], "opensim": []}
                  for c in conditions}
    models: dict[str, Path] = {}
    for condition in conditions:  # a first run of each, not timed: compiled code loaded, model.osim written
        key = f"{condition.name}_{condition.views}v"
        folder = out / "runs" / key
        condition.track(True, folder / "image")
        condition.track(True, folder / "image_one_thread", "off")
        models[key] = folder / "image" / "model.osim"
        (folder / "opensim").mkdir(parents=True, exist_ok=True)
        opensim_ik(models[key], condition.targets, folder / "opensim")
    for round_index in range(rounds):
        for condition in conditions:
            key = f"{condition.name}_{condition.views}v"
            folder = out / "runs" / key
            runs[key]["image"].append(condition.track(True, folder / "image"))
            runs[key]["opensim"].append(opensim_ik(models[key], condition.targets, folder / "opensim"))
            runs[key]["blind"].append(condition.track(False, folder / "blind"))
            runs[key]["image_one_thread"].append(condition.track(True, folder / "image_one_thread", "off"))
            image, opensim_run = runs[key]["image"][-1], runs[key]["opensim"][-1]
            print(f"round {round_index + 1}/{rounds} {key}: ibik image {image['solve_fps']:.1f} frames/s solving "
                  f"({image['wall_s']:.2f} s whole), OpenSim {condition.frames / opensim_run['run_s']:.1f} frames/s "
                  f"({opensim_run['whole_s']:.2f} s whole), ibik blind {runs[key]['blind'][-1]['solve_fps']:.1f}, "
                  f"ibik image on one thread {runs[key]['image_one_thread'][-1]['solve_fps']:.1f}",
                  flush=True)
    results: dict = {}
    for condition in conditions:
        key = f"{condition.name}_{condition.views}v"
        frames = condition.frames
        opensim_runs = runs[key]["opensim"]
        opensim_fps = [frames / run["run_s"] for run in opensim_runs]
        row: dict = {"motion": condition.name, "views": condition.views, "frames": frames,
                     "targets": os.path.relpath(condition.targets, out)}
        for label in ("image", "image_one_thread", "blind"):
            values = runs[key][label]
            row[f"ibik_{label}_solve_fps"] = float(np.median([v["solve_fps"] for v in values]))
            row[f"ibik_{label}_loop_fps"] = float(np.median([v["loop_fps"] for v in values]))
            row[f"ibik_{label}_wall_s"] = float(np.median([v["wall_s"] for v in values]))
            row[f"ibik_{label}_solve_over_opensim"] = median_ratio(
                [v["solve_fps"] / o for v, o in zip(values, opensim_fps, strict=True)])
            row[f"ibik_{label}_solve_over_opensim_rounds"] = [v["solve_fps"] / o
                                                              for v, o in zip(values, opensim_fps, strict=True)]
            row[f"ibik_{label}_loop_over_opensim"] = median_ratio(
                [v["loop_fps"] / o for v, o in zip(values, opensim_fps, strict=True)])
            row[f"ibik_{label}_whole_over_opensim_whole"] = median_ratio(
                [o["whole_s"] / v["wall_s"] for v, o in zip(values, opensim_runs, strict=True)])
            if "judged_error_mm" in values[0]:
                row[f"ibik_{label}_judged_error_mm"] = values[0]["judged_error_mm"]
        row["opensim_fps"] = float(np.median(opensim_fps))
        row["opensim_fps_rounds"] = opensim_fps
        row["opensim_whole_s"] = float(np.median([run["whole_s"] for run in opensim_runs]))
        row["opensim_marker_rms_mm"] = opensim_marker_rms_mm(models[key], condition.targets,
                                                             out / "runs" / key / "opensim")
        results[key] = row
    return results


def markdown(results: dict, rounds: int, header: str) -> str:
    lines = [header, "",
             f"Frames/s: medians of {rounds} rounds; each ratio the median of the rounds' ratios (the runs of a "
             "round are taken in turn).", "",
             "| motion, views | ibik image, solves [frames/s] | OpenSim IK [frames/s] | ratio | ibik image, frame "
             "loop | ratio | ibik image on one thread, solves | ratio | its frame loop | ratio | ibik blind, solves "
             "| ratio | whole run: ibik image [s] | OpenSim [s] | ratio |",
             "| --- |" + " ---: |" * 14]
    for row in results.values():
        lines.append(
            f"| {row['motion']}, {row['views']} | {row['ibik_image_solve_fps']:.1f} | {row['opensim_fps']:.1f} | "
            f"{row['ibik_image_solve_over_opensim']:.2f} | {row['ibik_image_loop_fps']:.1f} | "
            f"{row['ibik_image_loop_over_opensim']:.2f} | {row['ibik_image_one_thread_solve_fps']:.1f} | "
            f"{row['ibik_image_one_thread_solve_over_opensim']:.2f} | {row['ibik_image_one_thread_loop_fps']:.1f} | "
            f"{row['ibik_image_one_thread_loop_over_opensim']:.2f} | {row['ibik_blind_solve_fps']:.1f} | "
            f"{row['ibik_blind_solve_over_opensim']:.2f} | {row['ibik_image_wall_s']:.2f} | "
            f"{row['opensim_whole_s']:.2f} | {row['ibik_image_whole_over_opensim_whole']:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--json", type=Path, help="where the figures go (default: OUT/opensim_speed.json)")
    parser.add_argument("--frames", type=int, default=120, help="frames of each real-motion window (default 120)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--cache", type=Path, help="where the rendered inputs are kept (default: OUT/cache)")
    parser.add_argument("--conditions", default="boxing_a:2,boxing_a:4,cmu35_01:2,cmu35_01:4,demo:4",
                        help="comma-separated motion:views (motions: the real-mocap clips, demo)")
    arguments = parser.parse_args()
    try:
        import opensim  # noqa: F401
    except ImportError:
        raise SystemExit("opensim_speed: OpenSim's Python package is needed (pip install -e '.[opensim]')") from None
    arguments.out.mkdir(parents=True, exist_ok=True)
    cache = arguments.cache or arguments.out / "cache"
    started = time.perf_counter()
    conditions = []
    for item in arguments.conditions.split(","):
        motion, _, views = item.strip().partition(":")
        if motion == "demo":
            conditions.append(demo_condition(arguments.out / "demo_input"))
        elif motion in CLIPS:
            conditions.append(realdata_condition(motion, int(views), arguments.frames, cache))
        else:
            parser.error(f"--conditions: unknown motion {motion!r}; known: demo, {', '.join(CLIPS)}")
    load_before = os.getloadavg()
    results = measure(conditions, arguments.rounds, arguments.out)
    command = " ".join(["python experiments/opensim_speed.py", *sys.argv[1:]])
    figures = {"command": command, "revision": code_revision(), "rounds": arguments.rounds,
               "host": platform.node(), "cpus": os.cpu_count(), "load_average_before": list(load_before),
               "load_average_after": list(os.getloadavg()), "wall_s": time.perf_counter() - started,
               "conditions": results}
    header = (f"# Speed against OpenSim (`{command}`)\n\ncode at {figures['revision']}; {figures['cpus']} cores, "
              f"load average {load_before[0]:.1f} before, {figures['load_average_after'][0]:.1f} after; "
              f"{figures['wall_s']:.0f} s in all")
    text = markdown(results, arguments.rounds, header)
    print(text)
    (arguments.out / "opensim_speed.md").write_text(text)
    (arguments.json or arguments.out / "opensim_speed.json").write_text(strict_json(figures))


if __name__ == "__main__":
    main()
