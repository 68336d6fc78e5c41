"""Throughput of `ibik batch` on this machine with 1 and 2 workers, and what it means for 1,000 trials.

A tree of 8 trials (2 participants of 4, P1 with a static trial) of the bundled CMU 35 walking, 30
frames each at 30 Hz, 2 HumanEva-like cameras of 640 x 480 px (ibik_pin.synthetic.trials), is
tracked by `ibik batch` with the default track settings on a LocalCluster of 1, then 2 workers,
each run once, in a process of its own as a user would run it. Also measured: the time to start
and stop a LocalCluster of 2 workers, the fixed cost of a run.

The machine has 2 cores shared with other sessions: the load average is written beside every
figure, and the figures are slower and noisier than on an idle machine.

Writes batch_throughput.md and batch_throughput.json into --out.

Usage:
    python experiments/batch_throughput.py --out out/batch_throughput
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny matrices: threads only add overhead

import argparse
import csv
import json
import math
import shutil
import subprocess
import sys
import time
from pathlib import Path

from ibik_pin.synthetic.trials import write_trial_tree

WORKERS = (1, 2)
LAB_TRIALS = 1000
CLUSTER_SIZES = (2, 8, 32, 128)
LAB_TRIAL_FRAMES = (30, 300)  # these trials, and 10 s at 30 Hz


def cluster_start_seconds(workers: int) -> float:
    """Wall time to start a LocalCluster of `workers` processes, connect a client and close both [s]."""
    import logging

    from distributed import Client, LocalCluster

    start = time.perf_counter()
    with LocalCluster(n_workers=workers, threads_per_worker=1, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster, Client(cluster):
        pass
    return time.perf_counter() - start


def run_batch(root: Path, out: Path, workers: int) -> dict:
    shutil.rmtree(out, ignore_errors=True)
    load_before = os.getloadavg()[0]
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "ibik_pin.cli", "batch", str(root), "--out", str(out),
                    "--workers", str(workers), "--quiet"], check=True)
    wall = time.perf_counter() - start
    with open(out / "summary.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    if any(row["status"] != "ok" for row in rows):
        raise RuntimeError(f"a trial failed: {rows}")
    seconds = [float(row["seconds"]) for row in rows]
    frames = sum(int(row["frames"]) for row in rows)
    return {"workers": workers, "trials": len(rows), "frames": frames, "wall_s": wall,
            "trials_per_minute": 60.0 * len(rows) / wall, "frames_per_second": frames / wall,
            "trial_s_mean": sum(seconds) / len(seconds), "trial_s_max": max(seconds),
            "load_average_before": load_before, "load_average_after": os.getloadavg()[0]}


def lab_hours(trial_s: float, start_s: float, workers: int) -> float:
    """Hours for LAB_TRIALS trials of `trial_s` seconds each on `workers` workers of a core each."""
    return (start_s + math.ceil(LAB_TRIALS / workers) * trial_s) / 3600.0


def report(results: dict) -> str:
    runs, start = results["runs"], results["cluster_start_s"]
    lines = [
        "# `ibik batch` throughput (experiments/batch_throughput.py)", "",
        f"{runs[0]['trials']} trials of {runs[0]['frames'] // runs[0]['trials']} frames (CMU 35 walking at 30 Hz, "
        "2 cameras of 640 x 480 px, default track settings), on this repository's 2-core machine, shared "
        "with other sessions (load average = runnable processes, 1-min mean, at start and end of each run).", "",
        "| workers | wall [s] | trials/min | frames/s | trial on its worker, mean / max [s] | load average |",
        "| ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for run in runs:
        lines.append(f"| {run['workers']} | {run['wall_s']:.1f} | {run['trials_per_minute']:.1f} | "
                     f"{run['frames_per_second']:.1f} | {run['trial_s_mean']:.1f} / {run['trial_s_max']:.1f} | "
                     f"{run['load_average_before']:.1f} -> {run['load_average_after']:.1f} |")
    frame_s = runs[0]["trial_s_mean"] / (runs[0]["frames"] / runs[0]["trials"])
    lines += ["", f"Starting and stopping a LocalCluster of 2 workers: {start:.1f} s.", "",
              f"1,000 trials on N workers, one core each: hours = (start + ceil(1000 / N) x F x {frame_s:.3f} s) "
              f"/ 3600 for trials of F frames, with {frame_s:.3f} s per frame the mean trial on 1 worker here "
              "divided by its frames (its loading and setup included):", "",
              "| N | " + " | ".join(f"F = {frames} [h]" for frames in LAB_TRIAL_FRAMES) + " |",
              "| ---: |" + " ---: |" * len(LAB_TRIAL_FRAMES)]
    lines += [f"| {n} | " + " | ".join(f"{lab_hours(frames * frame_s, start, n):.2f}" for frames in LAB_TRIAL_FRAMES)
              + " |" for n in CLUSTER_SIZES]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--frames", type=int, default=30, help="frames per trial")
    arguments = parser.parse_args()
    arguments.out.mkdir(parents=True, exist_ok=True)
    root = arguments.out / "root"
    shutil.rmtree(root, ignore_errors=True)
    write_trial_tree(root, trials_per_participant=(4, 4), frames=arguments.frames, views=2,
                     size=(640, 480), frame_step=4)
    results = {"cluster_start_s": cluster_start_seconds(2),
               "runs": [run_batch(root, arguments.out / f"workers_{n}", n) for n in WORKERS]}
    (arguments.out / "batch_throughput.json").write_text(json.dumps(results, indent=2) + "\n")
    text = report(results)
    (arguments.out / "batch_throughput.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
