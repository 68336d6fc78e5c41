"""A frame's images as arrays in a slot of a shared memory mapping, and back
(readahead.image_process): what the child process writes and the parent reads in place.

A frame's FrameImages become a small picklable description and a list of arrays (`pack_frame`):
per view its support window, its silhouette bit-packed and its inside distance (for a read outside
the window, vision.support_parts), and its medial axis. The arrays go into one slot
(`FrameSlots.write`), each on a cache line; the parent rebuilds the FrameImages on read-only views
of the slot (`unpack_frame`), valid until the slot is handed back.
"""

from __future__ import annotations

import math
import mmap

import numpy as np

from ibik_pin.readahead.frame_images import FrameImages
from ibik_pin.tasks import View
from ibik_pin.tasks.silhouette_axis import AxisView
from ibik_pin.vision.support import SupportImage
from ibik_pin.vision.support_parts import WindowedParts, support_from_parts, windowed_parts

__all__ = ["ALIGNMENT", "FrameSlots", "pack_frame", "slot_bytes_for", "unpack_frame"]

ALIGNMENT = 64  # bytes; each array starts on a cache line


class FrameSlots:
    """Writes and reads arrays at offsets of the `count` slots of the shared mapping."""

    def __init__(self, memory: mmap.mmap, slot_bytes: int, count: int) -> None:
        self.memory, self.slot_bytes, self.count = memory, slot_bytes, count

    def write(self, slot: int, arrays: list[np.ndarray]) -> list:
        """Each array's place: (offset, shape, dtype) in the slot, or the array itself if the slot is full."""
        places: list = []
        offset = 0
        base = slot * self.slot_bytes
        for array in arrays:
            array = np.ascontiguousarray(array)
            if offset + array.nbytes > self.slot_bytes:
                places.append(array)
                continue
            target = np.frombuffer(self.memory, np.uint8, array.nbytes, base + offset)
            target[:] = array.reshape(-1).view(np.uint8)
            places.append((offset, array.shape, array.dtype.str))
            offset += -(-array.nbytes // ALIGNMENT) * ALIGNMENT
        return places

    def read(self, slot: int, places: list) -> list[np.ndarray]:
        """The arrays `write` placed, read-only views of the slot (valid until it is handed back)."""
        arrays = []
        for place in places:
            if isinstance(place, np.ndarray):
                arrays.append(place)
                continue
            offset, shape, dtype = place
            array = np.frombuffer(self.memory, dtype, math.prod(shape), slot * self.slot_bytes + offset).reshape(shape)
            array.setflags(write=False)
            arrays.append(array)
        return arrays


def pack_frame(images) -> tuple[tuple, list[np.ndarray]]:
    """FrameImages as (a picklable description, its arrays)."""
    arrays: list[np.ndarray] = []

    def add(array: np.ndarray) -> int:
        arrays.append(array)
        return len(arrays) - 1

    views: list[tuple] = []
    for view in images.views:
        parts = windowed_parts(view.support)
        if parts is not None:  # the arrays by their index in `arrays`
            views.append(("window", add(parts.values), parts.row, parts.column, parts.size, add(parts.mask_bits),
                          add(parts.inside_values), parts.inside_box, parts.silhouette_box, parts.inside_limit,
                          parts.inside_cap_px, parts.outside_cap_px, parts.smooth_sigma_px))
        else:
            views.append(("values", add(view.support.values), view.support.enabled))
    axes = None if images.axis_views is None else [(add(axis.pixels), axis.robust_scale_px)
                                                  for axis in images.axis_views]
    return (views, axes, list(images.disabled)), arrays


def unpack_frame(description: tuple, arrays: list[np.ndarray], cameras: list) -> FrameImages:
    views_packed, axes, disabled = description
    views = []
    for camera, (kind, values, *fields) in zip(cameras, views_packed, strict=True):
        if kind == "window":
            row, column, size, bits, inside, inside_box, silhouette_box, inside_limit, inside_cap, outside_cap, sigma \
                = fields
            support = support_from_parts(WindowedParts(arrays[values], row, column, size, arrays[bits], arrays[inside],
                                                       inside_box, silhouette_box, inside_limit, inside_cap,
                                                       outside_cap, sigma))
        else:
            support = SupportImage(arrays[values], enabled=fields[0])
        views.append(View(camera, support))
    axis_views = None if axes is None else [AxisView(camera, arrays[index], scale)
                                            for camera, (index, scale) in zip(cameras, axes, strict=True)]
    return FrameImages(views, disabled, axis_views)


def slot_bytes_for(first: FrameImages) -> int:
    """Room for a frame's arrays: every view's support and inside distance over the whole frame,
    its silhouette's bits, and four times the first frame's medial axes."""
    room = 0
    for view in first.views:
        width, height = view.support.size
        room += 8 * width * height + width * height // 8 + 3 * ALIGNMENT
    if first.axis_views is not None:
        room += sum(4 * axis.pixels.nbytes + 4096 for axis in first.axis_views)
    return max(room, ALIGNMENT)
