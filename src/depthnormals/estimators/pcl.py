"""PCL's organised-cloud normal estimators (``pcl::IntegralImageNormalEstimation``), from the maths.

Four modes share one frame (Holzer et al. 2012): a *depth-change map* marks the pixels on
either side of every depth jump (and every invalid pixel), a chamfer *distance map* gives
each pixel its distance to the nearest marked pixel, and the smoothing window of a pixel is
``s = int(min(distance, normal_smoothing_size [+ z / 10]))`` pixels wide: it shrinks next to
jumps so that it never reaches across one, and the pixel abstains (NaN) when ``s <= 2``.
Every window sum is a box sum of an integral image (O(1) per pixel whatever the window):

- ``average-3d-gradient``: box sums of the central 3-D differences ``P(u+1) - P(u-1)`` and
  ``P(v+1) - P(v-1)``; the normal is their cross product.
- ``covariance-matrix``: box sums of the points and of their products give the window's
  covariance; the normal is its smallest eigenvector.
- ``average-depth-change``: mean depths of four half-window boxes left, right, above and
  below the pixel give two tangents; the normal is their cross product.
- ``simple-3d-gradient``: the mean point of the window's right column minus that of its left
  column, and likewise bottom row minus top row; the normal is their cross product.

Kernels: :func:`_distance_units` (the depth-change map and chamfer distance, one thread),
:func:`_integral_rows` / :func:`_integral_cols` (the integral image, row then column bands),
:func:`_normals_rows` (one O(1) pass per pixel, row bands). Sums are float64 throughout.
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from .._validate import check_choice, check_real
from ..kernels.depth import prepare
from ..kernels.eig3 import smallest_eigenvector
from ..kernels.orient import store_normal

__all__ = [
    "BORDER_POLICIES",
    "MODES",
    "distance_map",
    "pcl_average_3d_gradient",
    "pcl_average_depth_change",
    "pcl_covariance_matrix",
    "pcl_integral_image",
    "pcl_simple_3d_gradient",
]

#: The estimation modes, PCL's ``NormalEstimationMethod`` names in lower case.
MODES = ("average-3d-gradient", "covariance-matrix", "average-depth-change", "simple-3d-gradient")
#: Border policies: ``"mirror"`` (PCL's BORDER_POLICY_MIRROR) or ``"ignore"`` (BORDER_POLICY_IGNORE).
BORDER_POLICIES = ("mirror", "ignore")

_NUMPY = "numpy"  # error_model: float division by zero gives inf/NaN, never raises

# integral-image channels per mode
_AVG3D, _COV, _ADC, _SIMPLE = 0, 1, 2, 3
_CHANNELS = (8, 10, 2, 4)
# distance map in integer chamfer units: a straight step is 5, a diagonal step 7 (PCL's 1 and
# 1.4, exactly: float sums of 1.4 round differently in different scan orders)
_STEP, _DIAG = 5, 7


# --------------------------------------------------------------- depth-change and distance

@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _distance_units(z, factor, out_units):
    """Depth-change map and its chamfer distance transform, in units of 1/5 pixel.

    Both pixels of a 4-neighbour pair are marked (distance 0) when either depth is invalid
    or they differ by more than ``2 factor (min(z, z') + 1)``; the others get the (5, 7)
    chamfer distance to the nearest marked pixel (``5 (w + h)`` when none is marked).
    Writes ``out_units`` (H, W) int64.
    """
    h, w = z.shape
    far = _STEP * (w + h)
    for v in range(h):
        for u in range(w):
            out_units[v, u] = far if z[v, u] == z[v, u] else 0
    for v in range(h):
        for u in range(w):
            a = z[v, u]
            if u + 1 < w:
                b = z[v, u + 1]
                if not (a == a and b == b and abs(a - b) <= 2.0 * factor * (min(a, b) + 1.0)):
                    out_units[v, u] = 0
                    out_units[v, u + 1] = 0
            if v + 1 < h:
                b = z[v + 1, u]
                if not (a == a and b == b and abs(a - b) <= 2.0 * factor * (min(a, b) + 1.0)):
                    out_units[v, u] = 0
                    out_units[v + 1, u] = 0
    # forward pass (up-left, up, up-right, left), then backward (the mirror image)
    for v in range(h):
        for u in range(w):
            d = out_units[v, u]
            if v > 0:
                d = min(d, out_units[v - 1, u] + _STEP)
                if u > 0:
                    d = min(d, out_units[v - 1, u - 1] + _DIAG)
                if u + 1 < w:
                    d = min(d, out_units[v - 1, u + 1] + _DIAG)
            if u > 0:
                d = min(d, out_units[v, u - 1] + _STEP)
            out_units[v, u] = d
    for v in range(h - 1, -1, -1):
        for u in range(w - 1, -1, -1):
            d = out_units[v, u]
            if v + 1 < h:
                d = min(d, out_units[v + 1, u] + _STEP)
                if u > 0:
                    d = min(d, out_units[v + 1, u - 1] + _DIAG)
                if u + 1 < w:
                    d = min(d, out_units[v + 1, u + 1] + _DIAG)
            if u + 1 < w:
                d = min(d, out_units[v, u + 1] + _STEP)
            out_units[v, u] = d


# ---------------------------------------------------------------------------- integral image

@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def _point(z, v, u, fx, fy, cx, cy):
    zz = np.float64(z[v, u])
    return (u - cx) * zz / fx, (v - cy) * zz / fy, zz


@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _integral_rows(v0, v1, z, fx, fy, cx, cy, mode, I):
    """Per-pixel values of ``mode`` and their prefix sums along each row, rows [v0, v1).

    ``I`` has shape (H + 1, W + 1, C); row ``v + 1`` receives the row prefix of image row
    ``v`` (column 0 stays 0). Invalid values contribute 0 (and 0 to the counts):
    average-3d-gradient: dx (3), dy (3), count dx, count dy; covariance-matrix: count, x, y, z,
    xx, xy, xz, yy, yz, zz; average-depth-change: count, z; simple-3d-gradient: count, x, y, z.
    """
    h, w = z.shape
    nc = I.shape[2]
    val = np.zeros(nc)
    for v in range(v0, v1):
        for c in range(nc):
            I[v + 1, 0, c] = 0.0
        for u in range(w):
            for c in range(nc):
                val[c] = 0.0
            if mode == _AVG3D:
                if 0 < u < w - 1 and z[v, u - 1] == z[v, u - 1] and z[v, u + 1] == z[v, u + 1]:
                    ax, ay, az = _point(z, v, u - 1, fx, fy, cx, cy)
                    bx, by, bz = _point(z, v, u + 1, fx, fy, cx, cy)
                    val[0] = bx - ax
                    val[1] = by - ay
                    val[2] = bz - az
                    val[6] = 1.0
                if 0 < v < h - 1 and z[v - 1, u] == z[v - 1, u] and z[v + 1, u] == z[v + 1, u]:
                    ax, ay, az = _point(z, v - 1, u, fx, fy, cx, cy)
                    bx, by, bz = _point(z, v + 1, u, fx, fy, cx, cy)
                    val[3] = bx - ax
                    val[4] = by - ay
                    val[5] = bz - az
                    val[7] = 1.0
            elif z[v, u] == z[v, u]:
                x, y, t = _point(z, v, u, fx, fy, cx, cy)
                val[0] = 1.0
                if mode == _ADC:
                    val[1] = t
                else:
                    val[1] = x
                    val[2] = y
                    val[3] = t
                    if mode == _COV:
                        val[4] = x * x
                        val[5] = x * y
                        val[6] = x * t
                        val[7] = y * y
                        val[8] = y * t
                        val[9] = t * t
            for c in range(nc):
                I[v + 1, u + 1, c] = I[v + 1, u, c] + val[c]


@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _integral_cols(c0, c1, I):
    """Accumulate the row prefixes of ``I`` down the rows, columns [c0, c1) of the image."""
    hp = I.shape[0]
    nc = I.shape[2]
    for r in range(2, hp):
        a = I[r, c0 + 1:c1 + 1]
        b = I[r - 1, c0 + 1:c1 + 1]
        for k in range(a.shape[0]):
            for c in range(nc):
                a[k, c] += b[k, c]


# ------------------------------------------------------------------------------ box queries

@nb.njit(cache=True, error_model=_NUMPY)
def _fold(a, b, n, seg):
    """Split the inclusive range [a, b] of the mirrored extension of [0, n) (pixel -k is
    pixel k - 1, pixel n - 1 + k is pixel n - k) into at most 3 ranges inside [0, n),
    written to ``seg`` (3, 2); returns their number. Needs -n <= a and b <= 2n - 1."""
    k = 0
    lo = max(a, 0)
    hi = min(b, n - 1)
    if lo <= hi:
        seg[k, 0] = lo
        seg[k, 1] = hi
        k += 1
    if a < 0:  # pixels a .. min(b, -1) -> -min(b, -1) - 1 .. -a - 1
        seg[k, 0] = -min(b, -1) - 1
        seg[k, 1] = -a - 1
        k += 1
    if b > n - 1:  # pixels max(a, n) .. b -> 2n - 1 - b .. 2n - 1 - max(a, n)
        seg[k, 0] = 2 * n - 1 - b
        seg[k, 1] = 2 * n - 1 - max(a, n)
        k += 1
    return k


@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def _box(I, r0, r1, c0, c1, rs, cs, acc):
    """acc[:] = sums of every channel of I over rows [r0, r1] x columns [c0, c1] of the
    mirrored image (inclusive ranges); returns (sum of the column indices, sum of the row
    indices) of the folded pixels, each pixel counted once whatever its validity.

    Windows inside the image take one integral-image query here (inlined); the others go to
    :func:`_box_folded`."""
    h = I.shape[0] - 1
    w = I.shape[1] - 1
    if r0 >= 0 and c0 >= 0 and r1 < h and c1 < w:
        for k in range(I.shape[2]):
            acc[k] = I[r1 + 1, c1 + 1, k] - I[r0, c1 + 1, k] - I[r1 + 1, c0, k] + I[r0, c0, k]
        nq = c1 - c0 + 1
        nr = r1 - r0 + 1
        return 0.5 * (c0 + c1) * nq * nr, 0.5 * (r0 + r1) * nq * nr
    return _box_folded(I, r0, r1, c0, c1, rs, cs, acc)


@nb.njit(cache=True, error_model=_NUMPY)
def _box_folded(I, r0, r1, c0, c1, rs, cs, acc):
    """:func:`_box` for a window that leaves the image: up to 3 x 3 queries (:func:`_fold`)."""
    h = I.shape[0] - 1
    w = I.shape[1] - 1
    nc = I.shape[2]
    for c in range(nc):
        acc[c] = 0.0
    nr = _fold(r0, r1, h, rs)
    nq = _fold(c0, c1, w, cs)
    su = 0.0
    sv = 0.0
    for i in range(nr):
        a = rs[i, 0]
        b = rs[i, 1] + 1
        for j in range(nq):
            p = cs[j, 0]
            q = cs[j, 1] + 1
            for c in range(nc):
                acc[c] += I[b, q, c] - I[a, q, c] - I[b, p, c] + I[a, p, c]
            su += 0.5 * (p + q - 1) * (q - p) * (b - a)
            sv += 0.5 * (a + b - 1) * (b - a) * (q - p)
    return su, sv


# ------------------------------------------------------------------------------- the normal

@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def _boxes(mode, v, u, r):
    """The (up to 4) boxes of ``mode`` at (v, u), half-size r: rows (r0, r1), columns (c0, c1)
    per box, inclusive; unused boxes repeat the first."""
    if mode == _AVG3D or mode == _COV:
        whole = (v - r, v + r, u - r, u + r)
        return (whole, whole, whole, whole)
    if mode == _SIMPLE:  # right column, left column, bottom row, top row
        return ((v - r, v + r, u + r, u + r), (v - r, v + r, u - r, u - r),
                (v + r, v + r, u - r, u + r), (v - r, v - r, u - r, u + r))
    # average depth change: left, right (r columns x 2q + 1 rows), above, below (2q + 1
    # columns x r rows); PCL's rect_width_4_ = s // 4 is q = r // 2 for s = 2r and 2r + 1
    q = r // 2
    return ((v - q, v + q, u - r, u - 1), (v - q, v + q, u + 1, u + r),
            (v - r, v - 1, u - q, u + q), (v + 1, v + r, u - q, u + q))


@nb.njit(cache=True, error_model=_NUMPY, inline="always")
def _solve(mode, a, b, cq, dq, pos, fx, fy, cx, cy):
    """The (unnormalised) normal of ``mode`` from the channel sums of its boxes (a, b, cq, dq:
    :func:`_boxes` order) and, for the average depth change, the mean pixel (u, v) of each box
    in ``pos`` (8,); NaN when a sum it needs is empty."""
    nan = np.nan
    if mode == _AVG3D:
        if a[6] == 0.0 or a[7] == 0.0:
            return nan, nan, nan
        return _cross(a[3], a[4], a[5], a[0], a[1], a[2])  # PCL: gradient_y x gradient_x
    if mode == _COV:
        n = a[0]
        if n < 3.0:
            return nan, nan, nan
        return smallest_eigenvector(a[4] - a[1] * a[1] / n, a[5] - a[1] * a[2] / n,
                                    a[6] - a[1] * a[3] / n, a[7] - a[2] * a[2] / n,
                                    a[8] - a[2] * a[3] / n, a[9] - a[3] * a[3] / n)
    if a[0] == 0.0 or b[0] == 0.0 or cq[0] == 0.0 or dq[0] == 0.0:
        return nan, nan, nan
    if mode == _SIMPLE:  # (bottom - top) x (right - left), mean points
        gx0 = a[1] / a[0] - b[1] / b[0]
        gx1 = a[2] / a[0] - b[2] / b[0]
        gx2 = a[3] / a[0] - b[3] / b[0]
        gy0 = cq[1] / cq[0] - dq[1] / dq[0]
        gy1 = cq[2] / cq[0] - dq[2] / dq[0]
        gy2 = cq[3] / cq[0] - dq[3] / dq[0]
        return _cross(gy0, gy1, gy2, gx0, gx1, gx2)
    # average depth change: each box back-projected at its mean pixel and mean depth
    zl = a[1] / a[0]
    zr = b[1] / b[0]
    zu = cq[1] / cq[0]
    zd = dq[1] / dq[0]
    tx0 = ((pos[2] - cx) * zr - (pos[0] - cx) * zl) / fx
    tx1 = ((pos[3] - cy) * zr - (pos[1] - cy) * zl) / fy
    ty0 = ((pos[6] - cx) * zd - (pos[4] - cx) * zu) / fx
    ty1 = ((pos[7] - cy) * zd - (pos[5] - cy) * zu) / fy
    return _cross(tx0, tx1, zr - zl, ty0, ty1, zd - zu)


@nb.njit(cache=True, error_model=_NUMPY)
def _pixel_sums(I, mode, v, u, r, rs, cs, a, b, cq, dq, pos):
    """The box sums of ``mode`` at one pixel, any window (mirrored where it leaves the image)."""
    bx = _boxes(mode, v, u, r)
    nbox = 1 if mode == _AVG3D or mode == _COV else 4
    for i in range(nbox):
        r0, r1, c0, c1 = bx[i]
        acc = a if i == 0 else (b if i == 1 else (cq if i == 2 else dq))
        su, sv = _box(I, r0, r1, c0, c1, rs, cs, acc)
        npx = (r1 - r0 + 1) * (c1 - c0 + 1)
        pos[2 * i] = su / npx
        pos[2 * i + 1] = sv / npx


@nb.njit(cache=True, error_model=_NUMPY)
def _row_sums(I, mode, v, r, lo, hi, S):
    """Box sums of ``mode`` with half-size r for the pixels (v, lo .. hi-1), every box inside
    the image: ``S[i, k, u]`` for box i, channel k (vectorisable slices)."""
    nc = I.shape[2]
    bx = _boxes(mode, v, lo, r)
    nbox = 1 if mode == _AVG3D or mode == _COV else 4
    m = hi - lo
    for i in range(nbox):
        r0, r1, c0, c1 = bx[i]
        for k in range(nc):
            t = S[i, k, lo:hi]
            p11 = I[r1 + 1, c1 + 1:c1 + 1 + m, k]
            p01 = I[r0, c1 + 1:c1 + 1 + m, k]
            p10 = I[r1 + 1, c0:c0 + m, k]
            p00 = I[r0, c0:c0 + m, k]
            for j in range(m):
                t[j] = p11[j] - p01[j] - p10[j] + p00[j]


@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _normals_rows(v0, v1, z, units, I, fx, fy, cx, cy, mode, size, depth_dependent, ignore, out):
    """Rows [v0, v1): window size from the distance map, border policy, normal of ``mode``.

    ``size``: normal_smoothing_size; ``ignore``: BORDER_POLICY_IGNORE (else mirror). The
    pixels whose window is the full ``int(size)`` and inside the image take their sums from
    whole-row slices (:func:`_row_sums`); the others from :func:`_pixel_sums`."""
    h, w = z.shape
    nc = I.shape[2]
    rs = np.empty((3, 2), dtype=np.int64)
    cs = np.empty((3, 2), dtype=np.int64)
    a = np.empty(nc)
    b = np.empty(nc)
    cq = np.empty(nc)
    dq = np.empty(nc)
    pos = np.zeros(8)
    ppos = np.zeros(8)
    S = np.empty((4, nc, w))
    border = int(size)
    rmax = min(h, w)  # the mirror folds at most one image size
    R = int(size) // 2
    full = _STEP * int(size)  # distance (units) from which the window is the full int(size)
    lo = R + 1
    hi = w - R - 1
    for v in range(v0, v1):
        fast = (not depth_dependent and R >= 1 and int(size) >= 3 and R <= rmax and v - R >= 1
                and v + R + 1 < h and lo < hi)
        if fast:
            _row_sums(I, mode, v, R, lo, hi, S)
            bx = _boxes(mode, v, 0, R)
            for i in range(4):
                r0, r1, c0, c1 = bx[i]
                pos[2 * i] = 0.5 * (c0 + c1)  # + u
                pos[2 * i + 1] = 0.5 * (r0 + r1)
        for u in range(w):
            out[v, u, 0] = np.nan
            out[v, u, 1] = np.nan
            out[v, u, 2] = np.nan
            zq = np.float64(z[v, u])
            if not (zq == zq):
                continue
            if fast and lo <= u < hi and units[v, u] >= full:
                if ignore and (u < border or u >= w - border or v < border or v >= h - border):
                    continue
                for k in range(nc):
                    a[k] = S[0, k, u]
                if mode != _AVG3D and mode != _COV:
                    for k in range(nc):
                        b[k] = S[1, k, u]
                        cq[k] = S[2, k, u]
                        dq[k] = S[3, k, u]
                    for i in range(4):
                        ppos[2 * i] = pos[2 * i] + u
                        ppos[2 * i + 1] = pos[2 * i + 1]
                nx, ny, nz = _solve(mode, a, b, cq, dq, ppos, fx, fy, cx, cy)
                store_normal(out, v, u, nx, ny, nz, (u - cx) * zq / fx, (v - cy) * zq / fy, zq)
                continue
            lim = size + zq / 10.0 if depth_dependent else size
            sm = min(units[v, u] / _STEP, lim)
            if not (sm > 2.0):
                continue
            r = min(int(sm) // 2, rmax)
            if ignore and (v < border or v >= h - border or u < border or u >= w - border
                           or v <= r or v + r >= h or u <= r or u + r >= w):
                continue
            _pixel_sums(I, mode, v, u, r, rs, cs, a, b, cq, dq, ppos)
            nx, ny, nz = _solve(mode, a, b, cq, dq, ppos, fx, fy, cx, cy)
            store_normal(out, v, u, nx, ny, nz, (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


# ----------------------------------------------------------------------------- public API

def distance_map(depth: Any, *, max_depth_change_factor: float = 0.02,
                 depth_scale: float | None = None) -> np.ndarray:
    """PCL's depth-change distance map: chamfer distance (pixels) to the nearest depth jump.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth in metres (the threshold is metric). Invalid depth counts as a jump.
    max_depth_change_factor : float, default 0.02
        Neighbours whose depths differ by more than ``2 factor (min(z, z') + 1)`` are a jump.
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    distance : ndarray, shape (H, W), float64
        0 on the pixels of a jump (both sides), at invalid depth and on the 4-neighbours of
        invalid depth (as in PCL: a pair with an invalid pixel is a jump); elsewhere the chamfer
        distance (straight step 1, diagonal step 1.4) to the nearest of them; ``H + W`` when
        there is none.
    """
    factor = check_real(max_depth_change_factor, "max_depth_change_factor", minimum=0.0,
                        hint="PCL's default is 0.02")
    z, _ = prepare(depth, (1.0, 1.0, 0.0, 0.0), depth_scale)
    units = np.empty(z.shape, dtype=np.int64)
    _distance_units(z, factor, units)
    return units / _STEP


def pcl_integral_image(depth: Any, K: Any, *, mode: str = "average-3d-gradient",
                       max_depth_change_factor: float = 0.02, normal_smoothing_size: float = 10.0,
                       depth_dependent_smoothing: bool = False, border_policy: str = "mirror",
                       depth_scale: float | None = None) -> np.ndarray:
    """PCL's integral-image normal estimation on an organised cloud (any of its four modes).

    A reproduction from the maths of ``pcl::IntegralImageNormalEstimation``: a depth-change
    map and its chamfer distance map bound each pixel's smoothing window so that it never
    reaches across a depth jump, window sums are box sums of integral images, and the pixel
    abstains (NaN) next to jumps (window of 2 pixels or fewer) and, with
    ``border_policy="ignore"``, within ``int(normal_smoothing_size)`` pixels of the border.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z in metres (PCL's thresholds are metric: pass ``depth_scale`` for
        millimetres). float32/float64; integers need ``depth_scale``. Invalid depth (0,
        negative, NaN, inf) gives NaN and counts as a depth jump with each of its 4-neighbours.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    mode : str, default "average-3d-gradient"
        One of :data:`MODES`: ``"average-3d-gradient"`` (PCL's default), ``"covariance-matrix"``,
        ``"average-depth-change"``, ``"simple-3d-gradient"``.
    max_depth_change_factor : float, default 0.02
        Neighbours whose depths (metres) differ by more than ``2 factor (min(z, z') + 1)`` are a
        depth jump (PCL's ``setMaxDepthChangeFactor``; 0.02 in its tutorial and constructor).
    normal_smoothing_size : float, default 10.0
        Largest window size in pixels (PCL's ``setNormalSmoothingSize``; 10 in its tutorial
        and constructor); must be >= 2, and over 2 unless ``depth_dependent_smoothing``
        (a pixel abstains unless its window exceeds 2: at 2 every normal would be NaN).
    depth_dependent_smoothing : bool, default False
        Grow the window with depth: ``normal_smoothing_size + z / 10`` pixels, z in metres.
    border_policy : {"mirror", "ignore"}, default "mirror"
        ``"mirror"``: windows that leave the image are mirrored back into it (every pixel
        gets a window). ``"ignore"``: PCL's default, NaN within ``int(normal_smoothing_size)``
        pixels of the border and wherever the window would leave the image.
    depth_scale : float, optional
        Metres per unit of integer depth (e.g. 0.001 for millimetres).

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth, next to depth jumps (within
        about 2 pixels) and, with ``border_policy="ignore"``, at the border.

    Notes
    -----
    The window of pixel (v, u) has half-size ``r = s // 2`` with
    ``s = int(min(d, normal_smoothing_size [+ z / 10]))``, d the chamfer distance (1 and
    1.4) to the nearest marked pixel; the pixel abstains unless ``min(...) > 2``.

    Where ours differs from PCL (interpretation; docs/estimators.md has the list):

    - Windows are symmetric, ``[u - r, u + r]`` (``s + 1`` pixels for even ``s``). PCL's
      windows start at ``u - s/2`` and hold ``s`` pixels, so even sizes (its default 10)
      centre them half a pixel up and left of the pixel; the half-pixel offset biases normals
      on curved surfaces and breaks the 180-degree rotation symmetry.
    - The depth-change threshold uses the nearer depth of the pair (PCL: the left/upper
      pixel's), every pair is tested (PCL skips the last row and column), and the distance
      map is computed exactly in integer units (PCL sums 1.4 in float32, so distances such
      as 7 round to 6.9999995 or 7.0000005 by scan order, changing ``int(s)``).
    - Mirror: the symmetric extension (pixel -1 is pixel 0, pixel W is pixel W - 1) on all
      four sides. PCL mirrors left and top like this but, on the right and bottom, drops the
      last column/row of windows that reach it and reflects about it; its mirror also raises
      for ``simple-3d-gradient``, where ours applies the same extension.
    - average-3d-gradient: differences are computed on every row (columns) where both
      neighbours exist and are valid; PCL writes zero differences on the outermost rows and
      columns and counts them as valid (they shrink the sums under the mirror policy).
    - covariance-matrix: the covariance stays float64; PCL casts the float64 sums to float32
      before subtracting the mean, which cancels ~7 digits at metre depths.
    - average-depth-change: each tangent joins the back-projected mean positions of two
      half-window boxes at their mean depths. PCL takes x and y from single points, and its
      upper and lower points sit one column left and right of the pixel and one row closer to
      it than its boxes (``index - r/4 * width - 1``), which tilts the normal even on planes.
    - simple-3d-gradient: means of the end columns/rows instead of their sums (equal when
      every pixel is valid, which the distance map guarantees).

    The viewpoint is the camera centre (PCL's default): normals face the camera, as in PCL.

    References
    ----------
    S. Holzer, R. B. Rusu, M. Dixon, S. Gedikli and N. Navab, "Adaptive Neighborhood
    Selection for Real-Time Surface Normal Estimation from Organized Point Cloud Data Using
    Integral Images," IEEE/RSJ International Conference on Intelligent Robots and Systems
    (IROS), 2012, pp. 2684-2689. doi:10.1109/IROS.2012.6385999

    D. Holz, S. Holzer, R. B. Rusu and S. Behnke, "Real-Time Plane Segmentation using RGB-D
    Cameras," RoboCup 2011: Robot Soccer World Cup XV, LNCS 7416, pp. 306-317, 2012.

    Point Cloud Library, ``pcl::IntegralImageNormalEstimation``
    (features/include/pcl/features/impl/integral_image_normal.hpp) and its tutorial
    "Normal Estimation Using Integral Images".

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import pcl_integral_image
    >>> n = pcl_integral_image(np.full((24, 32), 2.0), (500.0, 500.0, 15.5, 11.5))
    >>> n[12, 16].tolist()
    [0.0, 0.0, -1.0]
    >>> ignore = pcl_integral_image(np.full((24, 32), 2.0), (500.0, 500.0, 15.5, 11.5),
    ...                             border_policy="ignore")
    >>> int(np.isfinite(ignore[..., 0]).sum())  # rows and columns 10 .. W-11 only
    48
    """
    mode = check_choice(mode, "mode", MODES)
    policy = check_choice(border_policy, "border_policy", BORDER_POLICIES)
    factor = check_real(max_depth_change_factor, "max_depth_change_factor", minimum=0.0,
                        hint="PCL's default is 0.02")
    size = check_real(normal_smoothing_size, "normal_smoothing_size", minimum=2.0,
                      hint="PCL's default is 10")
    if not isinstance(depth_dependent_smoothing, (bool, np.bool_)):
        raise TypeError(f"depth_dependent_smoothing must be True or False; got "
                        f"{depth_dependent_smoothing!r}")
    if size <= 2.0 and not depth_dependent_smoothing:
        raise ValueError(f"normal_smoothing_size must exceed 2 unless depth_dependent_smoothing "
                         f"is True: a pixel abstains unless min(distance, normal_smoothing_size) "
                         f"exceeds 2, so {size:g} leaves every normal NaN (PCL's default is 10)")
    z, cam = prepare(depth, K, depth_scale)
    h, w = z.shape
    code = MODES.index(mode)
    units = np.empty((h, w), dtype=np.int64)
    _distance_units(z, factor, units)
    I = np.zeros((h + 1, w + 1, _CHANNELS[code]))
    run_rows(_integral_rows, h, z, cam.fx, cam.fy, cam.cx, cam.cy, code, I)
    run_rows(_integral_cols, w, I)
    out = np.empty((h, w, 3), dtype=np.float32)
    run_rows(_normals_rows, h, z, units, I, cam.fx, cam.fy, cam.cx, cam.cy, code, size,
             bool(depth_dependent_smoothing), policy == "ignore", out)
    return out


def _fixed_mode(mode: str, name: str):
    """The registered estimator ``name``: :func:`pcl_integral_image` with ``mode`` fixed."""

    def estimator(depth: Any, K: Any, *, max_depth_change_factor: float = 0.02,
                  normal_smoothing_size: float = 10.0, depth_dependent_smoothing: bool = False,
                  border_policy: str = "mirror", depth_scale: float | None = None) -> np.ndarray:
        return pcl_integral_image(depth, K, mode=mode,
                                  max_depth_change_factor=max_depth_change_factor,
                                  normal_smoothing_size=normal_smoothing_size,
                                  depth_dependent_smoothing=depth_dependent_smoothing,
                                  border_policy=border_policy, depth_scale=depth_scale)

    estimator.__name__ = estimator.__qualname__ = name.replace("-", "_")
    estimator.__doc__ = (
        f"PCL's integral-image normals, {mode.upper().replace('-', '_')} mode "
        f"(:func:`pcl_integral_image` with ``mode={mode!r}``).\n\n"
        "Abstains (NaN) next to depth jumps; see :func:`pcl_integral_image` for the options.\n")
    return estimator


# the four modes as registered estimators (metric thresholds: not scale invariant)
pcl_average_3d_gradient = _fixed_mode("average-3d-gradient", "pcl-average-3d-gradient")
pcl_covariance_matrix = _fixed_mode("covariance-matrix", "pcl-covariance-matrix")
pcl_average_depth_change = _fixed_mode("average-depth-change", "pcl-average-depth-change")
pcl_simple_3d_gradient = _fixed_mode("simple-3d-gradient", "pcl-simple-3d-gradient")
