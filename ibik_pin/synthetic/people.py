"""A second real person composited into a calibrated multi-view clip of one person.

The subject's own pixels from another moment of the clip (its segmentation, every view) are pasted
into each view as a person standing elsewhere in the room: moved by a 3D offset on the floor, so
that every view shows the copy where a person at that place would appear (its centre projected,
its size scaled by the depths' ratio: a similarity per view, exact for the centre and within a few
per cent elsewhere for a body a few metres away). The copy occludes the subject where it is the
nearer of the two in that view and is hidden behind the subject's silhouette otherwise. The copy
walks: its offset follows a path in time; its pose is the subject's `shift` frames later.

This gives a two-person clip with a known subject (the original person, whose reference
triangulation is untouched) from real images, for the tests of person association.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from ibik_pin.exceptions import InputError

__all__ = ["circle_path", "composite_second_person"]


def circle_path(frames: int, radius_m: float, start_deg: float, speed_m_s: float, frame_rate: float) -> np.ndarray:
    """(F, 3) offsets on the floor (Y up: X and Z move) along a circle about the subject, walked at
    `speed_m_s` from `start_deg` (counter-clockwise seen from above)."""
    angle = np.radians(start_deg) + speed_m_s / radius_m * np.arange(frames) / frame_rate
    return radius_m * np.column_stack((np.cos(angle), np.zeros(frames), np.sin(angle)))


def composite_second_person(frames: Sequence[Sequence[np.ndarray]], masks: Sequence[Sequence[np.ndarray]],
                            cameras: Sequence, centres_m: np.ndarray, offsets_m: np.ndarray,
                            shift: int) -> list[list[np.ndarray]]:
    """Each view's frames with the subject's copy pasted in.

    Args:
        frames: V views of F frames (H, W, 3) uint8.
        masks: V views of F (H, W) bool silhouettes of the subject.
        cameras: V cameras projecting `centres_m`'s frame.
        centres_m: (F, 3) the subject's centre (e.g. the hips' midpoint) [m].
        offsets_m: (F, 3) where the copy stands relative to the subject's centre of its source frame [m].
        shift: the copy of frame t is the subject of frame (t + shift) mod F.
    """
    views, count = len(frames), len(frames[0])
    if len(masks) != views or len(cameras) != views or centres_m.shape != (count, 3) or offsets_m.shape != (count, 3):
        raise InputError(f"composite_second_person: expected {views} views of {count} frames, masks, cameras and "
                         f"(F, 3) centres and offsets; found {len(masks)} masks, {len(cameras)} cameras, "
                         f"{centres_m.shape} and {offsets_m.shape}")
    result = []
    for view in range(views):
        camera = cameras[view]
        out = []
        for frame in range(count):
            source = (frame + shift) % count
            image = np.array(frames[view][frame], copy=True)
            centre = centres_m[source]
            moved = centre + offsets_m[frame]
            if not (np.isfinite(centre).all() and np.isfinite(moved).all()):
                out.append(image)
                continue
            depth_source = camera.points_camera(centre[None])[0, 2]
            depth_moved = camera.points_camera(moved[None])[0, 2]
            depth_subject = camera.points_camera(centres_m[frame][None])[0, 2]
            if depth_moved <= 0.1:
                out.append(image)
                continue
            scale = depth_source / depth_moved
            before, after = camera.project(np.array([centre, moved]))
            warp = np.array([[scale, 0.0, after[0] - scale * before[0]], [0.0, scale, after[1] - scale * before[1]]])
            height, width = image.shape[:2]
            copy = cv2.warpAffine(np.asarray(frames[view][source]), warp, (width, height), flags=cv2.INTER_LINEAR)
            region = cv2.warpAffine(np.asarray(masks[view][source], np.uint8) * 255, warp, (width, height),
                                    flags=cv2.INTER_LINEAR) > 127
            if depth_moved > depth_subject:  # behind the subject: the subject's pixels stay in front
                region &= ~np.asarray(masks[view][frame], bool)
            image[region] = copy[region]
            out.append(image)
        result.append(out)
    return result
