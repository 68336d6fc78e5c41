"""The swivel search's refutation rule, paired: IBIK 2 views with and without it on kept sweep conditions.

Runs ``ibik track`` (sweepkit.runs.run_condition_variant) on the files ``sweep.py --keep`` wrote,
with each condition's trial-refined static (static_images2v_<silhouettes>[_<filter>].trc, as the sweep's
``--lengths images``), once with the tracker's swivel search as it is (SwivelSearch.keep_unrefuted:
a limb the silhouettes do not refute gets no hint) and once hinting every limb as before. Same
inputs, same process: the difference is the rule alone. Prints and writes each run's mean error
per joint [mm].

With --real-mocap OUT, runs ``experiments/real_mocap.py --quick`` instead, with the earlier search
and then with the tracker's (OUT/before, OUT/after; the rendered inputs cached in OUT/cache).

Usage:
    python experiments/swivel_refute_paired.py --keep /tmp/h4_inputs --conditions 0-13 --out out/h4_paired.json
    python experiments/swivel_refute_paired.py --real-mocap out/h4_real_mocap
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path

import numpy as np
from sweepkit.conditions import draw_condition, load_condition
from sweepkit.runs import run_condition_variant

from ibik_pin.tracking import tracker as tracker_module
from ibik_pin.tracking.swivel import SwivelSearch

JOINTS = ("LElbow", "RElbow", "LKnee", "RKnee")
#: The swivel search before the refutation rule: every limb hinted, the trunk's section symmetric.
EARLIER = {"keep_unrefuted": False, "trunk_section": [0.75, 0.6]}


def _indices(text: str) -> list[int]:
    chosen: list[int] = []
    for part in text.split(","):
        first, _, last = part.partition("-")
        chosen += list(range(int(first), int(last or first) + 1))
    return chosen


def run(inputs, kind: str, search: dict, target_filter: str = "auto") -> dict:
    tracker_module.SwivelSearch = functools.partial(SwivelSearch, **search)  # type: ignore[misc]
    try:
        suffix = "" if target_filter == "off" else f"_{target_filter}"  # sweepkit.lengths.image_static's name
        static = inputs.folder / f"static_images2v_{kind}{suffix}.trc"
        result = run_condition_variant(inputs, "ibik2v", kind, None, static if static.exists() else None,
                                       target_filter)
    finally:
        tracker_module.SwivelSearch = SwivelSearch  # type: ignore[misc]
    return {joint: float(np.mean(result.errors[:, k]) * 1e3) for k, joint in enumerate(JOINTS)}


def real_mocap_before_after(out: Path, before: dict, after: dict) -> None:
    """experiments/real_mocap.py --quick with each search (its main reads sys.argv)."""
    import real_mocap

    for name, search in (("before", before), ("after", after)):
        tracker_module.SwivelSearch = functools.partial(SwivelSearch, **search)  # type: ignore[misc]
        saved = sys.argv
        sys.argv = ["real_mocap.py", "--quick", "--out", str(out / name), "--cache", str(out / "cache")]
        try:
            real_mocap.main()
        finally:
            sys.argv = saved
            tracker_module.SwivelSearch = SwivelSearch  # type: ignore[misc]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, help="the folder sweep.py --keep wrote")
    parser.add_argument("--real-mocap", type=Path, default=None, metavar="OUT",
                        help="run real_mocap.py --quick before and after into OUT instead")
    parser.add_argument("--conditions", default="0-13", help="indices, e.g. 0-13 or 8,22,36")
    parser.add_argument("--silhouettes", default="clean,defects")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--target-filter", default="auto", help="ibik track --target-filter (default: the sweep's)")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--before", type=json.loads, default=EARLIER,
                        help="SwivelSearch fields of the earlier run, JSON (default: %(default)s)")
    parser.add_argument("--after", type=json.loads, default={},
                        help="SwivelSearch fields of the later run, JSON (default: the defaults)")
    arguments = parser.parse_args(argv)
    if arguments.real_mocap is not None:
        real_mocap_before_after(arguments.real_mocap, arguments.before, arguments.after)
        return
    if arguments.keep is None:
        parser.error("--keep: the folder sweep.py --keep wrote (or --real-mocap OUT)")
    rows = []
    for index in _indices(arguments.conditions):
        condition = draw_condition(index, arguments.seed)
        inputs = load_condition(condition, arguments.keep / f"condition_{index:03d}")
        if inputs is None:
            raise SystemExit(f"condition {index}: no kept files under {arguments.keep}; run sweep.py --keep first")
        for kind in arguments.silhouettes.split(","):
            before, after = (run(inputs, kind, search, arguments.target_filter)
                             for search in (arguments.before, arguments.after))
            rows.append({"index": index, "motion": condition.motion, "silhouettes": kind, "before": before,
                         "after": after})
            print(f"{index:3d} {condition.motion:15s} {kind:7s} " + "  ".join(
                f"{joint} {before[joint]:5.1f}->{after[joint]:5.1f}" for joint in JOINTS), flush=True)
    for kind in arguments.silhouettes.split(","):
        chosen = [row for row in rows if row["silhouettes"] == kind]
        for group, joints in (("elbows", JOINTS[:2]), ("knees", JOINTS[2:])):
            before = [np.mean([row["before"][j] for j in joints]) for row in chosen]
            after = [np.mean([row["after"][j] for j in joints]) for row in chosen]
            print(f"{kind:7s} {group}: median {np.median(before):.1f} -> {np.median(after):.1f}, p90 "
                  f"{np.percentile(before, 90):.1f} -> {np.percentile(after, 90):.1f} mm over {len(chosen)} conditions")
    if arguments.out is not None:
        arguments.out.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
