"""The accuracy benchmark without the inverse crime: `ibik track` on raw motion capture.

Real motion capture (../shared/data): CMU walking 35_01 and 39_01 (ASF/AMC), CMU BVH 131_01
(walking), three 2-s windows of Boxing_Toes.bvh where the arms move most; 60 Hz. The targets and
the truth are the raw mocap joints mapped to Pose2Sim keypoints (every keypoint but LElbow, RElbow,
LKnee, RKnee is a target; those four are judged against the mocap joints); the silhouettes are
those of another body than the tracking model (tapered capsules and ellipsoids of adult
proportions around every joint of the mocap skeleton), in 4 HumanEva-like cameras; the static trial
comes from another trial of the subject where one exists. Nothing is posed on the tracking model.
Each clip's files (targets.trc, static.trc, calibration.toml, masks/<camera>/*.png; clean and with
Section 4's defects) are written once into --cache, then every variant runs `ibik track` on them
(run_track) as a user would: IK, PIK, IBIK with 1, 2 and 4 views.

Writes into --out: real_mocap.md and real_mocap.json (tables), previews/<clip>.png (one frame's
silhouettes with the projected mocap skeleton) and runs/<clip>/<condition>/<variant>/ (the outputs
of `ibik track`).

Usage:
    python experiments/real_mocap.py --out out/real_mocap            # the full benchmark
    python experiments/real_mocap.py --quick --set criterion=two-way  # about a minute
    python experiments/real_mocap.py --quick --target-filters off,auto  # both in one process, paired:
                                                                        # <out>/filter_<value>/ each
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import shutil
import sys
import time
from pathlib import Path

from realdata.clips import CLIPS, RATE_HZ
from realdata.inputs import CONDITIONS, prepare_inputs
from realdata.runner import (
    DEFAULT_DATA,
    REPOSITORY,
    code_revision,
    markdown,
    parse_settings,
    run_variant,
    summarize,
    tracking_settings,
    variant,
)

from ibik_pin.app.job import TrackJob

DEFAULTS = {"clips": ",".join(CLIPS), "views": "1,2,4", "conditions": ",".join(CONDITIONS), "frames": 120,
            "variants": "ik,pik,ibik"}
QUICK = {"clips": "cmu35_01,boxing_a", "views": "2", "conditions": "clean,defects", "frames": 40,
         "variants": "ik,pik,ibik"}


def _list(text: str) -> list[str]:
    return [item.strip() for item in text.split(",") if item.strip()]


def _clip_names(text: str) -> list[str]:
    names = []
    for item in _list(text):
        if item in ("all", "walking", "boxing"):
            names += [name for name, spec in CLIPS.items() if item in ("all", spec.kind)]
        elif item in CLIPS:
            names.append(item)
        else:
            raise SystemExit(f"real_mocap: error: --clips: unknown clip {item!r}; known: {', '.join(CLIPS)}, "
                             "walking, boxing, all")
    return list(dict.fromkeys(names))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=REPOSITORY / "out" / "real_mocap")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the shared data folder")
    parser.add_argument("--cache", type=Path, default=None,
                        help="where the rendered inputs are kept and reused (default: <out>/../real_mocap_cache)")
    parser.add_argument("--clips", help=f"comma-separated: {', '.join(CLIPS)}, walking, boxing, all "
                                         f"(default: all)")
    parser.add_argument("--views", help="IBIK view counts, comma-separated (default 1,2,4)")
    parser.add_argument("--conditions", help="clean, defects (default both)")
    parser.add_argument("--frames", type=int, help=f"frames per clip at {RATE_HZ:g} Hz (default 120)")
    parser.add_argument("--variants", help="ik, pik, ibik (default all three)")
    parser.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE",
                        help="override a TrackingSettings field for every variant (repeatable)")
    parser.add_argument("--drop-targets", default="", metavar="NAMES",
                        help="comma-separated target keypoints to leave out, e.g. LBigToe,RBigToe")
    parser.add_argument("--target-filters", default=str(TrackJob.__dataclass_fields__["target_filter"].default),
                        metavar="VALUES",
                        help="ibik track --target-filter values, comma-separated (default: ibik track's); with "
                             "several, each one's tables and runs go to <out>/filter_<value>/")
    parser.add_argument("--trial-lengths", choices=("off", "reach", "images"), default=None,
                        help="ibik track --trial-lengths for every run (default: ibik track's)")
    parser.add_argument("--quick", action="store_true",
                        help="40 frames, cmu35_01 and boxing_a, IK, PIK and IBIK 2v (explicit flags win)")
    parser.add_argument("--quiet", action="store_true", help="print only the tables' path and the wall time")
    arguments = parser.parse_args()
    preset = QUICK if arguments.quick else DEFAULTS
    for key, value in preset.items():
        if getattr(arguments, key) is None:
            setattr(arguments, key, value)
    try:
        overrides = parse_settings(arguments.settings)
        clips = _clip_names(arguments.clips)
        drop_targets = _list(arguments.drop_targets)
        conditions = _list(arguments.conditions)
        unknown = [c for c in conditions if c not in CONDITIONS]
        if unknown:
            raise SystemExit(f"real_mocap: error: --conditions: unknown {unknown}; known: {', '.join(CONDITIONS)}")
        variants = []
        for name in _list(arguments.variants):
            variants += [variant(f"ibik{v}v") for v in _list(arguments.views)] if name == "ibik" else [variant(name)]
    except Exception as error:  # bad flags: one line, exit code 2
        if isinstance(error, SystemExit):
            raise
        parser.error(str(error))
    cache = arguments.cache or arguments.out.parent / "real_mocap_cache"
    target_filters = _list(arguments.target_filters)
    outs = {f: arguments.out if len(target_filters) == 1 else arguments.out / f"filter_{f}" for f in target_filters}
    for out in outs.values():
        (out / "previews").mkdir(parents=True, exist_ok=True)

    def say(text: str) -> None:
        if not arguments.quiet:
            print(text, flush=True)

    revision = code_revision()  # the code this process loads now
    started = time.perf_counter()
    results: dict[str, list] = {f: [] for f in target_filters}
    total = len(clips) * len(conditions) * len(variants) * len(target_filters)
    count = 0
    for clip in clips:
        rendering = time.perf_counter()
        inputs = prepare_inputs(CLIPS[clip], arguments.data, arguments.frames, cache)
        for out in outs.values():
            shutil.copyfile(inputs.preview, out / "previews" / f"{clip}.png")
        say(f"{clip}: inputs in {inputs.folder} ({time.perf_counter() - rendering:.1f} s)")
        for condition in conditions:
            for chosen in variants:
                for target_filter in target_filters:  # the filters side by side: paired on this machine's state
                    count += 1
                    result = run_variant(inputs, chosen, condition, overrides,
                                         outs[target_filter] / "runs" / clip / condition / chosen.name, drop_targets,
                                         target_filter=target_filter, trial_lengths=arguments.trial_lengths)
                    results[target_filter].append(result)
                    errors = result.joint_errors_mm
                    residual = sum(result.residuals_mm.values()) / len(result.residuals_mm)
                    say(f"[{count}/{total}] {clip} {condition} {chosen.label} filter {target_filter}: "
                        + " ".join(f"{joint} {value:.1f}" for joint, value in errors.items())
                        + f" mm, judged {result.judged_mm:.1f} mm, target residual {residual:.1f} mm "
                        f"({result.wall_seconds:.1f} s)")
    wall = time.perf_counter() - started
    for target_filter, out in outs.items():
        _write_tables(out, arguments, results[target_filter], overrides, clips, conditions, variants,
                      drop_targets, target_filter, wall, revision)


def _write_tables(out: Path, arguments: argparse.Namespace, results: list, overrides: dict, clips: list[str],
                  conditions: list[str], variants: list, drop_targets: list[str], target_filter: str, wall: float,
                  revision: str) -> None:
    summary = summarize(results)
    settings = {condition: {v.name: dataclasses.asdict(tracking_settings(v, condition, overrides)) for v in variants}
                for condition in conditions}
    command = " ".join(["python experiments/real_mocap.py", *sys.argv[1:]])
    windows = ", ".join(f"{name} ({spec.file} from {spec.start_s:g} s, static: {spec.static_file or 'same file'} "
                        f"at {spec.static_start_s:g} s)" for name, spec in ((name, CLIPS[name]) for name in clips))
    header = (f"# Real motion capture benchmark (`{command}`)\n\n"
              f"Targets and truth are the raw mocap joints as Pose2Sim keypoints (every keypoint but the elbows "
              f"and knees is a target); silhouettes are those of a capsule-and-ellipsoid body around the mocap "
              f"skeleton in HumanEva-like cameras (640 x 480, 4 m; 1 view: the most frontal camera, 2 views: "
              f"the two most frontal, about 90 degrees apart); nothing is posed on the tracking model. "
              f"\"defects\": Section 4's silhouette defects and 5 mm of target noise, IBIK voting masks over "
              f"3 frames. Every run is `ibik track` (run_track) on the written files.\n\n"
              f"{len(clips)} clips, {arguments.frames} frames each at {RATE_HZ:g} Hz: {windows}. "
              f"Settings overridden: {overrides or 'none'}; targets left out: {', '.join(drop_targets) or 'none'}; "
              f"--target-filter {target_filter}. "
              f"Total wall time {wall:.0f} s on {platform.node()} ({len(results)} runs); code at {revision}.")
    (out / "real_mocap.md").write_text(markdown(results, summary, header))
    (out / "real_mocap.json").write_text(json.dumps({
        "command": command, "revision": revision, "clips": {name: dataclasses.asdict(CLIPS[name]) for name in clips},
        "frames": arguments.frames, "rate_hz": RATE_HZ, "overrides": overrides, "drop_targets": drop_targets,
        "target_filter": target_filter,
        "settings": settings,
        "wall_seconds": wall, "summary": summary, "runs": [r.row() for r in results],
    }, indent=2) + "\n")
    if not arguments.quiet:
        print((out / "real_mocap.md").read_text())
    print(f"tables in {out / 'real_mocap.md'}; total wall time {wall:.1f} s", flush=True)


if __name__ == "__main__":
    main()
