"""Where the sweep's remaining elbow and knee error comes from: each condition's IBIK run repeated
with one of its inputs made exact, paired against the run as the sweep makes it.

    python experiments/error_sources.py --keep /tmp/keep --out experiments/results

Variants (IBIK, `--views` cameras, clean silhouettes, `ibik track --target-filter auto`):

- as run: the limb lengths sweepkit.lengths.image_static chose (the sweep's `--lengths images`) and
  the noisy targets;
- exact targets: the noise-free mocap keypoints as targets, the same lengths;
- true leg sums: each leg's thigh + shank the trial's, its split between them as chosen;
- true leg splits: each leg's split the trial's, its sum as chosen;
- true legs, true arms: both segments of the limbs the trial's;
- true arm sums, true arm splits: as for the legs;
- all exact: every limb length the trial's and noise-free targets. What is left there is the
  tracking's own: the image criterion's peak, the swivel search, the model's joints.

A variant's change on a condition is its group's error minus the run's as run; the tables give the
median and 90th percentile over conditions and the paired changes. The conditions' inputs come from
`--keep` (written there if absent, as sweep.py --keep does), and so do the PIK pass and the chosen
static (lengths_against_truth.pik_estimate; static_images<V>v_clean_auto.trc).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from lengths_against_truth import pik_estimate
from realdata.runner import DEFAULT_DATA, tracking_settings, variant
from sweepkit.conditions import ConditionInputs, add_kept_arguments, kept_conditions
from sweepkit.lengths import image_static, static_lengths, write_static
from sweepkit.runs import run_condition_variant

from ibik_pin.io.trc import METRES_PER_UNIT, read_trc, write_trc
from ibik_pin.subject.scaling import segment_lengths_from_keypoints

LIMB_SEGMENTS = {"leg": ("thigh", "shank"), "arm": ("upper_arm", "forearm")}
VARIANTS = ("as_run", "exact_targets", "true_leg_sums", "true_leg_splits", "true_legs", "true_arm_sums",
            "true_arm_splits", "true_arms", "all_exact")
TRUE_PARTS = {"true_leg_sums": ("leg", "sum"), "true_leg_splits": ("leg", "split"), "true_legs": ("leg", "both"),
              "true_arm_sums": ("arm", "sum"), "true_arm_splits": ("arm", "split"), "true_arms": ("arm", "both")}
GROUPS = ("elbows", "knees")
TARGET_FILTER = "auto"


def with_true_parts(chosen: Mapping[str, float], true: Mapping[str, float], limb: str, part: str) -> dict[str, float]:
    """The `chosen` lengths [m] with both sides' `limb` ("leg" or "arm") made true in `part`: "sum"
    (each side's two segments scaled together until their sum is the true one, their ratio kept),
    "split" (the true ratio, the chosen sum kept) or "both" (the true lengths)."""
    if limb not in LIMB_SEGMENTS or part not in ("sum", "split", "both"):
        raise ValueError(f"limb {limb!r}, part {part!r}: expected leg or arm, and sum, split or both")
    lengths = dict(chosen)
    for side in ("left", "right"):
        upper, lower = (f"{side}_{segment}" for segment in LIMB_SEGMENTS[limb])
        if part == "both":
            lengths[upper], lengths[lower] = true[upper], true[lower]
            continue
        scale = ((true[upper] + true[lower]) / (chosen[upper] + chosen[lower]) if part == "sum"
                 else (chosen[upper] + chosen[lower]) / (true[upper] + true[lower]))
        source = chosen if part == "sum" else true
        lengths[upper], lengths[lower] = scale * source[upper], scale * source[lower]
    return lengths


def exact_targets(inputs: ConditionInputs) -> ConditionInputs:
    """The condition with its targets replaced by the noise-free mocap keypoints (a folder beside
    its own, the silhouettes and calibration linked)."""
    folder = inputs.folder.parent / f"{inputs.folder.name}_exact_targets"
    folder.mkdir(exist_ok=True)
    for name in ("masks", "calibration.toml", "static.trc"):
        if not (folder / name).exists():
            (folder / name).symlink_to((inputs.folder / name).resolve())
    targets = read_trc(inputs.targets())
    truth = inputs.truth[:, [inputs.truth_names.index(name) for name in targets.marker_names]]
    write_trc(folder / "targets.trc", dataclasses.replace(targets, positions=truth / METRES_PER_UNIT[targets.units]))
    return dataclasses.replace(inputs, folder=folder)


def chosen_static(inputs: ConditionInputs, views: int) -> Path:
    path = inputs.folder / f"static_images{views}v_clean_{TARGET_FILTER}.trc"
    if not path.is_file():
        estimate = pik_estimate(inputs, inputs.folder, TARGET_FILTER)
        path, _ = image_static(inputs, estimate, views, "clean", tracking_settings(variant(f"ibik{views}v"), "clean"),
                               target_filter=TARGET_FILTER)
    return path


def condition_row(inputs: ConditionInputs, views: int, variants: tuple[str, ...] = VARIANTS) -> dict:
    """`variants`' elbows and knees [mm] on one condition (as run always), and the chosen lengths'
    errors [mm]."""
    static = chosen_static(inputs, views)
    chosen_file = read_trc(static).in_metres()
    chosen = segment_lengths_from_keypoints(chosen_file.marker_names, chosen_file.positions)
    true = segment_lengths_from_keypoints(inputs.truth_names, inputs.truth)
    base = static_lengths(inputs)
    statics = {"as_run": static, "exact_targets": static}
    for name, (limb, part) in TRUE_PARTS.items():
        statics[name] = write_static(inputs, base, with_true_parts(chosen, true, limb, part), f"sources_{name}")
    statics["all_exact"] = write_static(inputs, base, with_true_parts(with_true_parts(chosen, true, "leg", "both"),
                                                                      true, "arm", "both"), "sources_all_exact")
    exact = exact_targets(inputs)
    row = {"index": inputs.condition.index, "motion": inputs.condition.motion,
           "target_noise_mm": inputs.condition.target_noise_mm,
           "length_errors_mm": {name: 1e3 * (chosen[name] - true[name]) for name in sorted(chosen)
                                if any(s in name for s in ("thigh", "shank", "arm"))}}
    for name in dict.fromkeys(("as_run", *variants)):
        run_inputs = exact if name in ("exact_targets", "all_exact") else inputs
        result = run_condition_variant(run_inputs, f"ibik{views}v", "clean", None, statics[name], TARGET_FILTER)
        row[name] = {group: value for group, value in result.groups_mm().items() if group in GROUPS}
    return row


def summarize(rows: list[dict]) -> dict:
    """Per variant the rows have and group: median and 90th percentile over conditions [mm], and
    the paired changes against as run (median, better and worse by more than 1 mm)."""
    summary: dict[str, dict] = {}
    for name in (name for name in VARIANTS if name in rows[0]):
        summary[name] = {}
        for group in GROUPS:
            values = np.array([row[name][group] for row in rows])
            change = values - np.array([row["as_run"][group] for row in rows])
            summary[name][group] = {"median": float(np.median(values)), "p90": float(np.percentile(values, 90)),
                                    "change_median": float(np.median(change)),
                                    "better": int(np.sum(change < -1.0)), "worse": int(np.sum(change > 1.0))}
    return summary


def markdown(summary: dict, header: str) -> str:
    lines = [header, "", "| variant | elbows | change | better / worse | knees | change | better / worse |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, groups in summary.items():
        cells = []
        for group in GROUPS:
            g = groups[group]
            cells += [f"{g['median']:.1f} / {g['p90']:.1f}", f"{g['change_median']:+.1f}",
                      f"{g['better']} / {g['worse']}"]
        lines.append(f"| {name.replace('_', ' ')} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_kept_arguments(parser, DEFAULT_DATA)
    parser.add_argument("--variants", default=",".join(VARIANTS),
                        help="comma-separated, of: " + ", ".join(VARIANTS) + " (as_run always runs)")
    parser.add_argument("--out", type=Path, default=None, help="where error_sources.json and .md go")
    arguments = parser.parse_args(argv)
    variants = tuple(name.strip() for name in arguments.variants.split(","))
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        parser.error(f"--variants: unknown {unknown}; known: {', '.join(VARIANTS)}")
    started = time.perf_counter()
    rows = []
    for inputs in kept_conditions(arguments):
        row = condition_row(inputs, arguments.views, variants)
        rows.append(row)
        condition = inputs.condition
        print(f"{condition.index:3d} {condition.motion[:14]:14s} " + "  ".join(
            f"{name[:12]} {row[name]['elbows']:5.1f}/{row[name]['knees']:5.1f}" for name in VARIANTS if name in row),
            flush=True)
    summary = summarize(rows)
    command = " ".join(argv or sys.argv[1:])
    header = (f"# Where the error comes from (`python experiments/error_sources.py {command}`)\n\n"
              f"{len(rows)} sweep conditions (seed {arguments.seed}), IBIK {arguments.views} views, clean silhouettes. "
              "Each cell: median / 90th percentile over conditions [mm]; change: the median of the paired change "
              "against as run; better / worse: conditions changed by more than 1 mm. "
              f"Wall time {time.perf_counter() - started:.0f} s.")
    text = markdown(summary, header)
    print(text)
    result = {"command": " ".join(sys.argv), "summary": summary, "rows": rows}
    if arguments.out:
        arguments.out.mkdir(parents=True, exist_ok=True)
        (arguments.out / "error_sources.json").write_text(json.dumps(result, indent=1) + "\n")
        (arguments.out / "error_sources.md").write_text(text)
    return result


if __name__ == "__main__":
    main()
