"""How many image steps a frame needs, and what the posture prior does between them: tracking
settings paired per condition on the sweep's conditions.

    python experiments/step_budget.py --keep /tmp/keep --out experiments/results [--variants base,image_step_0.1]

Each variant is `ibik track` (IBIK, `--views` cameras, clean silhouettes, `--target-filter auto`)
with TrackingSettings overridden, on the limb lengths the sweep chose (`--lengths images`: the
static error_sources.py reads, written to `--keep` if absent) and the condition's noisy targets.
Variants (VARIANTS):

- base: the defaults (at most `iterations` = 15 image steps a frame, each at most `image_step` =
  0.05 rad, ending at the criterion's peak);
- iterations_5/6/8: at most that many image steps a frame;
- image_step_0.075/0.1: a larger largest image step; image_step_0.1_iterations_6/8: both;
- posture_previous: the posture prior toward the previous frame's solution, not the neutral pose;
- posture_gain_0.1/0.3/0.5: the neutral posture prior corrects that share of its error a step
  (the default 1);
- swivel_smoothing_off / swivel_cutoff_4: the free elbows' and knees' swivels not low-passed over
  the trial after the frames are solved, or at 4 Hz (the default 6; tracking.swivel_smoothing).

A frame first takes up to 5 targets-only steps, whose lowest level is the posture prior (neutral,
gain 1, weight 1e-2: with the damping 3e-2 it takes 92 % of its error a step in whatever the targets
leave free, the limbs' swivels among them), then the image steps. Solver steps are counted over the
whole run (HierarchicalQPSolver.compute_step calls, the first frame's included).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from importlib import resources
from pathlib import Path

import numpy as np
import tomllib
from error_sources import chosen_static
from realdata.runner import DEFAULT_DATA
from sweepkit.conditions import add_kept_arguments, kept_conditions
from sweepkit.runs import run_condition_variant

from ibik_pin.solvers.hqp import HierarchicalQPSolver
from ibik_pin.tracking.stack import DEFAULT_STACK_FILE, Stack

GROUPS = ("elbows", "knees")
TARGET_FILTER = "auto"


def posture_stack(**posture: object) -> Stack:
    """The default stack with its posture task's keys replaced (e.g. reference="previous")."""
    text = resources.files("ibik_pin").joinpath("data").joinpath(DEFAULT_STACK_FILE).read_text()
    document = tomllib.loads(text)
    tasks = [task for level in document["level"] for task in level["tasks"] if task["kind"] == "posture"]
    if len(tasks) != 1:
        raise ValueError(f"the default stack has {len(tasks)} posture tasks, expected 1")
    tasks[0].update(posture)
    return Stack.from_dict(document, source="step_budget")


VARIANTS = {
    "base": dict,
    "iterations_5": lambda: {"iterations": 5},
    "iterations_6": lambda: {"iterations": 6},
    "iterations_8": lambda: {"iterations": 8},
    "image_step_0.075": lambda: {"image_step": 0.075},
    "image_step_0.1": lambda: {"image_step": 0.1},
    "image_step_0.1_iterations_6": lambda: {"image_step": 0.1, "iterations": 6},
    "image_step_0.1_iterations_8": lambda: {"image_step": 0.1, "iterations": 8},
    "posture_previous": lambda: {"stack": posture_stack(reference="previous")},
    "posture_gain_0.1": lambda: {"stack": posture_stack(gain=0.1)},
    "posture_gain_0.3": lambda: {"stack": posture_stack(gain=0.3)},
    "posture_gain_0.5": lambda: {"stack": posture_stack(gain=0.5)},
    "swivel_smoothing_off": lambda: {"swivel_cutoff_hz": None},
    "swivel_cutoff_4": lambda: {"swivel_cutoff_hz": 4.0},
}


class StepCounter:
    """Counts HierarchicalQPSolver.compute_step calls while active (a context manager)."""

    def __init__(self) -> None:
        self.steps = 0
        self._original = HierarchicalQPSolver.compute_step

    def __enter__(self) -> StepCounter:
        original, counter = self._original, self

        def counted(solver, *args, **kwargs):
            counter.steps += 1
            return original(solver, *args, **kwargs)

        HierarchicalQPSolver.compute_step = counted
        return self

    def __exit__(self, *exc: object) -> None:
        HierarchicalQPSolver.compute_step = self._original


