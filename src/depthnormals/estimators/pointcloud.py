"""Point-cloud estimators on the neighbourhood of back-projected points: PlaneSVD, PlanePCA,
VectorSVD, AreaWeighted, AngleWeighted."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numba as nb
import numpy as np

from ..registry import register
from ._common import new_output, prepare, store_normal
from ._eig3 import smallest_eigenvector

__all__ = ["angle_weighted", "area_weighted", "plane_pca", "plane_svd", "vector_svd"]

# the 8 neighbours in cyclic order around the centre (dv, du)
_RING = np.array([[-1, -1], [-1, 0], [-1, 1], [0, 1], [1, 1], [1, 0], [1, -1], [0, -1]],
                 dtype=np.int64)


def check_window(window: Any, name: str = "window") -> int:
    """An odd integer >= 3, or TypeError/ValueError."""
    if isinstance(window, bool) or not isinstance(window, numbers.Integral):
        raise TypeError(f"{name} must be an odd integer >= 3 (e.g. 3 or 5); got {window!r}")
    if window < 3 or window % 2 == 0:
        raise ValueError(f"{name} must be an odd integer >= 3 (e.g. 3 or 5); got {window}")
    return int(window)


@nb.njit(cache=True, parallel=True)
def _scatter_kernel(z, fx, fy, cx, cy, r, centred, out):
    """Smallest-eigenvalue direction of the (centred or raw) scatter of p_i - q over the
    valid pixels of the (2r+1)^2 window."""
    h, w = z.shape
    ifx = 1.0 / fx
    ify = 1.0 / fy
    for v in nb.prange(h):
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                continue
            xq = (u - cx) * zq * ifx
            yq = (v - cy) * zq * ify
            n = 0
            sx = sy = sz = 0.0
            sxx = sxy = sxz = syy = syz = szz = 0.0
            for rr in range(max(v - r, 0), min(v + r + 1, h)):
                ry = (rr - cy) * ify
                for cc in range(max(u - r, 0), min(u + r + 1, w)):
                    zn = z[rr, cc]
                    if not (zn == zn):
                        continue
                    dx = (cc - cx) * zn * ifx - xq
                    dy = ry * zn - yq
                    dz = zn - zq
                    n += 1
                    sx += dx
                    sy += dy
                    sz += dz
                    sxx += dx * dx
                    sxy += dx * dy
                    sxz += dx * dz
                    syy += dy * dy
                    syz += dy * dz
                    szz += dz * dz
            if n < 3:
                continue
            if centred:
                inv = 1.0 / n
                sxx -= sx * sx * inv
                sxy -= sx * sy * inv
                sxz -= sx * sz * inv
                syy -= sy * sy * inv
                syz -= sy * sz * inv
                szz -= sz * sz * inv
            nx, ny, nz = smallest_eigenvector(sxx, sxy, sxz, syy, syz, szz)
            store_normal(out, v, u, nx, ny, nz, xq, yq, zq)


@nb.njit(cache=True, parallel=True)
def _fan_kernel(z, fx, fy, cx, cy, ring, angle, out):
    """Weighted sum of the unit normals of the triangles (q, p_i, p_i+1) of the 8-ring."""
    h, w = z.shape
    ifx = 1.0 / fx
    ify = 1.0 / fy
    for v in nb.prange(h):
        d = np.empty((8, 3))
        ok = np.empty(8, np.bool_)
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                continue
            xq = (u - cx) * zq * ifx
            yq = (v - cy) * zq * ify
            for k in range(8):
                rr = v + ring[k, 0]
                cc = u + ring[k, 1]
                ok[k] = False
                if rr < 0 or rr >= h or cc < 0 or cc >= w:
                    continue
                zn = z[rr, cc]
                if not (zn == zn):
                    continue
                ok[k] = True
                d[k, 0] = (cc - cx) * zn * ifx - xq
                d[k, 1] = (rr - cy) * zn * ify - yq
                d[k, 2] = zn - zq
            sx = sy = sz = 0.0
            used = 0
            for k in range(8):
                k2 = (k + 1) % 8
                if not (ok[k] and ok[k2]):
                    continue
                ax, ay, az = d[k, 0], d[k, 1], d[k, 2]
                bx, by, bz = d[k2, 0], d[k2, 1], d[k2, 2]
                tx = ay * bz - az * by
                ty = az * bx - ax * bz
                tz = ax * by - ay * bx
                norm = math.sqrt(tx * tx + ty * ty + tz * tz)
                if not (norm > 0.0):
                    continue
                if angle:
                    wgt = math.atan2(norm, ax * bx + ay * by + az * bz) / norm
                else:
                    wgt = 0.5  # unit normal times area = cross / 2
                sx += wgt * tx
                sy += wgt * ty
                sz += wgt * tz
                used += 1
            if used == 0:
                continue
            store_normal(out, v, u, sx, sy, sz, xq, yq, zq)


_SHARED_PARAMS = """
    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres."""

_RETURNS = """
    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where fewer than three
        non-collinear valid points are left."""


def _scatter(depth, K, window, depth_scale, centred):
    r = check_window(window) // 2
    z, cam = prepare(depth, K, depth_scale)
    out = new_output(z.shape)
    _scatter_kernel(z, cam.fx, cam.fy, cam.cx, cam.cy, r, centred, out)
    return out


def _fan(depth, K, depth_scale, angle):
    z, cam = prepare(depth, K, depth_scale)
    out = new_output(z.shape)
    _fan_kernel(z, cam.fx, cam.fy, cam.cx, cam.cy, _RING, angle, out)
    return out


@register("plane-svd")
def plane_svd(depth: Any, K: Any, *, window: int = 3,
              depth_scale: float | None = None) -> np.ndarray:
    """PlaneSVD: the least-squares plane through the back-projected window, by SVD.

    The points of the ``window x window`` neighbourhood are centred on their mean; the
    normal is the right singular vector of the smallest singular value of the (n, 3)
    matrix, i.e. the eigenvector of the smallest eigenvalue of its scatter matrix
    (closed-form 3x3 solver, no LAPACK per pixel).
    {params}
    window : int, default 3
        Odd side of the square neighbourhood. Only valid pixels are used.
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    PlaneSVD and PlanePCA minimise the same orthogonal plane-fitting error, so they give
    the same normal up to rounding (the 3F2N+ paper reports identical errors for both).
    Interpretation (ours): the singular vectors of the centred (n, 3) matrix are computed
    from its 3x3 Gram matrix; invalid neighbours are left out, and three non-collinear
    valid points are needed.

    References
    ----------
    K. Klasing, D. Althoff, D. Wollherr and M. Buss, "Comparison of Surface Normal
    Estimation Methods for Range Sensing Applications," IEEE International Conference on
    Robotics and Automation (ICRA), 2009, pp. 3206-3211. doi:10.1109/ROBOT.2009.5152493

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import plane_svd
    >>> n = plane_svd(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _scatter(depth, K, window, depth_scale, True)


@register("plane-pca")
def plane_pca(depth: Any, K: Any, *, window: int = 3,
              depth_scale: float | None = None) -> np.ndarray:
    """PlanePCA: the normal is the least principal axis of the back-projected window.

    The covariance of the points of the ``window x window`` neighbourhood is formed; the
    normal is the eigenvector of its smallest eigenvalue.
    {params}
    window : int, default 3
        Odd side of the square neighbourhood. Only valid pixels are used.
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    The same minimiser as PlaneSVD (see :func:`plane_svd`); the covariance differs from
    the scatter matrix only by the factor 1/n. Interpretation (ours): invalid neighbours
    are left out.

    References
    ----------
    K. Klasing, D. Wollherr and M. Buss, "Realtime Segmentation of Range Data Using
    Continuous Nearest Neighbors," IEEE International Conference on Robotics and
    Automation (ICRA), 2009, pp. 2431-2436. doi:10.1109/ROBOT.2009.5152543

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import plane_pca
    >>> n = plane_pca(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _scatter(depth, K, window, depth_scale, True)


@register("vector-svd")
def vector_svd(depth: Any, K: Any, *, window: int = 3,
               depth_scale: float | None = None) -> np.ndarray:
    """VectorSVD: the direction most orthogonal to the difference vectors p_i - q.

    The normal is the right singular vector of the smallest singular value of the matrix
    of the difference vectors from the centre ``q`` to its valid neighbours in the
    ``window x window`` neighbourhood (not centred on their mean).
    {params}
    window : int, default 3
        Odd side of the square neighbourhood. Only valid pixels are used.
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    Interpretation (ours): the singular vector comes from the 3x3 matrix
    ``sum (p_i - q)(p_i - q)^T`` (closed-form solver); invalid neighbours are left out.

    References
    ----------
    K. Klasing, D. Althoff, D. Wollherr and M. Buss, "Comparison of Surface Normal
    Estimation Methods for Range Sensing Applications," IEEE International Conference on
    Robotics and Automation (ICRA), 2009, pp. 3206-3211. doi:10.1109/ROBOT.2009.5152493

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import vector_svd
    >>> n = vector_svd(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _scatter(depth, K, window, depth_scale, False)


@register("area-weighted")
def area_weighted(depth: Any, K: Any, *, depth_scale: float | None = None) -> np.ndarray:
    """AreaWeighted: the area-weighted mean of the normals of the 8 triangles around q.

    The 8 neighbours ``p_i`` of ``q`` are taken in cyclic order around it; each triangle
    ``(q, p_i, p_i+1)`` contributes its unit normal times its area, i.e. half the cross
    product ``(p_i - q) x (p_i+1 - q)``.
    {params}
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    Interpretation (ours): a triangle with an invalid or out-of-image vertex is left out;
    the method is defined on the 3x3 neighbourhood only (no ``window``).

    References
    ----------
    S. Jin, R. R. Lewis and D. West, "A comparison of algorithms for vertex normal
    computation," The Visual Computer, vol. 21, no. 1-2, pp. 71-82, 2005.
    doi:10.1007/s00371-004-0271-1

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import area_weighted
    >>> n = area_weighted(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _fan(depth, K, depth_scale, False)


@register("angle-weighted")
def angle_weighted(depth: Any, K: Any, *, depth_scale: float | None = None) -> np.ndarray:
    """AngleWeighted: the angle-weighted mean of the normals of the 8 triangles around q.

    As :func:`area_weighted`, but each triangle's unit normal is weighted by its angle at
    ``q``, ``atan2(|a x b|, a . b)`` with ``a = p_i - q``, ``b = p_i+1 - q``.
    {params}
    depth_scale : float, optional
        Metres per unit of integer depth.
    {returns}

    Notes
    -----
    Interpretation (ours): a triangle with an invalid or out-of-image vertex is left out;
    the method is defined on the 3x3 neighbourhood only (no ``window``).

    References
    ----------
    S. Jin, R. R. Lewis and D. West, "A comparison of algorithms for vertex normal
    computation," The Visual Computer, vol. 21, no. 1-2, pp. 71-82, 2005.
    doi:10.1007/s00371-004-0271-1

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import angle_weighted
    >>> n = angle_weighted(np.full((5, 6), 2.0), (500.0, 500.0, 2.5, 2.0))
    >>> bool(np.allclose(n[2, 2], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    return _fan(depth, K, depth_scale, True)


for _f in (plane_svd, plane_pca, vector_svd, area_weighted, angle_weighted):
    if _f.__doc__:  # None under python -OO
        _f.__doc__ = (_f.__doc__.replace("    {params}", _SHARED_PARAMS.strip("\n"))
                      .replace("    {returns}", _RETURNS.strip("\n")))
del _f
