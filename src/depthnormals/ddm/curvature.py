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

from .._parallel import run_rows
from .._validate import check_choice
from ..kernels.depth import prepare, row_arrays, row_dtype

__all__ = ["CURVATURES", "DERIVATIVES", "FOOTPRINTS", "SLOPES", "depth_curvature"]

CURVATURES = ("mean", "max", "normal", "gauss", "pixel-mean")
DERIVATIVES = ("inverse-depth", "depth")
SLOPES = ("min", "central")
FOOTPRINTS = ("pixel", "neighbours")
_INF = np.inf
_R2 = 1.0 / math.sqrt(2.0)


_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
_INL = {"cache": True, "error_model": "numpy", "inline": "always"}
_SCA = {"cache": True, "error_model": "numpy"}  # scalar helpers: LLVM inlines them
KIND_CODES = {"mean": 0, "max": 1, "normal": 2, "gauss": 3, "pixel-mean": 4}


@nb.njit(**_INL)
def _sample(z, v, u):
    h, w = z.shape
    if v < 0 or v >= h or u < 0 or u >= w:
        return np.nan
    return np.float64(z[v, u])


@nb.njit(**_SCA)
def _line(zm, z0, zp, off, inverse, minslope):
    """First derivative z_u, numerator N_u and A = z + off z_u along one image line.

    ``minslope``: z_u is the smallest in magnitude of the half central and the two one-sided
    differences (the public code's denominator), else the half central difference.
    Branch-free (selects only), so that row loops vectorise.
    """
    zd = 0.5 * (zp - zm)
    gl = z0 - zm
    gr = zp - z0
    zd1 = gl if (minslope & (abs(gl) < abs(zd))) else zd
    zd2 = gr if (minslope & (abs(gr) < abs(zd1))) else zd1
    num_inv = z0 * z0 * z0 * (1.0 / zm - 2.0 / z0 + 1.0 / zp)
    num_lit = 2.0 * zd2 * zd2 - z0 * (zp - 2.0 * z0 + zm)
    num = num_inv if inverse else num_lit
    return zd2, num, z0 + off * zd2


@nb.njit(**_SCA)
def _pow15(t):
    return t * math.sqrt(t)


@nb.njit(**_SCA)
def _graph_curv(c1, c2):
    return abs(c2) / _pow15(1.0 + c1 * c1)


@nb.njit(**_SCA)
def _four(z0, zl, zr, zt, zb, a_off, b_off, fx, fy, inverse, minslope):
    """The four directional curvatures k_u, k_v, k_g, k_b of one pixel (inf where undefined)."""
    oku = (zl == zl) & (zr == zr) & (z0 == z0)
    okv = (zt == zt) & (zb == zb) & (z0 == z0)
    zu, nu, a = _line(zl, z0, zr, a_off, inverse, minslope)
    zv, nv, b = _line(zt, z0, zb, b_off, inverse, minslope)
    ku = fx * fx * abs(nu) / _pow15(a * a + fx * fx * zu * zu)
    kv = fy * fy * abs(nv) / _pow15(b * b + fy * fy * zv * zv)
    c_x = fx * zu / a
    c_y = fy * zv / b
    c_xx = -fx * fx * nu / (a * a * a)
    c_yy = -fy * fy * nv / (b * b * b)
    kg = _graph_curv(_R2 * (c_x + c_y), _R2 * (c_xx + c_yy))
    kb = _graph_curv(_R2 * (c_x - c_y), _R2 * (c_xx - c_yy))
    okd = oku & okv & (a != 0.0) & (b != 0.0)
    return (ku if oku else _INF), (kv if okv else _INF), (kg if okd else _INF), \
        (kb if okd else _INF)


