"""Spatial discontinuity-aware SNE (SDA-SNE): multi-directional dynamic programming of depth
gradients, then the D2NT formula."""

from __future__ import annotations

import numbers
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..kernels.depth import new_output, prepare
from ..kernels.orient import store_normal

__all__ = ["sda_sne"]

_INF = np.inf


_P = 2  # padding of the working arrays: every neighbour read stays in bounds


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _laplacian_rows(v0, v1, zp, lu, lv, mu, mv):
    """Signed 1-D Laplacians ``2 z - z(-1) - z(+1)`` along u and v of the padded depth (NaN
    where undefined) and their magnitudes (inf where undefined), rows ``P + [v0, v1)``."""
    W = zp.shape[1]
    P = _P
    for v in range(v0 + P, v1 + P):
        for u in range(P, W - P):
            zc = zp[v, u]
            a = 2.0 * zc - zp[v, u - 1] - zp[v, u + 1]
            b = 2.0 * zc - zp[v - 1, u] - zp[v + 1, u]
            lu[v, u] = a
            lv[v, u] = b
            if a == a:
                mu[v, u] = abs(a)
            if b == b:
                mv[v, u] = abs(b)


def _setup(z):
    """Padded working arrays: depth (NaN pad), Laplacians and their magnitudes."""
    h, w = z.shape
    P = _P
    zp = np.full((h + 2 * P, w + 2 * P), np.nan)
    zp[P:P + h, P:P + w] = z
    lu = np.full(zp.shape, np.nan)
    lv = np.full(zp.shape, np.nan)
    mu = np.full(zp.shape, _INF)
    mv = np.full(zp.shape, _INF)
    run_rows(_laplacian_rows, h, zp, lu, lv, mu, mv)
    return zp, lu, lv, mu, mv


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _init(v0, v1, zp, mu, mv, Gu, Gv, Eu, Ev, Su, Sv):
    """Initial gradients: per direction the central, forward or backward difference whose
    |Laplacian| (at the pixel, the forward or the backward neighbour) is least.

    State: 2 central, 1 forward, 0 backward (-1 none). First minimum wins; with no finite
    energy, the first available difference with infinite energy.
    """
    W = zp.shape[1]
    for v in range(v0 + _P, v1 + _P):
        for u in range(_P, W - _P):
            zc = zp[v, u]
            if not (zc == zc):
                continue
            for d in range(2):
                if d == 0:
                    zf = zp[v, u + 1]
                    zb = zp[v, u - 1]
                    ec = mu[v, u]
                    ef = mu[v, u + 1]
                    eb = mu[v, u - 1]
                else:
                    zf = zp[v + 1, u]
                    zb = zp[v - 1, u]
                    ec = mv[v, u]
                    ef = mv[v + 1, u]
                    eb = mv[v - 1, u]
                gc = 0.5 * (zf - zb)
                gf = zf - zc
                gb = zc - zb
                if not (gc == gc):
                    ec = _INF
                if not (gf == gf):
                    ef = _INF
                if not (gb == gb):
                    eb = _INF
                best = -1
                be = _INF
                if ec < be:
                    be = ec
                    best = 2
                if ef < be:
                    be = ef
                    best = 1
                if eb < be:
                    be = eb
                    best = 0
                if best == -1:
                    if gc == gc:
                        best = 2
                    elif gf == gf:
                        best = 1
                    elif gb == gb:
                        best = 0
                    else:
                        continue
                g = gc if best == 2 else (gf if best == 1 else gb)
                if d == 0:
                    Gu[v, u] = g
                    Eu[v, u] = be
                    Su[v, u] = best
                else:
                    Gv[v, u] = g
                    Ev[v, u] = be
                    Sv[v, u] = best


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _across_costs(v0, v1, mu, mv, Eu, Ev, Cu, Cv):
    """Cost of reaching a pixel from across: ``Cu = |L_v| + E_u``, ``Cv = |L_u| + E_v``
    (padded rows ``[v0, v1)``)."""
    W = mu.shape[1]
    for v in range(v0, v1):
        for u in range(W):
            Cu[v, u] = mv[v, u] + Eu[v, u]
            Cv[v, u] = mu[v, u] + Ev[v, u]


