"""An arm's own overlap: the image criterion's support along an arm, read no deeper than an arm is thick.

The support image rewards a point by its depth inside the silhouette up to one cap for the whole
body, a limb's half width (tracking.views.LIMB_HALF_WIDTH, 40 mm at the subject's distance). An
arm is thinner than that cap allows for: the forearm's radius is about 35 mm on the model and
0.7-1.4 times that on the sweep's bodies, and a point a few millimetres off the forearm's axis
(target noise, lengths, an elliptical section) already reads less than the cap, while anywhere over
the trunk reads the whole cap. So along an elbow's swivel circle the overlap rises toward the
trunk: on the 2-view sweep (docs/sweep.md, "The elbows' tail"), where the criterion's best swivel
was more than 20 degrees from the truth, it lay nearer the trunk than the truth in nearly every
frame, the overlap alone peaking 20-99 degrees off (median per elbow) while the silhouette-axis term
peaked 3-50 degrees off.

Read no deeper than `ARM_CAP`, every swivel whose arm lies well inside the silhouettes scores the
same on the overlap, over the trunk or on the arm's own silhouette; the overlap keeps telling a
swivel that leaves the silhouettes, and the axis term chooses among the rest. The swivel search
(tracking.swivel.SwivelSearch.arm_cap) reads it only where the body-wide overlap's choice lies
nearer the trunk: a hanging arm's swivels all lie inside the silhouettes, and there the axis term
alone is no guide.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ibik_pin.tasks.image import ImageTask

__all__ = ["ARM_CAP", "REFUTE_SAMPLES", "arm_overlap", "cap_arm_overlap", "outside_counts"]

#: Depth [m] at which an arm's support is read full (docs/sweep.md: among 10, 20 and 30 mm, 20 put the
#: criterion's best swivel nearest the truth on the tail's elbows).
ARM_CAP = 0.02


def arm_overlap(image: ImageTask, roots: np.ndarray, middles: np.ndarray, ends: np.ndarray,
                cap: float = ARM_CAP) -> np.ndarray:
    """The image task's overlap (its mean over every sample and view, as values_at) of the two
    segments of limbs (L, 3) with the middle joint at candidates `middles` (L, C, 3), each sample's
    support read no deeper than `cap` [m] seen at the limb's root; only the limb's own samples
    (the image task's samples_per_segment on root-middle and middle-end): the rest of the body adds
    the same to every candidate of a limb. Shape (L, C)."""
    views = [view for view in image.views if view.support.enabled]
    count = image.samples_per_segment
    fractions = (np.arange(count) + 0.5) / count
    root, end, middle = roots[:, None, None], ends[:, None, None], middles[:, :, None]
    points = np.concatenate([root + fractions[:, None] * (middle - root),
                             middle + fractions[:, None] * (end - middle)], axis=2)  # (L, C, 2 count, 3)
    total = np.zeros(middles.shape[:2])
    for view, read in zip(views, image.supports_at(points.reshape(-1, 3)), strict=True):
        caps = np.asarray(view.camera.pixel_radius(roots, np.full(len(roots), float(cap))), dtype=float)
        caps = np.where(np.isfinite(caps), np.maximum(caps, 1.0), np.inf)  # a root behind the camera: no cap
        total += np.minimum(read.reshape(points.shape[:3]), caps[:, None, None]).sum(axis=2)
    return total / (len(image.segments) * count * max(len(views), 1))


def cap_arm_overlap(terms: Sequence[tuple[object, float]], weighted: np.ndarray, roots: np.ndarray,
                    middles: np.ndarray, ends: np.ndarray, cap: float = ARM_CAP) -> None:
    """Replace, in the weighted values (T, L, C) of the swivel search's terms for arms (L, 3) at
    candidates `middles` (L, C, 3), every image task's (ImageTask) by the arm's own overlap
    (arm_overlap) times its weight; a term weighted 0 or disabled is left as it is."""
    for index, (task, weight) in enumerate(terms):
        if isinstance(task, ImageTask) and weight != 0.0 and task.enabled and len(roots):
            weighted[index] = weight * arm_overlap(task, roots, middles, ends, cap)


#: Points sampled on each of a limb's two segments to count where it leaves the silhouettes.
REFUTE_SAMPLES = 6


def outside_counts(inside_silhouettes: Callable[[np.ndarray], np.ndarray], roots: np.ndarray,
                   middles: np.ndarray, ends: np.ndarray, samples: int = REFUTE_SAMPLES) -> np.ndarray:
    """How many of a limb's points lie outside the silhouettes (in some view), for limbs (L, 3)
    with their middle joints at `middles` (L, 3) or at candidates (L, C, 3): shape (L,) or (L, C).
    The points: `samples` on each segment, root-middle and middle-end, at the centres of equal parts."""
    middles = np.asarray(middles, dtype=float)
    single = middles.ndim == 2
    placed = middles[:, None] if single else middles
    fractions = (np.arange(samples) + 0.5) / samples
    root = np.broadcast_to(roots[:, None, None], (*placed.shape[:2], 1, 3))
    end = np.broadcast_to(ends[:, None, None], (*placed.shape[:2], 1, 3))
    middle = placed[:, :, None]
    points = np.concatenate([root + fractions[:, None] * (middle - root),
                             middle + fractions[:, None] * (end - middle)], axis=2)  # (L, C, 2 samples, 3)
    outside = ~inside_silhouettes(points.reshape(-1, 3)).reshape(points.shape[:3])
    counts = outside.sum(axis=2)
    return counts[:, 0] if single else counts
