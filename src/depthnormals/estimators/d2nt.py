"""Depth-to-normal translator (D2NT) and its refinements."""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from .._validate import check_choice
from ..kernels.depth import prepare
from ..kernels.orient import store_normal
from ..kernels.stencils import sample_or_nan

__all__ = ["VARIANTS", "d2nt", "neighbour_copy_refinement"]

VARIANTS = ("basic", "dag", "mnr")
_EPS = 1e-8


@nb.njit(cache=True, error_model="numpy")
def central_derivative(z, v, u, a_v, a_u):
    """dz along (a_v, a_u): central difference / 2, else one-sided, else NaN."""
    zc = z[v, u]
    zf = sample_or_nan(z, v + a_v, u + a_u)
    zb = sample_or_nan(z, v - a_v, u - a_u)
    if zf == zf and zb == zb:
        return 0.5 * (zf - zb)
    if zf == zf:
        return zf - zc
    if zb == zb:
        return zc - zb
    return np.nan


@nb.njit(cache=True, error_model="numpy", inline="always")
def _dag_weights(zbb, zb, zc, zf, zff):
    """DAG weights (backward, forward) from the 1-D Laplacians at the two neighbours.

    Equal to the public code's exp(-L) soft-min with epsilon 1e-8 and hard switch at a
    ratio of e, evaluated with one exponential: the switch happens when the Laplacians
    differ by more than 1 (their exponentials by more than a factor e).
    """
    lb = abs(zbb - 2.0 * zb + zc)
    lf = abs(zc - 2.0 * zf + zff)
    if not (lb == lb):
        lb = np.inf
    if not (lf == lf):
        lf = np.inf
    lo = min(lb, lf)
    if lo > 15.0:
        # both weights near the epsilon of the public code: evaluate it literally
        a = math.exp(-lb)
        b = math.exp(-lf)
        wb = (a + 0.5 * _EPS) / (_EPS + a + b)
        wf = (b + 0.5 * _EPS) / (_EPS + a + b)
        if wb / (wf + _EPS) > math.e:
            return 1.0, 0.0
        if wf / (wb + _EPS) > math.e:
            return 0.0, 1.0
        return wb, wf
    diff = lf - lb
    if diff > 1.0:
        return 1.0, 0.0
    if diff < -1.0:
        return 0.0, 1.0
    wb = 1.0 / (1.0 + math.exp(-diff))
    return wb, 1.0 - wb


@nb.njit(cache=True, error_model="numpy")
def dag_derivative(z, v, u, a_v, a_u):
    """Discontinuity-aware gradient (DAG) filter of D2NT along (a_v, a_u).

    One-sided differences g_b = z(0) - z(-1), g_f = z(+1) - z(0) weighted by
    exp(-|1-D Laplacian|) at the backward / forward neighbour, normalised with a small
    epsilon, and hard-switched to one side when one weight exceeds e times the other.
    A side whose difference needs an invalid pixel gets weight 0; a side whose Laplacian
    needs one gets exp(-L) = 0.
    """
    zc = z[v, u]
    zb = sample_or_nan(z, v - a_v, u - a_u)
    zf = sample_or_nan(z, v + a_v, u + a_u)
    gb = zc - zb
    gf = zf - zc
    okb = gb == gb
    okf = gf == gf
    if not okb and not okf:
        return np.nan
    if not okb:
        return gf
    if not okf:
        return gb
    wb, wf = _dag_weights(sample_or_nan(z, v - 2 * a_v, u - 2 * a_u), zb, zc, zf,
                          sample_or_nan(z, v + 2 * a_v, u + 2 * a_u))
    return wb * gb + wf * gf


@nb.njit(cache=True, error_model="numpy", fastmath={"nsz", "contract", "arcp"})
def _basic_row(zp, zc, zn, v, fx, fy, cx, cy, bx, by, bz, flag):
    """Branch-free (vectorisable) basic D2NT over the interior of one row."""
    w = zc.size
    b = v - cy
    for u in range(1, w - 1):
        zq = np.float64(zc[u])
        zu = 0.5 * (np.float64(zc[u + 1]) - np.float64(zc[u - 1]))
        zv = 0.5 * (np.float64(zn[u]) - np.float64(zp[u]))
        nx = fx * zu
        ny = fy * zv
        nz = -(zq + (u - cx) * zu + b * zv)
        nrm = math.sqrt(nx * nx + ny * ny + nz * nz)
        inv = 1.0 / nrm  # dot(n, X) = -z^2 < 0: already facing the camera
        bx[u] = nx * inv
        by[u] = ny * inv
        bz[u] = nz * inv
        t = nrm * zq
        flag[u] = not (t == t and t != 0.0 and abs(t) < np.inf)