@nb.njit(**_SCA)
def _fundamental_px(z0, zl, zr, zt, zb, a_off, b_off, fx, fy, inverse, minslope, gauss):
    """The paper's normal (or Gaussian) depth curvature of one pixel, guard-free form."""
    ok = z0 == z0 and zl == zl and zr == zr and zt == zt and zb == zb
    zu, nu, a = _line(zl, z0, zr, a_off, inverse, minslope)
    zv, nv, b = _line(zt, z0, zb, b_off, inverse, minslope)
    c_x = fx * zu / a
    c_y = fy * zv / b
    c_xx = -fx * fx * nu / (a * a * a)
    c_yy = -fy * fy * nv / (b * b * b)
    c_ll = _R2 * (c_xx + c_yy)
    c_tt = _R2 * (c_xx - c_yy)
    ll = c_xx * c_yy
    mm = c_xx * c_ll
    nn = c_tt * c_yy
    g = abs(ll * nn - mm * mm)
    num = ll * zu * zu + 2.0 * mm * zu * zv + nn * zv * zv
    den = c_x * zu + c_y * zv
    den = den * den
    k = abs(num) / den if den > 0.0 else (0.0 if num == 0.0 else _INF)
    val = g if gauss else k
    return val if (ok and a != 0.0 and b != 0.0) else _INF


@nb.njit(**_SCA)
def _pixel_line(zm, z0, zp):
    gc = 0.5 * (zp - zm)
    gl = z0 - zm
    gr = zp - z0
    g2 = min(gc * gc, min(gl * gl, gr * gr))
    return abs(zm - 2.0 * z0 + zp) / _pow15(1.0 + g2)


@nb.njit(**_SCA)
def _pixel_value(z0, zl, zr, zt, zb, a_off, b_off, fx, fy, kind, inverse, minslope):
    """Curvature of kind ``kind`` (KIND_CODES) at one pixel from its 5-point stencil."""
    if kind == 4:
        ok = z0 == z0 and zl == zl and zr == zr and zt == zt and zb == zb
        val = 0.5 * (_pixel_line(zl, z0, zr) + _pixel_line(zt, z0, zb))
        return val if ok else _INF
    if kind >= 2:
        return _fundamental_px(z0, zl, zr, zt, zb, a_off, b_off, fx, fy, inverse, minslope,
                               kind == 3)
    a, b, c, d = _four(z0, zl, zr, zt, zb, a_off, b_off, fx, fy, inverse, minslope)
    if kind == 1:
        return max(max(a, b), max(c, d))
    return 0.25 * (a + b + c + d)


#: Slots of the constants row of :func:`row_constants` (in the dtype of the row pass).
K_HALF, K_ONE, K_INF, K_ZERO, K_TWO, K_QUARTER, K_R2, K_FX, K_FY = range(9)


def row_constants(dtype: np.dtype, fx: float, fy: float) -> np.ndarray:
    """Constants of :func:`mean_max_row` in the dtype the row pass runs in."""
    return np.array([0.5, 1.0, np.inf, 0.0, 2.0, 0.25, _R2, fx, fy], dtype=dtype)


