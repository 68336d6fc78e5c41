"""Compiled loops (Numba) of the image criteria: what runs at every solver step over every sample.

The image level reads one or two hundred skeleton samples per view at every step. In numpy each
read is some forty array operations of a few microseconds each on arrays of a hundred elements:
the overhead of the calls, not the arithmetic, made the image criterion half of a whole-body step
(683 us of 1074 us on real boxing, 2 views). These loops do the same arithmetic point by point,
in one call per view.

- :func:`pinhole_project`: points through an OpenCV pinhole camera, distortion included, with the
  projection's analytic Jacobian (:class:`ibik_pin.vision.pinhole.PinholeCamera` projects with it;
  :func:`pinhole_project_views`: through several cameras in one call; :func:`pinhole_pixels_views`:
  the same without the Jacobian).
- :func:`support_sample`, :func:`support_overlap_at_segments`, :func:`support_values`: read a
  support image by bilinear interpolation with the interpolant's exact derivative: at pixels
  (:meth:`ibik_pin.vision.support.SupportImage.sample`); at projected samples along segments, their
  sum and each segment end's d support / d X_world; or the values alone at projected points.
  :func:`pinhole_overlap_at_segments`: the segments' reading with the samples placed from the
  frames' positions and projected through a pinhole camera in the same loop.
- :func:`axis_value_and_pixel_gradient`: the silhouette-axis term of one view and its derivative
  with respect to the projected segment ends (:func:`axis_value_and_frame_gradient`: with respect
  to the ends in the world) (:mod:`ibik_pin.tasks.silhouette_axis`).

The swivel search's reads of both criteria at many candidate poses are in
:mod:`ibik_pin.vision.candidate_kernels`.

They are compiled on first use and cached on disk (Numba's ``cache=True``), so only the first run
on a machine pays the compilation (these a few seconds; with the solvers' level loop,
:mod:`ibik_pin.solvers.kernels`, about 25 s on a 2-core machine).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["MIN_DEPTH", "axis_value_and_frame_gradient", "axis_value_and_pixel_gradient", "pinhole_overlap_at_segments",
           "pinhole_parameters", "pinhole_pixels_views", "pinhole_project", "pinhole_project_views",
           "support_overlap_at_segments", "support_sample", "support_values"]

# A point nearer the camera plane than this [m] is behind it: it reads 0 and pulls nowhere.
MIN_DEPTH = 1e-6


def pinhole_parameters(rotation: np.ndarray, translation: np.ndarray, intrinsics: np.ndarray,
                       distortion_terms) -> np.ndarray:
    """A pinhole camera's parameters as :func:`pinhole_project` reads them, shape (21,): R (row
    major), t [m], fx, fy, cx, cy [px], k1, k2, p1, p2, k3."""
    return np.concatenate((np.asarray(rotation, dtype=np.float64).ravel(), np.asarray(translation, dtype=np.float64),
                           [intrinsics[0, 0], intrinsics[1, 1], intrinsics[0, 2], intrinsics[1, 2]],
                           np.asarray(distortion_terms, dtype=np.float64)))


@njit(cache=True, nogil=True)
def _read_support(u, v, support, row0, column0, width, height):
    """The bilinear support at pixel (u, v) and its derivative (d/du, d/dv); `support` holds the
    frame's values from (row0, column0) on. Returns (value, d_u, d_v, inside the window); a NaN
    pixel reads 0 and pulls nowhere."""
    if u != u or v != v:
        return 0.0, 0.0, 0.0, True
    clipped_u = min(max(u, 0.0), width - 1.0)
    clipped_v = min(max(v, 0.0), height - 1.0)
    # The cell's top-left corner; on the last column/row the cell to its left/above, so that
    # u = W - 1 interpolates with weight 1 on the last pixel.
    column = min(int(clipped_u), max(width - 2, 0))
    row = min(int(clipped_v), max(height - 2, 0))
    right = min(width - 1, 1)
    down = min(height - 1, 1)
    local_row, local_column = row - row0, column - column0
    if (local_column < 0 or local_row < 0 or local_column + right >= support.shape[1]
            or local_row + down >= support.shape[0]):
        return 0.0, 0.0, 0.0, False
    fraction_u = clipped_u - column
    fraction_v = clipped_v - row
    top_left = np.float64(support[local_row, local_column])
    top_right = np.float64(support[local_row, local_column + right])
    bottom_left = np.float64(support[local_row + down, local_column])
    bottom_right = np.float64(support[local_row + down, local_column + right])
    across_top = top_right - top_left
    across_bottom = bottom_right - bottom_left
    top = top_left + fraction_u * across_top
    bottom = bottom_left + fraction_u * across_bottom
    value = top + fraction_v * (bottom - top)
    # The exact derivative of the interpolant; zero along an axis the clip moved (outside the image).
    d_u = (1.0 - fraction_v) * across_top + fraction_v * across_bottom if clipped_u == u else 0.0
    d_v = bottom - top if clipped_v == v else 0.0
    return value, d_u, d_v, True


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _project_point(camera, px, py, pz):
    """A world point's pixel (u, v) [px], depth [m] and d(u, v)/dX_world (2 x 3, row major) [px/m]
    through the pinhole `camera` (:func:`pinhole_parameters`). A point on the camera plane goes to
    infinity."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = camera[0:9]
    fx, fy, cx, cy = camera[12], camera[13], camera[14], camera[15]
    k1, k2, p1, p2, k3 = camera[16], camera[17], camera[18], camera[19], camera[20]
    depth = r20 * px + r21 * py + r22 * pz + camera[11]
    inverse_depth = 1.0 / depth
    x = (r00 * px + r01 * py + r02 * pz + camera[9]) * inverse_depth
    y = (r10 * px + r11 * py + r12 * pz + camera[10]) * inverse_depth
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    radial_slope = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r^2
    xy = x * y
    two_x_x, two_y_y = 2.0 * x * x, 2.0 * y * y  # each shared by a distorted coordinate and its slope
    u = fx * (x * radial + 2.0 * p1 * xy + p2 * (r2 + two_x_x)) + cx
    v = fy * (y * radial + p1 * (r2 + two_y_y) + 2.0 * p2 * xy) + cy
    # d(x_d, y_d)/d(x, y) (the two off-diagonal terms are equal) . d(x, y)/dX_cam, scaled by f.
    dxd_dx = radial + two_x_x * radial_slope + 2.0 * p1 * y + 6.0 * p2 * x
    dyd_dy = radial + two_y_y * radial_slope + 6.0 * p1 * y + 2.0 * p2 * x
    cross = 2.0 * xy * radial_slope + 2.0 * p1 * x + 2.0 * p2 * y
    a0, a1 = fx * dxd_dx * inverse_depth, fx * cross * inverse_depth
    a2 = -fx * (dxd_dx * x + cross * y) * inverse_depth
    b0, b1 = fy * cross * inverse_depth, fy * dyd_dy * inverse_depth
    b2 = -fy * (cross * x + dyd_dy * y) * inverse_depth
    # To the world: d/dX_world = d/dX_cam . R.
    return (u, v, depth,
            a0 * r00 + a1 * r10 + a2 * r20, a0 * r01 + a1 * r11 + a2 * r21, a0 * r02 + a1 * r12 + a2 * r22,
            b0 * r00 + b1 * r10 + b2 * r20, b0 * r01 + b1 * r11 + b2 * r21, b0 * r02 + b1 * r12 + b2 * r22)


