"""The paper's Section 4 on real motion: Tables 1 and 2, per-frame errors, overlays.

Jaume-i-Capó et al. 2010 compare IK, PIK and IBIK on HumanEva S1 (box: elbow, walking: knee).
Here the motion is real motion capture from ../shared/data (CMU walking, CMU BVH walking, the
boxing BVH), posed on the project's scaled human (the truth), with silhouettes rendered into
HumanEva-like cameras (640 x 480, 4 m, around the subject), clean and with realistic defects
(plus 5 mm target noise; IBIK then votes each mask pixel over 3 frames, as `ibik track
--mask-filter 1`). Methods: IK, PIK, IBIK with 1, 2 and 4 views under the Liegeois,
priority-stack and QP schemes. Errors: eq. (9), mean distance to the true joint [mm].

Writes into --out: tables.md and results.json (Table 1: arm/boxing elbow, leg/walking knee;
Table 2: whole body, per joint), frame_errors_{walking,boxing}.png (as Figs. 12-13) and
overlay_{walking,boxing}.png (as Figs. 10-11 and 14-15).

Usage: python experiments/paper_tables.py --out out/paper [--data ../shared/data] [--quick]
"""

from __future__ import annotations

import os

# One OpenBLAS thread for the solvers' tiny factorisations, set before numpy is imported: see
# ibik_pin/cli.py (the library itself leaves the environment alone). A user's setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import time
import warnings
from pathlib import Path

import cv2
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from paper.section4 import (
    CHAINS,
    DEFECT_MASK_FILTER_RADIUS,
    DEFECT_TARGET_NOISE_MM,
    DEFECTS,
    Chain,
    Clip,
    load_motion,
    prepare_clip,
    render_views,
    run_chain,
    run_full_body,
    subset_views,
    temporally_filtered,
)

from ibik_pin.exceptions import IbikWarning

# (name, file, source, frames at the file's rate, step) - windows of real motion.
WALKING = [
    ("cmu35_01", "cmu/35_01.amc", "asf", slice(0, 300), 2),
    ("cmu35_02", "cmu/35_02.amc", "asf", slice(0, 300), 2),
    ("cmu39_01", "cmu/39_01.amc", "asf", slice(0, 300), 2),
    ("cmu131_01", "bvh/131_01.bvh", "cmu_bvh", slice(300, 600), 2),
]
BOXING = [
    ("boxing_a", "bvh/Boxing_Toes.bvh", "boxing", slice(300, 600), 2),
    ("boxing_b", "bvh/Boxing_Toes.bvh", "boxing", slice(900, 1200), 2),
    ("boxing_c", "bvh/Boxing_Toes.bvh", "boxing", slice(1500, 1800), 2),
]
ASF = {"cmu/35_01.amc": "cmu/35.asf", "cmu/35_02.amc": "cmu/35.asf", "cmu/39_01.amc": "cmu/39.asf"}
METHODS = [("IK", "ik", None, 0), ("PIK", "pik", None, 0)] + [
    (f"IBIK {views}v {scheme}", "ibik", scheme, views)
    for views in (1, 2, 4) for scheme in ("liegeois", "stack", "qp")
]
CONDITIONS = {"clean": (None, 0.0), "defects": (DEFECTS, DEFECT_TARGET_NOISE_MM)}


def load_clip(data: Path, name: str, file: str, source: str, window: slice, step: int) -> Clip:
    asf = data / ASF[file] if file in ASF else None
    motion = load_motion(data / file, source, asf)
    return prepare_clip(name, motion, source, slice(window.start, window.stop, step))


def run_methods(kind: str, clip: Clip, condition: str, methods) -> dict:
    """Every method on a clip; kind "arm", "leg" or "body"."""
    defects, noise = CONDITIONS[condition]
    rig = render_views(clip, 4, defects=defects, seed=1)
    if defects is not None:
        rig = temporally_filtered(rig, DEFECT_MASK_FILTER_RADIUS)
    results = {}
    for label, method, scheme, views in methods:
        subset = subset_views(rig, views) if views else None
        if kind == "body":
            run = run_full_body(clip, subset, method, scheme or "qp", target_noise_mm=noise, seed=2)
        else:
            run = run_chain(kind, clip, subset, method, scheme or "liegeois", target_noise_mm=noise, seed=2)
        results[label] = run
    return results, rig


def markdown_table(title: str, columns: list[str], rows: dict[str, list[float]]) -> str:
    lines = [f"**{title}**", "", "| method | " + " | ".join(columns) + " |",
             "| --- | " + " | ".join("---:" for _ in columns) + " |"]
    lines += [f"| {label} | " + " | ".join(f"{v:.1f}" for v in values) + " |" for label, values in rows.items()]
    return "\n".join(lines)