@nb.njit(cache=True, error_model="numpy", inline="always")
def _pick(best_g, best_e, best_s, g, e, s):
    if g == g and e < best_e:
        return g, e, s
    return best_g, best_e, best_s


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _iterate(v0, v1, zp, lap, state, costs, step, out_state, out_moved):
    """One synchronous round of the nine transitions, for both directions.

    Reads the padded depth ``zp``, ``lap = (lu, lv, mu, mv)`` (:func:`_setup`), ``state =
    (Gu, Gv, Eu, Ev, Su, Sv)`` (gradients, energies, stencil choices) and ``costs = (Cu, Cv)``
    (:func:`_across_costs`); writes the next state into ``out_state`` (same layout) and the
    number of pixels that changed per row into ``out_moved``.

    Candidate order of the public code (first minimum wins): 0 extend from the backward
    neighbour, 1 from the forward neighbour, 2 stay, 3/4 copy from the backward / forward
    neighbour across, 5..8 the diagonals (back-back, back-fwd, fwd-back, fwd-fwd: across
    first, then along) with a mixed-derivative correction.
    """
    lu, lv, mu, mv = lap
    Gu, Gv, Eu, Ev, Su, Sv = state
    Cu, Cv = costs
    nGu, nGv, nEu, nEv, nSu, nSv = out_state
    moved = out_moved
    W = zp.shape[1]
    for v in range(v0 + _P, v1 + _P):
        m = 0
        for u in range(_P, W - _P):
            zc = zp[v, u]
            if not (zc == zc):
                continue
            gu = Gu[v, u]
            gv = Gv[v, u]
            # ---- gradient along u (across = v) ----
            bg = gu
            be = Eu[v, u]
            bs = 2
            s0 = Su[v, u]
            if s0 == 0 and Su[v, u - 1] == 0 and lu[v, u - 1] * lu[v, u - 2] > 0.0:
                e = mu[v, u - 1]
                g = gu + ((zc - zp[v, u - 1]) - Gu[v, u - 1]) * step
                if g == g and e < _INF and e <= be:
                    bg, be, bs = g, e, 0
            elif s0 == 1 and Su[v, u + 1] == 1 and lu[v, u + 1] * lu[v, u + 2] > 0.0:
                e = mu[v, u + 1]
                g = gu + ((zp[v, u + 1] - zc) - Gu[v, u + 1]) * step
                if g == g and e < _INF and e <= be:
                    bg, be, bs = g, e, 1
            cup = Cu[v - 1, u]
            cdn = Cu[v + 1, u]
            bg, be, bs = _pick(bg, be, bs, Gu[v - 1, u], 2.0 * cup, 3)
            bg, be, bs = _pick(bg, be, bs, Gu[v + 1, u], 2.0 * cdn, 4)
            bg, be, bs = _pick(bg, be, bs, Gu[v - 1, u] - Gv[v - 1, u - 1] + gv,
                               cup + Cv[v - 1, u - 1], 5)
            bg, be, bs = _pick(bg, be, bs, Gu[v - 1, u] + Gv[v - 1, u + 1] - gv,
                               cup + Cv[v - 1, u + 1], 6)
            bg, be, bs = _pick(bg, be, bs, Gu[v + 1, u] + Gv[v + 1, u - 1] - gv,
                               cdn + Cv[v + 1, u - 1], 7)
            bg, be, bs = _pick(bg, be, bs, Gu[v + 1, u] - Gv[v + 1, u + 1] + gv,
                               cdn + Cv[v + 1, u + 1], 8)
            nGu[v, u] = bg
            nEu[v, u] = be
            nSu[v, u] = bs
            if bs != 2:
                m += 1
            # ---- gradient along v (across = u) ----
            bg = gv
            be = Ev[v, u]
            bs = 2
            s0 = Sv[v, u]
            if s0 == 0 and Sv[v - 1, u] == 0 and lv[v - 1, u] * lv[v - 2, u] > 0.0:
                e = mv[v - 1, u]
                g = gv + ((zc - zp[v - 1, u]) - Gv[v - 1, u]) * step
                if g == g and e < _INF and e <= be:
                    bg, be, bs = g, e, 0
            elif s0 == 1 and Sv[v + 1, u] == 1 and lv[v + 1, u] * lv[v + 2, u] > 0.0:
                e = mv[v + 1, u]
                g = gv + ((zp[v + 1, u] - zc) - Gv[v + 1, u]) * step
                if g == g and e < _INF and e <= be:
                    bg, be, bs = g, e, 1
            cl = Cv[v, u - 1]
            cr = Cv[v, u + 1]
            bg, be, bs = _pick(bg, be, bs, Gv[v, u - 1], 2.0 * cl, 3)
            bg, be, bs = _pick(bg, be, bs, Gv[v, u + 1], 2.0 * cr, 4)
            bg, be, bs = _pick(bg, be, bs, Gv[v, u - 1] - Gu[v - 1, u - 1] + gu,
                               cl + Cu[v - 1, u - 1], 5)
            bg, be, bs = _pick(bg, be, bs, Gv[v, u - 1] + Gu[v + 1, u - 1] - gu,
                               cl + Cu[v + 1, u - 1], 6)
            bg, be, bs = _pick(bg, be, bs, Gv[v, u + 1] + Gu[v - 1, u + 1] - gu,
                               cr + Cu[v - 1, u + 1], 7)
            bg, be, bs = _pick(bg, be, bs, Gv[v, u + 1] - Gu[v + 1, u + 1] + gu,
                               cr + Cu[v + 1, u + 1], 8)
            nGv[v, u] = bg
            nEv[v, u] = be
            nSv[v, u] = bs
            if bs != 2:
                m += 1
        moved[v] = m


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _formula(v0, v1, z, Gu, Gv, fx, fy, cx, cy, out):
    w = z.shape[1]
    for v in range(v0, v1):
        for u in range(w):
            zq = z[v, u]
            gu = Gu[v, u]
            gv = Gv[v, u]
            if not (zq == zq and gu == gu and gv == gv):
                continue
            store_normal(out, v, u, fx * gu, fy * gv, -(zq + (u - cx) * gu + (v - cy) * gv),
                         (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


def sda_gradients(z: np.ndarray, iterations: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Refined depth gradients (dz/du, dz/dv) of SDA-SNE and the number of rounds applied.

    ``z`` is float depth with NaN at invalid pixels. Stops early when every pixel stays.
    """
    z = np.ascontiguousarray(z, dtype=np.float64)
    h, w = z.shape
    zp, lu, lv, mu, mv = _setup(z)
    shape = zp.shape
    Gu, Gv = np.full(shape, np.nan), np.full(shape, np.nan)
    Eu, Ev = np.full(shape, _INF), np.full(shape, _INF)
    Su, Sv = np.full(shape, -1, np.int8), np.full(shape, -1, np.int8)
    run_rows(_init, h, zp, mu, mv, Gu, Gv, Eu, Ev, Su, Sv)
    nxt = [a.copy() for a in (Gu, Gv, Eu, Ev, Su, Sv)]
    Cu, Cv = np.empty(shape), np.empty(shape)
    moved = np.zeros(shape[0], np.int64)
    done = 0
    for it in range(1, iterations + 1):
        run_rows(_across_costs, shape[0], mu, mv, Eu, Ev, Cu, Cv)
        run_rows(_iterate, h, zp, (lu, lv, mu, mv), (Gu, Gv, Eu, Ev, Su, Sv), (Cu, Cv),
                 1.0 / (it + 1.0), tuple(nxt), moved)
        if not moved.any():
            break
        done = it
        cur = [Gu, Gv, Eu, Ev, Su, Sv]
        Gu, Gv, Eu, Ev, Su, Sv = nxt
        nxt = cur
    P = _P
    return (np.ascontiguousarray(Gu[P:P + h, P:P + w]), np.ascontiguousarray(Gv[P:P + h, P:P + w]),
            done)


def sda_sne(depth: Any, K: Any, *, iterations: int = 3,
            depth_scale: float | None = None) -> np.ndarray:
    """Spatial discontinuity-aware SNE (SDA-SNE): DP-refined depth gradients, then D2NT.

    Per direction (u and v), each pixel starts from the central, forward or backward depth
    difference whose energy, the magnitude of the 1-D depth Laplacian at the pixel / the
    forward / the backward neighbour, is least. Then, for ``iterations`` synchronous
    rounds, every pixel takes the least-energy of nine transitions: extend a one-sided
    estimate from the left/right neighbour (only when both are in that one-sided state and
    the Laplacians there agree in sign; the gradient is updated by recursive polynomial
    interpolation ``G + (one-sided difference - G(neighbour)) / (i + 1)``), stay, copy the
    gradient of the neighbour across (energy ``2 (|L_across| + E)`` there), or move
    diagonally with a mixed-derivative correction. The refined ``z_u, z_v`` go into
    ``n ~ (fx z_u, fy z_v, -(z + (u - cx) z_u + (v - cy) z_v))``.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z. float32/float64; integers need ``depth_scale``. Invalid depth
        (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    iterations : int, default 3
        Maximum number of DP rounds (the public code's ``MAX_ITER``); it stops earlier
        when every pixel stays. 0 gives the initial minimum-Laplacian gradients.
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where no gradient exists.

    Notes
    -----
    Energies compare raw depth Laplacians, and the transitions compare them with sums of
    them, so the result depends on the depth unit only through ties (not scale invariant
    in general because of the recursive update; registered as such).

    Interpretation (ours): the public code filters with reflected borders and pads shifted
    arrays with zeros or infinities; here a candidate needing a pixel outside the image or
    an invalid pixel is simply not available (infinite energy), so an invalid neighbour
    never enters a gradient. A pixel with no finite-energy initial candidate takes the first
    available difference (central, forward, backward) with infinite energy. As in the public
    code, the state of a pixel after a round is the index of the transition it took, and
    ties go to the lowest index. The normal is oriented per pixel toward the camera.

    References
    ----------
    N. Ming, Y. Feng and R. Fan, "SDA-SNE: Spatial Discontinuity-Aware Surface Normal
    Estimation via Multi-Directional Dynamic Programming," International Conference on 3D
    Vision (3DV), 2022. Public code: https://github.com/ryming2001/SDA-SNE

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import sda_sne
    >>> v, u = np.mgrid[0:8, 0:10]
    >>> z = 2.0 + 0.01 * u                   # a surface tilted along u
    >>> n = sda_sne(z, (500.0, 500.0, 4.5, 3.5))
    >>> n.shape, n.dtype.name
    ((8, 10, 3), 'float32')
    >>> bool(np.all(n[..., 2] < 0))
    True
    """
    if isinstance(iterations, bool) or not isinstance(iterations, numbers.Integral):
        raise TypeError(f"iterations must be a non-negative integer; got {iterations!r}")
    if iterations < 0:
        raise ValueError(f"iterations must be >= 0; got {iterations}")
    z, cam = prepare(depth, K, depth_scale)
    Gu, Gv, _ = sda_gradients(z, int(iterations))
    out = new_output(z.shape)
    run_rows(_formula, z.shape[0], np.ascontiguousarray(z, dtype=np.float64), Gu, Gv, cam.fx,
             cam.fy, cam.cx, cam.cy, out)
    return out
