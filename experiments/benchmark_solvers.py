"""Per-step cost of the solvers on the whole-body human, against Pink (docs/method.md, "Speed anchors").

The problem on which Pink was first timed for this project: example-robot-data's human (36 DOF +
free flyer), 6 position targets (pelvis, ankles, wrists, head) from a random reachable pose, a
posture task, joint limits; steps from the neutral pose. Each scheme runs the same steps; the
figures are per-step wall times (median over steps, after a warm-up), the final target error, and
the steps whose QP failed.
Also timed: one evaluation of the image criterion and its gradient with 1, 2 and 4 views.

Pink (pip install '.[bench]') is optional: without it only ibik_pin's schemes run.

Usage: python experiments/benchmark_solvers.py --out out/benchmark [--steps 300] [--seed 0]
"""

from __future__ import annotations

import os

# One OpenBLAS thread for the solvers' tiny factorisations, set before numpy is imported: see
# ibik_pin/cli.py (the library itself leaves the environment alone). A user's setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from ibik_pin.configuration import Configuration
from ibik_pin.limits import JointLimits
from ibik_pin.model import HUMAN_END_EFFECTORS, load_human
from ibik_pin.solvers import make_solver
from ibik_pin.tasks import FramePositionTask, ImageTask, PostureTask, View
from ibik_pin.vision.pinhole import look_at_camera
from ibik_pin.vision.render import render_capsules
from ibik_pin.vision.support import support_from_mask


def random_reachable_targets(body, rng) -> dict[str, np.ndarray]:
    limits = JointLimits(body.model)
    q = pin.neutral(body.model)
    middle = 0.5 * (limits.lower + limits.upper)
    q[limits.q_index] = middle + 0.3 * (limits.upper - limits.lower) * rng.uniform(-0.5, 0.5, middle.size)
    configuration = Configuration(body.model, q)
    return {name: configuration.frame_position(body.frame_id(name)).copy() for name in HUMAN_END_EFFECTORS}


def time_ibik(body, targets, scheme: str, steps: int) -> dict:
    model = body.model
    tasks = {name: FramePositionTask(model, name, target) for name, target in targets.items()}
    levels = [[tasks["Hip"], tasks["LAnkle"], tasks["RAnkle"]],
              [tasks["LWrist"], tasks["RWrist"], tasks["Head"]],
              [PostureTask(model, weight=1e-2)]]
    solver = make_solver(scheme, limits=JointLimits(model))
    configuration = Configuration(model)
    durations, failed = [], 0
    for _ in range(steps):
        started = time.perf_counter()
        step = solver.compute_step(configuration, levels)
        configuration.update(solver.limits.clamp(configuration.integrate(step.dq)))
        durations.append(time.perf_counter() - started)
        failed += any(report.status == "failed" for report in step.levels)
    error = max(np.linalg.norm(task.compute_error(configuration)) for task in tasks.values())
    return summary(f"ibik_pin {scheme}", durations, error, failed)


def time_pink(body, targets, solver_name: str, steps: int) -> dict | None:
    try:
        import pink
        from pink.tasks import FrameTask
        from pink.tasks import PostureTask as PinkPosture
    except ImportError:
        return None
    model = body.model
    data = model.createData()
    configuration = pink.Configuration(model, data, pin.neutral(model))
    tasks = []
    for name, target in targets.items():
        task = FrameTask(body.keypoints[name], position_cost=1.0, orientation_cost=0.0)
        task.set_target(pin.SE3(np.eye(3), target))
        tasks.append(task)
    posture = PinkPosture(cost=1e-2)
    posture.set_target(pin.neutral(model))
    tasks.append(posture)
    dt = 1.0
    durations, failed = [], 0
    for _ in range(steps):
        started = time.perf_counter()
        try:
            velocity = pink.solve_ik(configuration, tasks, dt, solver=solver_name, safety_break=False)
            configuration.integrate_inplace(velocity, dt)
        except Exception:  # a failed QP is a measured outcome here
            failed += 1
        durations.append(time.perf_counter() - started)
    error = max(np.linalg.norm(configuration.get_transform_frame_to_world(body.keypoints[name]).translation
                               - target) for name, target in targets.items())
    return summary(f"pink {solver_name}", durations, error, failed)


def summary(name: str, durations: list[float], error: float, failed: int) -> dict:
    warm = np.array(durations[5:]) * 1e6
    return {"scheme": name, "median_step_us": float(np.median(warm)), "p90_step_us": float(np.percentile(warm, 90)),
            "final_max_target_error_m": float(error), "failed_steps": int(failed), "steps": len(durations)}


def time_image_criterion(body, views_count: int, repeats: int = 300) -> dict:
    q = pin.neutral(body.model)
    configuration = Configuration(body.model, q)
    ends = configuration.frame_positions(body.segment_frame_ids.reshape(-1)).reshape(-1, 2, 3)
    views = []
    for index in range(views_count):
        angle = 2 * np.pi * index / views_count
        camera = look_at_camera(f"cam{index}", (640, 480), 700.0,
                                np.array([4 * np.cos(angle), 1.0, 4 * np.sin(angle)]),
                                np.array([0.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
        mask = render_capsules(camera, ends[:, 0], ends[:, 1], body.segment_radii)
        views.append(View(camera, support_from_mask(mask)))
    task = ImageTask(body, views)
    durations = []
    for _ in range(repeats):
        configuration.update(q)
        started = time.perf_counter()
        task.compute_gradient(configuration)
        durations.append(time.perf_counter() - started)
    return {"views": views_count, "samples": len(body.segments) * task.samples_per_segment,
            "median_us": float(np.median(durations) * 1e6)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    arguments = parser.parse_args()
    arguments.out.mkdir(parents=True, exist_ok=True)
    body = load_human()
    targets = random_reachable_targets(body, np.random.default_rng(arguments.seed))
    rows = [time_ibik(body, targets, scheme, arguments.steps) for scheme in ("ik", "stack", "qp")]
    for solver_name in ("daqp", "proxqp"):
        row = time_pink(body, targets, solver_name, arguments.steps)
        if row is not None:
            rows.append(row)
    image = [time_image_criterion(body, count) for count in (1, 2, 4)]
    lines = ["| scheme | median step [us] | p90 [us] | final max target error [m] | failed steps |",
             "| --- | --- | --- | --- | --- |"]
    lines += [f"| {r['scheme']} | {r['median_step_us']:.0f} | {r['p90_step_us']:.0f} | "
              f"{r['final_max_target_error_m']:.2e} | {r['failed_steps']}/{r['steps']} |" for r in rows]
    lines += ["", "| image criterion + gradient | samples | median [us] |", "| --- | --- | --- |"]
    lines += [f"| {r['views']} view(s) | {r['samples']} | {r['median_us']:.0f} |" for r in image]
    table = "\n".join(lines)
    print(table)
    (arguments.out / "benchmark.md").write_text(table + "\n")
    (arguments.out / "benchmark.json").write_text(json.dumps({"solvers": rows, "image": image}, indent=2))


if __name__ == "__main__":
    main()
