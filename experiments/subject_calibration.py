"""Subject calibration on real data: the static fit's residual per keypoint, before and after placement.

"Before" is lengths-only scaling (scale_human with every length measured on the static frames, the
poses fitted); "after" is ibik_pin.subject.calibration (segment scales, shoulder height and a
placement of every keypoint, fitted with the poses). Data (../shared/data):

* CMU subject 35, walking 35_02 (ASF/AMC, mocap skeleton joints as Pose2Sim keypoints): its first
  frame alone, and 10 frames spread over the walk.
* Pose2Sim's demo, its own triangulation (ref3d, Butterworth-filtered) of a person balancing on a
  treadmill: frame 1 alone, and frames 1, 4, 7, 10 (standing, before the turn). A markerless
  triangulation: its segment lengths vary by 2-5 cm from frame to frame, which no rigid model fits.

Writes subject_calibration.md and subject_calibration.json into --out.

Usage:
    python experiments/subject_calibration.py --out out/subject_calibration
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny matrices: threads only add overhead

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ibik_pin.human import load_human
from ibik_pin.io.asf_amc import read_asf_amc
from ibik_pin.io.trc import read_trc
from ibik_pin.subject.calibration import calibrate_subject
from ibik_pin.synthetic.mocap import keypoints_from_motion

REPOSITORY = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPOSITORY.parent / "shared" / "data"
POSE2SIM_TRC = "pose2sim_demo/ref3d/S00_P00_T01_BalancingTrial_0-100_filt_butterworth.trc"


def cases(data: Path) -> list[tuple[str, list[str], np.ndarray, list[int]]]:
    """(label, names, positions (F, K, 3) [m], frame indices) of every measured static trial."""
    motion = read_asf_amc(data / "cmu" / "35.asf", data / "cmu" / "35_02.amc")
    cmu_names, cmu_positions = keypoints_from_motion(motion, "asf")
    trc = read_trc(data / POSE2SIM_TRC).in_metres()
    return [
        ("CMU 35_02, frame 1", cmu_names, cmu_positions, [0]),
        ("CMU 35_02, 10 frames over the walk", cmu_names, cmu_positions, list(range(0, 400, 40))),
        ("Pose2Sim demo triangulation, frame 1", trc.marker_names, trc.positions, [0]),
        ("Pose2Sim demo triangulation, frames 1, 4, 7, 10", trc.marker_names, trc.positions, [0, 3, 6, 9]),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPOSITORY / "out" / "subject_calibration")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the shared data folder")
    arguments = parser.parse_args()
    arguments.out.mkdir(parents=True, exist_ok=True)
    lines = ["# Subject calibration on real data (`python experiments/subject_calibration.py`)", "",
             "Static fit residual per keypoint [mm], mean (max) over the static frames: lengths-only "
             "scaling (before) and with placement (after); offset = the placement's change [mm] in its "
             "parent joint's frame (x forward, y up, z right).", ""]
    figures = {}
    for label, names, positions, frames in cases(arguments.data):
        start = time.perf_counter()
        result = calibrate_subject(load_human(), names, positions, frames=frames, source=label)
        seconds = time.perf_counter() - start
        figures[label] = {**result.to_json(), "seconds": round(seconds, 2)}
        lines += [f"## {label} ({seconds:.1f} s)", "", "| keypoint | before | after | offset |",
                  "| --- | ---: | ---: | --- |"]
        for k, name in enumerate(result.keypoint_names):
            before, after = 1000 * result.residual_before[k], 1000 * result.residual_after[k]
            offset = ", ".join(f"{1000 * value:+.0f}" for value in result.offsets[k])
            lines.append(f"| {name} | {before[0]:.1f} ({before[1]:.1f}) | {after[0]:.1f} ({after[1]:.1f}) | {offset} |")
        lines.append(f"| **mean** | {1000 * result.residual_before[:, 0].mean():.1f} | "
                     f"{1000 * result.residual_after[:, 0].mean():.1f} | |")
        scales = ", ".join(f"{name} {value:.3f}" for name, value in result.segment_scales.items())
        shifts = ", ".join(f"{name} {1000 * value:+.0f} mm" for name, value in result.joint_shifts.items())
        lines += ["", f"Segment scales against the default human: {scales}; {shifts}.", ""]
    (arguments.out / "subject_calibration.md").write_text("\n".join(lines))
    (arguments.out / "subject_calibration.json").write_text(json.dumps(figures, indent=2) + "\n")
    print(f"wrote {arguments.out / 'subject_calibration.md'}")


if __name__ == "__main__":
    main()
