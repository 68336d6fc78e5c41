"""The outcome of a subject calibration: the calibrated body, the static fit's figures and their report.

:class:`CalibrationResult` is what :func:`~ibik_pin.subject.calibration.calibrate_subject` returns;
its :meth:`~CalibrationResult.table` is what `ibik calibrate` prints and its
:meth:`~CalibrationResult.to_json` what it writes next to the subject's URDF.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ibik_pin.io.files import strict_json, write_text_atomically
from ibik_pin.model import BodyModel

__all__ = ["CalibrationResult", "write_calibration_figures"]


@dataclasses.dataclass
class CalibrationResult:
    """A calibrated subject and how well it explains its static trial.

    Attributes:
        body: the calibrated model (``calibrated`` True); the input body is not modified.
        keypoint_names: the K keypoints present in the static trial (fitted).
        frames: indices of the static frames used, shape (F,).
        q: the static poses of the calibrated model, shape (F, nq).
        residual_before: per keypoint, [mean, max] over frames of the distance to the static
            trial with lengths-only scaling (the start model, poses fitted), shape (K, 2) [m].
        residual_after: the same with the calibrated model, shape (K, 2) [m].
        offsets: per keypoint, the calibrated placement minus the start's (lengths-only scaling),
            in its parent joint's frame (for a keypoint at a joint centre: the proximal segment's
            joint frame, from that centre), shape (K, 3) [m].
        segment_scales: group name of :data:`~ibik_pin.subject.calibration_settings.SCALE_GROUPS`
            -> length of the calibrated group over the input model's (1.0: unchanged).
        joint_shifts: shift name of :data:`~ibik_pin.subject.calibration_settings.SHIFT_GROUPS`
            -> its distance [m] (0: as scaled).
        frame_numbers: the TRC frame numbers of ``frames``, when read from a file.
    """

    body: BodyModel
    keypoint_names: list[str]
    frames: np.ndarray
    q: np.ndarray
    residual_before: np.ndarray
    residual_after: np.ndarray
    offsets: np.ndarray
    segment_scales: dict[str, float]
    joint_shifts: dict[str, float]
    frame_numbers: np.ndarray | None = None

    def to_json(self) -> dict:
        """The figures as plain JSON types (millimetres for residuals and offsets)."""
        return {
            "frames": [int(frame) for frame in self.frames],
            "trc_frame_numbers": None if self.frame_numbers is None else [int(n) for n in self.frame_numbers],
            "segment_scales": {name: round(value, 5) for name, value in self.segment_scales.items()},
            "joint_shifts_mm": {name: _mm(value) for name, value in self.joint_shifts.items()},
            "keypoints": {
                name: {
                    "before_mm": {"mean": _mm(self.residual_before[k, 0]), "max": _mm(self.residual_before[k, 1])},
                    "after_mm": {"mean": _mm(self.residual_after[k, 0]), "max": _mm(self.residual_after[k, 1])},
                    "offset_mm": [_mm(value) for value in self.offsets[k]],
                }
                for k, name in enumerate(self.keypoint_names)
            },
            "mean_before_mm": _mm(float(np.mean(self.residual_before[:, 0]))),
            "mean_after_mm": _mm(float(np.mean(self.residual_after[:, 0]))),
        }

    def table(self) -> str:
        """The per-keypoint residual table [mm], one line per keypoint, as `ibik calibrate` prints."""
        lines = [f"{'keypoint':<10} {'before mean':>11} {'max':>7} {'after mean':>11} {'max':>7}  "
                 "offset [mm] (x, y, z)"]
        for k, name in enumerate(self.keypoint_names):
            before, after = 1000 * self.residual_before[k], 1000 * self.residual_after[k]
            offset = ", ".join(f"{1000 * value:+.0f}" for value in self.offsets[k])
            lines.append(f"{name:<10} {before[0]:11.1f} {before[1]:7.1f} {after[0]:11.1f} {after[1]:7.1f}  ({offset})")
        mean_before, mean_after = 1000 * self.residual_before[:, 0].mean(), 1000 * self.residual_after[:, 0].mean()
        lines.append(f"{'mean':<10} {mean_before:11.1f} {'':>7} {mean_after:11.1f}")
        return "\n".join(lines)


def write_calibration_figures(urdf: Path, static: Path, model: Path | None, result: CalibrationResult,
                              notes: list[str]) -> Path:
    """Write the calibration's figures beside the subject's URDF, as ``<stem>.calibration.json``
    (strict JSON, written atomically); returns that path."""
    path = urdf.with_name(urdf.stem + ".calibration.json")
    write_text_atomically(path, strict_json({"static": static, "model": model, "urdf": urdf,
                                             **result.to_json(), "notes": notes}))
    return path


def _mm(value: float) -> float:
    return round(1000.0 * float(value), 2)
