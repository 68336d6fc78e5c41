"""The evidence figures of `ibik track`'s self-diagnosis (app.diagnosis, app.input_checks), measured on
good inputs and on broken ones, so that each threshold sits with a margin between them.

1. Whole-frame jumps (input_checks.frame_jumps): the departure of each frame's targets from where the
   frames on either side put them, on every real recording of the shared data folder (CMU walking,
   hops, jumps, kneeling, turns; the boxing BVH; Pose2Sim's markerless triangulation of its demo),
   at 60, 30, 15 and 10 Hz, with 10 mm of Gaussian target noise (the sweep's largest); and the
   same with one frame shifted by 0.5 m.
2. Views (diagnosis.view_evidence): the share of the projected targets inside each view's
   silhouette over sampled frames, on the sweep's 42 conditions (experiments/sweep.py --keep: clean
   silhouettes and Section 4's defects, 4 views), and on the same conditions broken: cam1's and
   cam2's masks swapped, cam1's masks mirrored or of another moment, cam1's focal length 1e-300 or
   its rotation vector 1e12 or its focal length 2x, cam1 moved 0.5 m, the TRC's axes forced wrong
   (z-up on Y-up data); and the share of the image each silhouette covers.
3. The shifted frame (--timing): the demo (120 frames, 4 views) as it is and with frame 11's targets
   shifted by 1e6, 1e200 and 0.5 m, alternated 3 times: time ratios and joint differences.
4. Pose2Sim's real video (--pose2sim): tracked with background subtraction and MediaPipe's
   silhouettes; the diagnosis and warnings of these good runs.

Usage (the sweep's conditions kept by `python experiments/sweep.py --keep /tmp/sweep_inputs`):
    python experiments/diagnosis_thresholds.py --sweep-inputs /tmp/sweep_inputs --timing out/diag_timing \
        --pose2sim out/diag_pose2sim --out experiments/results
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
from realdata.clips import keypoints_and_joints, load_motion, resample
from realdata.runner import DEFAULT_DATA
from sweepkit.motions import MOTIONS

from ibik_pin.app.axes import TRC_TO_MODEL
from ibik_pin.app.diagnosis import VIEW_FLOOR, VIEW_RATIO, view_evidence
from ibik_pin.app.input_checks import JUMP_DISTANCE_M, frame_jumps
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.masks import list_mask_files, read_mask
from ibik_pin.io.trc import read_trc
from ibik_pin.vision.camera import cameras_in_frame

RATES_HZ = (60.0, 30.0, 15.0, 10.0)
NOISE_M = 0.010


def _recordings(data: Path) -> dict[str, np.ndarray]:
    """Every recording of the shared data folder once: name -> (motion, source)."""
    seen: dict[str, tuple] = {}
    for spec in MOTIONS.values():
        if spec.file not in seen:
            seen[spec.file] = (load_motion(data / spec.file, spec.source, data / spec.asf if spec.asf else None),
                               spec.source)
    return seen


def jump_figures(data: Path, seed: int = 0) -> dict:
    """Departures [m] of every frame of every recording at each rate, clean and with one frame shifted."""
    rng = np.random.default_rng(seed)
    rows = []
    for file, (motion, source) in _recordings(data).items():
        duration = (motion.positions.shape[0] - 1) / motion.frame_rate
        for rate in RATES_HZ:
            count = int(np.floor(duration * rate)) + 1
            window = resample(motion, 0.0, count, rate)
            _, keypoints, _ = keypoints_and_joints(window, source)
            keypoints = keypoints + rng.normal(0.0, NOISE_M, keypoints.shape)
            rows.append(_jump_row(file, rate, keypoints, np.arange(count) / rate, rng))
    reference = data / "pose2sim_demo" / "ref3d" / "S00_P00_T01_BalancingTrial_0-100.trc"
    if reference.is_file():
        trc = read_trc(reference).in_metres()
        times = np.asarray(trc.times, dtype=float)
        rate = 1.0 / float(np.median(np.diff(times)))
        for step in (1, 2, 4, 6):
            rows.append(_jump_row(f"pose2sim ref3d (unfiltered triangulation) every {step}", rate / step,
                                  trc.positions[::step], times[::step], rng))
    departures = [row["clean_max_departure_m"] for row in rows]
    shifted = [row["shifted_departure_m"] for row in rows]
    return {"threshold_m": JUMP_DISTANCE_M, "noise_m": NOISE_M, "rows": rows,
            "clean_max_departure_m": float(np.max(departures)),
            "clean_frames_dropped": int(sum(row["clean_dropped"] for row in rows)),
            "clean_frames": int(sum(row["frames"] for row in rows)),
            "shifted_min_departure_m": float(np.min(shifted)),
            "shifted_caught": int(sum(row["shifted_caught"] for row in rows)), "shifted_runs": len(rows)}


def _jump_row(name: str, rate: float, keypoints: np.ndarray, times: np.ndarray, rng) -> dict:
    clean = frame_jumps(keypoints, times)
    shifted = keypoints.copy()
    frame = int(rng.integers(1, len(keypoints) - 1))
    direction = rng.normal(size=3)
    shifted[frame] = keypoints[frame] + 0.5 * direction / np.linalg.norm(direction)
    found = frame_jumps(shifted, times)
    return {"recording": name, "rate_hz": rate, "frames": len(keypoints),
            "clean_max_departure_m": float(np.nanmax(clean.departure_m)),
            "clean_p99_departure_m": float(np.nanpercentile(clean.departure_m, 99)),
            "clean_dropped": int(clean.dropped.sum()), "clean_steps": int(clean.steps.sum()),
            "shifted_frame": frame, "shifted_departure_m": float(found.departure_m[frame]),
            "shifted_caught": bool(found.dropped[frame] and found.dropped.sum() == 1),
            "shifted_dropped": [int(f) for f in np.flatnonzero(found.dropped)]}


def _turned(camera, rotation_vector: np.ndarray):
    """The camera turned by a rotation vector (Rodrigues) about its own centre."""
    import cv2
    turn, _ = cv2.Rodrigues(np.asarray(rotation_vector, dtype=float).reshape(3, 1))
    return dataclasses.replace(camera, rotation=turn @ camera.rotation, translation=turn @ camera.translation)


BREAKS = ("swapped cam1/cam2 masks", "cam1 masks mirrored", "cam1 masks of another moment",
          "cam1 focal 1e-300", "cam1 rotation vector 1e12", "cam1 focal x2", "cam1 moved 0.5 m",
          "axes forced z-up")


def _view_row(folder: Path, silhouettes: str, broken: str | None) -> dict:
    cameras = cameras_in_frame(read_calibration(folder / "calibration.toml"), POSE2SIM_TRC_TO_WORLD)
    targets = read_trc(folder / "targets.trc").in_metres().positions
    files = [list_mask_files(folder / "masks" / silhouettes / camera.name) for camera in cameras]
    order = [list(range(len(files[0]))) for _ in cameras]
    sources = list(range(len(cameras)))
    mirror = False
    if broken == "swapped cam1/cam2 masks":
        sources[0], sources[1] = 1, 0
    elif broken == "cam1 masks mirrored":
        mirror = True
    elif broken == "cam1 masks of another moment":
        order[0] = list(np.roll(order[0], len(order[0]) // 2))
    elif broken == "cam1 focal 1e-300":
        intrinsics = cameras[0].intrinsics.copy()
        intrinsics[0, 0] = intrinsics[1, 1] = 1e-300
        cameras[0] = dataclasses.replace(cameras[0], intrinsics=intrinsics)
    elif broken == "cam1 rotation vector 1e12":
        cameras[0] = _turned(cameras[0], np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81]) * 1e12)
    elif broken == "cam1 focal x2":
        intrinsics = cameras[0].intrinsics.copy()
        intrinsics[:2, :2] *= 2.0
        cameras[0] = dataclasses.replace(cameras[0], intrinsics=intrinsics)
    elif broken == "cam1 moved 0.5 m":
        cameras[0] = dataclasses.replace(cameras[0], translation=cameras[0].translation + np.array([0.5, 0.0, 0.0]))
    elif broken == "axes forced z-up":
        targets = targets @ TRC_TO_MODEL["z-up"].T

    def masks(frame: int) -> list[np.ndarray]:
        listed = []
        for index, camera in enumerate(cameras):
            source = sources[index]
            mask = read_mask(files[source][order[index][frame]], tuple(cameras[source].size))
            if mask.shape != (camera.size[1], camera.size[0]):
                mask = np.zeros((camera.size[1], camera.size[0]), dtype=bool)  # never the case in one rig
            listed.append(mask[:, ::-1] if mirror and index == 0 else mask)
        return listed

    evidence = view_evidence(cameras, masks, targets)
    return {"condition": folder.name, "silhouettes": silhouettes, "broken": broken or "none",
            "median_share": evidence.median_share(), "median_foreground": evidence.median_foreground()}


def view_figures(sweep_inputs: Path) -> dict:
    """The views' evidence on every kept sweep condition, clean, with defects and broken."""
    rows = []
    for folder in sorted(sweep_inputs.glob("condition_*")):
        for silhouettes in ("clean", "defects"):
            rows.append(_view_row(folder, silhouettes, None))
        for broken in BREAKS:
            rows.append(_view_row(folder, "defects", broken))
    good = [share for row in rows if row["broken"] == "none" for share in row["median_share"].values()
            if share is not None]
    ratios = [_ratio(row) for row in rows if row["broken"] == "none"]
    verdicts: dict[str, dict[str, int]] = {}
    for row in rows:
        key = f"{row['broken']} ({row['silhouettes']})"
        counts = verdicts.setdefault(key, {"refused": 0, "warned": 0, "missed": 0})
        counts[_verdict(row)] += 1
    return {"view_floor": VIEW_FLOOR, "view_ratio": VIEW_RATIO, "good_views": len(good),
            "good_min_share": float(np.min(good)), "good_min_ratio_to_best": float(np.min(ratios)),
            "good_max_foreground": float(max(share for row in rows if row["broken"] == "none"
                                             for share in row["median_foreground"].values())),
            "verdicts": verdicts, "rows": rows}


