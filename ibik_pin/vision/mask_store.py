"""A camera's silhouettes over a whole video, each kept as the crop of its bounding box.

A person fills a few percent of a frame: the four 1088 x 1920 cameras of Pose2Sim's demo take
8.4 MB of bool masks per frame, the crops of their silhouettes about a tenth of that, so a long video
decoded up front fits in memory. Each access rebuilds the full frame, which the tracker reads once
per frame.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from ibik_pin.exceptions import InputError

__all__ = ["CroppedMasks"]


class CroppedMasks(Sequence):
    """Bool masks of one size (width, height), stored as bounding-box crops.

    Supports len, indexing (a full (H, W) bool mask, a new array each time), iteration,
    assignment of a full mask (`masks[i] = mask`) and `append`.
    """

    def __init__(self, size: tuple[int, int], masks: Iterable[np.ndarray] = ()) -> None:
        self.size = (int(size[0]), int(size[1]))
        self._crops: list[tuple[int, int, np.ndarray]] = []
        for mask in masks:
            self.append(mask)

    def _crop(self, mask: np.ndarray) -> tuple[int, int, np.ndarray]:
        mask = np.asarray(mask)
        if mask.shape != (self.size[1], self.size[0]):
            raise InputError(f"mask: expected {self.size[1]} x {self.size[0]} (rows x columns), found {mask.shape}")
        rows = np.flatnonzero(mask.any(axis=1))
        if rows.size == 0:
            return 0, 0, np.zeros((0, 0), bool)
        columns = np.flatnonzero(mask.any(axis=0))
        top, left = int(rows[0]), int(columns[0])
        return top, left, mask[top : rows[-1] + 1, left : columns[-1] + 1].astype(bool, copy=True)

    def append(self, mask: np.ndarray) -> None:
        """Add a full (H, W) mask (non-zero = person)."""
        self._crops.append(self._crop(mask))

    def __len__(self) -> int:
        return len(self._crops)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        top, left, crop = self._crops[index]
        full = np.zeros((self.size[1], self.size[0]), bool)
        full[top : top + crop.shape[0], left : left + crop.shape[1]] = crop
        return full

    def __setitem__(self, index: int, mask: np.ndarray) -> None:
        self._crops[index] = self._crop(mask)

    def crop(self, index: int) -> tuple[int, int, np.ndarray]:
        """The mask's bounding-box crop as stored: (top, left, crop); an empty mask gives a 0 x 0 crop.
        Work on a crop costs a fraction of work on the full frame."""
        return self._crops[index]

    def set_crop(self, index: int, top: int, left: int, crop: np.ndarray) -> None:
        """Replace mask `index` by `crop` (bool) placed at (top, left) [px], cut to its own bounding box."""
        self._crops[index] = self._placed(top, left, crop)

    def append_crop(self, top: int, left: int, crop: np.ndarray) -> None:
        """Add a mask given as `crop` (bool) placed at (top, left) [px], without building the full frame."""
        self._crops.append(self._placed(top, left, crop))

    def _placed(self, top: int, left: int, crop: np.ndarray) -> tuple[int, int, np.ndarray]:
        crop = np.asarray(crop, bool)
        width, height = self.size
        if top < 0 or left < 0 or top + crop.shape[0] > height or left + crop.shape[1] > width:
            raise InputError(f"mask crop: {crop.shape[0]} x {crop.shape[1]} at (top {top}, left {left}) leaves the "
                             f"{height} x {width} frame")
        rows = np.flatnonzero(crop.any(axis=1))
        if rows.size == 0:
            return 0, 0, np.zeros((0, 0), bool)
        columns = np.flatnonzero(crop.any(axis=0))
        return (top + int(rows[0]), left + int(columns[0]),
                crop[rows[0] : rows[-1] + 1, columns[0] : columns[-1] + 1].copy())

    def __iter__(self) -> Iterator[np.ndarray]:
        return (self[index] for index in range(len(self)))

    def fitted(self, size: tuple[int, int]) -> CroppedMasks:
        """The same masks padded with zeros or cut at the right and bottom to `size` (width, height)."""
        fitted = CroppedMasks(size)
        width, height = fitted.size
        for top, left, crop in self._crops:
            kept = crop[: max(height - top, 0), : max(width - left, 0)]
            fitted._crops.append((top, left, kept) if kept.size else (0, 0, np.zeros((0, 0), bool)))
        return fitted

    @property
    def nbytes(self) -> int:
        """Bytes held by the crops."""
        return sum(crop.nbytes for _, _, crop in self._crops)
