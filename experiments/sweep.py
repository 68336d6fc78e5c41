"""The sweep benchmark: PIK and IBIK over many seeded conditions of rig, body, lengths, noise and motion.

Each condition (sweepkit.conditions) draws one of 14 windows of real motion capture (walking,
turning, hops with turns and a spin, jumps, kneeling, boxing: every recording of the shared data
folder), a 4-camera rig (heights 0.5-2.5 m, distances 3-7 m, fields of view 50-90 deg, 640 x 480
to 1920 x 1080; 2 views 45-135 deg apart), a silhouette body around the mocap skeleton (limb radii
x0.7-1.4, elliptical sections, loose clothing), a static take whose segments are off the trial's by
up to +-4 % each, target noise of 0-10 mm and a keypoint set with or without toes. Targets are the
mocap joints but the elbows and knees, which are judged. Every run is ``ibik track`` (run_track) on
the written files: PIK (no image) once, IBIK with 1, 2 and 4 views on clean silhouettes and on
silhouettes with Section 4's defects (IBIK then votes masks over 3 frames).

Writes sweep.json (every condition, every run, the summaries) and sweep.md (median / 90th
percentile over conditions per joint group, variant and silhouettes; per motion kind and motion).

Usage:
    python experiments/sweep.py                       # 42 conditions into experiments/results/
    python experiments/sweep.py --quick --out out/sweep_quick
    python experiments/sweep.py --set swivel_search=false --out out/sweep_noswivel
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

from realdata.runner import DEFAULT_DATA, REPOSITORY, code_revision, parse_settings, tracking_settings, variant
from sweepkit.conditions import draw_condition, load_condition, write_condition
from sweepkit.lengths import LENGTHS, image_static, oracle_static, reach_static
from sweepkit.runs import markdown, paired_markdown, run_condition_variant, summarize

from ibik_pin.app.job import TrackJob

DEFAULTS = {"conditions": 42, "frames": 40, "rate": 30.0, "views": "1,2,4", "silhouettes": "clean,defects"}
QUICK = {"conditions": 2, "frames": 12, "rate": 30.0, "views": "2", "silhouettes": "clean,defects"}


def _list(text: str) -> list[str]:
    return [item.strip() for item in text.split(",") if item.strip()]


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=None,
                        help="where sweep.json and sweep.md go (default: experiments/results; "
                             "--quick: out/sweep_quick)")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the shared data folder")
    parser.add_argument("--conditions", type=int, help="number of conditions (default 42)")
    parser.add_argument("--first", type=int, default=0, help="index of the first condition")
    parser.add_argument("--seed", type=int, default=0, help="seed of every draw")
    parser.add_argument("--frames", type=int, help="frames per window (default 40)")
    parser.add_argument("--rate", type=float, help="frame rate of the windows [Hz] (default 30)")
    parser.add_argument("--views", help="IBIK view counts (default 1,2,4)")
    parser.add_argument("--silhouettes", help="clean, defects (default both)")
    parser.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE",
                        help="override a TrackingSettings field for every run (repeatable)")
    parser.add_argument("--lengths", choices=LENGTHS, default="static",
                        help="limb lengths: the static's; refined on the trial's targets (reach) or on its "
                             "targets and silhouettes (images; sweepkit/lengths.py); the trial's true ones "
                             "(oracle, a diagnostic)")
    parser.add_argument("--reach-smoothing", type=int, default=3, metavar="FRAMES",
                        help="frames the targets' reach is averaged over before its bound (trial_lengths; "
                             "default 3)")
    parser.add_argument("--target-filters", default=str(TrackJob.__dataclass_fields__["target_filter"].default),
                        help="ibik track --target-filter values, each run on every condition and variant, "
                             "paired (e.g. off,auto; default: ibik track's)")
    parser.add_argument("--keep", type=Path, default=None,
                        help="keep each condition's files under this folder, and reuse those already there")
    parser.add_argument("--quick", action="store_true", help="2 conditions of 12 frames, IBIK 2 views (a smoke test)")
    parser.add_argument("--merge", type=Path, nargs="+", default=None, metavar="JSON",
                        help="write the tables of these sweep.json files' runs together (no run)")
    parser.add_argument("--quiet", action="store_true")
    arguments = parser.parse_args(argv)
    preset = QUICK if arguments.quick else DEFAULTS
    for key, value in preset.items():
        if getattr(arguments, key) is None:
            setattr(arguments, key, value)
    if arguments.out is None:
        arguments.out = REPOSITORY / ("out/sweep_quick" if arguments.quick else "experiments/results")
    try:
        overrides = parse_settings(arguments.settings)
    except Exception as error:  # bad flags: one line, exit code 2
        parser.error(str(error))
    views = [int(v) for v in _list(arguments.views)]
    target_filters = _list(arguments.target_filters)
    silhouettes = _list(arguments.silhouettes)

    def say(text: str) -> None:
        if not arguments.quiet:
            print(text, flush=True)

    started = time.perf_counter()
    conditions, runs = [], []
    parts = [json.loads(path.read_text()) for path in arguments.merge or ()]
    for part in parts:
        conditions += part["conditions"]
        runs += part["runs"]
    if parts:
        arguments.conditions = len(conditions)
        overrides, arguments.lengths = parts[0]["overrides"], parts[0]["lengths"]
    for index in range(arguments.first, arguments.first + (0 if parts else arguments.conditions)):
        condition = draw_condition(index, arguments.seed)
        folder = (arguments.keep / f"condition_{index:03d}" if arguments.keep
                  else Path(tempfile.mkdtemp(prefix=f"sweep_{index:03d}_")))
        try:
            rendering = time.perf_counter()
            inputs = load_condition(condition, folder, tuple(silhouettes)) if arguments.keep else None
            if inputs is None or inputs.truth.shape[0] != arguments.frames:
                inputs = write_condition(condition, arguments.data, arguments.frames, arguments.rate, folder,
                                         tuple(silhouettes))
            say(f"condition {index} ({condition.motion}, {condition.size[0]}x{condition.size[1]}, limbs "
                f"x{condition.body.limb_radius_factor:.2f}, noise {condition.target_noise_mm:.1f} mm, "
                f"toes {condition.toes}): inputs in {time.perf_counter() - rendering:.1f} s")
            refinement: dict = {}
            for target_filter in target_filters:  # each filter's runs see its own filtered targets throughout
                suffix = "" if target_filter == "off" else f"+filter_{target_filter}"
                static = None
                if arguments.lengths in ("reach", "images"):  # PIK's lengths: the targets' only
                    static, refinement["pik" + suffix] = reach_static(inputs, arguments.reach_smoothing,
                                                                      target_filter)
                elif arguments.lengths == "oracle":
                    static, refinement["pik" + suffix] = oracle_static(inputs)
                chosen = [("pik", "clean")] + [(f"ibik{v}v", s) for s in silhouettes for v in views]
                first_pass = None
                for name, kind in chosen:
                    run_static = static
                    if arguments.lengths == "images" and name != "pik":
                        run_static, refinement[f"{name}/{kind}{suffix}"] = image_static(
                            inputs, first_pass, int(name[4:-1]), kind,
                            tracking_settings(variant(name), kind, overrides), arguments.reach_smoothing,
                            target_filter=target_filter)
                    result = run_condition_variant(inputs, name, kind, overrides, run_static, target_filter)
                    first_pass = result.estimate if name == "pik" else first_pass
                    run = dict(result.row(), target_filter=target_filter)
                    runs.append(run)
                    groups = run["groups_mm"]
                    say(f"  {name:7s} {run['silhouettes']:8s} filter {target_filter:4s} elbows "
                        f"{groups['elbows']:6.1f}  knees {groups['knees']:6.1f}  targets {groups['targets']:5.1f} mm "
                        f"({run['wall_seconds']:.1f} s)")
            conditions.append(dict(inputs.condition.row(), lengths=refinement))
        finally:
            if arguments.keep is None:
                shutil.rmtree(folder, ignore_errors=True)
    wall = time.perf_counter() - started + sum(part["wall_seconds"] for part in parts)
    filters = list(dict.fromkeys(run.get("target_filter", "off") for run in runs))
    summary = summarize(runs) if len(filters) == 1 else {
        f"target_filter={name}": summarize([run for run in runs if run.get("target_filter", "off") == name])
        for name in filters}
    command = " ".join(["python experiments/sweep.py", *(sys.argv[1:] if argv is None else argv)])
    header = (f"# Sweep benchmark (`{command}`)\n\n"
              f"{arguments.conditions} conditions (seed {arguments.seed}), {arguments.frames} frames at "
              f"{arguments.rate:g} Hz each; motions, rigs, bodies, static lengths (+-4 % per segment), target "
              f"noise (0-10 mm) and keypoint sets drawn per condition (experiments/sweepkit/conditions.py). "
              f"A condition's figure is the mean over its frames of the group's joints; each cell is the median / "
              f"90th percentile of those over conditions. Targets: estimated target keypoints against the "
              f"noise-free mocap joints. PIK uses no image (one run stands for both silhouette columns). "
              f"Settings overridden: {overrides or 'none'}; limb lengths: {arguments.lengths}. "
              f"Wall time {wall:.0f} s on {platform.node()}; code at "
              f"{code_revision()}.")
    arguments.out.mkdir(parents=True, exist_ok=True)
    result = {"command": command, "revision": code_revision(), "seed": arguments.seed, "frames": arguments.frames,
              "rate_hz": arguments.rate, "overrides": overrides, "lengths": arguments.lengths,
              "wall_seconds": wall, "summary": summary,
              "conditions": conditions, "runs": runs}
    (arguments.out / "sweep.json").write_text(json.dumps(result, indent=1) + "\n")
    tables = (markdown(summary, header) if len(filters) == 1 else
              "\n".join([header, "", paired_markdown(runs, filters)] +
                         [markdown(part, f"# {key}") for key, part in summary.items()]))
    (arguments.out / "sweep.md").write_text(tables)
    if not arguments.quiet:
        print((arguments.out / "sweep.md").read_text())
    print(f"tables in {arguments.out / 'sweep.md'}; wall time {wall:.1f} s", flush=True)
    return result


if __name__ == "__main__":
    main()
