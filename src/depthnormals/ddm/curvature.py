"""Depth curvature of 3F2N+ (section III-A of the paper), compiled with numba.

Five kinds, all maps of shape (H, W) where *lower means smoother*; ``inf`` marks pixels whose
curvature is undefined (a sample is invalid or outside the image):

``"mean"`` / ``"max"``
    The paper's metric curvatures. At every pixel ``p`` four directional curvatures are
    computed from first and second derivatives of depth (central differences):
    ``k_u = |c_xx| / (1 + c_x^2)^(3/2)`` (likewise ``k_v``), and along the diagonals
    ``k_g = |c_ll| / (1 + c_l^2)^(3/2)``, ``k_b = |c_tt| / (1 + c_t^2)^(3/2)`` with
    ``c_l, c_t = (c_x +- c_y) / sqrt 2`` and ``c_ll, c_tt = (c_xx +- c_yy) / sqrt 2``. The value
    at ``q`` is the mean / maximum of the eight values its neighbours contribute in the
    direction pointing at ``q``: ``k_u`` of the left and right neighbours, ``k_v`` of the up
    and down ones, ``k_g`` of the up-left and down-right ones (leading diagonal), ``k_b`` of
    the up-right and down-left ones (trailing diagonal).
``"normal"`` / ``"gauss"``
    The paper's fundamental-form expressions at ``q`` itself (absolute values).
``"pixel-mean"``
    The authors' public pixel-domain variant:
    ``k_u = |z(u-1) - 2 z(u) + z(u+1)| / (1 + min(g_c^2, g_l^2, g_r^2))^(3/2)`` with ``g_c`` the
    half central difference and ``g_l, g_r`` the one-sided differences (same for ``v``),
    ``k = (k_u + k_v) / 2``. It is in raw depth units (not invariant to the depth unit).

The guards for fronto-parallel rows
-----------------------------------
The paper writes everything with ``e_u = du/dz = 1 / z_u``, which is infinite on a row of
constant depth. Multiplying numerator and denominator by powers of ``z_u`` removes it:
with ``A = z + (u - cx) z_u`` (``A / fx`` is ``dx/du``) and ``N_u = 2 z_u^2 - z z_uu``,

    c_x = fx z_u / A,    c_xx = -fx^2 N_u / A^3,
    k_u = fx^2 |N_u| / (A^2 + fx^2 z_u^2)^(3/2),

which is exactly the paper's ``|fx^2 alpha_0 / (alpha_1^2 + fx^2)^(3/2)|`` wherever ``z_u != 0``
and stays finite (``fx^2 |z_uu| / z^2``) where ``z_u = 0``. ``k_u`` is the curvature of the
curve ``(x(u), z(u))`` in the camera's x-z plane. ``N_u = z^3 d^2(1/z)/du^2``, and inverse depth
is linear in ``u`` on any plane, so with ``derivatives="inverse-depth"`` (the default)
``N_u`` is discretised as ``z^3 (D(u-1) - 2 D(u) + D(u+1))``, ``D = 1/z``, which makes every
plane's curvature exactly zero; ``derivatives="depth"`` is the paper's literal
``2 z_u^2 - z z_uu`` with central differences (zero on planes only to fourth order).
The diagonal terms need ``c_x`` and ``c_xx`` themselves, so they are ``inf`` where ``A = 0``
(a surface seen exactly edge-on).

For ``"normal"``, ``e_u`` and ``e_v`` are removed the same way (numerator and denominator
times ``z_u^2 z_v^2``): ``k = |L z_u^2 + 2 M z_u z_v + N z_v^2| / (c_x z_u + c_y z_v)^2``, 0 where
both vanish. For ``"gauss"`` the paper's first fundamental form ``E = c_x^2, F = c_x c_y,
G = c_y^2`` has ``E G - F^2 = 0`` identically, so its ratio is never finite; we keep the
numerator ``|L N - M^2|`` as the ranking key (only the ordering matters for the selection).
The paper's closed form of ``c_ll`` drops the squares of ``fx, fy``; we follow its defining
line ``c_ll = (c_xx + c_yy) / sqrt 2``, which is dimensionally consistent.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from .._validate import check_choice
from ..estimators._common import prepare

__all__ = ["CURVATURES", "DERIVATIVES", "FOOTPRINTS", "SLOPES", "depth_curvature"]

CURVATURES = ("mean", "max", "normal", "gauss", "pixel-mean")
DERIVATIVES = ("inverse-depth", "depth")
SLOPES = ("min", "central")
FOOTPRINTS = ("pixel", "neighbours")
_INF = np.inf
_R2 = 1.0 / math.sqrt(2.0)


@nb.njit(cache=True, inline="always")
def _sample(z, v, u):
    h, w = z.shape
    if v < 0 or v >= h or u < 0 or u >= w:
        return np.nan
    return z[v, u]


@nb.njit(cache=True, inline="always")
def _line(zm, z0, zp, off, inverse, minslope):
    """First derivative z_u, numerator N_u and A = z + off z_u along one image line.

    ``minslope``: z_u is the smallest in magnitude of the half central and the two one-sided
    differences (the public code's denominator), else the half central difference.
    """
    zd = 0.5 * (zp - zm)
    if minslope:
        gl = z0 - zm
        gr = zp - z0
        if abs(gl) < abs(zd):
            zd = gl
        if abs(gr) < abs(zd):
            zd = gr
    if inverse:
        num = z0 * z0 * z0 * (1.0 / zm - 2.0 / z0 + 1.0 / zp)
    else:
        num = 2.0 * zd * zd - z0 * (zp - 2.0 * z0 + zm)
    return zd, num, z0 + off * zd


@nb.njit(cache=True, inline="always")
def _pow15(t):
    return t * math.sqrt(t)


@nb.njit(cache=True, inline="always")
def _graph_curv(c1, c2):
    return abs(c2) / _pow15(1.0 + c1 * c1)


@nb.njit(cache=True, parallel=True)
def _directional(z, fx, fy, cx, cy, inverse, minslope, ku, kv, kg, kb):
    """Directional curvatures k_u, k_v, k_g, k_b at every pixel (inf where undefined)."""
    h, w = z.shape
    for v in nb.prange(h):
        for u in range(w):
            z0 = z[v, u]
            zl = _sample(z, v, u - 1)
            zr = _sample(z, v, u + 1)
            zt = _sample(z, v - 1, u)
            zb = _sample(z, v + 1, u)
            oku = zl == zl and zr == zr and z0 == z0
            okv = zt == zt and zb == zb and z0 == z0
            zu = 0.0
            nu = 0.0
            a = 0.0
            zv = 0.0
            nv = 0.0
            b = 0.0
            if oku:
                zu, nu, a = _line(zl, z0, zr, u - cx, inverse, minslope)
                ku[v, u] = fx * fx * abs(nu) / _pow15(a * a + fx * fx * zu * zu)
            else:
                ku[v, u] = _INF
            if okv:
                zv, nv, b = _line(zt, z0, zb, v - cy, inverse, minslope)
                kv[v, u] = fy * fy * abs(nv) / _pow15(b * b + fy * fy * zv * zv)
            else:
                kv[v, u] = _INF
            if oku and okv and a != 0.0 and b != 0.0:
                c_x = fx * zu / a
                c_y = fy * zv / b
                c_xx = -fx * fx * nu / (a * a * a)
                c_yy = -fy * fy * nv / (b * b * b)
                kg[v, u] = _graph_curv(_R2 * (c_x + c_y), _R2 * (c_xx + c_yy))
                kb[v, u] = _graph_curv(_R2 * (c_x - c_y), _R2 * (c_xx - c_yy))
            else:
                kg[v, u] = _INF
                kb[v, u] = _INF


@nb.njit(cache=True, inline="always")
def _at_inf(k, v, u):
    h, w = k.shape
    if v < 0 or v >= h or u < 0 or u >= w:
        return _INF
    return k[v, u]


@nb.njit(cache=True, parallel=True)
def _aggregate(z, ku, kv, kg, kb, use_max, at_pixel, out):
    """Mean or maximum of the eight directional curvatures the neighbours point at q.

    ``at_pixel``: of the four directional curvatures of q itself instead.
    """
    h, w = z.shape
    for v in nb.prange(h):
        for u in range(w):
            if not (z[v, u] == z[v, u]):
                out[v, u] = _INF
                continue
            if at_pixel:
                a = ku[v, u]
                b = kv[v, u]
                c = kg[v, u]
                d = kb[v, u]
                if use_max:
                    out[v, u] = max(max(a, b), max(c, d))
                else:
                    out[v, u] = 0.25 * (a + b + c + d)
                continue
            t0 = _at_inf(ku, v, u - 1)
            t1 = _at_inf(ku, v, u + 1)
            t2 = _at_inf(kv, v - 1, u)
            t3 = _at_inf(kv, v + 1, u)
            t4 = _at_inf(kg, v - 1, u - 1)
            t5 = _at_inf(kg, v + 1, u + 1)
            t6 = _at_inf(kb, v - 1, u + 1)
            t7 = _at_inf(kb, v + 1, u - 1)
            if use_max:
                out[v, u] = max(max(max(t0, t1), max(t2, t3)), max(max(t4, t5), max(t6, t7)))
            else:
                out[v, u] = 0.125 * (t0 + t1 + t2 + t3 + t4 + t5 + t6 + t7)


@nb.njit(cache=True, parallel=True)
def _fundamental(z, fx, fy, cx, cy, inverse, minslope, gauss, out):
    """The paper's normal (or Gaussian) depth curvature at each pixel, guard-free form."""
    h, w = z.shape
    for v in nb.prange(h):
        for u in range(w):
            z0 = z[v, u]
            zl = _sample(z, v, u - 1)
            zr = _sample(z, v, u + 1)
            zt = _sample(z, v - 1, u)
            zb = _sample(z, v + 1, u)
            if not (z0 == z0 and zl == zl and zr == zr and zt == zt and zb == zb):
                out[v, u] = _INF
                continue
            zu, nu, a = _line(zl, z0, zr, u - cx, inverse, minslope)
            zv, nv, b = _line(zt, z0, zb, v - cy, inverse, minslope)
            if a == 0.0 or b == 0.0:
                out[v, u] = _INF
                continue
            c_x = fx * zu / a
            c_y = fy * zv / b
            c_xx = -fx * fx * nu / (a * a * a)
            c_yy = -fy * fy * nv / (b * b * b)
            c_ll = _R2 * (c_xx + c_yy)
            c_tt = _R2 * (c_xx - c_yy)
            ll = c_xx * c_yy
            mm = c_xx * c_ll
            nn = c_tt * c_yy
            if gauss:
                out[v, u] = abs(ll * nn - mm * mm)
                continue
            num = ll * zu * zu + 2.0 * mm * zu * zv + nn * zv * zv
            den = c_x * zu + c_y * zv
            den = den * den
            if den > 0.0:
                out[v, u] = abs(num) / den
            elif num == 0.0:
                out[v, u] = 0.0
            else:
                out[v, u] = _INF


@nb.njit(cache=True, inline="always")
def _pixel_line(zm, z0, zp):
    gc = 0.5 * (zp - zm)
    gl = z0 - zm
    gr = zp - z0
    g2 = min(gc * gc, min(gl * gl, gr * gr))
    return abs(zm - 2.0 * z0 + zp) / _pow15(1.0 + g2)


@nb.njit(cache=True, parallel=True)
def _pixel_mean(z, out):
    """The public code's pixel-domain mean curvature (raw depth units)."""
    h, w = z.shape
    for v in nb.prange(h):
        for u in range(w):
            z0 = z[v, u]
            zl = _sample(z, v, u - 1)
            zr = _sample(z, v, u + 1)
            zt = _sample(z, v - 1, u)
            zb = _sample(z, v + 1, u)
            if not (z0 == z0 and zl == zl and zr == zr and zt == zt and zb == zb):
                out[v, u] = _INF
                continue
            out[v, u] = 0.5 * (_pixel_line(zl, z0, zr) + _pixel_line(zt, z0, zb))


def curvature_map(z: np.ndarray, fx: float, fy: float, cx: float, cy: float, kind: str,
                  derivatives: str = "inverse-depth", slope: str = "min",
                  footprint: str = "pixel") -> np.ndarray:
    """Curvature map of prepared depth ``z`` (NaN at invalid pixels); see the module notes."""
    h, w = z.shape
    out = np.empty((h, w), dtype=np.float64)
    inverse = derivatives == "inverse-depth"
    minslope = slope == "min"
    if kind == "pixel-mean":
        _pixel_mean(z, out)
    elif kind in ("normal", "gauss"):
        _fundamental(z, fx, fy, cx, cy, inverse, minslope, kind == "gauss", out)
    else:
        ku = np.empty((h, w))
        kv = np.empty((h, w))
        kg = np.empty((h, w))
        kb = np.empty((h, w))
        _directional(z, fx, fy, cx, cy, inverse, minslope, ku, kv, kg, kb)
        _aggregate(z, ku, kv, kg, kb, kind == "max", footprint == "pixel", out)
    return out


def depth_curvature(depth: Any, K: Any, *, kind: str = "mean",
                    derivatives: str = "inverse-depth", slope: str = "min",
                    footprint: str = "pixel",
                    depth_scale: float | None = None) -> np.ndarray:
    """Depth curvature of 3F2N+ at every pixel (lower = smoother).

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z. float32/float64; integers need ``depth_scale``. Invalid depth
        (0, negative, NaN, inf) gives ``inf``.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    kind : {"mean", "max", "normal", "gauss", "pixel-mean"}, default "mean"
        Which curvature (see the module docstring of :mod:`depthnormals.ddm.curvature`).
    derivatives : {"inverse-depth", "depth"}, default "inverse-depth"
        Discretisation of the numerator ``2 z_u^2 - z z_uu`` of the metric kinds:
        ``z^3`` times the second difference of inverse depth (exactly zero on planes), or
        the paper's literal central differences of depth. Ignored by ``"pixel-mean"``.
    slope : {"min", "central"}, default "min"
        First derivative ``z_u`` of the metric kinds: the smallest in magnitude of the half
        central and the two one-sided differences (as the public code's denominator), or
        the paper's central difference, with which a depth jump reads as *flat* (its huge
        slope damps the curvature; measured in ``docs/3f2n-plus.md``).
    footprint : {"pixel", "neighbours"}, default "pixel"
        ``"mean"`` / ``"max"`` over the four directional curvatures of the pixel itself, or
        over the eight its neighbours point at it (the paper's ``k_u1 .. k_b2``, 5x5).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    k : ndarray, shape (H, W), float64
        Non-negative curvature (1 / depth unit for ``"mean"``, ``"max"``; a ranking key
        for ``"normal"``, ``"gauss"``; raw depth units for ``"pixel-mean"``); ``inf`` where
        undefined (an invalid sample or the image border).

    References
    ----------
    J. Yang, B. Xue, Y. Feng, D. Wang, R. Fan and Q. Chen, "Three-Filters-to-Normal+:
    Revisiting Discontinuity Discrimination in Depth-to-Normal Translation," IEEE
    Transactions on Automation Science and Engineering (section III-A).

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals.ddm import depth_curvature
    >>> v, u = np.mgrid[0:6, 0:8]
    >>> z = 1.0 / (0.5 + 0.01 * u - 0.02 * v)       # a tilted plane
    >>> k = depth_curvature(z, (500.0, 500.0, 3.5, 2.5))
    >>> float(np.abs(k[2:4, 2:6]).max()) < 1e-9
    True
    """
    check_choice(kind, "kind", CURVATURES)
    check_choice(derivatives, "derivatives", DERIVATIVES)
    check_choice(slope, "slope", SLOPES)
    check_choice(footprint, "footprint", FOOTPRINTS)
    z, cam = prepare(depth, K, depth_scale)
    return curvature_map(z, cam.fx, cam.fy, cam.cx, cam.cy, kind, derivatives, slope,
                         footprint)