@nb.njit(cache=True, error_model="numpy")
def _dag_row(z, v, fx, fy, cx, cy, out, flag):
    """DAG D2NT over the part of row v whose 5-point crosses are all valid (others flagged)."""
    w = z.shape[1]
    for u in range(2, w - 2):
        zq = np.float64(z[v, u])
        zl2 = np.float64(z[v, u - 2])
        zl = np.float64(z[v, u - 1])
        zr = np.float64(z[v, u + 1])
        zr2 = np.float64(z[v, u + 2])
        zt2 = np.float64(z[v - 2, u])
        zt = np.float64(z[v - 1, u])
        zb = np.float64(z[v + 1, u])
        zb2 = np.float64(z[v + 2, u])
        s = zq + zl2 + zl + zr + zr2 + zt2 + zt + zb + zb2
        if not (s == s):
            continue
        wb, wf = _dag_weights(zl2, zl, zq, zr, zr2)
        zu = wb * (zq - zl) + wf * (zr - zq)
        wb, wf = _dag_weights(zt2, zt, zq, zb, zb2)
        zv = wb * (zq - zt) + wf * (zb - zq)
        nx = fx * zu
        ny = fy * zv
        nz = -(zq + (u - cx) * zu + (v - cy) * zv)
        store_normal(out, v, u, nx, ny, nz, (u - cx) * zq / fx, (v - cy) * zq / fy, zq)
        flag[u] = False


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _d2nt_rows(v0, v1, z, fx, fy, cx, cy, dag, out):
    for v in range(v0, v1):
        _d2nt_row(z, v, fx, fy, cx, cy, dag, out)


