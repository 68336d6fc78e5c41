"""`ibik demo`: `ibik track` end to end on real walking bundled with the package.

The motion is 2 s of CMU subject 35 walking (ibik_pin/data, see its README). The project's human
model is scaled to the subject and posed to the motion; its silhouettes are rendered by the
project's renderer into 4 HumanEva-like calibrated cameras; the result is written as the files a
user brings (Pose2Sim calibration TOML, TRC of the end effectors, mask folders, and a static trial).
Then `ibik track` runs on them twice, with the image criterion (IBIK) and without (PIK), and the
elbow and knee errors of both are compared with the truth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import run_track
from ibik_pin.evaluation import ESTIMATED, mean_joint_errors_mm
from ibik_pin.human import load_human
from ibik_pin.io.asf_amc import read_asf_amc
from ibik_pin.io.files import strict_json, write_text_atomically
from ibik_pin.io.trc import TrcData, read_trc, write_trc
from ibik_pin.subject.scaling import scale_human, segment_lengths_from_keypoints
from ibik_pin.synthetic.dataset import write_dataset
from ibik_pin.synthetic.mocap import keypoints_from_motion, pose_model_to_keypoints
from ibik_pin.synthetic.rig import humaneva_rig
from ibik_pin.tracking.settings import TrackingSettings

DATA = Path(__file__).resolve().parents[1] / "data"


def prepare_demo_inputs(folder: Path, views: int = 4, frame_step: int = 2, seed: int = 0):
    """Write the demo's input files into `folder`; returns the data set's paths."""
    motion = read_asf_amc(DATA / "35.asf", DATA / "35_01_first240.amc")
    motion = motion.subset(slice(0, None, frame_step))
    names, positions = keypoints_from_motion(motion, "asf")
    body = scale_human(load_human(), segment_lengths_from_keypoints(names, positions))
    q, _ = pose_model_to_keypoints(body, names, positions)
    center = np.nanmean(positions[:, names.index("Hip")], axis=0)
    cameras = humaneva_rig(views, center, seed=seed)
    targets = [name for name in names if name not in ESTIMATED]
    paths = write_dataset(folder, body, q, cameras, motion.frame_rate, targets, seed=seed)
    truth = read_trc(paths.truth)
    static = TrcData(marker_names=truth.marker_names, times=truth.times[:1],
                     positions=truth.positions[:1], units=truth.units, data_rate=truth.data_rate,
                     frame_numbers=truth.frame_numbers[:1])
    write_trc(folder / "static.trc", static)
    return paths


def run_demo(out: Path, quiet: bool = False) -> dict:
    """Prepare the inputs, track with and without the image, compare; returns the comparison."""
    out = Path(out)
    paths = prepare_demo_inputs(out / "input")
    truth = read_trc(paths.truth)
    comparison = {}
    for variant, use_image in (("ibik", True), ("pik", False)):
        report = run_track(TrackJob(
            targets=paths.targets, static=paths.folder / "static.trc", calibration=paths.calibration,
            masks=paths.masks, out=out / variant, overlay=True, quiet=quiet,
            settings=TrackingSettings(use_image=use_image),
        ))
        estimate = read_trc(out / variant / "joints.trc")
        order = [estimate.marker_names.index(name) for name in truth.marker_names]
        errors = mean_joint_errors_mm(estimate.positions[:, order], truth.positions,
                                      truth.marker_names, ESTIMATED)
        comparison[variant] = {"joint_error_mm": errors, "mean_error_mm": float(np.mean(list(errors.values()))),
                               "solve_frames_per_second": report["solve_frames_per_second"]}
    write_text_atomically(out / "comparison.json", strict_json(comparison))
    if not quiet:
        print("mean error against the truth [mm] (eq. 9 of the paper):")
        print("joint     " + "".join(f"{name:>9}" for name in ESTIMATED) + "     mean")
        for variant, row in comparison.items():
            print(f"{variant.upper():<10}" + "".join(f"{row['joint_error_mm'][n]:9.1f}" for n in ESTIMATED)
                  + f"{row['mean_error_mm']:9.1f}")
        print(f"wrote {out}/ibik and {out}/pik (joints.trc, q.csv, motion.mot, model.osim, motion.bvh, report.json, "
              f"overlays, replay.html) and {out}/comparison.json")
    return comparison