@nb.njit(**_SCA)
def mean_max_row(zp, zc, zn, Rp, Rc, Rn, acol, b_off, k, use_max, inverse, minslope, out):
    """Branch-free "mean" / "max" (pixel footprint) over the interior of one row.

    Runs in the dtype of ``zc`` (``k``: :func:`row_constants`; ``acol[u] = u - cx``, ``b_off =
    v - cy``). ``Rp, Rc, Rn``: 1 / z of the three rows. Same algebra as :func:`_four`, with
    divisions shared (one reciprocal per line and one for both diagonal terms) and the
    inverse-depth numerator written ``z^2 ((z - z_l) / z_l + (z - z_r) / z_r)``, which has no
    cancellation of large terms (float32 keeps it accurate).
    """
    half = k[K_HALF]
    one = k[K_ONE]
    inf = k[K_INF]
    zero = k[K_ZERO]
    two = k[K_TWO]
    quarter = k[K_QUARTER]
    r2 = k[K_R2]
    fx = k[K_FX]
    fy = k[K_FY]
    fx2 = fx * fx
    fy2 = fy * fy
    w = zc.size
    for u in range(1, w - 1):
        z0 = zc[u]
        zl = zc[u - 1]
        zr = zc[u + 1]
        zt = zp[u]
        zb = zn[u]
        oku = (zl == zl) & (zr == zr) & (z0 == z0)
        okv = (zt == zt) & (zb == zb) & (z0 == z0)
        # first derivatives: half central difference, or the smallest one-sided one
        zu = half * (zr - zl)
        gl = z0 - zl
        gr = zr - z0
        zu = gl if (minslope & (abs(gl) < abs(zu))) else zu
        zu = gr if (minslope & (abs(gr) < abs(zu))) else zu
        zv = half * (zb - zt)
        gt = z0 - zt
        gb = zb - z0
        zv = gt if (minslope & (abs(gt) < abs(zv))) else zv
        zv = gb if (minslope & (abs(gb) < abs(zv))) else zv
        a = z0 + acol[u] * zu
        b = z0 + b_off * zv
        zz = z0 * z0
        nu_i = zz * (gl * Rc[u - 1] - gr * Rc[u + 1])
        nv_i = zz * (gt * Rp[u] - gb * Rn[u])
        nu_l = two * zu * zu - z0 * (gr - gl)
        nv_l = two * zv * zv - z0 * (gb - gt)
        nu = nu_i if inverse else nu_l
        nv = nv_i if inverse else nv_l
        su = a * a + fx2 * zu * zu
        sv = b * b + fy2 * zv * zv
        ku = fx2 * abs(nu) / (su * np.sqrt(su))
        kv = fy2 * abs(nv) / (sv * np.sqrt(sv))
        ia = one / a
        ib = one / b
        c_x = fx * zu * ia
        c_y = fy * zv * ib
        c_xx = -fx2 * nu * (ia * ia * ia)
        c_yy = -fy2 * nv * (ib * ib * ib)
        cg = r2 * (c_x + c_y)
        cb = r2 * (c_x - c_y)
        tg = one + cg * cg
        tb = one + cb * cb
        pg = tg * np.sqrt(tg)
        pb = tb * np.sqrt(tb)
        r = one / (pg * pb)
        kg = abs(r2 * (c_xx + c_yy)) * pb * r
        kb = abs(r2 * (c_xx - c_yy)) * pg * r
        okd = oku & okv & (a != zero) & (b != zero)
        ku = ku if oku else inf
        kv = kv if okv else inf
        kg = kg if okd else inf
        kb = kb if okd else inf
        mx = max(max(ku, kv), max(kg, kb))
        mn = quarter * (ku + kv + kg + kb)
        out[u] = mx if use_max else mn


@nb.njit(**_SCA)
def _pixel_mean_row(zp, zc, zn, out):
    """Branch-free "pixel-mean" over the interior of one row."""
    w = zc.size
    for u in range(1, w - 1):
        z0 = np.float64(zc[u])
        zl = np.float64(zc[u - 1])
        zr = np.float64(zc[u + 1])
        zt = np.float64(zp[u])
        zb = np.float64(zn[u])
        ok = (z0 == z0) & (zl == zl) & (zr == zr) & (zt == zt) & (zb == zb)
        val = 0.5 * (_pixel_line(zl, z0, zr) + _pixel_line(zt, z0, zb))
        out[u] = val if ok else _INF


@nb.njit(**_SCA)
def _other_row(zp, zc, zn, b_off, fx, fy, cx, kind, inverse, minslope, out):
    w = zc.size
    for u in range(1, w - 1):
        out[u] = _pixel_value(np.float64(zc[u]), np.float64(zc[u - 1]), np.float64(zc[u + 1]),
                              np.float64(zp[u]), np.float64(zn[u]), u - cx, b_off, fx, fy,
                              kind, inverse, minslope)


