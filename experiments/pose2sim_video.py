"""`ibik track` on a real four-camera video: the Pose2Sim single-person demo (../shared/data).

The targets are Pose2Sim's own triangulation of the demo (ref3d TRC) with the elbows and knees
removed; the full triangulation serves as the static trial that scales the segments (the demo has
no separate one); the silhouettes come from the real videos by OpenCV background subtraction; the
cameras from the demo's calibration. IBIK (with the image) and PIK (--no-image) estimate the elbows and
knees, which are compared with Pose2Sim's triangulated ones. Those are a markerless estimate, not
ground truth: the figures are agreement, not error.

Writes into --out: input/targets.trc, one `ibik track` output folder per variant (with overlays),
and agreement.json / agreement.md.

Usage: python experiments/pose2sim_video.py --out out/pose2sim [--data ../shared/data]
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

from ibik_pin.evaluation import ESTIMATED, mean_joint_errors_mm
from ibik_pin.io.trc import TrcData, read_trc, write_trc
from ibik_pin.tracking.pipeline import TrackJob, run_track
from ibik_pin.tracking.tracker import TrackingSettings

VARIANTS = {  # name -> (use the image, cameras)
    "pik": (False, None),
    "ibik_4_views": (True, None),
    "ibik_cam03_cam04": (True, ["cam_03", "cam_04"]),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parent.parent.parent / "shared" / "data")
    arguments = parser.parse_args()
    demo = arguments.data / "pose2sim_demo"
    reference = read_trc(demo / "ref3d" / "S00_P00_T01_BalancingTrial_0-100_filt_butterworth.trc")
    frames = slice(None)  # the 100 frames of the videos
    kept = [i for i, name in enumerate(reference.marker_names) if name not in ESTIMATED]
    targets = TrcData(marker_names=[reference.marker_names[i] for i in kept], times=reference.times[frames],
                      positions=reference.positions[frames][:, kept], units=reference.units,
                      data_rate=reference.data_rate, frame_numbers=reference.frame_numbers[frames])
    (arguments.out / "input").mkdir(parents=True, exist_ok=True)
    write_trc(arguments.out / "input" / "targets.trc", targets)
    rows = {}
    for variant, (use_image, cameras) in VARIANTS.items():
        started = time.perf_counter()
        report = run_track(TrackJob(
            targets=arguments.out / "input" / "targets.trc", calibration=demo / "Calib_qualisys_converted.toml",
            static=demo / "ref3d" / "S00_P00_T01_BalancingTrial_0-100_filt_butterworth.trc",
            videos=demo / "videos", cameras=cameras, out=arguments.out / variant, overlay=True,
            settings=TrackingSettings(use_image=use_image),
        ))
        estimate = read_trc(arguments.out / variant / "joints.trc")
        truth_positions = reference.positions[frames][:, [reference.marker_names.index(n) for n in ESTIMATED]]
        estimate_positions = estimate.positions[:, [estimate.marker_names.index(n) for n in ESTIMATED]]
        agreement = mean_joint_errors_mm(estimate_positions, truth_positions, ESTIMATED)
        rows[variant] = {"agreement_mm": agreement, "mean_mm": float(np.mean(list(agreement.values()))),
                         "solve_frames_per_second": report["solve_frames_per_second"],
                         "end_effector_residual_mm": 1000 * report["end_effector_residual_m"]["mean"],
                         "wall_seconds": time.perf_counter() - started}
        print(variant, json.dumps(rows[variant]), flush=True)
    lines = ["| variant | " + " | ".join(ESTIMATED) + " | mean | solve fps |", "| --- |" + " ---: |" * 6]
    lines += [f"| {name} | " + " | ".join(f"{row['agreement_mm'][j]:.1f}" for j in ESTIMATED)
              + f" | {row['mean_mm']:.1f} | {row['solve_frames_per_second']:.1f} |" for name, row in rows.items()]
    (arguments.out / "agreement.md").write_text("\n".join(lines) + "\n")
    (arguments.out / "agreement.json").write_text(json.dumps(rows, indent=2))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
