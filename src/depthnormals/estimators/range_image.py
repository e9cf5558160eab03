"""Range-image estimators: FALS and SRI (Badino et al. 2011) and LINE-MOD's depth normals."""

from __future__ import annotations

import functools
import math
from typing import Any

import numba as nb
import numpy as np

from .._validate import check_positive
from ..registry import register
from ._common import new_output, prepare, store_normal
from ._stencils import gradient_kernels, stencil_derivative
from .pointcloud import check_window

__all__ = ["fals", "line_mod", "sri"]


# ----------------------------------------------------------------------------------- FALS

@nb.njit(cache=True, parallel=True)
def _fals_full_inverse(h, w, fx, fy, cx, cy, r):
    """Inverse of M = sum v v^T over the full (clipped) window at every pixel (6 entries)."""
    out = np.empty((h, w, 6))
    for v in nb.prange(h):
        for u in range(w):
            m00 = m01 = m02 = m11 = m12 = m22 = 0.0
            for rr in range(max(v - r, 0), min(v + r + 1, h)):
                y = (rr - cy) / fy
                for cc in range(max(u - r, 0), min(u + r + 1, w)):
                    x = (cc - cx) / fx
                    s = 1.0 / (x * x + y * y + 1.0)
                    m00 += x * x * s
                    m01 += x * y * s
                    m02 += x * s
                    m11 += y * y * s
                    m12 += y * s
                    m22 += s
            c00 = m11 * m22 - m12 * m12
            c01 = m02 * m12 - m01 * m22
            c02 = m01 * m12 - m02 * m11
            c11 = m00 * m22 - m02 * m02
            c12 = m01 * m02 - m00 * m12
            c22 = m00 * m11 - m01 * m01
            det = m00 * c00 + m01 * c01 + m02 * c02
            out[v, u, 0] = c00 / det
            out[v, u, 1] = c01 / det
            out[v, u, 2] = c02 / det
            out[v, u, 3] = c11 / det
            out[v, u, 4] = c12 / det
            out[v, u, 5] = c22 / det
    return out


@functools.lru_cache(maxsize=4)
def _fals_cache(h: int, w: int, fx: float, fy: float, cx: float, cy: float,
                r: int) -> np.ndarray:
    # depth-independent, like the cache of OpenCV's RgbdNormals object
    return _fals_full_inverse(h, w, fx, fy, cx, cy, r)


@nb.njit(cache=True, parallel=True)
def _fals_rows(z, fx, fy, cx, cy, r, hb):
    """Row pass: windowed sums of b = v / range over valid pixels, and the valid count."""
    h, w = z.shape
    for v in nb.prange(h):
        y = (v - cy) / fy
        b0 = np.zeros(w + 1)
        b1 = np.zeros(w + 1)
        b2 = np.zeros(w + 1)
        bc = np.zeros(w + 1)
        for u in range(w):  # prefix sums along the row
            zz = z[v, u]
            x = (u - cx) / fx
            t0 = t1 = t2 = tc = 0.0
            if zz == zz:
                k = 1.0 / ((x * x + y * y + 1.0) * zz)  # v / range = (x, y, 1) / (s z)
                t0 = x * k
                t1 = y * k
                t2 = k
                tc = 1.0
            b0[u + 1] = b0[u] + t0
            b1[u + 1] = b1[u] + t1
            b2[u + 1] = b2[u] + t2
            bc[u + 1] = bc[u] + tc
        for u in range(w):
            lo = max(u - r, 0)
            hi = min(u + r + 1, w)
            hb[v, u, 0] = b0[hi] - b0[lo]
            hb[v, u, 1] = b1[hi] - b1[lo]
            hb[v, u, 2] = b2[hi] - b2[lo]
            hb[v, u, 3] = bc[hi] - bc[lo]


