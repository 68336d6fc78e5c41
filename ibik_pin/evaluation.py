"""Errors against ground truth: eq. (9) of the paper, per joint, in millimetres."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ibik_pin.exceptions import InputError

#: The joints left to the image in the paper's real-motion experiments (Section 4): no target is
#: given for them, and Tables 1 and 2 report their eq. (9) errors.
ESTIMATED = ("LElbow", "RElbow", "LKnee", "RKnee")


def per_frame_errors(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Euclidean distance of each joint to its truth, shape (F, K) [units of the inputs].

    Args:
        estimated, truth: (F, K, 3) joint positions; NaN in the truth marks an unknown joint.
    """
    estimated = np.asarray(estimated, dtype=float)
    truth = np.asarray(truth, dtype=float)
    if estimated.shape != truth.shape or estimated.ndim != 3 or estimated.shape[2] != 3:
        raise InputError(f"estimated and truth must both be (F, K, 3), got {estimated.shape} and {truth.shape}")
    return np.linalg.norm(estimated - truth, axis=2)


def mean_joint_errors_mm(
    estimated: np.ndarray, truth: np.ndarray, names: Sequence[str], joints: Sequence[str] | None = None
) -> dict[str, float]:
    """Eq. (9): mean over frames of the distance to the true joint, per joint [mm] (inputs in m)."""
    errors = per_frame_errors(estimated, truth) * 1000.0
    joints = list(names) if joints is None else list(joints)
    missing = [joint for joint in joints if joint not in names]
    if missing:
        raise InputError(f"joints {', '.join(missing)} are not among {', '.join(names)}")
    return {joint: float(np.nanmean(errors[:, list(names).index(joint)])) for joint in joints}