@nb.njit(**_JIT)
def _curvature_rows(v0, v1, z, fx, fy, cx, cy, kind, inverse, minslope, k, acol, bcol, out):
    """Curvature at the pixel itself (pixel footprint) for the rows [v0, v1)."""
    h, w = z.shape
    R = np.empty((3, w), dtype=z.dtype)  # rolling 1 / z of rows v-1, v, v+1 (slot = row % 3)
    row = np.empty(w, dtype=z.dtype)
    one = k[K_ONE]
    if kind <= 1:
        for r in range(max(v0 - 1, 0), min(v0 + 1, h)):
            for u in range(w):
                R[r % 3, u] = one / z[r, u]
    for v in range(v0, v1):
        b_off = v - cy
        if kind <= 1 and v + 1 < h:
            Rn = R[(v + 1) % 3]
            zn = z[v + 1]
            for u in range(w):
                Rn[u] = one / zn[u]
        if 0 < v < h - 1 and w > 2:
            if kind <= 1:
                mean_max_row(z[v - 1], z[v], z[v + 1], R[(v - 1) % 3], R[v % 3], R[(v + 1) % 3],
                             acol, bcol[v], k, kind == 1, inverse, minslope, row)
                for u in range(1, w - 1):
                    out[v, u] = row[u]
            elif kind == 4:
                _pixel_mean_row(z[v - 1], z[v], z[v + 1], out[v])
            else:
                _other_row(z[v - 1], z[v], z[v + 1], b_off, fx, fy, cx, kind, inverse,
                           minslope, out[v])
            edge = (0, w - 1)
        else:
            edge = (-1, -1)
        for u in range(w):
            if edge[0] >= 0 and u != edge[0] and u != edge[1]:
                continue
            out[v, u] = _pixel_value(_sample(z, v, u), _sample(z, v, u - 1),
                                     _sample(z, v, u + 1), _sample(z, v - 1, u),
                                     _sample(z, v + 1, u), u - cx, b_off, fx, fy, kind,
                                     inverse, minslope)


@nb.njit(**_JIT)
def _directional_rows(v0, v1, z, fx, fy, cx, cy, inverse, minslope, ku, kv, kg, kb):
    """Directional curvatures k_u, k_v, k_g, k_b at every pixel (inf where undefined)."""
    w = z.shape[1]
    for v in range(v0, v1):
        for u in range(w):
            a, b, c, d = _four(_sample(z, v, u), _sample(z, v, u - 1), _sample(z, v, u + 1),
                               _sample(z, v - 1, u), _sample(z, v + 1, u), u - cx, v - cy,
                               fx, fy, inverse, minslope)
            ku[v, u] = a
            kv[v, u] = b
            kg[v, u] = c
            kb[v, u] = d


def _directional(z, fx, fy, cx, cy, inverse, minslope, ku, kv, kg, kb):
    run_rows(_directional_rows, z.shape[0], z, fx, fy, cx, cy, inverse, minslope,
             ku, kv, kg, kb)


@nb.njit(**_INL)
def _at_inf(k, v, u):
    h, w = k.shape
    if v < 0 or v >= h or u < 0 or u >= w:
        return _INF
    return k[v, u]


@nb.njit(**_JIT)
def _aggregate_rows(v0, v1, z, ku, kv, kg, kb, use_max, out):
    """Mean or maximum of the eight directional curvatures the neighbours point at q."""
    w = z.shape[1]
    for v in range(v0, v1):
        for u in range(w):
            if not (z[v, u] == z[v, u]):
                out[v, u] = _INF
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


def curvature_map(z: np.ndarray, fx: float, fy: float, cx: float, cy: float, kind: str,
                  derivatives: str = "inverse-depth", slope: str = "min",
                  footprint: str = "pixel") -> np.ndarray:
    """Curvature map of prepared depth ``z`` (NaN at invalid pixels, as
    :func:`depthnormals.kernels.depth.row_dtype` gives it); see the module notes."""
    h, w = z.shape
    out = np.empty((h, w), dtype=np.float64)
    inverse = derivatives == "inverse-depth"
    minslope = slope == "min"
    if footprint == "neighbours" and kind in ("mean", "max"):
        ku = np.empty((h, w))
        kv = np.empty((h, w))
        kg = np.empty((h, w))
        kb = np.empty((h, w))
        _directional(z, fx, fy, cx, cy, inverse, minslope, ku, kv, kg, kb)
        run_rows(_aggregate_rows, h, z, ku, kv, kg, kb, kind == "max", out)
    else:
        with np.errstate(over="ignore", under="ignore"):  # only where the rows are not used
            k = row_constants(z.dtype, fx, fy)
        _, acol, bcol = row_arrays(z, fx, fy, cx, cy)
        run_rows(_curvature_rows, h, z, float(fx), float(fy), float(cx), float(cy),
                 KIND_CODES[kind], inverse, minslope, k, acol, bcol, out)
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
    z = row_dtype(z, cam.fx, cam.fy, cam.cx, cam.cy)
    return curvature_map(z, cam.fx, cam.fy, cam.cx, cam.cy, kind, derivatives, slope,
                         footprint)
