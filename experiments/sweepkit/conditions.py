"""One seeded condition of the sweep, and the files written for ``ibik track`` under it.

A condition draws (numpy's generator seeded by [seed, index]):

- the motion: the index cycles through :data:`motions.MOTIONS`, so every motion has as many
  conditions as any other (to one);
- a rig of 4 cameras: cam1 at any azimuth from the subject's mean facing, cam2 45-135 deg from it
  (either side), cam3 and cam4 roughly opposite them (+-30 deg); each camera 0.5-2.5 m high,
  3-7 m away (moved back by 0.25 m steps until the whole window is in its image), with a
  horizontal field of view of 50-90 deg; one image size for the rig among 640 x 480 ... 1920 x 1080;
  1 view is cam1, 2 views cam1 and cam2;
- the silhouette body (body.BodyShape): limb radii x0.7-1.4; round or elliptical sections (axis
  ratio 1.1-1.5) with even odds; no or 10-40 mm loose clothing with even odds;
- the static take: each segment of the keypoint tree (pelvis halves, thighs, shanks, feet, spine,
  neck, clavicles, upper arms, forearms) scaled by its own factor in [0.96, 1.04];
- target noise: Gaussian, sigma 0-10 mm per coordinate;
- the keypoint set: with or without the toe keypoints (even odds). CMU and the boxing file have no
  heel keypoint.

Defects are realdata's (Section 4's SilhouetteDefects), their sizes in pixels scaled by the
subject's height in each image against the 640 x 480, 4-m HumanEva camera's (306 px).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from paper.section4 import DEFECTS
from realdata.clips import ESTIMATED, STATIC_SPACING_S, MocapClip, load_clip
from realdata.inputs import ClipInputs

from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, write_calibration
from ibik_pin.io.trc import TrcData, write_trc
from ibik_pin.synthetic.defects import SilhouetteDefects, apply_defects
from ibik_pin.synthetic.mocap import UP
from ibik_pin.vision.pinhole import look_at_camera
from sweepkit.body import BodyShape, SweepBody
from sweepkit.motions import MOTIONS, anatomy_of

IMAGE_SIZES = ((640, 480), (1024, 768), (1280, 720), (1920, 1080))
TOES = ("LBigToe", "RBigToe", "LSmallToe", "RSmallToe", "LHeel", "RHeel")
# The keypoint tree whose segments the static take gets wrong: child -> parent.
PARENTS = {"LHip": "Hip", "RHip": "Hip", "LKnee": "LHip", "RKnee": "RHip", "LAnkle": "LKnee", "RAnkle": "RKnee",
           "LBigToe": "LAnkle", "RBigToe": "RAnkle", "Neck": "Hip", "Head": "Neck", "LShoulder": "Neck",
           "RShoulder": "Neck", "LElbow": "LShoulder", "RElbow": "RShoulder", "LWrist": "LElbow",
           "RWrist": "RElbow"}
REFERENCE_SUBJECT_PX = 1.75 * 700.0 / 4.0  # a 1.75-m subject 4 m from a 700-px focal camera
DISTANCE_STEP_M = 0.25
FRAME_MARGIN = 0.04  # of the image size, kept free around the subject


@dataclass(frozen=True)
class CameraDraw:
    """One drawn camera: azimuth from the subject's mean facing [deg], height [m], distance [m]
    (as drawn; `distance_used_m` after moving back to hold the subject), horizontal FOV [deg]."""

    azimuth_deg: float
    height_m: float
    distance_m: float
    fov_deg: float
    distance_used_m: float = 0.0


@dataclass(frozen=True)
class Condition:
    """Everything drawn for one condition (see the module's docstring)."""

    index: int
    seed: int
    motion: str
    kind: str
    size: tuple[int, int]
    cameras: tuple[CameraDraw, ...]
    body: BodyShape
    length_factors: dict[str, float] = field(default_factory=dict)
    target_noise_mm: float = 0.0
    toes: bool = True

    def row(self) -> dict:
        return dataclasses.asdict(self)


def draw_condition(index: int, seed: int) -> Condition:
    """The index-th condition of the sweep seeded by `seed`."""
    rng = np.random.default_rng([seed, index])
    names = list(MOTIONS)
    motion = names[index % len(names)]
    first = rng.uniform(-180.0, 180.0)
    second = first + rng.choice((-1.0, 1.0)) * rng.uniform(45.0, 135.0)
    azimuths = (first, second, first + 180.0 + rng.uniform(-30.0, 30.0), second + 180.0 + rng.uniform(-30.0, 30.0))
    size = IMAGE_SIZES[int(rng.integers(len(IMAGE_SIZES)))]
    cameras = tuple(CameraDraw(float((a + 180.0) % 360.0 - 180.0), float(rng.uniform(0.5, 2.5)),
                               float(rng.uniform(3.0, 7.0)), float(rng.uniform(50.0, 90.0))) for a in azimuths)
    body = BodyShape(limb_radius_factor=float(rng.uniform(0.7, 1.4)),
                     ellipticity=float(rng.uniform(1.1, 1.5)) if rng.random() < 0.5 else 1.0,
                     loose_m=float(rng.uniform(0.01, 0.04)) if rng.random() < 0.5 else 0.0)
    lengths = {child: float(rng.uniform(0.96, 1.04)) for child in PARENTS}
    return Condition(index, seed, motion, MOTIONS[motion].kind, size, cameras, body, lengths,
                     float(rng.uniform(0.0, 10.0)), bool(rng.random() < 0.5))


def drift_static(names: list[str], static: np.ndarray, factors: dict[str, float]) -> np.ndarray:
    """The static keypoints (S, K, 3) [m] with each segment child - parent scaled by its factor,
    the child's descendants carried along."""
    result = np.array(static, dtype=float)
    index = {name: k for k, name in enumerate(names)}
    done = {"Hip"}
    while len(done) < len(index):
        progressed = False
        for child, parent in PARENTS.items():
            if child in index and child not in done and parent in done:
                segment = static[:, index[child]] - static[:, index[parent]]
                result[:, index[child]] = result[:, index[parent]] + factors.get(child, 1.0) * segment
                done.add(child)
                progressed = True
        if not progressed:  # keypoints outside the tree stay where they were
            break
    return result


def _trc(names: list[str], positions: np.ndarray, rate: float) -> TrcData:
    count = positions.shape[0]
    return TrcData(list(names), np.arange(count) / rate, positions, "m", rate, np.arange(1, count + 1))


def place_cameras(clip: MocapClip, condition: Condition) -> tuple[list, Condition]:
    """The rig around the window's mean body centre, each camera moved back until every joint of
    every frame lies inside its image with FRAME_MARGIN to spare; the condition with the distances used."""
    centre = np.nanmean(clip.joints.reshape(-1, 3), axis=0)
    facing = clip.facing()
    left = np.cross(UP, facing)
    width, height = condition.size
    points = clip.joints.reshape(-1, 3)
    cameras, used = [], []
    for k, draw in enumerate(condition.cameras, start=1):
        focal = 0.5 * width / np.tan(np.radians(0.5 * draw.fov_deg))
        angle = np.radians(draw.azimuth_deg)
        direction = np.cos(angle) * facing + np.sin(angle) * left
        distance = draw.distance_m
        while True:
            eye = centre + distance * direction
            eye[1] = draw.height_m
            camera = look_at_camera(f"cam{k}", condition.size, focal, eye, centre, UP)
            pixels = camera.project(points)
            inside = (np.all(np.isfinite(pixels)) and pixels[:, 0].min() > FRAME_MARGIN * width
                      and pixels[:, 0].max() < (1 - FRAME_MARGIN) * width and pixels[:, 1].min() > FRAME_MARGIN * height
                      and pixels[:, 1].max() < (1 - FRAME_MARGIN) * height)
            if inside or distance > 20.0:
                break
            distance += DISTANCE_STEP_M
        cameras.append(camera)
        used.append(dataclasses.replace(draw, distance_used_m=float(distance)))
    return cameras, dataclasses.replace(condition, cameras=tuple(used))


def scaled_defects(camera, clip: MocapClip, stature_m: float) -> SilhouetteDefects:
    """Section 4's defects with their pixel sizes scaled to the subject's height in this image."""
    depth = float(np.linalg.norm(camera.center_world - np.nanmean(clip.joints.reshape(-1, 3), axis=0)))
    scale = stature_m * float(camera.intrinsics[1, 1]) / depth / REFERENCE_SUBJECT_PX

    def pixels(value: int) -> int:
        return max(1, int(round(value * scale))) if value else 0

    return dataclasses.replace(DEFECTS, erode_px=pixels(DEFECTS.erode_px), dilate_px=pixels(DEFECTS.dilate_px),
                               hole_radius_px=DEFECTS.hole_radius_px * scale,
                               blob_radius_px=DEFECTS.blob_radius_px * scale)


@dataclass
class ConditionInputs(ClipInputs):
    """The files of one condition (realdata's ClipInputs: folder, spec, cameras cam1 first, truth
    names and (F, K, 3) noise-free truth [m] Y up, target names) and what differs here: one targets
    file for both silhouette conditions, masks/<silhouettes>/<camera>/, and the static file a run
    calibrates on (None: the condition's static.trc).
    """

    condition: Condition
    frame_rate: float
    static_path: Path | None = None

    @property
    def static(self) -> Path:
        return self.static_path or self.folder / "static.trc"

    def targets(self, silhouettes: str = "clean") -> Path:
        return self.folder / "targets.trc"

    def masks(self, silhouettes: str) -> Path:
        return self.folder / "masks" / silhouettes

    def estimated_truth(self) -> np.ndarray:
        """(F, 4, 3) the true LElbow, RElbow, LKnee, RKnee [m]."""
        return self.truth[:, [self.truth_names.index(name) for name in ESTIMATED]]


def write_condition(condition: Condition, data: Path, frames: int, rate: float, folder: Path,
                    silhouettes: tuple[str, ...] = ("clean", "defects")) -> ConditionInputs:
    """Every file of the condition into `folder` (created)."""
    spec = MOTIONS[condition.motion]
    clip = load_clip(spec, data, frames, rate)
    cameras, condition = place_cameras(clip, condition)
    folder.mkdir(parents=True, exist_ok=True)
    write_calibration(folder / "calibration.toml",
                      [dataclasses.replace(c, rotation=c.rotation @ POSE2SIM_TRC_TO_WORLD.T) for c in cameras])
    static = drift_static(clip.keypoint_names, clip.static_keypoints, condition.length_factors)
    write_trc(folder / "static.trc", _trc(clip.keypoint_names, static, 1.0 / STATIC_SPACING_S))
    rng = np.random.default_rng([condition.seed, condition.index, 1])
    targets = [name for name in clip.target_names if condition.toes or name not in TOES]
    positions = clip.keypoints[:, [clip.keypoint_names.index(name) for name in targets]]
    positions = positions + rng.normal(0.0, condition.target_noise_mm * 1e-3, positions.shape)
    write_trc(folder / "targets.trc", _trc(targets, positions, rate))
    anatomy = anatomy_of(clip.joint_names, spec.source)
    body = SweepBody(clip.joint_names, spec.source, anatomy, clip.static_joints, condition.body)
    stature_m = body.scale * 1.75
    defects = [scaled_defects(camera, clip, stature_m) for camera in cameras]
    for kind in silhouettes:
        for camera in cameras:
            (folder / "masks" / kind / camera.name).mkdir(parents=True, exist_ok=True)
    for frame, joints in enumerate(clip.joints):
        for camera, camera_defects in zip(cameras, defects, strict=True):
            mask, limbs = body.render_frame(joints, camera)
            for kind in silhouettes:
                image = apply_defects(mask, camera_defects, rng, limbs) if kind == "defects" else mask
                path = folder / "masks" / kind / camera.name / f"{frame:06d}.png"
                if not cv2.imwrite(str(path), image.astype(np.uint8) * 255):
                    raise OSError(f"{path}: OpenCV cannot write this mask")
    np.savez(folder / "truth.npz", names=np.array(clip.keypoint_names), keypoints=clip.keypoints,
             targets=np.array(targets), rate=rate)
    inputs = ConditionInputs(folder, spec, [c.name for c in cameras], list(clip.keypoint_names), clip.keypoints,
                             targets, condition, rate)
    (folder / "condition.json").write_text(json.dumps(condition.row(), indent=2) + "\n")  # last: complete
    return inputs


def load_condition(condition: Condition, folder: Path,
                   silhouettes: tuple[str, ...] = ()) -> ConditionInputs | None:
    """The condition's files written earlier into `folder` by :func:`write_condition` for the same
    draw, or None when they are not there (or were written for another draw, or without one of
    the `silhouettes` asked for now)."""
    if not all((folder / "masks" / kind).is_dir() for kind in silhouettes):
        return None
    try:
        written = json.loads((folder / "condition.json").read_text())
        truth = np.load(folder / "truth.npz")
    except (OSError, ValueError):
        return None
    drawn = condition.row()
    if any(written[key] != drawn[key] for key in ("index", "seed", "motion", "target_noise_mm", "toes")):
        return None
    placed = dataclasses.replace(condition, cameras=tuple(CameraDraw(**camera) for camera in written["cameras"]))
    return ConditionInputs(folder, MOTIONS[condition.motion], [f"cam{k}" for k in range(1, len(placed.cameras) + 1)],
                           [str(n) for n in truth["names"]], truth["keypoints"], [str(n) for n in truth["targets"]],
                           placed, float(truth["rate"]))


def add_kept_arguments(parser: argparse.ArgumentParser, default_data: Path) -> None:
    """The options of an experiment that reruns the sweep's conditions kept by `sweep.py --keep`:
    --keep, --data, --first, --conditions, --seed, --views, --frames (kept_conditions reads them)."""
    parser.add_argument("--keep", type=Path, required=True, help="the conditions' inputs (sweep.py --keep)")
    parser.add_argument("--data", type=Path, default=default_data)
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--conditions", type=int, default=42)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--views", type=int, default=2)
    parser.add_argument("--frames", type=int, default=40)


def kept_conditions(arguments: argparse.Namespace) -> Iterator[ConditionInputs]:
    """Each condition add_kept_arguments names, with clean silhouettes: read from --keep, or written
    there (at 30 Hz, as the sweep) when absent or of another length."""
    for index in range(arguments.first, arguments.first + arguments.conditions):
        condition = draw_condition(index, arguments.seed)
        folder = arguments.keep / f"condition_{index:03d}"
        inputs = load_condition(condition, folder, ("clean",))
        if inputs is None or inputs.truth.shape[0] != arguments.frames:
            inputs = write_condition(condition, arguments.data, arguments.frames, 30.0, folder, ("clean",))
        yield inputs