@nb.njit(cache=True, parallel=True)
def _fals_solve(z, fx, fy, cx, cy, r, hb, minv, out):
    h, w = z.shape
    for v in nb.prange(h):
        lo = max(v - r, 0)
        hi = min(v + r + 1, h)
        full = (hi - lo) * 1.0
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                continue
            s0 = s1 = s2 = sc = 0.0
            for rr in range(lo, hi):
                s0 += hb[rr, u, 0]
                s1 += hb[rr, u, 1]
                s2 += hb[rr, u, 2]
                sc += hb[rr, u, 3]
            xq = (u - cx) * zq / fx
            yq = (v - cy) * zq / fy
            ncols = min(u + r + 1, w) - max(u - r, 0)
            if sc == full * ncols:  # every pixel of the window valid: cached M^-1
                m = minv[v, u]
                nx = m[0] * s0 + m[1] * s1 + m[2] * s2
                ny = m[1] * s0 + m[3] * s1 + m[4] * s2
                nz = m[2] * s0 + m[4] * s1 + m[5] * s2
                store_normal(out, v, u, nx, ny, nz, xq, yq, zq)
                continue
            # incomplete window: M over the valid pixels only, and a collinearity check
            m00 = m01 = m02 = m11 = m12 = m22 = 0.0
            n = 0
            su = sv = suu = suv = svv = 0.0
            for rr in range(lo, hi):
                y = (rr - cy) / fy
                for cc in range(max(u - r, 0), min(u + r + 1, w)):
                    if not (z[rr, cc] == z[rr, cc]):
                        continue
                    x = (cc - cx) / fx
                    s = 1.0 / (x * x + y * y + 1.0)
                    m00 += x * x * s
                    m01 += x * y * s
                    m02 += x * s
                    m11 += y * y * s
                    m12 += y * s
                    m22 += s
                    du = cc - u
                    dv = rr - v
                    n += 1
                    su += du
                    sv += dv
                    suu += du * du
                    suv += du * dv
                    svv += dv * dv
            # pixel positions collinear <=> rays coplanar with the centre <=> M singular
            if n < 3 or (n * suu - su * su) * (n * svv - sv * sv) - (n * suv - su * sv) ** 2 <= 0:
                continue
            c00 = m11 * m22 - m12 * m12
            c01 = m02 * m12 - m01 * m22
            c02 = m01 * m12 - m02 * m11
            c11 = m00 * m22 - m02 * m02
            c12 = m01 * m02 - m00 * m12
            c22 = m00 * m11 - m01 * m01
            nx = c00 * s0 + c01 * s1 + c02 * s2  # adj(M) b: det(M) > 0 only scales
            ny = c01 * s0 + c11 * s1 + c12 * s2
            nz = c02 * s0 + c12 * s1 + c22 * s2
            store_normal(out, v, u, nx, ny, nz, xq, yq, zq)