def summarize(rows: list[dict], names: list[str]) -> dict:
    """Per variant: per group the median and 90th percentile over conditions [mm] and the paired
    change against the first variant (median, mean, better and worse by more than 1 mm, the
    largest worsening); solver steps a frame (mean over conditions)."""
    first = names[0]
    summary: dict[str, dict] = {}
    for name in names:
        entry: dict = {"steps_per_frame": float(np.mean([row[name]["steps_per_frame"] for row in rows]))}
        for group in GROUPS:
            values = np.array([row[name][group] for row in rows])
            change = values - np.array([row[first][group] for row in rows])
            entry[group] = {"median": float(np.median(values)), "p90": float(np.percentile(values, 90)),
                            "change_median": float(np.median(change)), "change_mean": float(np.mean(change)),
                            "better": int(np.sum(change < -1.0)), "worse": int(np.sum(change > 1.0)),
                            "largest_worse": float(change.max())}
        summary[name] = entry
    return summary


def markdown(summary: dict, header: str) -> str:
    lines = [header, "", "| variant | steps a frame | elbows | paired median / mean | better / worse (largest) "
             "| knees | paired median / mean | better / worse (largest) |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, entry in summary.items():
        cells = [f"{entry['steps_per_frame']:.1f}"]
        for group in GROUPS:
            g = entry[group]
            cells += [f"{g['median']:.1f} / {g['p90']:.1f}", f"{g['change_median']:+.2f} / {g['change_mean']:+.2f}",
                      f"{g['better']} / {g['worse']} ({g['largest_worse']:+.1f})"]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_kept_arguments(parser, DEFAULT_DATA)
    parser.add_argument("--variants", default=",".join(VARIANTS),
                        help=f"comma-separated, the first the reference (default all: {', '.join(VARIANTS)})")
    parser.add_argument("--out", type=Path, default=None, help="where step_budget.json and .md go")
    parser.add_argument("--merge", type=Path, nargs="+", default=None, metavar="JSON",
                        help="summarize these step_budget.json files (other conditions or variants) instead")
    arguments = parser.parse_args(argv)
    names = arguments.variants.split(",")
    unknown = [name for name in names if name not in VARIANTS]
    if unknown:
        parser.error(f"unknown variant(s) {', '.join(unknown)}; known: {', '.join(VARIANTS)}")
    started = time.perf_counter()
    rows = []
    if arguments.merge:  # rows of one condition from several files (other variants) are joined
        joined: dict[int, dict] = {}
        for path in arguments.merge:
            for row in json.loads(path.read_text())["rows"]:
                joined.setdefault(row["index"], {}).update(row)
        rows = [joined[index] for index in sorted(joined)]
        missing = sorted({name for row in rows for name in names if name not in row})
        if missing:
            parser.error(f"--merge: no rows of {', '.join(missing)} for some conditions")
    for inputs in ([] if arguments.merge else kept_conditions(arguments)):
        index, condition = inputs.condition.index, inputs.condition
        static = chosen_static(inputs, arguments.views)
        row: dict = {"index": index, "motion": condition.motion}
        for name in names:
            with StepCounter() as counter:
                result = run_condition_variant(inputs, f"ibik{arguments.views}v", "clean", VARIANTS[name](), static,
                                               TARGET_FILTER)
            row[name] = {group: value for group, value in result.groups_mm().items() if group in GROUPS}
            row[name]["steps_per_frame"] = counter.steps / inputs.truth.shape[0]
        rows.append(row)
        print(f"{index:3d} {condition.motion[:14]:14s} " + "  ".join(
            f"{name[:16]} {row[name]['elbows']:5.1f}/{row[name]['knees']:5.1f}" for name in names), flush=True)
    summary = summarize(rows, names)
    command = " ".join(argv or sys.argv[1:])
    header = (f"# Image steps a frame (`python experiments/step_budget.py {command}`)\n\n"
              f"{len(rows)} sweep conditions (seed {arguments.seed}), IBIK {arguments.views} views, clean "
              "silhouettes, the sweep's chosen lengths. Elbows, knees: median / 90th percentile over conditions "
              f"[mm]; paired: the change against {names[0]} per condition; better / worse: conditions changed "
              "by more than 1 mm. Steps a frame: solver steps (targets-only, image and closing steps), mean "
              "over conditions." + ("" if arguments.merge else f" Wall time {time.perf_counter() - started:.0f} s."))
    text = markdown(summary, header)
    print(text)
    result = {"command": " ".join(sys.argv), "summary": summary, "rows": rows}
    if arguments.out:
        arguments.out.mkdir(parents=True, exist_ok=True)
        (arguments.out / "step_budget.json").write_text(json.dumps(result, indent=1) + "\n")
        (arguments.out / "step_budget.md").write_text(text)
    return result


if __name__ == "__main__":
    main()
