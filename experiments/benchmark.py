"""Speed of the solve loop, in the paper's setting and on the whole body, against Pink.

Measures in one run:
- arm: the paper's 6-DOF arm chain (experiments/paper/section4.py) on --frames frames of a boxing
  window (every second frame), 15 iterations per frame, support images built from 640 x 480 masks
  every frame, 1 and 2 views, with and without the image term: frames/s of the whole run and of the
  frames after the first (the first frame's multi-start search runs once per sequence), in a warm
  process;
- whole body: `ibik track` (the human with a free flyer, subject calibrated on a static trial) on
  real motion (CMU boxing, the real-mocap benchmark's inputs: silhouettes of another body, 640 x 480),
  2 and 4 views, liegeois, stack and qp: report.json's frames/s (the whole frame loop: silhouettes
  read, support images built, solves) and its frames/s of the solves alone, and the median time of one solver
  step with the image term and of one without (timed around HierarchicalQPSolver.compute_step, in a run
  on one thread: --read-ahead off, so that no support image is built beside the step, as none is beside
  Pink's);
- Pink (`pip install -e '.[bench]'`; skipped without it): one IK step toward the same targets from
  the same configurations (each frame's targets from the previous frame's solution), DAQP and
  ProxQP, position tasks on the same keypoint frames, a posture task, limits in Pink's QP; our timed
  run and Pink's steps alternate over --rounds rounds, and each ratio is the median of the rounds'
  (the machine's speed drifts between runs);
- the time split of the qp run with 2 views on one thread by part (cProfile's own times grouped by
  function), and
  the process's peak memory;
- each QP backend of the qp scheme (solvers.available_qp_solvers(): the compiled active set,
  proxsuite, qpsolvers' installed solvers): `ibik track` with 2 views on one thread, its median step
  with and without the image term, the backends in turn in each of --rounds rounds, each backend's
  step over the default backend's (the median of the rounds' ratios: the machine's speed drifts
  3x within a day, a ratio of figures taken together does not), its error and its trial's largest
  joint distance to the default backend's trial (`--qp-backends-only` runs this part alone).

Every frames/s figure is the median of --rounds rounds, which take the settings in turn (every
round's figure is in the JSON as `<figure>_rounds`): a single run on this shared machine can fall
in a slow minute (the arm once 725 frames/s between runs of 1022-1120).

A benchmark, not a test: absolute times on a shared 2-core machine are indicative, ratios less so.

Usage: python experiments/benchmark.py --out out/benchmark [--json PATH] [--frames 120] [--rounds 3]
       [--qp-backends-only | --steps-only]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see ibik_pin/cli.py

import argparse
import contextlib
import cProfile
import json
import pstats
import resource
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parent))

from paper.section4 import load_motion, prepare_clip, render_views, run_chain, subset_views
from realdata.clips import CLIPS
from realdata.inputs import prepare_inputs
from realdata.runner import run_variant, variant

from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import prepare_body
from ibik_pin.io.files import strict_json
from ibik_pin.io.trc import read_trc
from ibik_pin.solvers import DEFAULT_QP_SOLVER, available_qp_solvers
from ibik_pin.solvers.hqp import HierarchicalQPSolver
from ibik_pin.tasks.base import GradientTask

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
BOXING = CLIPS["boxing_a"]
SCHEMES = ("liegeois", "stack", "qp")
# What each part of the solve loop is, by the functions cProfile times (module path fragments and
# function names); a function in no group counts as "other".
PARTS = {
    "kinematics": ("configuration.py", "pinocchio"),
    "projection and sampling": ("pinhole.py", "camera.py", "tasks/image.py", "silhouette_axis.py", "segments.py"),
    "support images": ("support.py", "medial_axis.py", "distance.py", "frame_images.py", "GaussianBlur"),
    "QP": ("qp_backends.py", "proxsuite", "qpsolvers", "daqp"),
    "linear algebra": ("nullspace.py", "level_loop.py", "solvers/kernels.py", "linalg", "einsum", "projection.py"),
    "solver and task bookkeeping": ("solvers/", "tasks/", "swivel.py", "tracker.py", "outcomes.py", "limits.py"),
    "reading masks, subject calibration, writing outputs": ("imread", "masks.py", "silhouette_files.py",
                                                            "subject/", "io/", "imwrite"),
}


class StepTimer:
    """Times every HierarchicalQPSolver.compute_step while active, split by whether the levels hold
    the image task."""

    def __init__(self) -> None:
        self.image: list[float] = []
        self.blind: list[float] = []

    @contextlib.contextmanager
    def active(self):
        original = HierarchicalQPSolver.compute_step

        def timed(solver, configuration, levels, *args, **kwargs):
            started = time.perf_counter()
            step = original(solver, configuration, levels, *args, **kwargs)
            with_image = any(isinstance(task, GradientTask) for level in levels for task in level)
            (self.image if with_image else self.blind).append(time.perf_counter() - started)
            return step

        HierarchicalQPSolver.compute_step = timed  # type: ignore[method-assign]
        try:
            yield self
        finally:
            HierarchicalQPSolver.compute_step = original  # type: ignore[method-assign]

    @staticmethod
    def median_us(values: list[float]) -> float | None:
        return float(np.median(values) * 1e6) if values else None


def arm_fps(frames: int, rounds: int) -> dict:
    """The paper's arm: frames/s with and without the image, 1 and 2 views, over the whole run and
    over the frames after the first (each solved from the one before, as the paper's 19 frames/s;
    the first frame's search from the neutral pose, 8 starts of 100 steps, runs once per sequence).
    A first run, not timed, warms the process (imports, compiled code loaded, first solver objects).
    Each figure is the median of `rounds` rounds (rounds_median)."""
    motion = load_motion(DATA / BOXING.file, BOXING.source)
    start = int(round(BOXING.start_s * motion.frame_rate))
    clip = prepare_clip("boxing_a", motion, BOXING.source, slice(start, start + 2 * frames, 2))
    rig = render_views(clip, 4, seed=1)
    run_chain("arm", clip, subset_views(rig, 1), "ibik", "qp", iterations=15)  # the warm-up, not timed
    settings = [(views, label, method) for views in (1, 2) for label, method in (("image", "ibik"), ("blind", "pik"))]
    measured: dict = {(views, label): [] for views, label, _ in settings}
    for _ in range(rounds):
        for views, label, method in settings:
            started = time.perf_counter()
            run = run_chain("arm", clip, subset_views(rig, views) if method == "ibik" else None, method, "qp",
                            iterations=15)
            seconds = time.perf_counter() - started
            measured[(views, label)].append({"fps": len(clip.q) / seconds,
                                             "tracked_fps": (len(clip.q) - 1) / run.tracked_seconds,
                                             "elbow_error_mm": run.mean_error_mm})
    results: dict = {}
    for (views, label), runs in measured.items():
        results.setdefault(f"views_{views}", {})[label] = rounds_median(runs, ("fps", "tracked_fps"),
                                                                        "elbow_error_mm")
    return results


def rounds_median(runs: list[dict], timed: tuple[str, ...], exact: str) -> dict:
    """One setting's figures over the rounds: each timed figure the median of the rounds' (all kept,
    as `<figure>_rounds`), the error once. The rounds take the settings in turn, so that a slow
    minute of the shared machine falls on one round of each setting rather than on every round of
    one. The error is the same in every round (the solves are deterministic, whatever the two
    processes' timing: tests/test_tracker.py); a round that differs is an error, not noise."""
    if len({run[exact] for run in runs}) != 1:
        raise RuntimeError(f"{exact} differs between rounds: {[run[exact] for run in runs]}")
    figures: dict = {key: float(np.median([run[key] for run in runs])) for key in timed}
    figures[exact] = runs[0][exact]
    figures.update({f"{key}_rounds": [run[key] for run in runs] for key in timed})
    return figures


def whole_body(frames: int, cache: Path, rounds: int) -> tuple[dict, dict, cProfile.Profile]:
    """`ibik track` per scheme and view count, each the median of `rounds` rounds (rounds_median);
    the qp 2-view run profiled and its steps timed."""
    inputs = prepare_inputs(BOXING, DATA, frames, cache)
    profile = cProfile.Profile()
    out = cache.parent / "benchmark_runs"
    settings = [(scheme, views) for views in (2, 4) for scheme in SCHEMES]
    measured: dict = {setting: [] for setting in [*settings, ("pik", 0)]}
    for _ in range(rounds):
        for scheme, views in settings:
            folder = out / f"{scheme}_{views}v"
            run = run_variant(inputs, variant(f"ibik{views}v"), "clean", {"method": scheme}, out=folder)
            measured[(scheme, views)].append({"fps": run.loop_fps, "solve_fps": run.solve_fps,
                                              "wall_s": run.wall_seconds, "judged_error_mm": run.judged_mm})
        blind = run_variant(inputs, variant("pik"), "clean", out=out / "pik")
        measured[("pik", 0)].append({"fps": blind.loop_fps, "solve_fps": blind.solve_fps,
                                     "wall_s": blind.wall_seconds, "judged_error_mm": blind.judged_mm})
    results: dict = {scheme: {} for scheme in SCHEMES}
    for (scheme, views), runs in measured.items():
        figures = rounds_median(runs, ("fps", "solve_fps", "wall_s"), "judged_error_mm")
        if scheme == "pik":
            results["pik"] = figures
        else:
            figures["mean_iterations_per_frame"] = _mean_iterations(out / f"{scheme}_{views}v")
            results[scheme][f"views_{views}"] = figures
    # Once more profiled, apart from the timed steps (step_rounds): the profiler's cost per call,
    # several times a small numpy call's, would weigh on our steps and not on Pink's. On one thread:
    # cProfile sees the calling thread only, and the support images would be built in another.
    profile.enable()
    run_variant(inputs, variant("ibik2v"), "clean", {"method": "qp", "read_ahead": "off"},
                out=out / "qp_2v_profiled")
    profile.disable()
    return results, {"inputs": inputs, "q_run": out / "qp_2v"}, profile


def step_rounds(inputs, run_folder: Path, frames: int, rounds: int) -> tuple[dict, dict, dict]:
    """Our qp steps (2 views) and Pink's, measured in turn `rounds` times: the machine's speed
    drifts by up to 2x between runs, so each round's ratio compares figures taken together.

    Returns our steps (medians over the rounds), Pink's (the same) and the ratios (each the median
    of the rounds' ratios, with every round's)."""
    ours_rounds, pink_rounds = [], []
    for round_index in range(rounds):
        steps = StepTimer()
        with steps.active():  # on one thread, as Pink's steps are timed: no support images built beside
            run_variant(inputs, variant("ibik2v"), "clean", {"method": "qp", "read_ahead": "off"},
                        out=run_folder.parent / f"qp_2v_timed_{round_index}")
        ours_rounds.append({"step_with_image_us": steps.median_us(steps.image),
                            "step_without_image_us": steps.median_us(steps.blind),
                            "steps_per_frame": (len(steps.image) + len(steps.blind)) / frames})
        pink_rounds.append(pink_steps(inputs, run_folder, frames))
    ours = {key: float(np.median([row[key] for row in ours_rounds])) for key in ours_rounds[0]}
    ratios: dict = {}
    pink: dict = pink_rounds[0] if "skipped" in pink_rounds[0] else {}
    for backend in ("daqp", "proxqp"):
        if backend not in pink_rounds[0]:
            continue
        pink[backend] = {"step_us": float(np.median([row[backend]["step_us"] for row in pink_rounds])),
                         "failed_steps": sum(row[backend]["failed_steps"] for row in pink_rounds),
                         "steps": sum(row[backend]["steps"] for row in pink_rounds)}
        for kind in ("image", "blind"):
            per_round = [mine[f"step_with{'out' if kind == 'blind' else ''}_image_us"] / row[backend]["step_us"]
                         for mine, row in zip(ours_rounds, pink_rounds, strict=True)]
            ratios[f"qp_{kind}_step_over_pink_{backend}_step"] = float(np.median(per_round))
            ratios[f"qp_{kind}_step_over_pink_{backend}_step_rounds"] = per_round
    return ours, pink, ratios


def qp_backend_rounds(inputs, run_folder: Path, rounds: int) -> dict:
    """Every QP backend's `ibik track` (2 views, one thread), the backends in turn in each round.

    Returns, per backend, its median steps [us] (medians over the rounds, every round's kept), its
    step over the default backend's in the same round (the median of the rounds' ratios), its
    judged error [mm] and the largest distance [mm] of its joints.trc to the default backend's."""
    names = available_qp_solvers()
    per_round: dict[str, list[dict]] = {name: [] for name in names}
    for _ in range(rounds):
        for name in names:
            steps = StepTimer()
            folder = run_folder.parent / f"qp_backend_{name}"
            with steps.active():
                run = run_variant(inputs, variant("ibik2v"), "clean", {"method": "qp", "qp_solver": name,
                                                                       "read_ahead": "off"}, out=folder)
            joints = read_trc(folder / "joints.trc").in_metres().positions
            per_round[name].append({"step_with_image_us": steps.median_us(steps.image),
                                    "step_without_image_us": steps.median_us(steps.blind),
                                    "judged_error_mm": run.judged_mm, "joints": joints})
    results: dict = {}
    for name in names:
        rows = per_round[name]
        figures: dict = {"judged_error_mm": rows[-1]["judged_error_mm"],
                         "max_joint_distance_to_default_mm": float(np.nanmax(np.linalg.norm(
                             rows[-1]["joints"] - per_round[DEFAULT_QP_SOLVER][-1]["joints"], axis=2)) * 1000.0)}
        for key in ("step_with_image_us", "step_without_image_us"):
            figures[key] = float(np.median([row[key] for row in rows]))
            figures[f"{key}_rounds"] = [row[key] for row in rows]
            ratios = [row[key] / default[key] for row, default in zip(rows, per_round[DEFAULT_QP_SOLVER], strict=True)]
            figures[f"{key.removesuffix('_us')}_over_default"] = float(np.median(ratios))
            figures[f"{key.removesuffix('_us')}_over_default_rounds"] = ratios
        results[name] = figures
    return results


def qp_backend_lines(backends: dict, rounds: int) -> list[str]:
    """The backends' table."""
    lines = [f"| QP backend (qp, 2 views, one thread; median of {rounds} rounds) | step with the image [us] | "
             f"over {DEFAULT_QP_SOLVER} | step without [us] | over {DEFAULT_QP_SOLVER} | error [mm] | "
             f"largest joint distance to {DEFAULT_QP_SOLVER}'s [mm] |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, values in backends.items():
        lines.append(f"| {name} | {values['step_with_image_us']:.0f} | {values['step_with_image_over_default']:.2f} | "
                     f"{values['step_without_image_us']:.0f} | {values['step_without_image_over_default']:.2f} | "
                     f"{values['judged_error_mm']:.2f} | {values['max_joint_distance_to_default_mm']:.3g} |")
    return lines


def _mean_iterations(run_folder: Path) -> float | None:
    return json.loads((run_folder / "report.json").read_text()).get("mean_iterations_per_frame")


def pink_steps(inputs, run_folder: Path, frames: int) -> dict:
    """One Pink step per frame toward that frame's targets, from our previous frame's solution."""
    try:
        import pink
        from pink.tasks import FrameTask
        from pink.tasks import PostureTask as PinkPosture
    except ImportError:
        return {"skipped": "pink is not installed (pip install -e '.[bench]')"}
    targets = read_trc(inputs.targets("clean"))
    names = list(targets.marker_names)
    targets_m = targets.in_metres().positions
    job = TrackJob(targets=inputs.targets("clean"), out=run_folder.parent / "unused", static=inputs.static)
    body = prepare_body(job, names, targets_m)
    q_rows = np.loadtxt(run_folder / "q.csv", delimiter=",", skiprows=1)
    solved = q_rows[:, 1:]  # the first column is the time
    results = {}
    for backend in ("daqp", "proxqp"):
        tasks = {name: FrameTask(body.keypoints[name], position_cost=1.0, orientation_cost=0.0) for name in names}
        posture = PinkPosture(cost=1e-2)
        durations, failed = [], 0
        for frame in range(1, frames):
            configuration = pink.Configuration(body.model, body.model.createData(), solved[frame - 1])
            posture.set_target(solved[frame - 1])
            present = [name for k, name in enumerate(names) if np.isfinite(targets_m[frame, k]).all()]
            for name in present:
                tasks[name].set_target(pin.SE3(np.eye(3), targets_m[frame, names.index(name)]))
            active = [tasks[name] for name in present] + [posture]
            started = time.perf_counter()
            try:
                pink.solve_ik(configuration, active, 1.0, solver=backend, safety_break=False)
            except Exception:  # a failed QP is a measured outcome here
                failed += 1
            durations.append(time.perf_counter() - started)
        results[backend] = {"step_us": float(np.median(durations) * 1e6), "failed_steps": failed,
                            "steps": len(durations)}
    return results


def time_split(profile: cProfile.Profile) -> dict:
    """Seconds of own time per part of the loop (PARTS), from the profile of one run."""
    split = dict.fromkeys([*PARTS, "other"], 0.0)
    for (path, _, function), (_, _, own, _, _) in pstats.Stats(profile).stats.items():  # type: ignore[attr-defined]
        where = f"{path}:{function}"
        part = next((name for name, marks in PARTS.items() if any(mark in where for mark in marks)), "other")
        split[part] += own
    return {part: round(seconds, 3) for part, seconds in split.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--json", type=Path, help="where the figures go (default: OUT/benchmark.json)")
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--rounds", type=int, default=3,
                        help="rounds of every timed figure, each figure their median; our steps and Pink's timed "
                        "in turn in each (default 3)")
    parser.add_argument("--cache", type=Path, help="where the rendered inputs are kept (default: OUT/cache; the "
                        "real-mocap benchmark's cache is reused when given)")
    parser.add_argument("--qp-backends-only", action="store_true",
                        help="time the QP backends alone (their table and JSON, nothing else)")
    parser.add_argument("--steps-only", action="store_true",
                        help="time our qp steps (2 views, one thread) against Pink's alone (their JSON, nothing else)")
    arguments = parser.parse_args()
    arguments.out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    cache = arguments.cache or arguments.out / "cache"
    if arguments.qp_backends_only:
        backends = qp_backend_rounds(prepare_inputs(BOXING, DATA, arguments.frames, cache),
                                     cache.parent / "benchmark_runs" / "qp_2v", arguments.rounds)
        table = "\n".join(qp_backend_lines(backends, arguments.rounds))
        print(table)
        (arguments.out / "benchmark.md").write_text(f"`python experiments/benchmark.py --out {arguments.out} "
                                                    f"--qp-backends-only`\n\n{table}\n")
        (arguments.json or arguments.out / "benchmark.json").write_text(strict_json(
            {"qp_backends": backends, "frames": arguments.frames, "wall_s": time.perf_counter() - started}))
        return
    if arguments.steps_only:
        inputs = prepare_inputs(BOXING, DATA, arguments.frames, cache)
        run_folder = cache.parent / "benchmark_runs" / "qp_2v"
        run_variant(inputs, variant("ibik2v"), "clean", {"method": "qp"}, out=run_folder)  # Pink starts from its q
        steps, pink_results, ratios = step_rounds(inputs, run_folder, arguments.frames, arguments.rounds)
        figures = {"steps": steps, "pink": pink_results, "ratios": ratios, "frames": arguments.frames,
                   "load_average": list(os.getloadavg()), "wall_s": time.perf_counter() - started}
        print(strict_json(figures))
        (arguments.json or arguments.out / "benchmark_steps.json").write_text(strict_json(figures))
        return
    arm = arm_fps(arguments.frames, arguments.rounds)
    body, context, profile = whole_body(arguments.frames, cache, arguments.rounds)
    steps, pink_results, ratios = step_rounds(context["inputs"], context["q_run"], arguments.frames,
                                              arguments.rounds)
    backends = qp_backend_rounds(context["inputs"], context["q_run"], arguments.rounds)
    ours = body["qp"]["views_2"]
    ours.update(steps)
    figures = {"arm": arm, "whole_body": body, "pink": pink_results, "ratios": ratios, "qp_backends": backends,
               "split_qp_2_views_s": time_split(profile),
               "peak_memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
               "frames": arguments.frames, "wall_s": time.perf_counter() - started}
    def spread(values: dict, key: str, digits: int) -> str:  # the median, then the rounds' range
        low, high = min(values[f"{key}_rounds"]), max(values[f"{key}_rounds"])
        return f"{values[key]:.{digits}f} ({low:.{digits}f}-{high:.{digits}f})"

    lines = [f"frames/s: the median of {arguments.rounds} rounds (their range)", "",
             "| the paper's arm, 15 steps a frame | frames/s, whole run | frames/s, frames after the first | "
             "elbow error [mm] |", "| --- | ---: | ---: | ---: |"]
    for views, row in arm.items():
        for label, values in row.items():
            lines.append(f"| {views.replace('_', ' ')}, {label} | {spread(values, 'fps', 0)} | "
                         f"{spread(values, 'tracked_fps', 0)} | {values['elbow_error_mm']:.1f} |")
    lines += ["", "| setting | frames/s | frames/s, solves alone | error [mm] |", "| --- | ---: | ---: | ---: |"]
    for scheme in SCHEMES:
        for views, values in body[scheme].items():
            lines.append(f"| whole body {scheme}, {views.replace('_', ' ')} | {spread(values, 'fps', 1)} | "
                         f"{spread(values, 'solve_fps', 1)} | {values['judged_error_mm']:.1f} |")
    blind = body["pik"]
    lines.append(f"| whole body, blind (PIK) | {spread(blind, 'fps', 1)} | {spread(blind, 'solve_fps', 1)} | "
                 f"{blind['judged_error_mm']:.1f} |")
    lines += ["", "| one step | median [us] |", "| --- | ---: |",
              f"| ours, qp, with the image (2 views) | {ours['step_with_image_us']:.0f} |",
              f"| ours, qp, without the image | {ours['step_without_image_us']:.0f} |"]
    lines += [f"| Pink + {backend} | {values['step_us']:.0f} |" for backend, values in pink_results.items()
              if isinstance(values, dict)]
    lines += ["", *qp_backend_lines(backends, arguments.rounds)]
    lines += ["", "| part of the profiled qp run, 2 views, one thread (own time; numpy's small-array calls in "
              "\"other\") | [s] |",
              "| --- | ---: |"]
    lines += [f"| {part} | {seconds:.2f} |" for part, seconds in figures["split_qp_2_views_s"].items()]
    lines += ["", f"ratios (median of {arguments.rounds} rounds): "
              f"{', '.join(f'{k} {v:.2f}' for k, v in ratios.items() if not k.endswith('_rounds'))}; steps per frame "
              f"{ours['steps_per_frame']:.1f}; peak memory {figures['peak_memory_mb']:.0f} MB; "
              f"{figures['wall_s']:.0f} s in all"]
    table = "\n".join(lines)
    print(table)
    (arguments.out / "benchmark.md").write_text(f"`python experiments/benchmark.py --out {arguments.out}`\n\n{table}\n")
    (arguments.json or arguments.out / "benchmark.json").write_text(strict_json(figures))


if __name__ == "__main__":
    main()
