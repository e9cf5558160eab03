"""Three-filters-to-normal (3F2N)."""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from .._validate import check_choice
from ..kernels.depth import pinhole, prepare, row_dtype
from ..kernels.stencils import KERNELS, gradient_kernels
from ..kernels.threefn_rows import NEIGHBOURS8, Filters, RowScratch, row_normals, row_setup

__all__ = ["AGGREGATES", "three_filters_to_normal"]

AGGREGATES = ("median", "mean", "trimean", "trimmed-mean")


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _threefn_rows(v0, v1, rows, cam, filters, out):
    """3F2N of rows [v0, v1) into ``out`` (H, W, 3) float32, row by row through
    :func:`depthnormals.kernels.threefn_rows.row_normals`."""
    z = rows.z
    w = z.shape[1]
    scratch = RowScratch(np.empty((7, w), dtype=z.dtype), np.empty(w, dtype=np.bool_),
                         np.empty(8))
    bx = np.empty(w, dtype=z.dtype)
    by = np.empty(w, dtype=z.dtype)
    bz = np.empty(w, dtype=z.dtype)
    prev = np.int64(-1)  # not the literal -1: row_normals would compile twice
    for v in range(v0, v1):
        prev = row_normals(v, rows, cam, filters, scratch, prev, (bx, by, bz))
        for u in range(w):
            out[v, u, 0] = bx[u]
            out[v, u, 1] = by[u]
            out[v, u, 2] = bz[u]


def three_filters_to_normal(depth: Any, K: Any, *, kernel: str = "fd", kernel_size: int = 3,
                            aggregate: str = "median",
                            depth_scale: float | None = None) -> np.ndarray:
    """Three-filters-to-normal (3F2N): normals from inverse-depth gradients.

    A plane ``n . p + d = 0`` makes inverse depth linear in the pixel position, so
    ``nx = fx * d(1/z)/du`` and ``ny = fy * d(1/z)/dv`` (two image filters); each of the 8
    neighbours ``p_i`` of ``q`` then gives ``nz_i = -(nx dx_i + ny dy_i) / dz_i`` with
    ``(dx, dy, dz) = p_i - q``, and the third filter takes their central tendency.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    kernel : {"fd", "sobel", "scharr", "prewitt", "roberts"}, default "fd"
        Gradient filter. ``fd`` is the central difference (a least-squares slope for larger
        sizes); ``sobel``, ``scharr`` (smoothing 3, 10, 3) and ``prewitt`` (1, 1, 1) are
        correctly named (the public MATLAB swaps the last two); ``roberts`` is the 2x2 cross,
        its diagonal derivatives rotated back into u, v derivatives.
    kernel_size : {3, 5, 7, 9, 11}, default 3
        Size of the gradient kernel (ignored by ``roberts``, which is 2x2).
    aggregate : {"median", "mean", "trimean", "trimmed-mean"}, default "median"
        The third filter over the valid ``nz_i`` candidates. ``trimean`` is
        (Q1 + 2 Q2 + Q3) / 4 with linearly interpolated quartiles; ``trimmed-mean`` drops
        the smallest and the largest candidate (when at least 3 remain).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where no gradient exists.

    Notes
    -----
    Conventions: OpenCV camera frame, planar depth, pixel centres on integers. As in the
    public reference, neighbours with ``dz = 0`` are dropped, and when none is left the
    normal is ``(0, 0, -1)``; so is it where the inverse-depth gradient is exactly zero (the
    reference returns NaN there when the remaining candidates come from another surface).
    Interpretation (ours): invalid pixels never enter a stencil;
    a stencil row that would touch one falls back to a central, then one-sided difference,
    and neighbours that are invalid give no candidate. The normal is then oriented per pixel
    toward the camera, which the reference achieves with a global sign.

    Speed: the default FD kernel (size 3, median or mean) runs a vectorised row pass in the
    dtype of the depth, so float32 sensor depth is processed 8 pixels per AVX2 vector. Each
    division ``1 / (z_i - z_q)`` is shared by the two pixels it joins, and the gradient is
    formed as ``(z[u-1] - z[u+1]) / (2 z[u-1] z[u+1])``, which has no cancellation. Against
    the float64 general path, float32 depth moves the normals by < 5e-3 deg (99.9 % of
    pixels < 5e-4 deg); pixels at the border or next to invalid depth take the general path.

    References
    ----------
    R. Fan, H. Wang, B. Xue, H. Huang, Y. Wang, M. Liu and I. Pitas, "Three-Filters-to-Normal:
    An Accurate and Ultrafast Surface Normal Estimator," IEEE Robotics and Automation Letters,
    vol. 6, no. 3, pp. 5405-5412, 2021. doi:10.1109/LRA.2021.3067308

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import three_filters_to_normal
    >>> v, u = np.mgrid[0:6, 0:8]
    >>> z = 1.0 / (0.5 + 0.001 * u)          # a plane: inverse depth linear in u
    >>> n = three_filters_to_normal(z, (500.0, 500.0, 3.5, 2.5))
    >>> bool(np.allclose(np.linalg.norm(n, axis=-1), 1.0))
    True
    """
    check_choice(kernel, "kernel", tuple(KERNELS))
    mode = AGGREGATES.index(check_choice(aggregate, "aggregate", AGGREGATES))
    z, cam = prepare(depth, K, depth_scale)
    if kernel == "roberts":
        deriv, smooth = np.zeros(1), np.ones(1)
    else:
        deriv, smooth = gradient_kernels(kernel, kernel_size)
    out = np.empty((*z.shape, 3), dtype=np.float32)
    fast_fd = kernel == "fd" and kernel_size == 3 and mode in (0, 1)
    if fast_fd:
        z = row_dtype(z, cam.fx, cam.fy, cam.cx, cam.cy)
    rows = row_setup(z, cam.fx, cam.fy, cam.cx, cam.cy, fast_fd)
    filters = Filters(deriv, smooth, kernel == "roberts", mode, fast_fd, NEIGHBOURS8)
    run_rows(_threefn_rows, z.shape[0], rows, pinhole(cam), filters, out)
    return out
