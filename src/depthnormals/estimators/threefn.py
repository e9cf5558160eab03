"""Three-filters-to-normal (3F2N)."""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from .._validate import check_choice
from ..registry import register
from ._common import new_output, prepare, store_normal
from ._stencils import KERNELS, gradient_kernels, roberts_gradient, stencil_derivative

__all__ = ["AGGREGATES", "three_filters_to_normal"]

AGGREGATES = ("median", "mean", "trimean", "trimmed-mean")

# neighbour offsets (dv, du), the 8-neighbourhood
_NB = np.array([[-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0], [1, 1]], dtype=np.int64)


@nb.njit(cache=True, inline="always")
def _quantile_sorted(c, n, q):
    pos = q * (n - 1)
    lo = int(pos)
    hi = lo + 1 if lo + 1 < n else lo
    f = pos - lo
    return c[lo] * (1.0 - f) + c[hi] * f


@nb.njit(cache=True)
def central_tendency(c, n, mode):
    """Central tendency of c[:n]: 0 median, 1 mean, 2 trimean, 3 trimmed mean (AGGREGATES order).

    Sorts c[:n] in place.
    """
    if mode == 1:
        s = 0.0
        for i in range(n):
            s += c[i]
        return s / n
    for i in range(1, n):  # insertion sort, n <= 8
        x = c[i]
        j = i - 1
        while j >= 0 and c[j] > x:
            c[j + 1] = c[j]
            j -= 1
        c[j + 1] = x
    if mode == 0:
        return _quantile_sorted(c, n, 0.5)
    if mode == 2:
        return 0.25 * (_quantile_sorted(c, n, 0.25) + 2.0 * _quantile_sorted(c, n, 0.5)
                       + _quantile_sorted(c, n, 0.75))
    lo = 1 if n >= 3 else 0
    hi = n - 1 if n >= 3 else n
    s = 0.0
    for i in range(lo, hi):
        s += c[i]
    return s / (hi - lo)


@nb.njit(cache=True, parallel=True)
def _threefn_kernel(z, fx, fy, cx, cy, deriv, smooth, roberts, mode, nb_off, out):
    h, w = z.shape
    D = 1.0 / z
    for v in nb.prange(h):
        cand = np.empty(8)
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                continue
            if roberts:
                gu, gv = roberts_gradient(D, v, u)
            else:
                gu = stencil_derivative(D, v, u, 0, 1, deriv, smooth)
                gv = stencil_derivative(D, v, u, 1, 0, deriv, smooth)
            if not (gu == gu and gv == gv):
                continue
            nx = fx * gu
            ny = fy * gv
            xq = (u - cx) * zq / fx
            yq = (v - cy) * zq / fy
            n = 0
            for k in range(8):
                r = v + nb_off[k, 0]
                c = u + nb_off[k, 1]
                if r < 0 or r >= h or c < 0 or c >= w:
                    continue
                zn = z[r, c]
                if not (zn == zn):
                    continue
                dz = zn - zq
                if dz == 0.0:
                    continue
                dx = (c - cx) * zn / fx - xq
                dy = (r - cy) * zn / fy - yq
                cand[n] = -(nx * dx + ny * dy) / dz
                n += 1
            if n == 0:
                nx = 0.0
                ny = 0.0
                nz = -1.0
            else:
                nz = central_tendency(cand, n, mode)
            store_normal(out, v, u, nx, ny, nz, xq, yq, zq)




@register("3f2n")
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
    normal is ``(0, 0, -1)``. Interpretation (ours): invalid pixels never enter a stencil;
    a stencil row that would touch one falls back to a central, then one-sided difference,
    and neighbours that are invalid give no candidate. The normal is then oriented per pixel
    toward the camera, which the reference achieves with a global sign.

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
    out = new_output(z.shape)
    _threefn_kernel(z, cam.fx, cam.fy, cam.cx, cam.cy, deriv, smooth, kernel == "roberts",
                    mode, _NB, out)
    return out
