"""How much a sub-millimetre change of the targets moves the real-mocap benchmark's judged joints.

The target filter (ibik track --target-filter auto) moves the noise-free mocap targets by about
0.5 mm rms (their own marker jitter): is a change of the judged joints of that run within what any
such change gives? Here the clip's targets get seeded Gaussian noise of a few tenths of a
millimetre, the filter off, and each run's judged joints are compared with the unperturbed run's.

Usage:
    python experiments/target_filter_sensitivity.py --clip cmu35_01 --sigma-mm 0.3 --seeds 4
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
from realdata.clips import CLIPS
from realdata.inputs import prepare_inputs
from realdata.runner import DEFAULT_DATA, REPOSITORY, run_variant, variant

from ibik_pin.io.trc import read_trc, write_trc


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clip", default="cmu35_01", choices=sorted(CLIPS))
    parser.add_argument("--condition", default="clean")
    parser.add_argument("--variant", default="ibik2v")
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--sigma-mm", type=float, default=0.3, help="noise per coordinate [mm]")
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--cache", type=Path, default=REPOSITORY / "out" / "real_mocap_cache")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "out" / "target_filter_sensitivity.json")
    arguments = parser.parse_args()
    inputs = prepare_inputs(CLIPS[arguments.clip], DEFAULT_DATA, arguments.frames, arguments.cache)
    chosen = variant(arguments.variant)
    baseline = run_variant(inputs, chosen, arguments.condition)
    rows = [{"seed": None, "judged_mm": baseline.judged_mm, "joints_mm": baseline.joint_errors_mm}]
    print(f"unperturbed: judged {baseline.judged_mm:.2f} mm {baseline.joint_errors_mm}", flush=True)
    scratch = Path(tempfile.mkdtemp(prefix="sensitivity_"))
    try:
        folder = scratch / "clip"
        shutil.copytree(inputs.folder, folder)
        perturbed_inputs = dataclasses.replace(inputs, folder=folder)
        targets = read_trc(inputs.targets(arguments.condition))
        scale = {"m": 1e-3, "mm": 1.0, "cm": 0.1}[targets.units]
        for seed in range(arguments.seeds):
            noisy = dataclasses.replace(targets, positions=targets.positions + np.random.default_rng(seed).normal(
                0.0, arguments.sigma_mm * scale, targets.positions.shape))
            write_trc(perturbed_inputs.targets(arguments.condition), noisy)
            result = run_variant(perturbed_inputs, chosen, arguments.condition)
            rows.append({"seed": seed, "judged_mm": result.judged_mm, "joints_mm": result.joint_errors_mm})
            print(f"seed {seed}: judged {result.judged_mm:.2f} mm ({result.judged_mm - baseline.judged_mm:+.2f}) "
                  f"{result.joint_errors_mm}", flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    changes = [row["judged_mm"] - baseline.judged_mm for row in rows[1:]]
    summary = {"clip": arguments.clip, "condition": arguments.condition, "variant": arguments.variant,
               "sigma_mm": arguments.sigma_mm, "rows": rows, "judged_change_mm": changes,
               "largest_abs_change_mm": float(np.max(np.abs(changes)))}
    arguments.out.parent.mkdir(parents=True, exist_ok=True)
    arguments.out.write_text(json.dumps(summary, indent=1) + "\n")
    print(f"judged joints' change over {arguments.seeds} seeds: {', '.join(f'{c:+.2f}' for c in changes)} mm")


if __name__ == "__main__":
    main()
