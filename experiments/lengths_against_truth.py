"""How close the refined limb lengths come to the trial's true ones, without tracking: per sweep
condition, each segment's error [mm] with the static's lengths, with sweepkit.lengths.image_static's
without its split (the legs' one factor on the silhouettes, the arms' reach), and with the legs'
split on the centre lines (--trial split, image_static's default) or the arms' factor on the
silhouettes (--trial arms).

    python experiments/lengths_against_truth.py --keep /tmp/keep --conditions 14 --trial split

The conditions' inputs come from `--keep` (written there if absent, as sweep.py --keep does); the PIK
pass each refinement starts from is cached there too (pik_<filter>.trc).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from realdata.runner import DEFAULT_DATA, tracking_settings, variant
from sweepkit.conditions import draw_condition, load_condition, write_condition
from sweepkit.lengths import image_static, reach_static
from sweepkit.runs import run_condition_variant

from ibik_pin.io.trc import read_trc, write_trc
from ibik_pin.subject.scaling import segment_lengths_from_keypoints

LEGS = ("left_thigh", "left_shank", "right_thigh", "right_shank")
ARMS = ("left_upper_arm", "left_forearm", "right_upper_arm", "right_forearm")


def pik_estimate(inputs, folder: Path, target_filter: str):
    path = folder / f"pik_{target_filter}.trc"
    if not path.is_file():
        static, _ = reach_static(inputs, 3, target_filter)
        result = run_condition_variant(inputs, "pik", "clean", {}, static, target_filter)
        write_trc(path, result.estimate)
    return read_trc(path).in_metres()


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, required=True)
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--conditions", type=int, default=14)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--views", type=int, default=2)
    parser.add_argument("--silhouettes", default="clean")
    parser.add_argument("--target-filter", default="auto")
    parser.add_argument("--trial", choices=("split", "arms"), default="split")
    parser.add_argument("--out", type=Path, default=None, help="a JSON of every leg's figures")
    arguments = parser.parse_args(argv)
    segments = ARMS if arguments.trial == "arms" else LEGS
    rows = []
    for index in range(arguments.first, arguments.first + arguments.conditions):
        condition = draw_condition(index, arguments.seed)
        folder = arguments.keep / f"condition_{index:03d}"
        inputs = load_condition(condition, folder, (arguments.silhouettes,))
        if inputs is None:
            inputs = write_condition(condition, arguments.data, 40, 30.0, folder, (arguments.silhouettes,))
        estimate = pik_estimate(inputs, folder, arguments.target_filter)
        settings = tracking_settings(variant(f"ibik{arguments.views}v"), arguments.silhouettes)
        truth = segment_lengths_from_keypoints(inputs.truth_names, inputs.truth)
        _, one = image_static(inputs, estimate, arguments.views, arguments.silhouettes, settings,
                              target_filter=arguments.target_filter, split=False)
        _, two = image_static(inputs, estimate, arguments.views, arguments.silhouettes, settings,
                              target_filter=arguments.target_filter, split=arguments.trial == "split",
                              arms="images" if arguments.trial == "arms" else "reach")
        row = {"index": index, "motion": condition.motion}
        for name in segments:
            row[name] = {"truth_mm": 1e3 * truth[name], "static_mm": one[name]["static_mm"] - 1e3 * truth[name],
                         "one_mm": one[name]["trial_mm"] - 1e3 * truth[name],
                         "trial_mm": two[name]["trial_mm"] - 1e3 * truth[name]}
        row["evidence"] = two["evidence"]
        rows.append(row)
        text = "  ".join(f"{name[:1]}{name.split('_')[-1][:2]} {row[name]['static_mm']:+6.1f} "
                         f"{row[name]['one_mm']:+6.1f} {row[name]['trial_mm']:+6.1f}" for name in segments)
        print(f"{index:3d} {condition.motion[:14]:14s} {text}", flush=True)
    print("per segment: static, image_static's, the trial's error [mm]")
    for kind in ("static_mm", "one_mm", "trial_mm"):
        errors = np.array([[row[name][kind] for name in segments] for row in rows])
        shares = np.array([[row[upper][kind] - row[lower][kind] for upper, lower in (segments[:2], segments[2:])]
                                for row in rows])
        print(f"{kind:10s} mean |error| {np.mean(np.abs(errors)):5.1f} mm (p90 "
              f"{np.percentile(np.abs(errors), 90):5.1f}); |upper - lower error| {np.mean(np.abs(shares)):5.1f} mm",
              flush=True)
    result = {"command": " ".join(sys.argv), "rows": rows}
    if arguments.out:
        arguments.out.write_text(json.dumps(result, indent=1) + "\n")
    return result


if __name__ == "__main__":
    main()
