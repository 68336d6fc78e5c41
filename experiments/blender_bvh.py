"""Does Blender import the BVH `ibik track` writes where joints.trc says the joints are?

Imports OUTDIR/motion.bvh with Blender's own BVH importer (the `bpy` module: Blender as a Python
package, `pip install bpy` in a Python 3.11 environment of its own; it does not install beside this
package's), then compares the heads of the knee, ankle and elbow bones with joints.trc's LKnee,
LAnkle, RKnee, RAnkle, LElbow, RElbow at every frame (Blender turns the BVH's Y up into its Z up).
Prints Blender's version and the worst distance [mm].

Usage: python experiments/blender_bvh.py OUTDIR      (OUTDIR: an `ibik track` or `ibik demo` output
folder holding motion.bvh and joints.trc; run with the Python that has bpy)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import bpy
import numpy as np

BONES = {"left_knee": "LKnee", "right_knee": "RKnee", "left_ankle": "LAnkle", "right_ankle": "RAnkle",
         "left_elbow": "LElbow", "right_elbow": "RElbow"}


def joints_trc(path: Path) -> tuple[list[str], np.ndarray]:
    """Names and (F, M, 3) positions of a TRC written in metres (read without the package: bpy's Python)."""
    lines = path.read_text().splitlines()
    names = [name for name in lines[3].split("\t")[2:] if name]
    rows = np.array([[float(cell) for cell in line.split("\t")] for line in lines[5:] if line.strip()])
    return names, rows[:, 2:].reshape(len(rows), len(names), 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="an ibik output folder (motion.bvh, joints.trc in metres)")
    folder = parser.parse_args().out
    names, positions = joints_trc(folder / "joints.trc")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=str(folder / "motion.bvh"), global_scale=1.0, update_scene_fps=True)
    armature = next(item for item in bpy.data.objects if item.type == "ARMATURE")
    worst = 0.0
    for frame in range(1, len(positions) + 1):
        bpy.context.scene.frame_set(frame)
        for bone, keypoint in BONES.items():
            head = np.array(armature.matrix_world @ armature.pose.bones[bone].head)
            x, y, z = positions[frame - 1, names.index(keypoint)]
            worst = max(worst, float(np.linalg.norm(head - (x, -z, y))))
    print(f"Blender {bpy.app.version_string}: {len(armature.data.bones)} bones, {len(positions)} frames at "
          f"{bpy.context.scene.render.fps} fps; worst joint distance to joints.trc {1000 * worst:.3f} mm")


if __name__ == "__main__":
    main()
