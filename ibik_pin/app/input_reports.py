"""What the application found of its inputs, as report.json's "silhouettes" and "triangulation":
records that the input modules fill and the report writes."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["SilhouetteQuality", "TriangulationReport"]


@dataclass
class SilhouetteQuality:
    """How well each camera's silhouettes hold the subject (report.json's "silhouettes").

    Attributes:
        segmenter: "mediapipe", "mog2" or "masks" (given).
        targets_inside_per_view: per camera, per frame, the share of the projected targets inside
            the silhouette [0-1] (None in a frame without targets).
        targets_inside_mean: per camera, its mean over frames.
        mask_area_per_view: per camera, per frame, the silhouette's area [px].
    """

    segmenter: str
    targets_inside_per_view: dict[str, list[float | None]] = field(default_factory=dict)
    targets_inside_mean: dict[str, float | None] = field(default_factory=dict)
    mask_area_per_view: dict[str, list[int]] = field(default_factory=dict)


@dataclass
class TriangulationReport:
    """How the targets were triangulated from the videos (report.json's "triangulation").

    Attributes:
        file: the triangulated TRC written with the outputs.
        keypoints: its keypoint names; tracked_keypoints: those used as targets.
        frames_swapped_per_view: per camera, the frames whose left and right the detector had
            exchanged (resolved across views).
        landmarks_used_per_view: per camera, the share of landmarks it contributed [0-1].
        reprojection_median_m: median over frames of the median reprojection error, at the
            point's depth [m].
    """

    file: str
    keypoints: list[str]
    tracked_keypoints: list[str]
    frames_swapped_per_view: dict[str, int]
    landmarks_used_per_view: dict[str, float]
    reprojection_median_m: float | None
