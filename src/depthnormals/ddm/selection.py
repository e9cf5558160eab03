"""Stage 1 of 3F2N+: each pixel takes the normal of its best candidate (section III-A), and the
correlation-only selection of stage 2 (section III-B), compiled with numba.

:func:`select_min` is the entry point (any neighbourhood: :func:`_select_pixel`, the per-pixel
reference); the cross neighbourhood runs the vectorised row kernel :func:`cross_select_row`,
which the fused 3F2N+ pass (:mod:`depthnormals.ddm.threefn_plus`) calls too. The consistency
test is :func:`inconsistency`. The CRF of stage 3 is :mod:`depthnormals.ddm.crf`.

Every kernel is a serial numba function over a band of rows, run on threads by
:func:`depthnormals._parallel.run_rows`; candidates are the pixels of a neighbourhood whose depth
is valid and whose input normal is finite, so invalid pixels never give a normal. The chosen
normal is re-oriented toward the camera at the receiving pixel.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..kernels.depth import C_FX, C_FY, C_INF, C_MAX, C_ONE, C_TIE2, C_ZERO, Pinhole, row_arrays
from ..kernels.orient import faces_away, store_nan, store_normal

__all__ = ["CROSS", "SQUARE", "clamp_key", "cross_select_row", "inconsistency", "inconsistency_pq",
           "select_min", "select_ring_row"]

# candidate offsets (dv, du), self first (self wins ties). CROSS is the public code's order:
# self, up, left, right, down.
CROSS = np.array([[0, 0], [-1, 0], [0, -1], [0, 1], [1, 0]], dtype=np.int64)
SQUARE = np.array([[0, 0], [-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0],
                   [1, 1]], dtype=np.int64)
_KEY_MAX = np.finfo(np.float64).max  # keys at or above it tie (first wins)


_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
_INL = {"cache": True, "error_model": "numpy", "inline": "always"}
#: The helpers of the vectorised cross selection: its flags, compiled once and called (LLVM
#: inlines them into its loop); ``inline="always"`` would copy and re-type them at every call,
#: seconds of the first run.
_CROSS_HELPER = {"cache": True, "error_model": "numpy", "fastmath": {"nsz", "contract", "arcp"}}


@nb.njit(**_INL)
def _ok(z, n, r, c):
    h, w = z.shape
    if r < 0 or r >= h or c < 0 or c >= w:
        return False
    return z[r, c] == z[r, c] and n[r, c, 0] == n[r, c, 0]


@nb.njit(**_INL)
def _side(r, d, step, one, zero):
    """(|N|, |D|) with ``rho = fx |N| / |D|``: the residual of a neighbour at ``z_p = r z_q``
    to the plane through q's point, which predicts ``z_q d / (d + step)`` on its ray. An
    invalid neighbour (NaN ``r``) reads as (1, 0): an infinite residual."""
    den = d + step
    num = r * den - d
    ok = num == num
    return (abs(num) if ok else one), (abs(den) if ok else zero)


@nb.njit(**_INL)
def _axis(rm, rp, d, step, one, zero):
    """(N, D) of the smaller residual of the two neighbours along one axis (division-free)."""
    nm, dm = _side(rm, d, -step, one, zero)
    np_, dp = _side(rp, d, step, one, zero)
    take_m = nm * dp < np_ * dm
    return (nm if take_m else np_), (dm if take_m else dp)


@nb.njit(**_INL)
def inconsistency_pq(a, b, t, rl, rr, rt, rb, A, B, ifx, ify, fx, one, zero):
    """One-sided tangent inconsistency of the candidate normal (a, b, t) at pixel q, as a
    fraction ``S = P / Q`` (``Q = 0``: infinite), free of divisions.

    ``S = min(rho_left, rho_right)^2 + min(rho_up, rho_down)^2`` with ``rho_p`` the residual
    of the neighbour point ``X_p`` to the plane with this normal through ``X_q``, along p's
    ray, in footprints ``z_q / fx``. With ``d = n . ray_q`` (ray ``((u - cx) / fx,
    (v - cy) / fy, 1)``) the plane predicts ``z_q d / (d -+ a / fx)`` left / right (likewise
    with ``b / fy`` up / down), so ``rho_p = fx |z_p / z_q - d / (d + step)|``. ``rl .. rb``:
    the neighbours' ``z_p / z_q`` (NaN when invalid); ``A, B``: ``u - cx``, ``v - cy``.
    Small when the normal is tangent to the depth on at least one side along each axis
    (right at creases and occlusions); infinite when an axis has no valid side. ``one``,
    ``zero``: 1 and 0 in the working dtype.
    """
    sa = a * ifx
    sb = b * ify
    d = sa * A + sb * B + t
    nu, du = _axis(rl, rr, d, sa, one, zero)
    nv, dv = _axis(rt, rb, d, sb, one, zero)
    du2 = du * du
    dv2 = dv * dv
    return fx * fx * (nu * nu * dv2 + nv * nv * du2), du2 * dv2


@nb.njit(**_INL)
def inconsistency(a, b, t, rl, rr, rt, rb, A, B, ifx, ify, fx, inf):
    """:func:`inconsistency_pq` as a number (``inf`` where undefined)."""
    p, q = inconsistency_pq(a, b, t, rl, rr, rt, rb, A, B, ifx, ify, fx, 1.0, 0.0)
    s = p / q
    return s if s < inf else inf


@nb.njit(**_CROSS_HELPER)
def _pq_fast(a, b, t, rl, rr, rt, rb, A, B, ifx, ify, fx, one, zero):
    """:func:`inconsistency_pq` with the flags of :func:`_cross_select`, compiled once and
    called (not inlined by numba: LLVM inlines it) for each of the five normals there: five
    numba-inlined copies cost about 8 s of compile on the first run, this costs well under 1 s
    at the same speed and with the same bits (the same instructions and flags once inlined)."""
    return inconsistency_pq(a, b, t, rl, rr, rt, rb, A, B, ifx, ify, fx, one, zero)


@nb.njit(**_INL)
def _ratios(z, v, u):
    h, w = z.shape
    zq = np.float64(z[v, u])
    rl = np.float64(z[v, u - 1]) / zq if u > 0 else np.nan
    rr = np.float64(z[v, u + 1]) / zq if u + 1 < w else np.nan
    rt = np.float64(z[v - 1, u]) / zq if v > 0 else np.nan
    rb = np.float64(z[v + 1, u]) / zq if v + 1 < h else np.nan
    return rl, rr, rt, rb


@nb.njit(**_INL)
def _select_pixel(z, normals, key, offs, fx, fy, cx, cy, v, u, selfw, eps, out):
    """The selection at one pixel, any neighbourhood (``offs[0]`` is the pixel itself).

    A candidate that beats the best key is taken when it passes the consistency test
    (``eps`` >= 0; :func:`inconsistency`): ``S_candidate < S_own + eps``. The test is off with
    ``eps < 0``, and skipped where the pixel has no normal or ``S_own`` is infinite.
    """
    zq = z[v, u]
    if not (zq == zq):
        store_nan(out, v, u)
        return
    rl, rr, rt, rb = _ratios(z, v, u)
    A = u - cx
    B = v - cy
    ifx = 1.0 / fx
    ify = 1.0 / fy
    s_own = np.inf
    if eps >= 0.0 and normals[v, u, 0] == normals[v, u, 0]:
        s_own = inconsistency(np.float64(normals[v, u, 0]), np.float64(normals[v, u, 1]),
                              np.float64(normals[v, u, 2]), rl, rr, rt, rb, A, B, ifx, ify, fx,
                              np.inf)
    best = np.inf
    bv = np.int64(v)
    bu = np.int64(u)
    for k in range(offs.shape[0]):
        r = v + offs[k, 0]
        c = u + offs[k, 1]
        if not _ok(z, normals, r, c):
            continue
        kk = clamp_key(key[r, c], _KEY_MAX)
        kk = kk * selfw if k == 0 else kk
        if not (kk < best):
            continue
        if k > 0 and s_own < np.inf:
            s = inconsistency(np.float64(normals[r, c, 0]), np.float64(normals[r, c, 1]),
                              np.float64(normals[r, c, 2]), rl, rr, rt, rb, A, B, ifx, ify,
                              fx, np.inf)
            if not (s < s_own + eps):
                continue
        best = kk
        bv = r
        bu = c
    if best < np.inf:
        store_normal(out, v, u, np.float64(normals[bv, bu, 0]), np.float64(normals[bv, bu, 1]),
                     np.float64(normals[bv, bu, 2]), A * zq / fx, B * zq / fy, zq)
    else:
        store_nan(out, v, u)


@nb.njit(**_INL)
def clamp_key(k, big):
    """A valid candidate's key: ``inf`` and NaN read as ``big`` (any valid candidate beats
    none; among keys >= ``big`` the first wins)."""
    return k if k < big else big


@nb.njit(**_CROSS_HELPER)
def _key(kr, xr, big, inf):
    return clamp_key(kr, big) if xr == xr else inf


@nb.njit(**_CROSS_HELPER)
def _pick(kr, k, ok, xr, yr, tr, x, y, t):
    """(key, normal) of the candidate if its key is strictly smaller and it passes ``ok``."""
    kr = np.float64(kr)
    tk = (kr < k) & ok
    return (kr if tk else k), (xr if tk else x), (yr if tk else y), (tr if tk else t)


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"},
         inline="always")
def _cross_select(z3, n3, k3, acol, b, c, selfw, eps, out_row, test):
    """Body of :func:`cross_select_row`; ``test`` (a constant in each caller): consistency."""
    zp, zc, zn = z3
    (px, py, pz), (qx, qy, qz), (nx, ny, nz) = n3
    kp, kq, kn = k3
    bx, by, bz = out_row
    one = c[C_ONE]
    inf = c[C_INF]
    zero = c[C_ZERO]
    fx = c[C_FX]
    big = c[C_MAX]
    nan = zero * inf
    ifx = one / fx
    ify = one / c[C_FY]
    bfy = b * ify
    tie2 = c[C_TIE2]
    p2y = one + bfy * bfy
    for u in range(bx.size):
        i = u + 1
        zq = zc[i]
        A = acol[u]
        x = qx[i]
        y = qy[i]
        t = qz[i]
        ok1 = True
        ok2 = True
        ok3 = True
        ok4 = True
        if test:  # a constant in each of the two compiled versions below
            iz = one / zq
            rl = zc[i - 1] * iz
            rr = zc[i + 1] * iz
            rt = zp[i] * iz
            rb = zn[i] * iz
            # S_candidate < S_own + eps, cross-multiplied: one division per pixel
            p0, q0 = _pq_fast(x, y, t, rl, rr, rt, rb, A, b, ifx, ify, fx, one, zero)
            lim = p0 / q0 + eps
            free = not ((x == x) & (lim < inf))
            p1, q1 = _pq_fast(px[i], py[i], pz[i], rl, rr, rt, rb, A, b, ifx, ify, fx, one, zero)
            ok1 = free | (p1 < lim * q1)
            p2, q2 = _pq_fast(qx[i - 1], qy[i - 1], qz[i - 1], rl, rr, rt, rb, A, b, ifx,
                                      ify, fx, one, zero)
            ok2 = free | (p2 < lim * q2)
            p3, q3 = _pq_fast(qx[i + 1], qy[i + 1], qz[i + 1], rl, rr, rt, rb, A, b, ifx,
                                      ify, fx, one, zero)
            ok3 = free | (p3 < lim * q3)
            p4, q4 = _pq_fast(nx[i], ny[i], nz[i], rl, rr, rt, rb, A, b, ifx, ify, fx, one, zero)
            ok4 = free | (p4 < lim * q4)
        k = np.float64(_key(kq[i], x if zq == zq else nan, big, inf)) * selfw
        xr = px[i]
        k, x, y, t = _pick(_key(kp[i], xr if zp[i] == zp[i] else nan, big, inf), k, ok1, xr,
                           py[i], pz[i], x, y, t)
        xr = qx[i - 1]
        k, x, y, t = _pick(_key(kq[i - 1], xr if zc[i - 1] == zc[i - 1] else nan, big, inf),
                           k, ok2, xr, qy[i - 1], qz[i - 1], x, y, t)
        xr = qx[i + 1]
        k, x, y, t = _pick(_key(kq[i + 1], xr if zc[i + 1] == zc[i + 1] else nan, big, inf),
                           k, ok3, xr, qy[i + 1], qz[i + 1], x, y, t)
        xr = nx[i]
        k, x, y, t = _pick(_key(kn[i], xr if zn[i] == zn[i] else nan, big, inf), k, ok4, xr,
                           ny[i], nz[i], x, y, t)
        n2 = x * x + y * y + t * t
        nrm = np.sqrt(n2)
        inv = one / nrm
        ax = A * ifx
        inv = -inv if faces_away(x * ax + y * bfy + t, n2, ax * ax + p2y, x, y, t, tie2) else inv
        inv = inv if (zq == zq) & (k < inf) else nan
        bx[u] = x * inv
        by[u] = y * inv
        bz[u] = t * inv


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"})
def _cross_plain(z3, n3, k3, acol, b, c, selfw, eps, out_row):
    _cross_select(z3, n3, k3, acol, b, c, selfw, eps, out_row, False)


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"})
def _cross_consistent(z3, n3, k3, acol, b, c, selfw, eps, out_row):
    _cross_select(z3, n3, k3, acol, b, c, selfw, eps, out_row, True)


@nb.njit(cache=True, error_model="numpy")
def cross_select_row(z3, n3, k3, acol, b, c, selfw, eps, out_row):
    """The cross selection (self, up, left, right, down) of one row from padded planar rows.

    ``z3 = (zp, zc, zn)``: depth of the rows above, at and below; ``n3 = ((px, py, pz), (qx,
    qy, qz), (nx, ny, nz))``: their normal components; ``k3 = (kp, kq, kn)``: their keys; all
    indexed ``u + 1`` (columns 0 and W + 1 are padding: NaN). ``b = v - cy``; writes the
    selected normals into ``out_row = (bx, by, bz)`` (W). A candidate is valid where its depth
    and normal are. Rule (as :func:`_select_pixel`): keys clamped (:func:`clamp_key`) and
    compared in float64, self first with its key times ``selfw``, a candidate taken when its
    key is strictly smaller and (``eps >= 0``) it passes the consistency test against the
    pixel's own normal. The winner is renormalised and turned toward the camera; NaN where
    none or where the pixel's depth is invalid. ``c``: the constants row of
    :func:`depthnormals.kernels.depth.row_arrays` (slots ``C_ONE`` .. ``C_TIE2``).
    """
    if eps >= 0.0:
        _cross_consistent(z3, n3, k3, acol, b, c, selfw, eps, out_row)
    else:
        _cross_plain(z3, n3, k3, acol, b, c, selfw, eps, out_row)


@nb.njit(cache=True, error_model="numpy")
def fill_padded(zrow, nrow, krow, zb, nb3, kb):
    """Copy one row of depth, (interleaved) normals and keys into padded planar buffers."""
    w = zrow.size
    for u in range(w):
        zb[u + 1] = zrow[u]
        kb[u + 1] = krow[u]
    for j in range(3):
        for u in range(w):
            nb3[j, u + 1] = nrow[u, j]


@nb.njit(**_INL)
def _select_body(v0, v1, z, normals, key, offs, cam, c, acol, bcol, selfw, eps, out, cross,
                 consistent):
    """Selection of rows [v0, v1) into ``out``; ``cross`` (the cross neighbourhood: the
    vectorised row kernel) and ``consistent`` (``eps >= 0``) are compile-time constants of the
    kernels below."""
    fx, fy, cx, cy = cam
    h, w = z.shape
    if not cross:
        for v in range(v0, v1):
            for u in range(w):
                _select_pixel(z, normals, key, offs, fx, fy, cx, cy, v, u, selfw, eps, out)
        return
    # ring of padded planar rows (slot r % 3; slot 3 stays NaN: rows outside the image)
    zb = np.full((4, w + 2), np.nan, dtype=z.dtype)
    nb3 = np.full((4, 3, w + 2), np.nan, dtype=normals.dtype)
    kb = np.full((4, w + 2), np.inf, dtype=key.dtype)
    bx = np.empty(w, dtype=normals.dtype)
    by = np.empty(w, dtype=normals.dtype)
    bz = np.empty(w, dtype=normals.dtype)
    for r in range(max(v0 - 1, 0), min(v1 + 1, h)):
        fill_padded(z[r], normals[r], key[r], zb[r % 3], nb3[r % 3], kb[r % 3])
        for q in range(r - 1, r + 1 if r == h - 1 else r):  # the last row has none below
            if v0 <= q < v1:
                select_ring_row(q, h, (zb, nb3, kb), acol, bcol, c, selfw, eps, consistent,
                                (bx, by, bz))
                for u in range(w):
                    out[q, u, 0] = bx[u]
                    out[q, u, 1] = by[u]
                    out[q, u, 2] = bz[u]


@nb.njit(**_JIT)
def _select_rows_pixel(v0, v1, z, normals, key, offs, cam, c, acol, bcol, selfw, eps, out):
    """Any neighbourhood, per pixel (:func:`_select_pixel`)."""
    _select_body(v0, v1, z, normals, key, offs, cam, c, acol, bcol, selfw, eps, out, False, False)


@nb.njit(**_JIT)
def _select_rows_cross(v0, v1, z, normals, key, offs, cam, c, acol, bcol, selfw, eps, out):
    """The cross neighbourhood, vectorised, without the consistency test."""
    _select_body(v0, v1, z, normals, key, offs, cam, c, acol, bcol, selfw, eps, out, True, False)


@nb.njit(**_JIT)
def _select_rows_cross_consistent(v0, v1, z, normals, key, offs, cam, c, acol, bcol, selfw, eps,
                                  out):
    """The cross neighbourhood, vectorised, with the consistency test."""
    _select_body(v0, v1, z, normals, key, offs, cam, c, acol, bcol, selfw, eps, out, True, True)


@nb.njit(**_INL)
def select_ring_row(q, h, ring, acol, bcol, c, selfw, eps, consistent, out_row):
    """:func:`cross_select_row` for row ``q`` from ring buffers ``ring = (zb, nb3, kb)`` (slot
    ``row % 3``, slot 3: outside the image) of padded depth, planar normals and keys, once rows
    q - 1 .. q + 1 are in them; writes ``out_row = (bx, by, bz)``.

    ``consistent`` (``eps >= 0``: the consistency test) must be a compile-time constant of the
    caller: only the kernel it needs is compiled, which matters on the first run."""
    zb, nb3, kb = ring
    a = (q - 1) % 3 if q > 0 else 3
    s = (q + 1) % 3 if q + 1 < h else 3
    m = q % 3
    z3 = (zb[a], zb[m], zb[s])
    n3 = ((nb3[a, 0], nb3[a, 1], nb3[a, 2]), (nb3[m, 0], nb3[m, 1], nb3[m, 2]),
          (nb3[s, 0], nb3[s, 1], nb3[s, 2]))
    k3 = (kb[a], kb[m], kb[s])
    if consistent:
        _cross_consistent(z3, n3, k3, acol, bcol[q], c, selfw, eps, out_row)
    else:
        _cross_plain(z3, n3, k3, acol, bcol[q], c, selfw, eps, out_row)


def select_min(z, normals, key, offs, fx, fy, cx, cy, out, self_weight=1.0, consistency=None):
    """Each valid pixel takes the normal of the candidate with the least ``key`` (self first).

    The pixel's own key is multiplied by ``self_weight`` first (1: plain arg-min, the pixel
    winning ties; < 1: a neighbour must be clearly better). ``consistency`` (footprints^2,
    None: off): a neighbour is taken only if its normal fits the pixel's depth about as well
    as the pixel's own (:func:`inconsistency`). Writes every pixel of ``out`` (NaN at
    invalid depth and where no candidate exists). ``z`` as
    :func:`depthnormals.kernels.depth.row_dtype` gives it.
    """
    cross = offs.shape == CROSS.shape and bool((offs == CROSS).all())
    c, acol, bcol = row_arrays(z, fx, fy, cx, cy)
    eps = -1.0 if consistency is None else float(consistency)
    kernel = (_select_rows_pixel if not cross else
              _select_rows_cross_consistent if eps >= 0.0 else _select_rows_cross)
    run_rows(kernel, z.shape[0], z, normals, key, offs,
             Pinhole(float(fx), float(fy), float(cx), float(cy)), c, acol, bcol, float(self_weight),
             eps, out)