@njit(cache=True, nogil=True, error_model="numpy")  # as _project_point, inlined here
def pinhole_project(points, camera, pixels, jacobian, depth):
    """Project world points (N, 3) [m] through a pinhole camera (21,) (:func:`pinhole_parameters`):
    writes pixels (N, 2) [px], d pixels / d X_world (N, 2, 3) [px/m] and depth (N,) [m]."""
    for m in range(points.shape[0]):
        (pixels[m, 0], pixels[m, 1], depth[m], jacobian[m, 0, 0], jacobian[m, 0, 1], jacobian[m, 0, 2],
         jacobian[m, 1, 0], jacobian[m, 1, 1], jacobian[m, 1, 2]) = _project_point(
            camera, points[m, 0], points[m, 1], points[m, 2])


@njit(cache=True, nogil=True, error_model="numpy")  # as _project_point, inlined here
def pinhole_project_views(points, cameras, pixels, jacobian, depth):
    """:func:`pinhole_project` through V cameras (V, 21) at once: writes pixels (V, N, 2),
    jacobian (V, N, 2, 3) and depth (V, N)."""
    for view in range(cameras.shape[0]):
        pinhole_project(points, cameras[view], pixels[view], jacobian[view], depth[view])


@njit(cache=True, nogil=True, error_model="numpy")  # as _project_point, inlined here
def pinhole_pixels_views(points, cameras, pixels, depth):
    """:func:`pinhole_project_views` without the Jacobian (inlined, the compiler drops its
    arithmetic: half the time): writes pixels (V, N, 2) and depth (V, N)."""
    for view in range(cameras.shape[0]):
        for m in range(points.shape[0]):
            pixels[view, m, 0], pixels[view, m, 1], depth[view, m] = _project_point(
                cameras[view], points[m, 0], points[m, 1], points[m, 2])[:3]