def _ratio(row: dict) -> float:
    shares = [share for share in row["median_share"].values() if share is not None]
    return min(shares) / max(shares)


def _verdict(row: dict) -> str:
    """What app.diagnosis.check_views does with the row's shares: refused, warned (a view the break
    touched is suspect; with the axes every view is) or missed."""
    shares = {name: share for name, share in row["median_share"].items() if share is not None}
    best = max(shares.values())
    if best < VIEW_FLOOR:
        return "refused"
    touched = {"none": (), "swapped cam1/cam2 masks": ("cam1", "cam2")}.get(row["broken"], ("cam1",))
    if row["broken"] == "axes forced z-up":
        touched = tuple(shares)
    suspect = [name for name in touched if shares.get(name, 1.0) < max(VIEW_FLOOR, VIEW_RATIO * best)]
    if row["broken"] == "none":  # a false alarm counts as "warned" on a good row
        suspect = [name for name, share in shares.items() if share < max(VIEW_FLOOR, VIEW_RATIO * best)]
    return "warned" if suspect else "missed"


def pose2sim_figures(data: Path, out: Path) -> dict:
    """`ibik track` on the real 4-camera Pose2Sim video, Pose2Sim's targets without the elbows and knees,
    silhouettes by background subtraction (mog2) and by MediaPipe: good runs, whose diagnosis and
    warnings are recorded."""
    import warnings

    from ibik_pin.app.job import TrackJob
    from ibik_pin.app.track import run_track
    from ibik_pin.evaluation import ESTIMATED
    from ibik_pin.io.trc import TrcData, write_trc

    demo = data / "pose2sim_demo"
    reference_path = demo / "ref3d" / "S00_P00_T01_BalancingTrial_0-100_filt_butterworth.trc"
    reference = read_trc(reference_path)
    kept = [i for i, name in enumerate(reference.marker_names) if name not in ESTIMATED]
    out.mkdir(parents=True, exist_ok=True)
    write_trc(out / "targets.trc", TrcData(marker_names=[reference.marker_names[i] for i in kept],
                                           times=reference.times, positions=reference.positions[:, kept],
                                           units=reference.units, data_rate=reference.data_rate,
                                           frame_numbers=reference.frame_numbers))
    rows = {}
    for segmenter in ("mog2", "mediapipe"):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            report = run_track(TrackJob(targets=out / "targets.trc", static=reference_path,
                                        calibration=demo / "Calib_qualisys_converted.toml", videos=demo / "videos",
                                        out=out / segmenter, quiet=True, segmenter=segmenter))
        rows[segmenter] = {"diagnosis": report.diagnosis,
                           "warnings": [str(warning.message) for warning in caught
                                        if any(module in str(warning.filename)
                                               for module in ("diagnosis", "input_checks"))]}
    return rows


