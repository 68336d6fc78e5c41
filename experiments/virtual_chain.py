"""The paper's virtual experiments (Jaume-i-Capó et al. 2010, Section 3, Figs. 6-8) on the planar chain.

For each experiment, IK (eq. 3, blind) and IBIK (the image criterion as secondary task, eq. 4, and
the same level under the priority stack and the hierarchical QP) run from the same start with the
same iterations. Writes into --out:
    fig6.png, fig7.png, fig8.png   left IK, right IBIK: the chain at several iterations over the
                                   objective's silhouette (fig8: over the object)
    metrics.json                   one record per experiment, method and scheme

Usage: python experiments/virtual_chain.py --out out/virtual_chain
"""

from __future__ import annotations

import os

# One OpenBLAS thread for the solvers' tiny factorisations, set before numpy is imported: see
# ibik_pin/cli.py (the library itself leaves the environment alone). A user's setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from paper.virtual_scenes import PAPER_EXPERIMENTS, PlanarRun, run_paper_experiment

from ibik_pin.synthetic.planar import PlanarScene

SHOWN_ITERATIONS = (0, 2, 5, 10, 20, 50, 100, 200)


def draw_panel(axes, scene: PlanarScene, run: PlanarRun, title: str) -> None:
    """The chain at SHOWN_ITERATIONS (light to dark) and at the end (blue) over the image."""
    height, width = scene.support.values.shape
    background = np.ones((height, width, 3))
    if scene.silhouette is not None:
        background[scene.silhouette] = (0.65, 0.85, 0.65)
    if scene.object_mask is not None:
        background[scene.object_mask] = (0.9, 0.45, 0.45)
    axes.imshow(background, origin="upper")
    shown = [k for k in SHOWN_ITERATIONS if k < len(run.trajectory) - 1]
    for rank, k in enumerate(shown):
        pixels = scene.camera.project(scene.keypoint_positions(run.trajectory[k]))
        shade = 0.85 - 0.6 * rank / max(len(shown) - 1, 1)
        axes.plot(pixels[:, 0], pixels[:, 1], "-o", color=(shade, shade, shade), lw=1.2, ms=2.5)
    final = scene.camera.project(scene.keypoint_positions(run.trajectory[-1]))
    axes.plot(final[:, 0], final[:, 1], "-o", color="tab:blue", lw=2.0, ms=4, label="final")
    target = scene.camera.project(scene.keypoint_positions(scene.objective_q))[-1:]
    axes.set_title(title, fontsize=10)
    axes.set_xlim(0, width)
    axes.set_ylim(height, 0)
    axes.set_xticks([])
    axes.set_yticks([])
    return target


def figure(name: str, scene: PlanarScene, runs: dict[str, PlanarRun], target_pixel: np.ndarray, path: Path) -> None:
    fig = Figure(figsize=(8.0, 4.3))
    FigureCanvasAgg(fig)
    for column, (label, run) in enumerate(runs.items()):
        axes = fig.add_subplot(1, 2, column + 1)
        draw_panel(axes, scene, run, f"{label}: ee {run.end_effector_error:.1e}, internal "
                   f"{run.internal_joint_error:.3f}" + (f", hits {run.object_hits}" if name == "fig8" else ""))
        axes.plot(*target_pixel, "x", color="tab:red", ms=10, mew=2, label="target")
        axes.legend(loc="lower left", fontsize=8)
    fig.suptitle(f"{name}: {PAPER_EXPERIMENTS[name].description}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def record(name: str, method: str, scheme: str, run: PlanarRun) -> dict:
    return {
        "experiment": name,
        "method": method,
        "scheme": scheme,
        "iterations": len(run.trajectory) - 1,
        "end_effector_error": run.end_effector_error,
        "internal_joint_error": run.internal_joint_error,
        "overlap": run.overlap,
        "object_hits": run.object_hits,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    arguments = parser.parse_args()
    arguments.out.mkdir(parents=True, exist_ok=True)
    records = []
    for name, experiment in PAPER_EXPERIMENTS.items():
        scene, ik = run_paper_experiment(name, use_image=False, solver_name="ik")
        records.append(record(name, "ik", "ik", ik))
        ibik_runs = {}
        for scheme in ("liegeois", "stack", "qp"):
            _, ibik_runs[scheme] = run_paper_experiment(name, use_image=True, solver_name=scheme)
            records.append(record(name, "ibik", scheme, ibik_runs[scheme]))
        target = np.array(experiment.target) if experiment.target is not None else \
            scene.keypoint_positions(scene.objective_q)[-1]
        figure(name, scene, {"IK": ik, "IK with image constraint": ibik_runs["liegeois"]},
               scene.camera.project(target[None])[0], arguments.out / f"{name}.png")
        for entry in records[-4:]:
            print(f"{entry['experiment']} {entry['method']:>4} {entry['scheme']:>8}: end effector "
                  f"{entry['end_effector_error']:.1e}, internal joints {entry['internal_joint_error']:.4f}, "
                  f"overlap {entry['overlap']:.2f}, object hits {entry['object_hits']}")
    (arguments.out / "metrics.json").write_text(json.dumps(records, indent=2))
    print(f"wrote {arguments.out}/fig6.png, fig7.png, fig8.png and metrics.json")


if __name__ == "__main__":
    main()