@njit(cache=True, nogil=True)
def support_sample(pixels, support, row0, column0, width, height, values, gradient):
    """The support and its derivative at pixels (M, 2) [px]: writes values (M,) [support units]
    and gradient (M, 2) d values / d (u, v); `support` as in :func:`support_overlap_at_segments`.

    Returns complete (False: a pixel read outside `support`, the outputs partly written).
    """
    for m in range(pixels.shape[0]):
        values[m], gradient[m, 0], gradient[m, 1], inside = _read_support(
            pixels[m, 0], pixels[m, 1], support, row0, column0, width, height)
        if not inside:
            return False
    return True


@njit(cache=True, nogil=True)
def support_overlap_at_segments(pixels, jacobians, depth, support, row0, column0, width, height, sample_start,
                                sample_end, sample_fraction, frame_gradient):
    """Sum of the support at projected samples p = (1 - s) X_a + s X_b of segments between frames,
    each sample's derivative passed on to the frames: (1 - s) of it to X_a, s to X_b.

    Args:
        pixels: (M, 2) the samples' projections [px]; jacobians: (M, 2, 3) their d pixels / d X_world
            [px/m]; depth: (M,) [m] (a sample nearer than MIN_DEPTH is behind the camera: it reads 0).
        support: (h, w) float32 support values of the frame from (row0, column0) on.
        width, height: the frame's size [px].
        sample_start, sample_end: (M,) each sample's rows a and b of frame_gradient;
            sample_fraction: (M,) its s.
        frame_gradient: (K, 3) to which each frame's d support / d X_world [support units/m] is
            added, only when every sample read inside `support`.

    Returns:
        (sum of the support over the samples in front of the camera, complete): complete is False,
        and frame_gradient untouched, when a sample reads outside `support`; the caller then reads
        the whole frame instead.
    """
    gradient = np.zeros_like(frame_gradient)
    total = 0.0
    for m in range(pixels.shape[0]):
        if not depth[m] > MIN_DEPTH:
            continue
        value, d_u, d_v, inside = _read_support(pixels[m, 0], pixels[m, 1], support, row0, column0, width, height)
        if not inside:
            return total, False
        total += value
        a, b, s = sample_start[m], sample_end[m], sample_fraction[m]
        for axis in range(3):
            pull = d_u * jacobians[m, 0, axis] + d_v * jacobians[m, 1, axis]
            gradient[a, axis] += (1.0 - s) * pull
            gradient[b, axis] += s * pull
    frame_gradient += gradient
    return total, True


@njit(cache=True, nogil=True, error_model="numpy")  # as _project_point, inlined here
def pinhole_overlap_at_segments(positions, frame_ids, sample_start, sample_end, sample_fraction, camera, support,
                                row0, column0, width, height, frame_gradient):
    """:func:`support_overlap_at_segments` of the samples placed and projected here: sample m at
    (1 - s) X_a + s X_b, X_a = positions[frame_ids[a]] (positions (F, 3) [m] of every model frame),
    through the pinhole `camera` (:func:`pinhole_parameters`). One call per view for the whole
    reading (numpy's placing and the projection's wrapper were half of an arm's image step)."""
    gradient = np.zeros_like(frame_gradient)
    total = 0.0
    for m in range(sample_start.shape[0]):
        a, b, s = sample_start[m], sample_end[m], sample_fraction[m]
        start, end = frame_ids[a], frame_ids[b]
        u, v, depth, j00, j01, j02, j10, j11, j12 = _project_point(
            camera, (1.0 - s) * positions[start, 0] + s * positions[end, 0],
            (1.0 - s) * positions[start, 1] + s * positions[end, 1],
            (1.0 - s) * positions[start, 2] + s * positions[end, 2])
        if not depth > MIN_DEPTH:
            continue
        value, d_u, d_v, inside = _read_support(u, v, support, row0, column0, width, height)
        if not inside:
            return total, False
        total += value
        pull_x, pull_y, pull_z = d_u * j00 + d_v * j10, d_u * j01 + d_v * j11, d_u * j02 + d_v * j12
        gradient[a, 0] += (1.0 - s) * pull_x
        gradient[a, 1] += (1.0 - s) * pull_y
        gradient[a, 2] += (1.0 - s) * pull_z
        gradient[b, 0] += s * pull_x
        gradient[b, 1] += s * pull_y
        gradient[b, 2] += s * pull_z
    frame_gradient += gradient
    return total, True


@njit(cache=True, nogil=True)
def support_values(pixels, depth, support, row0, column0, width, height, behind, values):
    """The support at projected points, `behind` for those behind the camera: writes values (M,)
    [support units].

    Same arguments as :func:`support_overlap_at_segments`; returns complete (False: a point read outside
    `support`, values partly written).
    """
    for m in range(pixels.shape[0]):
        values[m] = behind
        if not depth[m] > MIN_DEPTH:
            continue
        value, _, _, inside = _read_support(pixels[m, 0], pixels[m, 1], support, row0, column0, width, height)
        if not inside:
            return False
        values[m] = value
    return True


