"""A synthetic recording written as the files `ibik track` reads, with its truth beside them.

The data set holds a Pose2Sim calibration TOML, TRC files of the target keypoints (with noise)
and of every keypoint (the truth), the true configurations, one folder of masks per camera
(rendered silhouettes, optionally degraded) and a JSON of the parameters. Pose2Sim's calibration
world is Z up while its TRC files, like the model frame, are Y up: the cameras are written in the
Z-up world (:data:`~ibik_pin.io.calibration.POSE2SIM_TRC_TO_WORLD`), the keypoints Y up.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from ibik_pin.exceptions import InputError, UnknownNameError
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, write_calibration
from ibik_pin.io.files import strict_json
from ibik_pin.io.trc import TrcData, write_trc
from ibik_pin.model import BodyModel
from ibik_pin.synthetic.defects import SilhouetteDefects, apply_defects
from ibik_pin.synthetic.silhouettes import keypoint_positions, render_limb_masks, render_silhouettes
from ibik_pin.vision.pinhole import PinholeCamera

__all__ = ["DatasetPaths", "write_dataset"]


@dataclass(frozen=True)
class DatasetPaths:
    """The files :func:`write_dataset` wrote.

    Attributes:
        folder: the data set's folder.
        calibration: Pose2Sim calibration TOML (Z-up world, see the module docstring).
        targets: TRC of the target keypoints, model frame (Y up), metres, with noise.
        truth: TRC of every keypoint of the posed model, no noise.
        truth_q: .npy of the true configurations, shape (F, nq).
        masks: folder with one sub-folder of masks per camera (``<camera>/000000.png``, 0/255).
        metadata: JSON of the parameters (frame rate, cameras, noise, defects, seed).
    """

    folder: Path
    calibration: Path
    targets: Path
    truth: Path
    truth_q: Path
    masks: Path
    metadata: Path


def write_dataset(
    out_dir: str | Path,
    body: BodyModel,
    q: np.ndarray,
    cameras: Sequence[PinholeCamera],
    frame_rate: float,
    target_keypoints: Sequence[str],
    noise_mm: float = 0.0,
    defects: SilhouetteDefects | None = None,
    seed: int = 0,
) -> DatasetPaths:
    """Write a synthetic sequence as the files `ibik track` reads.

    ``ibik track --targets targets.trc --calibration calibration.toml --masks masks`` runs on it;
    truth.trc and truth_q.npy are what the estimate is compared with.

    Args:
        out_dir: the folder (created if needed; files of the same names are replaced).
        body: the model the truth was posed with.
        q: true configurations, shape (F, nq).
        cameras: pinhole cameras mapping model-frame points (e.g. :func:`humaneva_rig`).
        frame_rate: frames per second [Hz].
        target_keypoints: the keypoints written to targets.trc (the known end-effectors).
        noise_mm: standard deviation of the Gaussian noise added to each target coordinate [mm].
        defects: silhouette defects, or None for the clean rendered masks.
        seed: seeds the noise and the defects (two independent streams).

    Returns:
        The paths written.

    Raises:
        InputError: shapes, names or values that do not fit.
        UnknownNameError: a target keypoint the body does not have.
    """
    model = body.model
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != model.nq or q.shape[0] == 0:
        raise InputError(f"q: expected shape (F, {model.nq}) with F >= 1, got {q.shape}")
    frame_rate = float(frame_rate)
    if not (np.isfinite(frame_rate) and frame_rate > 0.0):
        raise InputError(f"frame_rate: expected a positive number [Hz], got {frame_rate}")
    noise_mm = float(noise_mm)
    if not (np.isfinite(noise_mm) and noise_mm >= 0.0):
        raise InputError(f"noise_mm: expected a non-negative standard deviation [mm], got {noise_mm}")
    if isinstance(target_keypoints, str) or not list(target_keypoints):
        raise InputError(f"target_keypoints: expected a non-empty list of keypoint names, got {target_keypoints!r}")
    target_keypoints = list(target_keypoints)
    unknown = [name for name in target_keypoints if name not in body.keypoints]
    if unknown:
        raise UnknownNameError(
            f"target_keypoints: unknown keypoint(s) {unknown}; known: {', '.join(body.keypoints)}"
        )
    if len(set(target_keypoints)) != len(target_keypoints):
        raise InputError(f"target_keypoints: expected each name once, got {target_keypoints}")
    cameras = list(cameras)
    if not cameras:
        raise InputError("cameras: expected at least one camera, got none")
    if defects is not None and not isinstance(defects, SilhouetteDefects):
        raise InputError(f"defects: expected a SilhouetteDefects or None, got {type(defects).__name__}")

    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    paths = DatasetPaths(
        folder=folder,
        calibration=folder / "calibration.toml",
        targets=folder / "targets.trc",
        truth=folder / "truth.trc",
        truth_q=folder / "truth_q.npy",
        masks=folder / "masks",
        metadata=folder / "dataset.json",
    )
    write_calibration(paths.calibration, [_in_pose2sim_world(camera) for camera in cameras])

    keypoints = list(body.keypoints)
    truth = np.array([[points[name] for name in keypoints]
                      for points in (keypoint_positions(body, q_frame) for q_frame in q)])
    frame_count = q.shape[0]
    times = np.arange(frame_count) / frame_rate
    frame_numbers = np.arange(1, frame_count + 1)
    write_trc(paths.truth, TrcData(keypoints, times, truth, "m", frame_rate, frame_numbers))
    noise_rng = np.random.default_rng([seed, 0])
    defect_rng = np.random.default_rng([seed, 1])
    target_indices = [keypoints.index(name) for name in target_keypoints]
    targets = truth[:, target_indices] + noise_rng.normal(0.0, noise_mm * 1e-3, (frame_count, len(target_indices), 3))
    write_trc(paths.targets, TrcData(target_keypoints, times, targets, "m", frame_rate, frame_numbers))
    np.save(paths.truth_q, q)

    folders = [paths.masks / camera.name for camera in cameras]
    for camera_folder in folders:
        camera_folder.mkdir(parents=True, exist_ok=True)
    lose_limbs = defects is not None and defects.missing_limb_probability > 0.0
    for frame, q_frame in enumerate(q):
        masks = render_silhouettes(body, q_frame, cameras)
        for camera, camera_folder, mask in zip(cameras, folders, masks, strict=True):
            if defects is not None:
                limbs = render_limb_masks(body, q_frame, camera) if lose_limbs else None
                mask = apply_defects(mask, defects, defect_rng, limbs)
            path = camera_folder / f"{frame:06d}.png"
            if not cv2.imwrite(str(path), mask.astype(np.uint8) * 255):
                raise InputError(f"{path}: OpenCV cannot write this mask")

    metadata = {
        "frames": frame_count,
        "frame_rate": frame_rate,
        "cameras": [camera.name for camera in cameras],
        "target_keypoints": target_keypoints,
        "truth_keypoints": keypoints,
        "noise_mm": noise_mm,
        "defects": None if defects is None else asdict(defects),
        "seed": seed,
        "model": model.name,
        "nq": model.nq,
    }
    paths.metadata.write_text(strict_json(metadata))
    return paths


def _in_pose2sim_world(camera: PinholeCamera) -> PinholeCamera:
    """The camera of model-frame points (Y up) as a camera of Pose2Sim's Z-up world points."""
    if not isinstance(camera, PinholeCamera):
        raise InputError(
            f"cameras: expected PinholeCamera (a calibration TOML holds no other kind), got {type(camera).__name__}"
        )
    # world = M @ model frame, so R_world = R_model @ M^T maps each world point to the camera
    # coordinates of its model-frame point: the translation stays.
    rotation = camera.rotation @ POSE2SIM_TRC_TO_WORLD.T
    return PinholeCamera(camera.name, camera.size, camera.intrinsics, camera.distortion, rotation, camera.translation)