@register("fals")
def fals(depth: Any, K: Any, *, window: int = 5, depth_scale: float | None = None) -> np.ndarray:
    """Fast approximate least squares (FALS): a plane fit in the range image.

    A plane ``n . p = d`` seen along the unit ray ``v`` at range ``r`` satisfies
    ``n . v / d = 1 / r``. Least squares over the window gives ``n ~ M^-1 b`` with
    ``M = sum v v^T`` (depth-independent, cached per camera and image size) and
    ``b = sum v / r``.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    window : int, default 5
        Odd side of the square window (OpenCV's ``window_size``, default 5 there too).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where the valid pixels of
        the window are collinear.

    Notes
    -----
    Interpretation (ours): both sums run over the valid pixels of the window only, and the
    window is clipped at the image border. OpenCV's ``RgbdNormals`` (FALS) instead sums
    ``M`` over the whole window whatever the validity (``b`` gets zeros from invalid
    pixels) and reflects the window at the border, which bends its normals next to holes
    and at the image edge; on fully valid windows the two agree (see docs/estimators.md).
    The orientation is per pixel toward the camera (OpenCV flips to ``n_z < 0``).

    References
    ----------
    H. Badino, D. Huber, Y. Park and T. Kanade, "Fast and Accurate Computation of Surface
    Normals from Range Images," IEEE International Conference on Robotics and Automation
    (ICRA), 2011, pp. 3084-3091. doi:10.1109/ICRA.2011.5980275

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import fals
    >>> n = fals(np.full((7, 8), 2.0), (500.0, 500.0, 3.5, 3.0))
    >>> bool(np.allclose(n[3, 4], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    r = check_window(window) // 2
    z, cam = prepare(depth, K, depth_scale)
    h, w = z.shape
    minv = _fals_cache(h, w, cam.fx, cam.fy, cam.cx, cam.cy, r)
    hb = np.empty((h, w, 4))
    _fals_rows(z, cam.fx, cam.fy, cam.cx, cam.cy, r, hb)
    out = new_output(z.shape)
    _fals_solve(z, cam.fx, cam.fy, cam.cx, cam.cy, r, hb, minv, out)
    return out


# ------------------------------------------------------------------------------------ SRI

@nb.njit(cache=True, parallel=True)
def _sri_kernel(z, fx, fy, cx, cy, deriv, smooth, out):
    h, w = z.shape
    # range image r(u, v) = z sqrt(x'^2 + y'^2 + 1)
    R = np.empty((h, w))
    for v in nb.prange(h):
        y = (v - cy) / fy
        for u in range(w):
            x = (u - cx) / fx
            R[v, u] = z[v, u] * math.sqrt(x * x + y * y + 1.0)
    for v in nb.prange(h):
        y = (v - cy) / fy
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                continue
            ru = stencil_derivative(R, v, u, 0, 1, deriv, smooth)
            rv = stencil_derivative(R, v, u, 1, 0, deriv, smooth)
            if not (ru == ru and rv == rv):
                continue
            x = (u - cx) / fx
            rho2 = x * x + y * y + 1.0
            # azimuth theta = atan(x), elevation phi = asin(y / sqrt(rho2))
            ct = 1.0 / math.sqrt(1.0 + x * x)
            st = x * ct
            sp = y / math.sqrt(rho2)
            cp = math.sqrt(1.0 + x * x) / math.sqrt(rho2)
            # Jacobian of (theta, phi) w.r.t. (u, v): theta_v = 0
            th_u = 1.0 / (fx * (1.0 + x * x))
            ph_u = -x * y / (fx * rho2 * math.sqrt(1.0 + x * x))
            ph_v = math.sqrt(1.0 + x * x) / (fy * rho2)
            r_phi = rv / ph_v
            r_theta = (ru - r_phi * ph_u) / th_u
            rq = R[v, u]
            a = r_theta / (rq * cp)
            b = r_phi / rq
            # n ~ s - a e_theta - b e_phi (spherical frame: s radial)
            nx = st * cp - a * ct + b * st * sp
            ny = sp - b * cp
            nz = ct * cp + a * st + b * ct * sp
            store_normal(out, v, u, nx, ny, nz, x * zq, y * zq, zq)


@register("sri")
def sri(depth: Any, K: Any, *, window: int = 5, depth_scale: float | None = None) -> np.ndarray:
    """Spherical range image (SRI): normals from derivatives of range in azimuth/elevation.

    With ``p = r s(theta, phi)``, ``s = (sin theta cos phi, sin phi, cos theta cos phi)``,
    azimuth ``theta`` (from z to x) and elevation ``phi`` (toward y), the normal is
    ``n ~ s - (dr/dtheta) / (r cos phi) e_theta - (dr/dphi) / r e_phi`` in the local
    spherical frame, rotated back to the camera frame.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    window : {3, 5, 7, 9, 11}, default 5
        Size of the Sobel derivative kernel (OpenCV's ``window_size``, default 5 there too).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where no derivative exists.

    Notes
    -----
    Interpretation (ours): the derivatives ``dr/dtheta`` and ``dr/dphi`` are taken on the
    image grid and converted by the exact chain rule (``theta`` depends on u only, ``phi``
    on u and v), instead of resampling the range image onto a regular (theta, phi) grid and
    back with bilinear interpolation as OpenCV does; the two agree on smooth surfaces, but
    ours never interpolates across invalid pixels or resamples. The Sobel stencil falls back
    to central, then one-sided differences next to invalid pixels.

    References
    ----------
    H. Badino, D. Huber, Y. Park and T. Kanade, "Fast and Accurate Computation of Surface
    Normals from Range Images," IEEE International Conference on Robotics and Automation
    (ICRA), 2011, pp. 3084-3091. doi:10.1109/ICRA.2011.5980275

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import sri
    >>> n = sri(np.full((7, 8), 2.0), (500.0, 500.0, 3.5, 3.0))
    >>> bool(np.allclose(n[3, 4], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    window = check_window(window)
    if window > 11:
        raise ValueError(f"window must be one of 3, 5, 7, 9, 11 for sri; got {window}")
    z, cam = prepare(depth, K, depth_scale)
    deriv, smooth = gradient_kernels("sobel", window)
    out = new_output(z.shape)
    _sri_kernel(z, cam.fx, cam.fy, cam.cx, cam.cy, deriv, smooth, out)
    return out


# ------------------------------------------------------------------------------- LINE-MOD

@nb.njit(cache=True, parallel=True)
def _linemod_kernel(z, fx, fy, cx, cy, r, thr, out):
    h, w = z.shape
    for v in nb.prange(h):
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                continue
            a00 = a01 = a11 = 0.0
            b0 = b1 = 0.0
            for j in range(-1, 2):
                rr = v + j * r
                if rr < 0 or rr >= h:
                    continue
                for i in range(-1, 2):
                    cc = u + i * r
                    if cc < 0 or cc >= w or (i == 0 and j == 0):
                        continue
                    zn = z[rr, cc]
                    if not (zn == zn):
                        continue
                    dz = zn - zq
                    if abs(dz) > thr:
                        continue
                    du = i * r
                    dv = j * r
                    a00 += du * du
                    a01 += du * dv
                    a11 += dv * dv
                    b0 += du * dz
                    b1 += dv * dz
            det = a00 * a11 - a01 * a01
            if not (det > 0.0):
                continue
            zu = (a11 * b0 - a01 * b1) / det
            zv = (a00 * b1 - a01 * b0) / det
            # tangents at q along u and v with this gradient; their cross product (D2NT form)
            store_normal(out, v, u, fx * zu, fy * zv, -(zq + (u - cx) * zu + (v - cy) * zv),
                         (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


@register("line-mod", scale_invariant=False)
def line_mod(depth: Any, K: Any, *, window: int = 11, threshold: float = 0.05,
             depth_scale: float | None = None) -> np.ndarray:
    """LINE-MOD's depth normals: a least-squares depth gradient from thresholded neighbours.

    The first-order Taylor expansion ``z(q + d) - z(q) = d . grad z`` is solved in the least
    squares sense over the samples ``d`` of the window whose depth differs from the centre's
    by at most ``threshold``; the plane through ``q`` and the two points one pixel along u
    and v with that gradient gives the normal.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z. float32/float64; integers need ``depth_scale``. Invalid depth
        (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    window : int, default 11
        Odd side of the window; the samples are its 8 corner and edge-midpoint pixels,
        at offsets ``{-r, 0, r}^2`` with ``r = window // 2`` (OpenCV: r = 5, i.e. 11).
    threshold : float, default 0.05
        Largest accepted depth difference to the centre, in the unit of the depth after
        ``depth_scale`` (metres for depth in metres: 0.05 m is OpenCV's 50 on millimetre
        input).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where the accepted samples
        do not determine a gradient (all on one line through q, or none).

    Notes
    -----
    Interpretation (ours): invalid and out-of-image samples are skipped, so the estimate
    reaches the image border (OpenCV leaves an ``r``-pixel frame as NaN and does not test
    validity, so zero depth enters its fit). The normal is the cross product of the exact
    tangents ``dX/du``, ``dX/dv`` for the fitted gradient, i.e. the limit of the paper's
    three-point plane (OpenCV uses the finite points at ``u + 1`` and ``v + 1``, which
    differs by the curvature of depth over one pixel, ~0.01 deg on a plane). The threshold
    makes the method depend on the depth unit.

    References
    ----------
    S. Hinterstoisser, C. Cagniart, S. Ilic, P. Sturm, N. Navab, P. Fua and V. Lepetit,
    "Gradient Response Maps for Real-Time Detection of Textureless Objects," IEEE
    Transactions on Pattern Analysis and Machine Intelligence, vol. 34, no. 5,
    pp. 876-888, 2012. doi:10.1109/TPAMI.2011.206

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import line_mod
    >>> n = line_mod(np.full((12, 12), 2.0), (500.0, 500.0, 5.5, 5.5))
    >>> bool(np.allclose(n[6, 6], [0.0, 0.0, -1.0], atol=1e-6))
    True
    """
    r = check_window(window) // 2
    thr = check_positive(threshold, "threshold")
    z, cam = prepare(depth, K, depth_scale)
    out = new_output(z.shape)
    _linemod_kernel(z, cam.fx, cam.fy, cam.cx, cam.cy, r, thr, out)
    return out