@njit(cache=True, nogil=True)
def axis_value_and_pixel_gradient(samples, end_pixels, start_index, end_index, scale, pixel_gradient):
    """h_axis of one view and its derivative with respect to the projected segment ends.

    Args:
        samples: (N, 2) medial-axis samples [px].
        end_pixels: (K, 2) projected segment ends [px].
        start_index, end_index: (S,) rows of end_pixels of each segment's ends.
        scale: c [px], the robust scale.
        pixel_gradient: (K, 2) to which dh/d end_pixels is added.

    Returns:
        The view's h_axis [px]: -mean over samples of c/2 (1 - exp(-(d/c)^2)), d the distance to
        the nearest segment (the first of equals).
    """
    count = samples.shape[0]
    segments = start_index.shape[0]
    inverse_scale_squared = 1.0 / (scale * scale)
    # Segment by segment over all samples, the nearest so far kept per sample: long loops without
    # branches, which the compiler vectorises (a third faster than sample by sample).
    sample_u, sample_v = np.ascontiguousarray(samples[:, 0]), np.ascontiguousarray(samples[:, 1])
    best = np.full(count, np.inf)
    best_segment = np.zeros(count, dtype=np.int64)
    for segment in range(segments):
        a, b = start_index[segment], end_index[segment]
        start_u, start_v = end_pixels[a, 0], end_pixels[a, 1]
        along_u, along_v = end_pixels[b, 0] - start_u, end_pixels[b, 1] - start_v
        inverse_length_squared = 1.0 / max(along_u * along_u + along_v * along_v, 1e-12)
        for i in range(count):
            offset_u = sample_u[i] - start_u
            offset_v = sample_v[i] - start_v
            s = min(max((offset_u * along_u + offset_v * along_v) * inverse_length_squared, 0.0), 1.0)
            offset_u -= s * along_u  # the residual: sample minus closest point
            offset_v -= s * along_v
            distance_squared = offset_u * offset_u + offset_v * offset_v
            closer = distance_squared < best[i]  # strict: the first of equals stays
            best[i] = distance_squared if closer else best[i]
            best_segment[i] = segment if closer else best_segment[i]
    total = 0.0
    for i in range(count):
        # The nearest segment's closest point again, by the same arithmetic.
        a, b = start_index[best_segment[i]], end_index[best_segment[i]]
        start_u, start_v = end_pixels[a, 0], end_pixels[a, 1]
        along_u, along_v = end_pixels[b, 0] - start_u, end_pixels[b, 1] - start_v
        inverse_length_squared = 1.0 / max(along_u * along_u + along_v * along_v, 1e-12)
        offset_u = sample_u[i] - start_u
        offset_v = sample_v[i] - start_v
        best_s = min(max((offset_u * along_u + offset_v * along_v) * inverse_length_squared, 0.0), 1.0)
        best_u = offset_u - best_s * along_u
        best_v = offset_v - best_s * along_v
        weight = np.exp(-best[i] * inverse_scale_squared)
        total += 1.0 - weight
        pull = weight / (scale * count)
        pixel_gradient[a, 0] += (1.0 - best_s) * pull * best_u
        pixel_gradient[a, 1] += (1.0 - best_s) * pull * best_v
        pixel_gradient[b, 0] += best_s * pull * best_u
        pixel_gradient[b, 1] += best_s * pull * best_v
    return -0.5 * scale * total / count


@njit(cache=True, nogil=True)
def axis_value_and_frame_gradient(samples, end_pixels, jacobians, depth, start_index, end_index, scale,
                                  frame_gradient):
    """h_axis of one view and its derivative with respect to the segment ends in the world.

    Args:
        samples, start_index, end_index, scale: as :func:`axis_value_and_pixel_gradient`.
        end_pixels, jacobians, depth: the ends' projection: pixels (K, 2) [px], d pixels / d X_world
            (K, 2, 3) [px/m], depth (K,) [m].
        frame_gradient: (K, 3) to which dh/d X_world of each end is added.

    Returns:
        (h_axis [px], in front): with an end behind the camera (depth <= MIN_DEPTH) the view means
        nothing: (0, False), frame_gradient untouched.
    """
    for k in range(depth.shape[0]):
        if not depth[k] > MIN_DEPTH:
            return 0.0, False
    pixel_gradient = np.zeros((end_pixels.shape[0], 2))
    value = axis_value_and_pixel_gradient(samples, end_pixels, start_index, end_index, scale, pixel_gradient)
    for k in range(end_pixels.shape[0]):
        for axis in range(3):
            frame_gradient[k, axis] += (pixel_gradient[k, 0] * jacobians[k, 0, axis]
                                        + pixel_gradient[k, 1] * jacobians[k, 1, axis])
    return value, True
