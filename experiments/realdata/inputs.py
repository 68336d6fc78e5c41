"""The files a user brings to ``ibik track``, written for one clip and cached on disk.

Per clip (one folder per clip, window length and settings of the inputs, under the cache folder):

- calibration.toml: 4 HumanEva-like cameras (humaneva_rig: 640 x 480, 4 m, 1.5 m high), renamed
  cam1..cam4 from the most frontal (the subject's mean facing) to the least, so that 1 view is
  cam1 and 2 views are cam1 and cam2 (about 90 degrees apart); Pose2Sim's Z-up world;
- static.trc: every keypoint (elbows and knees too) of the static trial (Y up, m);
- truth.trc: every keypoint of the window (Y up, m), the truth of the elbows and knees;
- <condition>/targets.trc: every keypoint but the elbows and knees ("defects": 5 mm of Gaussian
  noise per coordinate, as the Section 4 experiments);
- <condition>/masks/<camera>/000000.png...: the mocap body's silhouettes ("defects": Section 4's
  DEFECTS, the lost limbs taken from the same body's forearm and shank pixels);
- preview.png: the middle frame's silhouettes with the projected mocap skeleton and keypoints;
- inputs.json: what was written and the key it was written for; present only when complete.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from paper.section4 import DEFECT_TARGET_NOISE_MM, DEFECTS

from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, write_calibration
from ibik_pin.io.trc import TrcData, read_trc, write_trc
from ibik_pin.synthetic.defects import apply_defects
from ibik_pin.synthetic.rig import humaneva_rig
from realdata import body as body_module
from realdata.body import MocapBody, draw_preview
from realdata.clips import RATE_HZ, STATIC_SPACING_S, ClipSpec, MocapClip, load_clip

CONDITIONS = ("clean", "defects")
RIG_VIEWS = 4
RIG_SEED = 0
INPUTS_VERSION = 2  # bump when what is written changes, so that caches are rebuilt


@dataclass
class ClipInputs:
    """The written files of one clip and the truth to judge a run by.

    Attributes:
        folder: where the files are.
        spec: the clip.
        cameras: the camera names, most frontal first.
        truth_names: every keypoint; truth: (F, K, 3) their true positions [m], Y up.
        target_names: the keypoints written as targets.
    """

    folder: Path
    spec: ClipSpec
    cameras: list[str]
    truth_names: list[str]
    truth: np.ndarray
    target_names: list[str]

    @property
    def frames(self) -> int:
        return self.truth.shape[0]

    @property
    def calibration(self) -> Path:
        return self.folder / "calibration.toml"

    @property
    def static(self) -> Path:
        return self.folder / "static.trc"

    @property
    def preview(self) -> Path:
        return self.folder / "preview.png"

    def targets(self, condition: str) -> Path:
        return self.folder / condition / "targets.trc"

    def masks(self, condition: str) -> Path:
        return self.folder / condition / "masks"


def _key(spec: ClipSpec, frames: int) -> dict:
    body_sizes = {name: getattr(body_module, name) for name in dir(body_module)
                  if name.isupper() and isinstance(getattr(body_module, name), (float, tuple, dict))}
    return {
        "version": INPUTS_VERSION, "clip": dataclasses.asdict(spec), "frames": int(frames), "rate_hz": RATE_HZ,
        "rig": {"views": RIG_VIEWS, "seed": RIG_SEED}, "defects": dataclasses.asdict(DEFECTS),
        "defect_target_noise_mm": DEFECT_TARGET_NOISE_MM, "body": repr(sorted(body_sizes.items())),
    }


def _ordered_rig(clip: MocapClip) -> list:
    """The rig's cameras from the most frontal to the least, renamed cam1..camN in that order."""
    centre = np.nanmean(clip.keypoint("Hip"), axis=0)
    cameras = humaneva_rig(RIG_VIEWS, centre, seed=RIG_SEED)
    facing = clip.facing()
    frontal = [float(facing @ (c.center_world - centre) / np.linalg.norm(c.center_world - centre)) for c in cameras]
    ordered = [cameras[k] for k in np.argsort(frontal)[::-1]]
    return [dataclasses.replace(camera, name=f"cam{k}") for k, camera in enumerate(ordered, start=1)]


