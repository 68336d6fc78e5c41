"""Priority strategies compared on the real-motion benchmark: `ibik track --stack` on raw mocap.

The benchmark of experiments/real_mocap.py (raw mocap joints of ../shared/data as targets and
truth, silhouettes of another body than the tracking model, HumanEva-like cameras; see
experiments/realdata), tracked with several priority stacks and schemes, all with the default
criterion (two-way) so that only the priorities change:

- liegeois: the paper's eq. (4), every target in one primary task, then the image (2 levels);
- default: today's 4 strict levels (pelvis and legs, other targets, image, posture), QP;
- image_above_arms: the image at level 2, above the trunk, head and arm targets;
- weighted_w<W>: every task weighted in one QP level (Pink-like soft priorities): targets 1,
  image W (its row asks the image step along its gradient, tasks.criterion_step), posture 1e-2;
- default_clamping: the default stack solved by the projection stack, limits by clamping
  (against the QP's limits as constraints);
- pik: the default stack without the image (reference).

Writes into --out: priority_strategies.md and .json (elbow error on boxing, knee error on walking,
target residuals, joint-limit hits and violations, solve frames per second), per-level residual
plots (levels_<clip>_<condition>_<views>v.png), the stacks as TOML (stacks/, usable with
`ibik track --stack`) and runs/ (the outputs of `ibik track`).

Usage:
    python experiments/priority_strategies.py --out out/priority_strategies   # about 12 min here
    python experiments/priority_strategies.py --frames 20 --views 2 --conditions clean  # a few min
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import tomli_w
from realdata.clips import CLIPS, RATE_HZ
from realdata.inputs import CONDITIONS, prepare_inputs
from realdata.runner import DEFAULT_DATA, REPOSITORY, Variant, run_variant

from ibik_pin.human import load_human
from ibik_pin.limits import JointLimits
from ibik_pin.tracking.stack import Stack

LOWER_BODY = ["Hip", "LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle", "LBigToe", "LSmallToe", "LHeel",
              "RBigToe", "RSmallToe", "RHeel"]
IMAGE_WEIGHTS = (0.01, 0.1, 1.0)
# The posture weight of the weighted stacks: 1e-2, the strict stack's, pulled the boxing targets 4-5 cm off
# their targets in one weighted level (20-frame probe); 1e-4 keeps the prior light against them.
WEIGHTED_POSTURE = 1e-4
DEFAULTS = {"clips": "cmu35_01,boxing_a", "views": "2,4", "conditions": "clean,defects", "frames": 40}


def _level(name: str, *tasks: dict, strict: bool = True) -> dict:
    return {"name": name, "strict": strict, "tasks": list(tasks)}


def _stacks() -> dict[str, dict]:
    """Each strategy's stack as TOML data (None: the package's default stack)."""
    lower = {"kind": "position", "keypoints": LOWER_BODY}
    others = {"kind": "position", "keypoints": "present"}
    stacks = {
        "liegeois": {"level": [_level("end effectors", others), _level("image", {"kind": "image"})]},
        "image_above_arms": {"level": [_level("lower-body targets", lower), _level("image", {"kind": "image"}),
                                       _level("upper-body targets", others),
                                       _level("posture", {"kind": "posture"})]},
    }
    for weight in IMAGE_WEIGHTS:
        stacks[f"weighted_w{weight:g}"] = {"level": [
            _level("targets", others, strict=False), _level("image", {"kind": "image", "weight": weight}, strict=False),
            _level("posture", {"kind": "posture", "weight": WEIGHTED_POSTURE}, strict=False)]}
    return stacks


@dataclass(frozen=True)
class Strategy:
    name: str
    method: str
    stack: str | None  # a key of _stacks(), or None for the default stack
    image: bool = True


STRATEGIES = [Strategy("liegeois", "liegeois", "liegeois"), Strategy("default", "qp", None),
              Strategy("image_above_arms", "qp", "image_above_arms"),
              *[Strategy(f"weighted_w{weight:g}", "qp", f"weighted_w{weight:g}") for weight in IMAGE_WEIGHTS],
              Strategy("default_clamping", "stack", None), Strategy("pik", "qp", None, image=False)]


def _list(text: str) -> list[str]:
    return [item.strip() for item in text.split(",") if item.strip()]


def _limit_violation(q_csv: Path, limits: JointLimits) -> float:
    """Largest distance [rad] of any limited coordinate outside its range, over the frames."""
    q = np.loadtxt(q_csv, delimiter=",", skiprows=1, ndmin=2)[:, 1:][:, limits.q_index]  # column 0: time
    return float(max(np.max(limits.lower - q), np.max(q - limits.upper), 0.0))


def run_all(arguments) -> list[dict]:
    stack_folder = arguments.out / "stacks"
    stack_folder.mkdir(parents=True, exist_ok=True)
    stacks = {}
    for name, document in _stacks().items():
        path = stack_folder / f"{name}.toml"
        path.write_text(tomli_w.dumps(document))
        stacks[name] = Stack.from_toml(path)
    limits = JointLimits(load_human().model)
    chosen = [s for s in STRATEGIES if s.name in _list(arguments.strategies)] if arguments.strategies else STRATEGIES
    rows: list[dict] = []
    for clip in _list(arguments.clips):
        inputs = prepare_inputs(CLIPS[clip], arguments.data, arguments.frames, arguments.cache)
        for condition in _list(arguments.conditions):
            for views in [int(v) for v in _list(arguments.views)]:
                for strategy in chosen:
                    if not strategy.image and views != int(_list(arguments.views)[0]):
                        continue  # blind: the same run whatever the views
                    out = arguments.out / "runs" / clip / condition / f"{views}v" / strategy.name
                    overrides = {} if strategy.stack is None else {"stack": stacks[strategy.stack]}
                    chosen_variant = Variant(strategy.name, strategy.method, views if strategy.image else 0)
                    result = run_variant(inputs, chosen_variant, condition, overrides, out)
                    report = json.loads((out / "report.json").read_text())
                    levels = report["solver_levels"]
                    rows.append({
                        "clip": clip, "kind": result.kind, "condition": condition,
                        "views": views if strategy.image else 0, "strategy": strategy.name,
                        "judged_mm": result.judged_mm, "errors_mm": result.joint_errors_mm,
                        "target_residual_mm": float(np.mean(list(result.residuals_mm.values()))),
                        "residuals_mm": result.residuals_mm,
                        "limit_hits_per_frame": sum(map(len, report["joint_limit_hits"].values())) / report["frames"],
                        "limit_violation_rad": _limit_violation(out / "q.csv", limits),
                        "solve_fps": result.solve_fps, "wall_seconds": result.wall_seconds,
                        "levels": levels["levels"], "residual_per_frame": levels["residual_per_frame"],
                        "mean_residual": levels["mean_residual"], "mean_sacrificed": levels["mean_sacrificed"],
                        "status_counts": levels["frames_per_status"],
                    })
                    if not arguments.quiet:
                        row = rows[-1]
                        print(f"{clip} {condition} {views}v {strategy.name}: judged {row['judged_mm']:.1f} mm, "
                              f"targets {row['target_residual_mm']:.1f} mm, {row['solve_fps']:.1f} fps "
                              f"({row['wall_seconds']:.1f} s)", flush=True)
    return rows


def summarize(rows: list[dict]) -> list[dict]:
    """Per strategy, condition and view count: means over the clips of each kind."""
    table = []
    keys = dict.fromkeys((r["strategy"], r["condition"], r["views"]) for r in rows)
    for strategy, condition, views in keys:
        runs = [r for r in rows if (r["strategy"], r["condition"], r["views"]) == (strategy, condition, views)]

        def mean(values):
            values = list(values)
            return float(np.mean(values)) if values else None

        table.append({
            "strategy": strategy, "condition": condition, "views": views,
            "elbows_boxing_mm": mean(r["judged_mm"] for r in runs if r["kind"] == "boxing"),
            "knees_walking_mm": mean(r["judged_mm"] for r in runs if r["kind"] == "walking"),
            "target_residual_mm": mean(r["target_residual_mm"] for r in runs),
            "upper_targets_mm": mean(np.mean([r["residuals_mm"][k] for k in r["residuals_mm"] if k not in LOWER_BODY])
                                     for r in runs),
            "limit_hits_per_frame": mean(r["limit_hits_per_frame"] for r in runs),
            "limit_violation_rad": max(r["limit_violation_rad"] for r in runs),
            "solve_fps": mean(r["solve_fps"] for r in runs),
        })
    return table


def _cell(value, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def markdown(table: list[dict], header: str) -> str:
    lines = [header, "", "| condition | views | strategy | elbows, boxing [mm] | knees, walking [mm] | "
             "target residual [mm] | trunk, head, arm targets [mm] | limit hits / frame | limit violation [rad] | "
             "solve fps |", "| --- | ---: | --- |" + " ---: |" * 7]
    for row in sorted(table, key=lambda r: (r["condition"], r["views"])):
        lines.append(f"| {row['condition']} | {row['views'] or 'blind'} | {row['strategy']} | "
                     f"{_cell(row['elbows_boxing_mm'])} | {_cell(row['knees_walking_mm'])} | "
                     f"{_cell(row['target_residual_mm'])} | {_cell(row['upper_targets_mm'])} | "
                     f"{_cell(row['limit_hits_per_frame'], 2)} | {row['limit_violation_rad']:.1e} | "
                     f"{_cell(row['solve_fps'])} |")
    return "\n".join(lines) + "\n"


def plot_levels(rows: list[dict], out: Path, clip: str, condition: str, views: int) -> Path | None:
    """Per strategy, each level's residual over the frames (log scale)."""
    runs = [r for r in rows if (r["clip"], r["condition"], r["views"]) == (clip, condition, views)]
    if not runs:
        return None
    figure, axes = plt.subplots(len(runs), 1, figsize=(8, 1.9 * len(runs)), sharex=True, squeeze=False)
    for axis, run in zip(axes[:, 0], runs, strict=True):
        for level in run["levels"]:
            values = np.array([np.nan if v is None else v for v in run["residual_per_frame"][level]], dtype=float)
            if np.isfinite(values).any():
                axis.semilogy(np.arange(values.size) / RATE_HZ, np.maximum(values * 1000.0, 1e-3), label=level)
        axis.set_title(run["strategy"], fontsize=9)
        axis.set_ylabel("residual\n[mm, mrad]", fontsize=8)
        axis.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time [s]")
    figure.suptitle(f"per-level residual, {clip}, {condition}, {views} views (posture: sqrt(w) x rad)", fontsize=10)
    figure.tight_layout()
    path = out / f"levels_{clip}_{condition}_{views}v.png"
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPOSITORY / "out" / "priority_strategies")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=None, help="rendered inputs (default: <out>/../real_mocap_cache)")
    parser.add_argument("--clips", default=DEFAULTS["clips"], help=f"comma-separated: {', '.join(CLIPS)}")
    parser.add_argument("--views", default=DEFAULTS["views"], help="view counts, comma-separated")
    parser.add_argument("--conditions", default=DEFAULTS["conditions"], help=", ".join(CONDITIONS))
    parser.add_argument("--frames", type=int, default=DEFAULTS["frames"], help=f"frames per clip at {RATE_HZ:g} Hz")
    parser.add_argument("--strategies", default="", help="comma-separated subset: "
                        + ", ".join(s.name for s in STRATEGIES))
    parser.add_argument("--quiet", action="store_true")
    arguments = parser.parse_args()
    unknown = [c for c in _list(arguments.clips) if c not in CLIPS] + \
        [c for c in _list(arguments.conditions) if c not in CONDITIONS]
    if unknown:
        parser.error(f"unknown clip or condition {unknown[0]!r}")
    arguments.cache = arguments.cache or arguments.out.parent / "real_mocap_cache"
    started = time.perf_counter()
    rows = run_all(arguments)
    wall = time.perf_counter() - started
    table = summarize(rows)
    command = " ".join(["python experiments/priority_strategies.py", *sys.argv[1:]])
    header = (f"# Priority strategies on the real-motion benchmark (`{command}`)\n\n"
              f"Clips {arguments.clips}, {arguments.frames} frames each at {RATE_HZ:g} Hz (the benchmark's first "
              f"{arguments.frames / RATE_HZ:.2f} s of each window), views {arguments.views}, conditions "
              f"{arguments.conditions}; every run is `ibik track` with the default criterion (two-way) and the "
              f"stack and scheme of its strategy. Elbow error on the boxing clips, knee error on the walking clips "
              f"(eq. 9, against the raw mocap joints); target residual: mean over every target keypoint; limit hits: "
              f"joints at a limit per frame; limit violation: the largest excursion of q.csv outside the model's "
              f"limits. Total wall time {wall:.0f} s on {platform.node()} ({len(rows)} runs; 2 cores shared with "
              f"other sessions: the frame rates are lowered by that sharing).")
    (arguments.out / "priority_strategies.md").write_text(markdown(table, header))
    plots = [plot_levels(rows, arguments.out, clip, condition, int(_list(arguments.views)[0]))
             for clip in _list(arguments.clips) for condition in _list(arguments.conditions)[:1]]
    (arguments.out / "priority_strategies.json").write_text(json.dumps({
        "command": command, "frames": arguments.frames, "rate_hz": RATE_HZ, "wall_seconds": wall,
        "stacks": _stacks(), "strategies": [s.__dict__ for s in STRATEGIES], "summary": table,
        "runs": [{k: v for k, v in r.items() if k != "residual_per_frame"} for r in rows],
        "plots": [str(p) for p in plots if p is not None]}, indent=2) + "\n")
    if not arguments.quiet:
        print((arguments.out / "priority_strategies.md").read_text())
    print(f"tables in {arguments.out / 'priority_strategies.md'}; total wall time {wall:.1f} s", flush=True)


if __name__ == "__main__":
    main()
