"""The clean-depth selection of the module: one-sided plane hypotheses, then propagation.

Ours (issue 13; not in the paper): on clean depth (renders, CAD, simulation) the error of every
estimator sits at creases and occlusions, where a stencil straddles two surfaces. On a plane
inverse depth ``w = 1 / z`` is linear in the pixel coordinates (NOTES section 2), so a stencil
lies on one plane exactly when its second differences of ``w`` vanish. Each pixel ``p``:

1. **Hypotheses.** Five planes through ``p``: the central differences of ``w`` along ``u``
   and ``v``, and the four one-sided quadrants (backward or forward along each axis). Each
   is scored by how far the pixels it relies on are from being one plane, in pixel
   footprints (``|dw| z f``): the mixed second difference
   ``w(p) - w(p + s_u) - w(p + s_v) + w(p + s_u + s_v)`` of the quadrant's 2x2 block (the
   mean of the four for the central stencil), plus :data:`LAPLACE_WEIGHT` times the 1-D
   second differences of ``w`` centred at ``p + s_u`` and ``p + s_v`` (they see creases
   parallel to an image axis, which the mixed difference cannot). The central stencil's
   score is multiplied by :data:`CENTRE_WEIGHT`: on a smooth curved surface every stencil
   scores alike and the central one is the second-order accurate one. The lowest score wins
   (ties: central first). (The four mixed stencils, central along one axis and one-sided
   along the other, change nothing measurable once the planes propagate: torus knot 1.2555
   vs 1.2556 deg, and are left out.)
2. **Propagation** (:data:`ITERATIONS` synchronous passes over the 8 neighbours, as in the
   spatial propagation of PatchMatch stereo: M. Bleyer, C. Rhemann, C. Rother, "PatchMatch
   Stereo - Stereo Matching with Slanted Support Windows", BMVC 2011): a pixel takes its
   neighbour ``q``'s plane when ``|w(p) - plane_q(p)| z f + score_q`` is below its own
   score, i.e. when ``q``'s plane is better supported and passes through ``p``. Where no
   stencil at ``p`` lies on one plane
   (a facet narrower than two pixels, a one-pixel ledge) this carries the plane of the
   surface ``p`` belongs to from where it is well measured.

The normal of the plane ``w = c + a (u - u_p) + b (v - v_p)`` is
``(fx a, fy b, c - a (u_p - cx) - b (v_p - cy))``, oriented to the camera. Exact on planes
(up to rounding), and on every facet at least two pixels wide along both axes.

Measured (docs/3f2n-plus.md, "Plane hypotheses for clean depth"): the 3F2N torus-knot frame
1.251 deg (the curvature selection 1.396, SDA-SNE 1.323), clean synthetic indoor 0.13 deg
(SDA-SNE 0.277). It is a clean-depth method: its one-pixel stencils pass noise straight
through, so ``selection="auto"`` uses it only below :data:`depthnormals.ddm.auto.PLANES_NOISE`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .._parallel import run_rows

__all__ = ["CENTRE_WEIGHT", "ITERATIONS", "LAPLACE_WEIGHT", "plane_normals"]

#: The central stencil's score is multiplied by this (the tie-break toward second order).
CENTRE_WEIGHT = 0.5
#: Weight of the 1-D second differences against the mixed one (a tie-breaker: creases along
#: an image axis leave the mixed difference at 0).
LAPLACE_WEIGHT = 1e-4
#: Synchronous propagation passes over the 8 neighbours.
ITERATIONS = 4
#: Score of a term whose pixels are missing (invalid depth or outside the image), in units of
#: 1/z (the hypotheses compare unscaled second differences; far above any real one).
_MISSING = np.float32(1e12)
_F0 = np.float32(0.0)
_HALF = np.float32(0.5)
_QUARTER = np.float32(0.25)
_TWO = np.float32(2.0)
_INF = np.float32(np.inf)
_NAN = np.float32(np.nan)
_ONE = np.float32(1.0)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _term(x):
    """``|x|``, :data:`_MISSING` when ``x`` is NaN (branch-free; capped there)."""
    return np.fmin(abs(x), _MISSING)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _pick(c, ga, gb, best, a, b):
    """The running arg-min of the hypotheses: ``c`` wins if strictly lower and both slopes
    exist (``0 (ga + gb)`` is NaN otherwise, and NaN never compares lower)."""
    c = c + _F0 * (ga + gb)
    take = c < best
    return (c if take else best), (ga if take else a), (gb if take else b)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _empty_row(RA, RB, RC, RS, k, s):
    """Ring row ``(k, s)`` with no plane anywhere (score inf, NaN slopes)."""
    for x in range(RA.shape[2]):
        RA[k, s, x] = _NAN
        RB[k, s, x] = _NAN
        RC[k, s, x] = _NAN
        RS[k, s, x] = _INF


@nb.njit(cache=True, error_model="numpy")
def _w_row(z, r, W, s):
    """Ring row ``s`` of inverse depth: ``1 / z`` of image row ``r`` (NaN outside the image;
    the two columns of padding on each side stay NaN)."""
    width = z.shape[1]
    if r < 0 or r >= z.shape[0]:
        for x in range(width):
            W[s, x + 2] = _NAN
        return
    for x in range(width):
        W[s, x + 2] = _ONE / z[r, x]


@nb.njit(cache=True, error_model="numpy")
def _hypotheses_row(W, r, fx, ratio, lw, RA, RB, RC, RS, s):
    """Stage 1 for image row ``r`` into ring row ``(0, s)``: the best of the five planes at
    each pixel (slopes of ``w``, score in footprints; NaN / inf where no stencil exists),
    and the plane's value at the pixel, ``w`` itself. ``W`` is the five-row ring of ``w``
    (row ``r + i`` in slot ``(r + i) % 5``), padded by two NaN columns on each side."""
    width = W.shape[1] - 4
    y2 = (r - 2) % 5
    y1 = (r - 1) % 5
    y = r % 5
    b1 = (r + 1) % 5
    b2 = (r + 2) % 5
    for x in range(2, width + 2):
        wp = W[y, x]
        sc = fx / wp
        wl = W[y, x - 1]
        wr = W[y, x + 1]
        wt = W[y1, x]
        wb = W[b1, x]
        # mixed second differences of the four 2x2 blocks around p
        m_ll = _term(wp - wl - wt + W[y1, x - 1])
        m_rl = _term(wp - wr - wt + W[y1, x + 1])
        m_lr = _term(wp - wl - wb + W[b1, x - 1])
        m_rr = _term(wp - wr - wb + W[b1, x + 1])
        # 1-D second differences centred at p - 1, p, p + 1 along each axis
        cu_m = lw * _term(W[y, x - 2] - _TWO * wl + wp)
        cu_0 = lw * _term(wl - _TWO * wp + wr)
        cu_p = lw * _term(wp - _TWO * wr + W[y, x + 2])
        cv_m = lw * _term(W[y2, x] - _TWO * wt + wp)
        cv_0 = lw * _term(wt - _TWO * wp + wb)
        cv_p = lw * _term(wp - _TWO * wb + W[b2, x])
        gu_m = wp - wl
        gu_p = wr - wp
        gu_0 = _HALF * (wr - wl) + _F0 * wp  # NaN at an invalid pixel, as the others
        gv_m = wp - wt
        gv_p = wb - wp
        gv_0 = _HALF * (wb - wt)
        # central first, then the four quadrants; the first lowest wins
        best, a, b = _pick(ratio * (_QUARTER * (m_ll + m_rl + m_lr + m_rr) + cu_0 + cv_0),
                           gu_0, gv_0, _INF, _NAN, _NAN)
        best, a, b = _pick(m_ll + cu_m + cv_m, gu_m, gv_m, best, a, b)
        best, a, b = _pick(m_lr + cu_m + cv_p, gu_m, gv_p, best, a, b)
        best, a, b = _pick(m_rl + cu_p + cv_m, gu_p, gv_m, best, a, b)
        best, a, b = _pick(m_rr + cu_p + cv_p, gu_p, gv_p, best, a, b)
        RA[0, s, x - 1] = a
        RB[0, s, x - 1] = b
        RS[0, s, x - 1] = best * sc  # in footprints: compared across pixels from here on
    # a separate loop: a fourth store above stops LLVM from vectorising it
    for x in range(2, width + 2):
        RC[0, s, x - 1] = W[y, x]


@nb.njit(cache=True, error_model="numpy", inline="always")
def _offer(RA, RB, RC, RS, k, sq, x, i, j, zp, fx, best, a, b, c):
    """Ring pixel ``(k, sq, x)``'s plane (the neighbour at row offset ``i``, column offset
    ``j``), taken if it explains the pixel (depth ``zp``) with a strictly lower score: the
    residual ``|1/zp - plane(p)| zp fx`` in footprints plus the neighbour's score
    (branch-free; an empty neighbour has score inf and NaN slopes, and NaN never compares
    lower)."""
    aq = RA[k, sq, x]
    bq = RB[k, sq, x]
    pred = RC[k, sq, x] - aq * np.float32(j) - bq * np.float32(i)
    s = abs(_ONE - pred * zp) * fx + RS[k, sq, x]
    take = s < best
    return (s if take else best), (aq if take else a), (bq if take else b), (pred if take else c)


@nb.njit(cache=True, error_model="numpy")
def _propagate_row(z, r, fx, QA, QB, QC, QS, q, RA, RB, RC, RS, k, sp, sm, sn):
    """A propagation pass for image row ``r``: reads ring rows ``sp``, ``sm``, ``sn`` (rows
    r - 1, r, r + 1) of stage ``q`` of the ``Q`` set, writes row ``sm`` of stage ``k`` of the
    ``R`` set (two sets, so that reads and writes never share an array: LLVM vectorises)."""
    width = z.shape[1]
    for x in range(1, width + 1):
        zp = z[r, x - 1]
        best = QS[q, sm, x]
        a = QA[q, sm, x]
        b = QB[q, sm, x]
        c = QC[q, sm, x]
        best, a, b, c = _offer(QA, QB, QC, QS, q, sm, x + 1, 0, 1, zp, fx, best, a, b, c)
        best, a, b, c = _offer(QA, QB, QC, QS, q, sm, x - 1, 0, -1, zp, fx, best, a, b, c)
        best, a, b, c = _offer(QA, QB, QC, QS, q, sn, x, 1, 0, zp, fx, best, a, b, c)
        best, a, b, c = _offer(QA, QB, QC, QS, q, sp, x, -1, 0, zp, fx, best, a, b, c)
        best, a, b, c = _offer(QA, QB, QC, QS, q, sn, x + 1, 1, 1, zp, fx, best, a, b, c)
        best, a, b, c = _offer(QA, QB, QC, QS, q, sn, x - 1, 1, -1, zp, fx, best, a, b, c)
        best, a, b, c = _offer(QA, QB, QC, QS, q, sp, x + 1, -1, 1, zp, fx, best, a, b, c)
        best, a, b, c = _offer(QA, QB, QC, QS, q, sp, x - 1, -1, -1, zp, fx, best, a, b, c)
        RA[k, sm, x] = a
        RB[k, sm, x] = b
        RC[k, sm, x] = c
        RS[k, sm, x] = best


@nb.njit(cache=True, error_model="numpy")
def _normal_row(z, r, RA, RB, RC, k, s, fx, fy, cx, cy, tmp, out):
    """Normals of ring row ``(k, s)``'s planes (image row ``r``), oriented to the camera
    (dot with the point < 0); NaN at invalid depth and where no plane was found. Computed
    into the planar ``tmp`` (3, W) first: interleaved stores stop LLVM from vectorising."""
    width = z.shape[1]
    dv = np.float32(r) - cy  # fx, fy, cx, cy in the ring's type: float32 stays float32
    for u in range(width):
        a = RA[k, s, u + 1]
        b = RB[k, s, u + 1]
        c = RC[k, s, u + 1]
        nx = fx * a
        ny = fy * b
        nz = c - a * (np.float32(u) - cx) - b * dv
        n2 = nx * nx + ny * ny + nz * nz
        inv = _ONE / np.sqrt(n2)
        # no normal where its length under- or overflows (depths near the dtype's limits:
        # 1e-30 in float32, 1e-300 in float64; a zero or NaN vector otherwise)
        inv = inv if (n2 > _F0) & (n2 < _INF) else _NAN
        # n . (du / fx, dv / fy, 1) = c, the plane's 1/z at the pixel (> 0): flip
        inv = -inv if c > _F0 else inv
        inv = inv + _F0 * z[r, u]  # NaN at invalid depth
        tmp[0, u] = nx * inv
        tmp[1, u] = ny * inv
        tmp[2, u] = nz * inv
    for u in range(width):
        out[r, u, 0] = tmp[0, u]
        out[r, u, 1] = tmp[1, u]
        out[r, u, 2] = tmp[2, u]


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _planes_rows(v0, v1, z, fxw, fyw, cxw, cyw, ratio, lw, iters, out):
    """Rows ``v0 .. v1`` of the normals: the hypotheses and ``iters`` propagation passes in
    one sweep over ring buffers of three rows per stage (stage ``k``'s row ``r`` at step
    ``r + k``), recomputing the ``iters``-row halo of the band, so the result does not depend
    on how the image is split into bands."""
    h = z.shape[0]
    width = z.shape[1]
    n = iters // 2 + 1
    tmp = np.empty((3, width), np.float32)
    W = np.empty((5, width + 4), z.dtype)
    for s in range(5):
        for x in (0, 1, width + 2, width + 3):
            W[s, x] = _NAN
    for r in range(v0 - iters - 2, v0 - iters + 2):
        _w_row(z, r, W, r % 5)
    # stage k's rings: set k % 2 (E or O), index k // 2
    # the eight rings in one allocation, each row padded to a stride that is not a multiple
    # of 4 KiB apart: separate allocations put them at addresses that alias in the cache or
    # not, by chance (the same run measured 6.9 or 8.3 ms, process to process)
    stride = width + 2 + 16
    ring = np.empty((8, n, 3, stride), z.dtype)
    EA = ring[0]
    EB = ring[1]
    EC = ring[2]
    ES = ring[3]
    OA = ring[4]
    OB = ring[5]
    OC = ring[6]
    OS = ring[7]
    for k in range(n):
        for s in range(3):
            for x in (0, width + 1):
                EA[k, s, x] = OA[k, s, x] = _NAN
                EB[k, s, x] = OB[k, s, x] = _NAN
                EC[k, s, x] = OC[k, s, x] = _NAN
                ES[k, s, x] = OS[k, s, x] = _INF
    for t in range(v0 - iters, v1 + iters):
        _w_row(z, t + 2, W, (t + 2) % 5)
        for k in range(iters + 1):
            r = t - k
            if r < v0 - (iters - k) or r >= v1 + (iters - k):
                continue
            s = r % 3
            sp = (r - 1) % 3
            sn = (r + 1) % 3
            if r < 0 or r >= h:
                if k % 2 == 0:
                    _empty_row(EA, EB, EC, ES, k // 2, s)
                else:
                    _empty_row(OA, OB, OC, OS, k // 2, s)
            elif k == 0:
                _hypotheses_row(W, r, fxw, ratio, lw, EA, EB, EC, ES, s)
            elif k % 2 == 1:
                _propagate_row(z, r, fxw, EA, EB, EC, ES, (k - 1) // 2, OA, OB, OC, OS,
                               k // 2, sp, s, sn)
            else:
                _propagate_row(z, r, fxw, OA, OB, OC, OS, (k - 1) // 2, EA, EB, EC, ES,
                               k // 2, sp, s, sn)
        r = t - iters
        if v0 <= r < v1:
            if iters % 2 == 0:
                _normal_row(z, r, EA, EB, EC, iters // 2, r % 3, fxw, fyw, cxw, cyw, tmp, out)
            else:
                _normal_row(z, r, OA, OB, OC, iters // 2, r % 3, fxw, fyw, cxw, cyw, tmp, out)


def planes_from_prepared(z: np.ndarray, fx: float, fy: float, cx: float, cy: float, *,
                         iterations: int = ITERATIONS, centre_weight: float = CENTRE_WEIGHT,
                         laplace_weight: float = LAPLACE_WEIGHT) -> np.ndarray:
    """:func:`plane_normals` on prepared depth ``z`` (NaN at invalid pixels)."""
    shape = z.shape
    # float32 depth runs in float32 (twice the vector lanes; its rounding is that of the
    # depth itself); anything else in float64
    dt = np.float32 if z.dtype == np.float32 else np.float64
    z = np.ascontiguousarray(z, dt)
    out = np.empty((*shape, 3), np.float32)
    run_rows(_planes_rows, shape[0], z, dt(fx), dt(fy), dt(cx), dt(cy), dt(centre_weight),
             dt(laplace_weight), int(iterations), out)
    return out


def plane_normals(depth: np.ndarray, K: np.ndarray, *, iterations: int = ITERATIONS,
                  depth_scale: float | None = None) -> np.ndarray:
    """Normals of clean depth from one-sided plane hypotheses and their propagation.

    The clean branch of ``selection="auto"`` (module docstring for the method; ours, issue
    13). Use it on noise-free depth (renders, simulation); on sensor depth its one-pixel
    stencils pass the noise through (``selection="auto"`` then takes the box-fit).

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth; invalid pixels (0, negative, NaN, inf) get NaN normals.
    K : array_like, shape (3, 3), or Intrinsics
        Camera matrix (pixels, 0-based principal point).
    iterations : int >= 0, keyword-only, default 4
        Propagation passes (0: the hypotheses alone).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where a valid pixel has no
        valid neighbour along an axis and no neighbour's plane reaches it.

    Notes
    -----
    Ours; the propagation step is that of PatchMatch stereo (M. Bleyer, C. Rhemann,
    C. Rother, "PatchMatch Stereo - Stereo Matching with Slanted Support Windows", BMVC 2011),
    with planes of inverse depth instead of disparity. Interpretation and measurements:
    docs/3f2n-plus.md, "Plane hypotheses for clean depth".

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals.ddm import plane_normals
    >>> z = np.full((4, 5), 2.0)
    >>> plane_normals(z, (500.0, 500.0, 2.0, 1.5))[1, 2].tolist()
    [-0.0, -0.0, -1.0]
    """
    from .._validate import check_int
    from ..kernels.depth import prepare

    it = check_int(iterations, "iterations", minimum=0, maximum=64)
    z, cam = prepare(depth, K, depth_scale)
    return planes_from_prepared(z, cam.fx, cam.fy, cam.cx, cam.cy, iterations=it)
