"""Compiled loops (Numba) of the swivel search (tracking.swivel): both image criteria read at many
candidate poses, each moving one segment end about a pose (a limb's middle joint on its circle).

- :func:`moved_samples`: the overlap term's samples that the moves change, each the pose's sample
  shifted with the placed end (:meth:`ibik_pin.tasks.image.ImageTask.values_at_moves`);
- :func:`segment_squared_distances`, :func:`nearest_of_rows`: every medial-axis sample's distance to
  every segment, and the nearest of some; :func:`candidate_axis_values`: the silhouette-axis term of
  candidate placements of some segments, the others' distances shared;
  :func:`moved_axis_values`: the same for several moves of a pose in one call
  (:mod:`ibik_pin.tasks.silhouette_axis`).

Cached on disk like :mod:`ibik_pin.vision.kernels`; everything a loop here calls lives here, since
Numba's cache checks only the file of the function it compiles.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ibik_pin.vision.kernels import MIN_DEPTH

__all__ = ["candidate_axis_values", "moved_axis_values", "moved_samples", "nearest_of_rows",
           "segment_squared_distances"]


@njit(cache=True, nogil=True)
def moved_samples(pose_samples, interpolation, changing, placed_rows, bounds, placed, positions, points):
    """The samples that several moves of a pose change, each move placing one segment end at
    candidate points (ImageTask.values_at_moves): a changing sample moves with its weight on the
    placed end times that end's displacement.

    Args:
        pose_samples: (M, 3) the samples at the pose [m]; interpolation: (M, K) each sample's
            weights on the segment ends; changing: (moves, M) bool, the samples each move
            changes; placed_rows: (moves,) the end each move places; bounds: (moves + 1,) where
            each move's candidates start in placed (P, 3) [m]; positions: (K, 3) the pose's
            segment ends [m].
        points: written, move by move and candidate by candidate, the changing samples in order.
    """
    out = 0
    for m in range(placed_rows.shape[0]):
        row = placed_rows[m]
        for c in range(bounds[m], bounds[m + 1]):
            shift_x = placed[c, 0] - positions[row, 0]
            shift_y = placed[c, 1] - positions[row, 1]
            shift_z = placed[c, 2] - positions[row, 2]
            for j in range(pose_samples.shape[0]):
                if changing[m, j]:
                    weight = interpolation[j, row]
                    points[out, 0] = pose_samples[j, 0] + weight * shift_x
                    points[out, 1] = pose_samples[j, 1] + weight * shift_y
                    points[out, 2] = pose_samples[j, 2] + weight * shift_z
                    out += 1


@njit(cache=True, nogil=True)
def segment_squared_distances(samples, starts, ends, distances):
    """Squared distance [px^2] of each sample (N, 2) to each segment from starts (S, 2) to ends
    (S, 2): writes distances (S, N)."""
    for k in range(starts.shape[0]):
        along_u, along_v = ends[k, 0] - starts[k, 0], ends[k, 1] - starts[k, 1]
        length_squared = max(along_u * along_u + along_v * along_v, 1e-12)
        for i in range(samples.shape[0]):
            offset_u, offset_v = samples[i, 0] - starts[k, 0], samples[i, 1] - starts[k, 1]
            s = min(max((offset_u * along_u + offset_v * along_v) / length_squared, 0.0), 1.0)
            offset_u -= s * along_u
            offset_v -= s * along_v
            distances[k, i] = offset_u * offset_u + offset_v * offset_v


@njit(cache=True, nogil=True)
def nearest_of_rows(distances, rows, nearest):
    """Per sample, the smallest of distances (S, N) over the segments `rows` (R,): writes nearest
    (N,) (inf without rows)."""
    nearest[:] = np.inf
    for k in rows:
        for i in range(distances.shape[1]):
            nearest[i] = min(nearest[i], distances[k, i])


@njit(cache=True, nogil=True)
def candidate_axis_values(samples, starts, ends, fixed, scale, values):
    """The silhouette-axis term of one view for each candidate placement of some segments:
    -mean over samples of c/2 (1 - exp(-(d/c)^2)), d a sample's distance to the nearest of the
    candidate's segments or of the segments every candidate shares, c = `scale`.

    Args:
        samples: (N, 2) [px]; starts, ends: (C, S, 2) the candidates' segment ends [px];
        fixed: (N,) the squared distance to the shared segments [px^2] (inf: none);
        scale: c [px]; values: (C,) written [px].

    A sample whose `fixed` distance is below its distance to the box of every candidate's ends is
    read once for all candidates (no segment can come nearer): the candidates move one joint, most
    samples lie far.
    """
    candidates, segments = starts.shape[0], starts.shape[1]
    inverse_scale_squared = 1.0 / (scale * scale)
    low_u, low_v, high_u, high_v = np.inf, np.inf, -np.inf, -np.inf
    # Each segment's start, direction and 1 / length^2, contiguous over the candidates: the loop
    # over them, innermost, is vectorised (twice as fast as over the segments, which are one or two).
    start_u, start_v = np.empty((segments, candidates)), np.empty((segments, candidates))
    along_u, along_v = np.empty((segments, candidates)), np.empty((segments, candidates))
    inverse_length_squared = np.empty((segments, candidates))
    for c in range(candidates):
        values[c] = 0.0
        for k in range(segments):
            for u, v in ((starts[c, k, 0], starts[c, k, 1]), (ends[c, k, 0], ends[c, k, 1])):
                low_u, high_u = min(low_u, u), max(high_u, u)
                low_v, high_v = min(low_v, v), max(high_v, v)
            start_u[k, c], start_v[k, c] = starts[c, k, 0], starts[c, k, 1]
            along_u[k, c], along_v[k, c] = ends[c, k, 0] - starts[c, k, 0], ends[c, k, 1] - starts[c, k, 1]
            inverse_length_squared[k, c] = 1.0 / max(along_u[k, c] ** 2 + along_v[k, c] ** 2, 1e-12)
    shared = 0.0  # the samples read once, for every candidate
    best = np.empty(candidates)
    for i in range(samples.shape[0]):
        su, sv = samples[i, 0], samples[i, 1]
        beyond_u = max(low_u - su, su - high_u, 0.0)
        beyond_v = max(low_v - sv, sv - high_v, 0.0)
        # Only where no segment can come nearer; the margin is far above the rounding of either.
        if fixed[i] < (beyond_u * beyond_u + beyond_v * beyond_v) * (1.0 - 1e-9) - 1e-6:
            shared += 1.0 - np.exp(-fixed[i] * inverse_scale_squared)
            continue
        best[:] = fixed[i]
        for k in range(segments):
            for c in range(candidates):
                offset_u, offset_v = su - start_u[k, c], sv - start_v[k, c]
                s = (offset_u * along_u[k, c] + offset_v * along_v[k, c]) * inverse_length_squared[k, c]
                s = min(max(s, 0.0), 1.0)
                offset_u -= s * along_u[k, c]
                offset_v -= s * along_v[k, c]
                best[c] = min(best[c], offset_u * offset_u + offset_v * offset_v)
        # The exponential (a library call, not vectorised) once for the candidates that no segment
        # of their own came nearer to: the same value, for most candidates of a sample.
        at_fixed = 1.0 - np.exp(-fixed[i] * inverse_scale_squared)
        for c in range(candidates):
            values[c] += at_fixed if best[c] == fixed[i] else 1.0 - np.exp(-best[c] * inverse_scale_squared)
    for c in range(candidates):
        values[c] = -0.5 * scale * (values[c] + shared) / max(samples.shape[0], 1)


@njit(cache=True, nogil=True)
def moved_axis_values(samples, known, pose_pixels, pose_in_front, placed_rows, changing, bounds, placed_pixels,
                      placed_depth, start_index, end_index, scale, values, visible):
    """The silhouette-axis term of one view for several moves of a pose, each placing one segment end
    at candidate points (SilhouetteAxisTask.values_at_moves): per move, the distance to the segments
    it leaves alone read from the pose's, and candidate_axis_values over those it changes.

    Args:
        samples: (N, 2) [px]; known: (S, N) each sample's squared distance to each segment at the
            pose [px^2]; pose_pixels: (K, 2) the pose's segment ends [px]; pose_in_front: (K,) bool.
        placed_rows: (M,) the row of pose_pixels each move places; changing: (M, S) bool, the
            segments whose values each move changes; bounds: (M + 1,) where each move's candidates
            start in placed_pixels (P, 2) [px] and placed_depth (P,) [m].
        start_index, end_index: (S,) rows of each segment's ends; scale: c [px].
        values: (P,) written [px]; visible: (P,) written, whether every end is in front of the camera.
    """
    segments = start_index.shape[0]
    fixed = np.empty(samples.shape[0])
    for m in range(placed_rows.shape[0]):
        row = placed_rows[m]
        first, last = bounds[m], bounds[m + 1]
        count = last - first
        fixed[:] = np.inf
        in_front = True
        for k in range(pose_in_front.shape[0]):
            if k != row and not pose_in_front[k]:
                in_front = False
        changed = 0
        for k in range(segments):
            if changing[m, k]:
                changed += 1
            else:
                for i in range(samples.shape[0]):
                    fixed[i] = min(fixed[i], known[k, i])
        starts, ends = np.empty((count, changed, 2)), np.empty((count, changed, 2))
        column = 0
        for k in range(segments):
            if not changing[m, k]:
                continue
            for c in range(count):
                for end_row, out in ((start_index[k], starts), (end_index[k], ends)):
                    if end_row == row:
                        out[c, column, 0], out[c, column, 1] = placed_pixels[first + c, 0], placed_pixels[first + c, 1]
                    else:
                        out[c, column, 0], out[c, column, 1] = pose_pixels[end_row, 0], pose_pixels[end_row, 1]
            column += 1
        candidate_axis_values(samples, starts, ends, fixed, scale, values[first:last])
        for c in range(count):
            visible[first + c] = in_front and placed_depth[first + c] > MIN_DEPTH