@nb.njit(cache=True, error_model="numpy")
def _d2nt_row(z, v, fx, fy, cx, cy, dag, out):
    h, w = z.shape
    flag = np.ones(w, dtype=np.bool_)
    if dag and 1 < v < h - 2:
        _dag_row(z, v, fx, fy, cx, cy, out, flag)
    if not dag and 0 < v < h - 1 and w > 2:
        bx = np.empty(w)
        by = np.empty(w)
        bz = np.empty(w)
        _basic_row(z[v - 1], z[v], z[v + 1], v, fx, fy, cx, cy, bx, by, bz, flag)
        for u in range(1, w - 1):
            out[v, u, 0] = bx[u]
            out[v, u, 1] = by[u]
            out[v, u, 2] = bz[u]
    for u in range(w):
        if not flag[u]:
            continue
        zq = z[v, u]
        out[v, u, 0] = np.nan
        out[v, u, 1] = np.nan
        out[v, u, 2] = np.nan
        if not (zq == zq):
            continue
        if dag:
            zu = dag_derivative(z, v, u, 0, 1)
            zv = dag_derivative(z, v, u, 1, 0)
        else:
            zu = central_derivative(z, v, u, 0, 1)
            zv = central_derivative(z, v, u, 1, 0)
        if not (zu == zu and zv == zv):
            continue
        nx = fx * zu
        ny = fy * zv
        nz = -(zq + (u - cx) * zu + (v - cy) * zv)
        store_normal(out, v, u, nx, ny, nz, (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


@nb.njit(cache=True, error_model="numpy")
def _laplacian_row(z, v, lap):
    w = z.shape[1]
    for u in range(w):
        s = (sample_or_nan(z, v, u - 1) + sample_or_nan(z, v, u + 1) + sample_or_nan(z, v - 1, u)
             + sample_or_nan(z, v + 1, u) - 4.0 * z[v, u])
        lap[v, u] = abs(s) if s == s else np.inf


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _laplacian_rows(v0, v1, z, lap):
    for v in range(v0, v1):
        _laplacian_row(z, v, lap)


@nb.njit(cache=True, error_model="numpy")
def _copy_row(z, normals, lap, v, fx, fy, cx, cy, out):
    # candidate order of the public code: left, right, up, down, self (first minimum wins)
    h, w = z.shape
    dvs = (0, 0, -1, 1, 0)
    dus = (-1, 1, 0, 0, 0)
    for u in range(w):
        zq = z[v, u]
        if not (zq == zq):
            out[v, u, 0] = np.nan
            out[v, u, 1] = np.nan
            out[v, u, 2] = np.nan
            continue
        best = np.inf
        bv = v
        bu = u
        for k in range(5):
            r = v + dvs[k]
            c = u + dus[k]
            if r < 0 or r >= h or c < 0 or c >= w:
                continue
            if not (normals[r, c, 0] == normals[r, c, 0]):
                continue
            if lap[r, c] < best:
                best = lap[r, c]
                bv = r
                bu = c
        store_normal(out, v, u, normals[bv, bu, 0], normals[bv, bu, 1], normals[bv, bu, 2],
                     (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _copy_rows(v0, v1, z, normals, lap, fx, fy, cx, cy, out):
    for v in range(v0, v1):
        _copy_row(z, normals, lap, v, fx, fy, cx, cy, out)


def neighbour_copy_refinement(normals: np.ndarray, z: np.ndarray, fx: float, fy: float,
                              cx: float, cy: float) -> np.ndarray:
    """D2NT's one-pass refinement: copy the normal of the smoothest of {left, right, up, down, self}.

    Smoothness is the magnitude of the 4-neighbour Laplacian of depth (infinite where a
    neighbour is invalid). ``z`` is depth with NaN at invalid pixels.
    """
    out = np.empty((*z.shape, 3), dtype=np.float32)
    lap = np.empty(z.shape)
    run_rows(_laplacian_rows, z.shape[0], z, lap)
    run_rows(_copy_rows, z.shape[0], z, normals, lap, fx, fy, cx, cy, out)
    return out


def d2nt(depth: Any, K: Any, *, variant: str = "mnr", depth_scale: float | None = None) -> np.ndarray:
    """Depth-to-normal translator (D2NT): normals in closed form from depth derivatives.

    ``n ~ (fx z_u, fy z_v, -(z + (u - cx) z_u + (v - cy) z_v))``, with ``z_u, z_v`` the
    derivatives of depth per pixel.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z. float32/float64; integers need ``depth_scale``. Invalid depth
        (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    variant : {"basic", "dag", "mnr"}, default "mnr"
        ``basic``: central differences / 2. ``dag``: the discontinuity-aware gradient filter
        (one-sided differences weighted by exp(-|Laplacian|) at the neighbours, hard switch
        at a ratio of e). ``mnr``: ``dag`` followed by the one-pass refinement in which each
        pixel takes the normal of whichever of {left, right, up, down, self} has the smallest
        |4-neighbour Laplacian of depth| (the public code's "MRF refinement"; first minimum
        wins in that order).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where no derivative exists.

    Notes
    -----
    The DAG weights and the refinement compare raw depth differences through ``exp(-L)``,
    so ``dag`` and ``mnr`` depend on the depth unit (as in the public code, which works in
    the dataset's units); ``basic`` does not. Interpretation (ours): invalid pixels never
    enter a difference; a side whose difference or Laplacian needs one gets weight 0.

    References
    ----------
    Y. Feng, B. Xue, M. Liu, Q. Chen and R. Fan, "D2NT: A High-Performing Depth-to-Normal
    Translator," IEEE International Conference on Robotics and Automation (ICRA), 2023,
    pp. 12360-12366. doi:10.1109/ICRA48891.2023.10161000

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import d2nt
    >>> n = d2nt(np.full((5, 5), 3.0), (400.0, 400.0, 2.0, 2.0), variant="basic")
    >>> n[2, 2].tolist()
    [0.0, 0.0, -1.0]
    """
    check_choice(variant, "variant", VARIANTS)
    z, cam = prepare(depth, K, depth_scale)
    out = np.empty((*z.shape, 3), dtype=np.float32)
    run_rows(_d2nt_rows, z.shape[0], z, cam.fx, cam.fy, cam.cx, cam.cy, variant != "basic", out)
    if variant == "mnr":
        out = neighbour_copy_refinement(out, z, cam.fx, cam.fy, cam.cx, cam.cy)
    return out