def plot_frame_errors(path: Path, clip: Clip, runs: dict, joint: str, labels: list[str]) -> None:
    fig = Figure(figsize=(7.5, 3.2))
    FigureCanvasAgg(fig)
    axes = fig.add_subplot(1, 1, 1)
    times = np.arange(len(clip.q)) / clip.frame_rate
    for label in labels:
        run = runs[label]
        axes.plot(times, run.errors[:, run.joints.index(joint)] * 1000.0, label=label, lw=1.3)
    axes.set_xlabel("time [s]")
    axes.set_ylabel(f"{joint} error [mm]")
    axes.set_title(f"{clip.name}: {joint} error per frame (eq. 9)", fontsize=10)
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def overlay(path: Path, clip: Clip, rig, runs: dict, chain: Chain, labels: dict[str, tuple[int, int, int]],
            frame: int) -> None:
    """Frame `frame` in the first two views: the mask, the truth (white) and each method's chain."""
    truth = np.stack([clip.keypoint(name)[frame] for name in (chain.root, chain.internal, chain.end)])
    panels = []
    for index, camera in enumerate(rig.cameras[:2]):
        image = np.dstack([rig.masks[frame][index].astype(np.uint8) * 90] * 3)
        for label, color in [("truth", (255, 255, 255))] + list(labels.items()):
            points = truth if label == "truth" else runs[label].positions[frame]
            pixels = camera.project(points).astype(int)
            cv2.polylines(image, [pixels.reshape(-1, 1, 2)], False, color, 2, cv2.LINE_AA)
            for pixel in pixels:
                cv2.circle(image, tuple(int(v) for v in pixel), 3, color, -1)
        cv2.putText(image, camera.name, (10, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2)
        panels.append(image)
    legend = "white: truth, " + ", ".join(f"{name}: {'green' if c == (0, 200, 0) else 'red'}"
                                         for name, c in labels.items())
    canvas = np.hstack(panels)
    cv2.putText(canvas, legend, (10, canvas.shape[0] - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 1)
    cv2.imwrite(str(path), canvas)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parent.parent.parent / "shared" / "data")
    parser.add_argument("--quick", action="store_true", help="one clip each, shorter windows")
    arguments = parser.parse_args()
    arguments.out.mkdir(parents=True, exist_ok=True)
    warnings.simplefilter("ignore", IbikWarning)  # e.g. Boxing_Toes.bvh's extra frame
    started = time.perf_counter()
    walking, boxing = WALKING, BOXING
    if arguments.quick:
        walking = [(n, f, s, slice(w.start, w.start + 120), st) for n, f, s, w, st in WALKING[:1]]
        boxing = [(n, f, s, slice(w.start, w.start + 120), st) for n, f, s, w, st in BOXING[:1]]
    results: dict = {"table1": {}, "table2": {}, "clips": {}}
    examples = {}
    for kind, clips in (("leg", walking), ("arm", boxing)):
        for spec in clips:
            clip = load_clip(arguments.data, *spec)
            results["clips"][clip.name] = {"frames": len(clip.q), "frame_rate": clip.frame_rate,
                                           "fit_residual_mm": float(np.mean(clip.fit_residual) * 1000)}
            for condition in CONDITIONS:
                runs, rig = run_methods(kind, clip, condition, METHODS)
                results["table1"].setdefault(kind, {}).setdefault(condition, {})[clip.name] = {
                    label: run.mean_error_mm for label, run in runs.items()}
                print(f"{time.perf_counter() - started:6.0f} s  {kind} {clip.name} {condition}: " + ", ".join(
                    f"{label} {runs[label].mean_error_mm:.1f}" for label in ("IK", "PIK", "IBIK 1v liegeois",
                                                                            "IBIK 2v liegeois", "IBIK 4v liegeois")),
                      flush=True)
                if condition == "clean" and kind not in examples:
                    examples[kind] = (clip, rig, runs)
    body_methods = [m for m in METHODS if m[2] in (None, "qp")]
    for spec in (walking[0], boxing[0]):
        clip = load_clip(arguments.data, *spec)
        for condition in CONDITIONS:
            runs, _ = run_methods("body", clip, condition, body_methods)
            results["table2"].setdefault(condition, {})[clip.name] = {
                label: {joint: float(np.mean(run.errors[:, j]) * 1000) for j, joint in enumerate(run.joints)}
                for label, run in runs.items()}
            print(f"{time.perf_counter() - started:6.0f} s  body {clip.name} {condition}: " + ", ".join(
                f"{label} {run.mean_error_mm:.1f}" for label, run in runs.items()), flush=True)

    sections = ["# Section 4 on real motion: mean internal-joint error [mm] (eq. 9)", "",
                f"Produced by `python experiments/paper_tables.py --out {arguments.out}"
                + (" --quick" if arguments.quick else "") + "`.", ""]
    for condition in CONDITIONS:
        columns, rows = [], {label: [] for label, *_ in METHODS}
        for kind, joint in (("arm", "elbow, boxing"), ("leg", "knee, walking")):
            per_clip = results["table1"][kind][condition]
            columns.append(f"{kind} ({joint}, {len(per_clip)} clips)")
            for label in rows:
                rows[label].append(float(np.mean([clip[label] for clip in per_clip.values()])))
        noise = f" (+{DEFECT_TARGET_NOISE_MM:.0f} mm target noise)" if condition == "defects" else ""
        sections += [markdown_table(f"Table 1 analogue, {condition} silhouettes" + noise, columns, rows), ""]
    for condition in CONDITIONS:
        for clip_name, per_method in results["table2"][condition].items():
            columns = list(next(iter(per_method.values())))
            rows = {label: list(values.values()) for label, values in per_method.items()}
            sections += [markdown_table(f"Table 2 analogue, whole body, {clip_name}, {condition}", columns, rows), ""]
    (arguments.out / "tables.md").write_text("\n".join(sections))
    (arguments.out / "results.json").write_text(json.dumps(results, indent=2))
    for kind, name, joint in (("leg", "walking", "RKnee"), ("arm", "boxing", "RElbow")):
        clip, rig, runs = examples[kind]
        plot_frame_errors(arguments.out / f"frame_errors_{name}.png", clip, runs, joint,
                          ["IK", "IBIK 1v liegeois", "IBIK 2v liegeois", "IBIK 4v liegeois"])
        frame = int(np.argmax(runs["IK"].errors[:, 0]))
        overlay(arguments.out / f"overlay_{name}.png", clip, rig, runs, CHAINS[kind],
                {"IK": (0, 0, 230), "IBIK 2v liegeois": (0, 200, 0)}, frame)
    print("\n".join(sections))
    print(f"done in {time.perf_counter() - started:.0f} s; wrote {arguments.out}")


if __name__ == "__main__":
    main()