def _azimuths(clip: MocapClip, cameras: list) -> list[float]:
    """Each camera's horizontal angle from the subject's mean facing, seen from the subject [deg]."""
    centre = np.nanmean(clip.keypoint("Hip"), axis=0)
    facing = clip.facing()
    left = np.cross(np.array([0.0, 1.0, 0.0]), facing)
    angles = []
    for camera in cameras:
        direction = camera.center_world - centre
        angles.append(float(np.degrees(np.arctan2(direction @ left, direction @ facing))))
    return angles


def _trc(names: list[str], positions: np.ndarray, rate: float) -> TrcData:
    count = positions.shape[0]
    return TrcData(list(names), np.arange(count) / rate, positions, "m", rate, np.arange(1, count + 1))


def _write(folder: Path, clip: MocapClip, key: dict, seed: int) -> None:
    """Every file of the clip into `folder`."""
    cameras = _ordered_rig(clip)
    write_calibration(folder / "calibration.toml",
                      [dataclasses.replace(c, rotation=c.rotation @ POSE2SIM_TRC_TO_WORLD.T) for c in cameras])
    body = MocapBody.for_subject(clip.joint_names, clip.spec.source, clip.static_joints)
    rate = clip.frame_rate
    write_trc(folder / "static.trc", _trc(clip.keypoint_names, clip.static_keypoints, 1.0 / STATIC_SPACING_S))
    write_trc(folder / "truth.trc", _trc(clip.keypoint_names, clip.keypoints, rate))
    targets = [clip.keypoint_names.index(name) for name in clip.target_names]
    noise = np.random.default_rng([seed, 0]).normal(
        0.0, DEFECT_TARGET_NOISE_MM * 1e-3, (clip.keypoints.shape[0], len(targets), 3))
    for condition in CONDITIONS:
        positions = clip.keypoints[:, targets] + (noise if condition == "defects" else 0.0)
        (folder / condition).mkdir()
        write_trc(folder / condition / "targets.trc", _trc(clip.target_names, positions, rate))
        for camera in cameras:
            (folder / condition / "masks" / camera.name).mkdir(parents=True)
    defect_rng = np.random.default_rng([seed, 1])
    middle = clip.joints.shape[0] // 2
    for frame, joints in enumerate(clip.joints):
        rendered = [body.render_frame(joints, camera) for camera in cameras]
        if frame == middle:
            preview = draw_preview([mask for mask, _ in rendered], cameras, joints, clip.parents,
                                   clip.keypoints[frame])
            cv2.imwrite(str(folder / "preview.png"), preview)
        for camera, (mask, limbs) in zip(cameras, rendered, strict=True):
            for condition in CONDITIONS:
                image = apply_defects(mask, DEFECTS, defect_rng, limbs) if condition == "defects" else mask
                path = folder / condition / "masks" / camera.name / f"{frame:06d}.png"
                if not cv2.imwrite(str(path), image.astype(np.uint8) * 255):
                    raise OSError(f"{path}: OpenCV cannot write this mask")
    metadata = dict(key, cameras=[camera.name for camera in cameras], camera_azimuths_deg=_azimuths(clip, cameras),
                    body_scale=body.scale, target_names=clip.target_names, seed=seed)
    (folder / "inputs.json").write_text(json.dumps(metadata, indent=2) + "\n")


def prepare_inputs(spec: ClipSpec, data: Path, frames: int, cache: Path, seed: int = 0) -> ClipInputs:
    """The clip's files under `cache`, written now unless a complete copy for the same key is there.

    The folder is built beside its final place and renamed into it when complete, so that an
    interrupted run or two runs at once never leave a half-written folder that looks complete.
    """
    key = _key(spec, frames)
    digest = hashlib.sha256(json.dumps(dict(key, seed=seed), sort_keys=True).encode()).hexdigest()[:10]
    folder = Path(cache) / f"{spec.name}_{frames}f_{digest}"
    if not (folder / "inputs.json").is_file():
        clip = load_clip(spec, data, frames)
        folder.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
        try:
            _write(staging, clip, key, seed)
            shutil.rmtree(folder, ignore_errors=True)  # an incomplete leftover
            os.replace(staging, folder)
        except OSError:
            if not (folder / "inputs.json").is_file():
                raise
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    metadata = json.loads((folder / "inputs.json").read_text())
    truth = read_trc(folder / "truth.trc")
    return ClipInputs(folder, spec, metadata["cameras"], list(truth.marker_names), truth.positions,
                      metadata["target_names"])