def shifted_frame_figures(folder: Path, repeats: int = 3) -> dict:
    """The demo (120 frames, 4 views, default settings) tracked as it is and with frame 11's targets
    all shifted by 1e6 m, 1e200 m and 0.5 m, alternately `repeats` times: wall-time ratios within one
    run of this script (the machine's speed drifts), and how far each shifted run's joints lie from
    the unshifted run's, frame 11 apart."""
    import time
    import warnings

    from ibik_pin.app.demo import prepare_demo_inputs
    from ibik_pin.app.job import TrackJob
    from ibik_pin.app.track import run_track
    from ibik_pin.exceptions import IbikWarning
    from ibik_pin.io.trc import write_trc

    paths = prepare_demo_inputs(folder / "input")
    targets = read_trc(paths.targets)
    variants = {"unshifted": paths.targets}
    for name, shift in (("1e6 m", 1e6), ("1e200 m", 1e200), ("0.5 m", 0.5)):
        shifted = dataclasses.replace(targets, positions=np.array(targets.positions, dtype=float))
        shifted.positions[10] += shift
        variants[name] = folder / "input" / f"targets_{name.replace(' ', '_')}.trc"
        write_trc(variants[name], shifted)
    seconds: dict[str, list[float]] = {name: [] for name in variants}
    joints: dict[str, np.ndarray] = {}
    for _ in range(repeats):
        for name, path in variants.items():
            out = folder / name.replace(" ", "_")
            started = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", IbikWarning)
                run_track(TrackJob(targets=path, static=paths.folder / "static.trc", calibration=paths.calibration,
                                   masks=paths.masks, out=out, quiet=True))
            seconds[name].append(time.perf_counter() - started)
            joints[name] = read_trc(out / "joints.trc").in_metres().positions
    others = np.ones(len(targets.positions), dtype=bool)
    others[10] = False
    return {"frames": len(targets.positions), "repeats": repeats, "seconds": seconds,
            "time_ratio_to_unshifted": {name: float(np.median(values) / np.median(seconds["unshifted"]))
                                        for name, values in seconds.items()},
            "largest_joint_difference_m_other_frames": {
                name: float(np.nanmax(np.linalg.norm(values[others] - joints["unshifted"][others], axis=2)))
                for name, values in joints.items()},
            "frame_11_joint_difference_m": {
                name: float(np.nanmax(np.linalg.norm(values[10] - joints["unshifted"][10], axis=1)))
                for name, values in joints.items()}}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--sweep-inputs", type=Path, default=None, help="the sweep's kept condition folders")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--timing", type=Path, default=None, metavar="FOLDER",
                        help="also time the demo with one frame shifted against the unshifted one, in FOLDER")
    parser.add_argument("--pose2sim", type=Path, default=None, metavar="FOLDER",
                        help="also track the real Pose2Sim video into FOLDER (mog2 and MediaPipe silhouettes)")
    arguments = parser.parse_args(argv)
    figures = {"jumps": jump_figures(arguments.data)}
    if arguments.timing is not None:
        figures["shifted_frame"] = shifted_frame_figures(arguments.timing)
        print(json.dumps(figures["shifted_frame"], indent=1), file=sys.stderr)
    if arguments.pose2sim is not None:
        figures["pose2sim"] = pose2sim_figures(arguments.data, arguments.pose2sim)
        for segmenter, row in figures["pose2sim"].items():
            print(segmenter, row["diagnosis"]["targets_inside_sampled"], row["diagnosis"]["skeleton_inside_median"],
                  row["diagnosis"]["findings"], row["warnings"], file=sys.stderr)
    if arguments.sweep_inputs is not None:
        figures["views"] = view_figures(arguments.sweep_inputs)
        print(json.dumps({k: v for k, v in figures["views"].items() if k != "rows"}, indent=1), file=sys.stderr)
    text = json.dumps(figures, indent=1)
    if arguments.out is not None:
        arguments.out.mkdir(parents=True, exist_ok=True)
        (arguments.out / "diagnosis_thresholds.json").write_text(text + "\n")
    summary = {k: v for k, v in figures["jumps"].items() if k != "rows"}
    print(json.dumps(summary, indent=1), file=sys.stderr)
    for row in figures["jumps"]["rows"]:
        print(f"{row['recording'][:40]:40s} {row['rate_hz']:6.1f} Hz {row['frames']:6d} fr  "
              f"max {row['clean_max_departure_m']:.3f}"
              f" p99 {row['clean_p99_departure_m']:.3f} dropped {row['clean_dropped']} steps {row['clean_steps']}"
              f"  shifted {row['shifted_departure_m']:.3f} caught {row['shifted_caught']}")
    return figures


if __name__ == "__main__":
    main()
