"""The face switch of the measured support: a cell by a crease takes the face whose plane explains
its own 3x3 clearly better (ours, not the paper's; session 31, after the session-19 prototype
``benchmarks/crease_refinement.py``).

Why: within 10 px of the creases of the real frames' planes (``evaluate.crease_band``) the
measured support erred more than PCL's average 3D gradient (28.25 against 22.35 deg, mean over
the real folders; docs/benchmarks.md section 16, "Session 19"). Near a crease the windows that
hold a pixel on one face include windows that hold mostly the other: a few pixels of one face
barely raise a window's residual, so the least residual of the nine is a coin flip between the
faces for the pixels within a few pixels of the crease, and the fallback's five-standard-
deviation test (:data:`depthnormals.ddm.support.DEVIATION`) only stops a face carried further
than the noise hides it. The pixel's own neighbourhood still tells which face it is on, and a
3x3 of points is nine times less noisy in variance than one.

The rule (:func:`switch_faces`), on the grid of the choice (every second row and column from
:data:`~depthnormals.ddm.support.HALF_RADIUS` on), for each cell with depth and a normal whose
3x3 holds no depth jump (no neighbour more than :data:`JUMP` of its depth away):

- every cell ``q`` with depth and a normal carries the plane of its normal ``n_q`` through the
  centroid ``c_q`` of its own 3x3's points (the back-projected cells with depth and a normal);
- over the cell itself and the eight cells :data:`SPAN` pixels away (rows, columns and
  diagonals; half as many cells on the half grid) the mean squared distance of the cell's 3x3
  points to each such plane, ``n_q^T C_p n_q + (n_q . (c_p - c_q))^2`` (``C_p`` the 3x3's
  covariance), is split into the planes within :data:`ANGLE` degrees of ``n_p`` (its own face,
  its own plane included; the least is ``same``) and the others (the least is ``other``, from
  ``q*``, the first in :data:`DIRECTIONS` order of equal ones);
- the cell takes ``n_{q*}`` where ``other < MARGIN same``.

Measured (docs/benchmarks.md section 22): the real frames' crease bands 28.25 -> 22.16 deg (mean
over folders; PCL 22.35), plane interiors 3.76 -> 3.73, rims 9.96 -> 9.88; the synthetic
kinect_v1 and realsense_d4xx columns 2.4-9.1 % lower mean error. :data:`MARGIN` 0.7: at 1.0 the
real plane pixels that the map rated reliable lost most (correlated Kinect noise lets a 3x3 fit
the other face by chance; rims 9.99). The prototype's tile gate (the other face within 6x the
tile's typical own fit) changed nothing measurable on the frames that run this and is left out.
The frames of the i.i.d. box-fit (Gaussian, Kinect v2, ToF models) do not run it. Cost: 1.5-2.2
ms a 640x480 frame's half grid, one thread (:func:`_switch_rows`). The uncertainty map reads the
decisions (:data:`depthnormals.ddm.uncertainty.DECIDED_MAP`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .._parallel import run_rows

__all__ = ["ANGLE", "DIRECTIONS", "JUMP", "MARGIN", "SPAN", "switch_faces"]

#: Planes of normals within this many degrees of the cell's own count as its own face.
ANGLE = 20.0
#: A 3x3 whose depths differ from the centre's by more than this share holds a depth jump (an
#: occlusion, where a plane through the foreground says nothing of the background): no switch.
JUMP = 0.02
#: The other face's fit must be below this share of the best fit of the cell's own face (on
#: real Kinect depth, correlated over the matching window, a 3x3 fits the other face by chance).
MARGIN = 0.7
#: Distance (pixels) of the eight candidate cells; on the half grid ``SPAN // 2`` cells.
SPAN = 4
#: Offsets (row, column) of the candidate cells, in units of the span, in the order ties break.
DIRECTIONS = np.array([[-1, 0], [1, 0], [0, -1], [0, 1], [-1, -1], [-1, 1], [1, -1], [1, 1]],
                      dtype=np.int64)


def _bit_tables() -> tuple[np.ndarray, np.ndarray]:
    """For every byte, its set bits (ascending) and how many."""
    bits = np.zeros((256, 8), dtype=np.int64)
    count = np.zeros(256, dtype=np.int64)
    for b in range(256):
        ks = [k for k in range(8) if b >> k & 1]
        bits[b, :len(ks)] = ks
        count[b] = len(ks)
    return bits, count


_BITS, _COUNT = _bit_tables()

#: Taylor coefficients of ``asin(s) = sum_k c_k s^(2k + 1)``, ``c_k = (2k)! / (4^k k!^2 (2k +
#: 1))``: 23 terms reach float64's precision for ``|s| <= 1/2`` (:func:`_log_acos`).
_ASIN_SERIES = np.array([math.factorial(2 * k) / (4 ** k * math.factorial(k) ** 2 * (2 * k + 1))
                         for k in range(23)])
#: ``atanh(s) = sum_k s^(2k + 1) / (2k + 1)``: 12 terms for ``|s| <= 3 - 2 sqrt(2)``.
_ATANH_SERIES = np.array([1.0 / (2 * k + 1) for k in range(12)])
#: ``ln 2`` split so that ``e * _LN2_HI`` is exact for the exponents of float64.
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_MANTISSA = np.int64(0x000FFFFFFFFFFFFF)
_EXPONENT_ONE = np.int64(0x3FF0000000000000)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _log_acos(n, ratio, dot, mant, out_log, out_deg):
    """``out_log[i] = log(ratio[i])`` and ``out_deg[i] = degrees(acos(clip(dot[i], -1, 1)))``
    for ``i < n`` (float64 buffers; ``mant`` int64 scratch), in loops without a call or a
    branch, which lets the compiler vectorise them (libm's ``log`` and ``acos``, one call a
    value, cost about 19 ns a pair, these about 4, measured; the generated code not read): the
    logarithm from the exponent and the mantissa ``m`` in ``[sqrt(1/2), sqrt(2))``, ``log m = 2
    atanh((m - 1) / (m + 1))``; the arc cosine as ``pi / 2 - asin(d)`` for ``|d| <= 1/2``, else
    from ``asin(sqrt((1 - |d|) / 2))``. Within 3 units in the last place of float64 of libm's on
    2 million random values, and equal to them once rounded to float32 (the decisions' type). A
    ratio that is not a positive normal float64 (or NaN) takes libm's."""
    bits = ratio.view(np.int64)
    for i in range(n):
        mant[i] = (bits[i] & _MANTISSA) | _EXPONENT_ONE
    mf = mant.view(np.float64)
    sq2 = math.sqrt(2.0)
    for i in range(n):
        e = np.float64(((bits[i] >> 52) & 0x7FF) - 1023)
        m = mf[i]
        big = m > sq2
        m = m * 0.5 if big else m
        e = e + 1.0 if big else e
        s = (m - 1.0) / (m + 1.0)
        z = s * s
        p = _ATANH_SERIES[11]
        for k in range(10, -1, -1):
            p = p * z + _ATANH_SERIES[k]
        out_log[i] = e * _LN2_HI + (e * _LN2_LO + 2.0 * s * p)
    half_pi = 0.5 * math.pi
    for i in range(n):
        d = min(max(dot[i], -1.0), 1.0)
        a = abs(d)
        small = a <= 0.5
        s = d if small else math.sqrt((1.0 - a) * 0.5)
        z = s * s
        p = _ASIN_SERIES[22]
        for k in range(21, -1, -1):
            p = p * z + _ASIN_SERIES[k]
        r = s * p
        t = half_pi - r if small else (2.0 * r if d > 0.0 else math.pi - 2.0 * r)
        out_deg[i] = math.degrees(t)
    for i in range(n):  # outside the series' domain (never for the fits' ratios): libm
        x = ratio[i]
        if not (x >= 2.3e-308 and x <= 1.7e308):
            out_log[i] = np.log(x)
        if not (dot[i] == dot[i]):
            out_deg[i] = np.nan


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _planar(n, z, out):
    """``out`` (3, H, W): the normals ``n`` (H, W, 3) planar, NaN where ``z`` is (the half
    grid's choice gives a cell without depth a normal, for the pixels of its 2x2 that have)."""
    h, w = z.shape
    nan = np.float32(np.nan)
    for v in range(h):
        zr = z[v]
        for k in range(3):
            o = out[k, v]
            for u in range(w):
                o[u] = n[v, u, k] if zr[u] == zr[u] else nan


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _row_moments(z, n, r, cam, tmp, out):
    """``out`` (10, W): the points of row ``r`` with depth and a normal (count, x, y, z and the
    six products; zeros elsewhere) summed over each column's three neighbours along the row
    (``tmp`` (10, W) scratch). Loops over slices that start at 0: an index ``u + du`` keeps
    LLVM from vectorising."""
    w = z.shape[1]
    fx, fy, cx, cy = cam
    ry = (r - cy) / fy
    zr = z[r]
    nr = n[0, r]
    t0, t1, t2, t3, t4 = tmp[0], tmp[1], tmp[2], tmp[3], tmp[4]
    t5, t6, t7, t8, t9 = tmp[5], tmp[6], tmp[7], tmp[8], tmp[9]
    for u in range(w):
        zz = zr[u]
        good = (zz == zz) & (nr[u] == nr[u])
        x = (u - cx) / fx * zz
        y = ry * zz
        x = x if good else 0.0
        y = y if good else 0.0
        zz = zz if good else 0.0
        t0[u] = 1.0 if good else 0.0
        t1[u] = x
        t2[u] = y
        t3[u] = zz
        t4[u] = x * x
        t5[u] = x * y
        t6[u] = x * zz
        t7[u] = y * y
        t8[u] = y * zz
        t9[u] = zz * zz
    for k in range(10):
        a = tmp[k]
        o = out[k]
        left = a[:w - 2]
        mid = a[1:w - 1]
        right = a[2:]
        oi = o[1:w - 1]
        for u in range(w - 2):
            oi[u] = left[u] + mid[u] + right[u]
        if w > 1:
            o[0] = a[0] + a[1]
            o[w - 1] = a[w - 2] + a[w - 1]
        else:
            o[0] = a[0]


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _sums_row(t, z, n, cam, rows, tmp, out):
    """``out`` (14, W): the 3x3 sums of row ``t`` from the ring ``rows`` (3, 10, W) of row
    moments (:func:`_row_moments`), which must hold rows ``t - 1`` and ``t`` (zeros outside):
    row ``t + 1`` enters it here; then the centroids ``sums[1:4] / sums[0]`` and ``1 /
    sums[0]`` (NaN outside the image; without a point, NaN and inf)."""
    h = z.shape[0]
    if t < 0 or t >= h:
        out[:] = np.nan
        if 0 <= t + 1 < h:
            _row_moments(z, n, t + 1, cam, tmp, rows[(t + 1) % 3])
        return
    if t + 1 < h:
        _row_moments(z, n, t + 1, cam, tmp, rows[(t + 1) % 3])
    else:
        rows[(t + 1) % 3] = 0.0
    a0 = rows[(t - 1) % 3]
    a1 = rows[t % 3]
    a2 = rows[(t + 1) % 3]
    for k in range(10):
        x0 = a0[k]
        x1 = a1[k]
        x2 = a2[k]
        o = out[k]
        for u in range(x0.size):
            o[u] = x0[u] + x1[u] + x2[u]
    s0 = out[0]
    ic = out[13]
    for u in range(s0.size):
        ic[u] = 1.0 / s0[u]
    for k in range(3):  # the centroids (NaN without a point), read by the neighbours
        sk = out[1 + k]
        o = out[10 + k]
        for u in range(s0.size):
            o[u] = sk[u] * ic[u]


@nb.njit(cache=True, error_model="numpy", inline="always")
def _quad(qx, qy, qz, cov, u):
    """``q^T C q`` of the covariance ``C`` stored in column ``u`` of ``cov`` (6, W: xx, xy,
    xz, yy, yz, zz)."""
    return (qx * qx * cov[0, u] + qy * qy * cov[3, u] + qz * qz * cov[5, u]
            + 2.0 * (qx * qy * cov[1, u] + qx * qz * cov[2, u] + qy * qz * cov[4, u]))


@nb.njit(cache=True, error_model="numpy", inline="always")
def _distance(n, sums, r, q, acc, cov, u):
    """The mean squared distance of the 3x3 points of the row's cell ``u`` (centroid
    ``acc[10:13, u]``, covariance ``cov[:, u]``) to the plane of cell (r, q) (normal
    ``n[:, r, q]``, through the centroid of its own 3x3, ``sums[10:13, q]``):
    ``n^T C n + (n . (c_p - c_q))^2``."""
    qx = np.float64(n[0, r, q])
    qy = np.float64(n[1, r, q])
    qz = np.float64(n[2, r, q])
    d = (qx * (acc[10, u] - sums[10, q]) + qy * (acc[11, u] - sums[11, q])
         + qz * (acc[12, u] - sums[12, q]))
    return _quad(qx, qy, qz, cov, u) + d * d


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _switch_rows(v0, v1, z, n, cam, span, cos_min, jump, margin, want, out, out_switch, out_dec):
    """Rows ``[v0, v1)`` of the switch (module doc): ``n`` (3, H, W) the normals (planar, NaN
    where the cell has no depth, a copy of ``out``); ``out`` (H, W, 3) takes the other face's
    normal where the rule says so, ``out_switch`` (H, W) marks those cells; with ``want``,
    ``out_dec`` (2, H, W) the decisions of the cells that saw another face (``log(other /
    same)``, the angle in degrees; NaN elsewhere). One sweep: the 3x3 sums of rows ``v - span
    .. v + span`` in a ring with their centroids (a candidate plane passes through the
    centroid of its own cell's 3x3), every loop along a row but the cells that see another
    face, whose set bits of direction it walks (no branch on a test that flips at random;
    with ``want``, every decided cell's eight distances over the row's list of them, then
    selects: session 39, 0.3-0.9 -> 0.1-0.35 ms a 640x480 frame, the same values); the row's
    decisions take their logarithms and arc cosines together (:func:`_log_acos`)."""
    h, w = z.shape
    nd = DIRECTIONS.shape[0]
    size = 2 * span + 1
    rows = np.zeros((3, 10, w))
    tmp = np.empty((10, w))
    ring = np.zeros((size, 14, w))
    dots = np.empty((nd, w), dtype=np.float32)
    smooth = np.empty(w, dtype=np.bool_)
    idx = np.empty(w, dtype=np.int64)
    own = np.empty(w)
    dist = np.empty(w)
    obits = np.empty(w, dtype=np.uint8)  # the directions of another face, and of its own
    sbits = np.empty(w, dtype=np.uint8)
    ratio = np.empty(w)  # the row's decisions before their logarithm and arc cosine
    cosine = np.empty(w)
    mant = np.empty(w, dtype=np.int64)
    logs = np.empty(w)
    degs = np.empty(w)
    at = np.empty(w, dtype=np.int64)
    cov = np.empty((6, w))  # the row's covariances
    vals = np.empty((nd, w))  # with want: the decided cells' distances to the eight planes
    g_ob = np.empty(w, dtype=np.uint8)  # and, per decided cell, its bits and least distances
    g_sb = np.empty(w, dtype=np.uint8)
    g_other = np.empty(w)
    g_best = np.empty(w, dtype=np.int64)
    g_same = np.empty(w)
    tiny = 1e-300
    cm = np.float32(cos_min)
    two = np.float32(2.0)
    t0 = v0 - span
    for r in range(t0 - 1, t0 + 1):  # the row moments before the first sums
        if 0 <= r < h:
            _row_moments(z, n, r, cam, tmp, rows[r % 3])
    for t in range(t0, v0 + span):
        _sums_row(t, z, n, cam, rows, tmp, ring[t % size])
    for v in range(v0, v1):
        _sums_row(v + span, z, n, cam, rows, tmp, ring[(v + span) % size])
        acc = ring[v % size]
        x0 = n[0, v]
        x1 = n[1, v]
        x2 = n[2, v]
        zr = z[v]
        for u in range(w):
            out_switch[v, u] = False
            smooth[u] = (zr[u] == zr[u]) & (x0[u] == x0[u])
            obits[u] = 0
            sbits[u] = 0
        if want:
            for u in range(w):
                out_dec[0, v, u] = np.nan
                out_dec[1, v, u] = np.nan
        for dv in range(-1, 2):  # a jump in the 3x3: no switch (NaN neighbours are none)
            q = v + dv
            if q < 0 or q >= h:
                continue
            for du in range(-1, 2):
                lo = max(0, -du)
                hi = min(w, w - du)
                zq = z[q, lo + du:hi + du]
                zc = zr[lo:hi]
                fl = smooth[lo:hi]
                for i in range(hi - lo):
                    fl[i] = fl[i] & ~(abs(zq[i] - zc[i]) > jump * zc[i])
        # every cell's covariance, and its own plane's fit (d = 0 there)
        c0, c1, c2, ir = acc[10], acc[11], acc[12], acc[13]
        for u in range(w):
            px = c0[u]
            py = c1[u]
            pz = c2[u]
            ic = ir[u]
            cov[0, u] = acc[4, u] * ic - px * px
            cov[1, u] = acc[5, u] * ic - px * py
            cov[2, u] = acc[6, u] * ic - px * pz
            cov[3, u] = acc[7, u] * ic - py * py
            cov[4, u] = acc[8, u] * ic - py * pz
            cov[5, u] = acc[9, u] * ic - pz * pz
            own[u] = _quad(np.float64(x0[u]), np.float64(x1[u]), np.float64(x2[u]), cov, u)
        # the cosines to the eight cells (2 outside the image or without a normal), along
        # slices from 0 (vectorised); a direction of another face counts where its plane
        # passes within sqrt(margin own) of the cell's centroid (a plane at distance d fits
        # no better than d^2, and the switch needs ``margin own``; the map reads them all)
        for k in range(nd):
            dk = dots[k]
            for u in range(w):
                dk[u] = two
            r = v + span * DIRECTIONS[k, 0]
            if r < 0 or r >= h:
                continue
            du = span * DIRECTIONS[k, 1]
            lo = max(0, -du)
            hi = min(w, w - du)
            y0 = n[0, r, lo + du:hi + du]
            y1 = n[1, r, lo + du:hi + du]
            y2 = n[2, r, lo + du:hi + du]
            a0 = x0[lo:hi]
            a1 = x1[lo:hi]
            a2 = x2[lo:hi]
            ds = dk[lo:hi]
            ob = obits[lo:hi]
            sb = sbits[lo:hi]
            ow = own[lo:hi]
            p0 = c0[lo:hi]
            p1 = c1[lo:hi]
            p2 = c2[lo:hi]
            rk = ring[r % size]
            q0 = rk[10, lo + du:hi + du]
            q1 = rk[11, lo + du:hi + du]
            q2 = rk[12, lo + du:hi + du]
            bit = np.uint8(1 << k)
            for i in range(hi - lo):  # (three loops of one type each: each vectorises)
                dot = a0[i] * y0[i] + a1[i] * y1[i] + a2[i] * y2[i]
                ds[i] = dot if dot == dot else two
            dd = dist[lo:hi]
            if want:
                dd[:] = -1.0
            else:
                for i in range(hi - lo):
                    d = (y0[i] * (p0[i] - q0[i]) + y1[i] * (p1[i] - q1[i])
                         + y2[i] * (p2[i] - q2[i]))
                    dd[i] = d * d - margin * ow[i]
            for i in range(hi - lo):
                dot = ds[i]
                ob[i] |= bit if (dot < cm) & (dd[i] < 0.0) else np.uint8(0)
                sb[i] |= bit if (dot >= cm) & (dot <= np.float32(1.5)) else np.uint8(0)
        c = 0
        for u in range(w):  # the cells that see another face, without a branch
            idx[c] = u
            c += (obits[u] != 0) & smooth[u]
        nd_row = 0  # decisions kept for the map in this row
        if want:
            # the map reads every decided cell's planes of both faces: each cell's distance to
            # all eight candidates (the column clamped where the candidate lies outside: its
            # bits are unset there), one direction at a time over the row's list of decided
            # cells (a loop of gathers that vectorises), then both faces' least by selects
            # (the same values, ties and order as the walk of set bits below; half its cost)
            for k in range(nd):
                vk = vals[k]
                r = v + span * DIRECTIONS[k, 0]
                if r < 0 or r >= h:
                    for j0 in range(c):
                        vk[j0] = np.inf
                    continue
                du = span * DIRECTIONS[k, 1]
                rk = ring[r % size]
                for j0 in range(c):
                    u = idx[j0]
                    vk[j0] = _distance(n, rk, r, min(max(u + du, 0), w - 1), acc, cov, u)
            for j0 in range(c):
                u = idx[j0]
                g_ob[j0] = obits[u]
                g_sb[j0] = sbits[u]
                g_other[j0] = np.inf
                g_best[j0] = -1
                g_same[j0] = own[u]
            for k in range(nd):
                vk = vals[k]
                for j0 in range(c):
                    m = vk[j0]
                    lt = ((g_ob[j0] >> k) & 1 == 1) & (m < g_other[j0])
                    g_other[j0] = m if lt else g_other[j0]
                    g_best[j0] = k if lt else g_best[j0]
                    g_same[j0] = min(g_same[j0], m) if (g_sb[j0] >> k) & 1 == 1 else g_same[j0]
        for j0 in range(c):
            u = idx[j0]
            if want:
                other = g_other[j0]
                best = g_best[j0]
                same = g_same[j0]
                if best < 0:
                    continue
            else:
                other = np.inf
                best = -1
                ob = obits[u]
                for j in range(_COUNT[ob]):  # the other face's planes first (set bits: no
                    k = _BITS[ob, j]  # branch on a direction whose test flips at random)
                    r = v + span * DIRECTIONS[k, 0]
                    m = _distance(n, ring[r % size], r, u + span * DIRECTIONS[k, 1], acc, cov, u)
                    if m < other:
                        other = m
                        best = k
                if best < 0:
                    continue
                # then the own face's: the cell's own plane and the candidates within the angle
                same = own[u]
                sb = sbits[u]
                for j in range(_COUNT[sb]):
                    if not (other < margin * same):
                        break  # the normals alone need no more
                    k = _BITS[sb, j]
                    r = v + span * DIRECTIONS[k, 0]
                    same = min(same, _distance(n, ring[r % size], r, u + span * DIRECTIONS[k, 1],
                                               acc, cov, u))
            if want:  # for the map: how clear the decision was, the angle to the other face
                ratio[nd_row] = max(other, tiny) / max(same, tiny)
                cosine[nd_row] = np.float64(dots[best, u])
                at[nd_row] = u
                nd_row += 1
            if other < margin * same:
                r = v + span * DIRECTIONS[best, 0]
                q = u + span * DIRECTIONS[best, 1]
                out[v, u, 0] = n[0, r, q]
                out[v, u, 1] = n[1, r, q]
                out[v, u, 2] = n[2, r, q]
                out_switch[v, u] = True
        if nd_row:  # log(other / same) and the angle (degrees), vectorised over the row
            _log_acos(nd_row, ratio, cosine, mant, logs, degs)
            for j in range(nd_row):
                out_dec[0, v, at[j]] = logs[j]
                out_dec[1, v, at[j]] = degs[j]


def switch_faces(z: np.ndarray, normals: np.ndarray, fx: float, fy: float, cx: float,
                 cy: float, *, span: int = SPAN, angle: float = ANGLE, jump: float = JUMP,
                 margin: float = MARGIN, decisions: bool = False,
                 min_rows: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The face switch (module doc) of ``normals`` (H, W, 3) float32 on the depth ``z`` (H, W;
    NaN invalid) of the grid ``fx, fy, cx, cy`` (pixels of that grid; ``span`` in its cells).

    Returns the switched normals (``normals`` itself, switched in place, when it is a
    C-contiguous float32 array), the mask (H, W) of the cells that switched and, with
    ``decisions``, the decisions (2, H, W) float32 of the cells that saw another face (NaN
    elsewhere; else None): ``log(other / same)`` of the two faces' fits and the angle (degrees)
    between the cell's normal and the other face's, which the uncertainty map reads
    (:mod:`depthnormals.ddm.uncertainty`).
    """
    h, w = z.shape
    zz = np.ascontiguousarray(z, dtype=np.float64)
    n = np.ascontiguousarray(normals, dtype=np.float32)
    planar = np.empty((3, h, w), dtype=np.float32)
    _planar(n, zz, planar)
    switched = np.empty((h, w), dtype=np.bool_)
    dec = np.empty((2, h, w) if decisions else (2, 1, 1), dtype=np.float32)
    # in place: the kernel reads the normals from ``planar``
    run_rows(_switch_rows, h, zz, planar, (float(fx), float(fy), float(cx), float(cy)),
             int(span), math.cos(math.radians(angle)), float(jump), float(margin),
             bool(decisions), n, switched, dec, min_rows=min_rows)
    return n, switched, (dec if decisions else None)
