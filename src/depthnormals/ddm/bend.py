"""How far a surface bends at the scale of tens of pixels: the large-scale spread of the normals.

The expected-error map (:mod:`depthnormals.ddm.uncertainty`) reads the spread of the normals a
few pixels away; this module reads it at the scale of tens of pixels. On a grid of every
:data:`STEP`-th pixel the normals are averaged over a box of ``2 BOX + 1`` cells (nine
normals 8 px apart: most of the noise averages out), and each cell's mean normal is compared
with the mean normals :data:`SPAN` cells (48 px) away, right, left, below and above, whose
points lie on the same near-plane (the chord between the two points within :data:`GATE_DEG`
of both mean tangent planes; a chord across a crease or a jump fails): the mean angle, in
degrees, is the cell's *bend* (0 where no cell qualifies).

Why it is an error term (ours; measured in docs/benchmarks.md section 27): on real depth a
plane is seldom flat at that scale. A Kinect's low-frequency depth distortion, time of
flight's multipath by a concave corner, a lens's residual bend the measured surface over
tens of pixels, and the normals of every estimator follow the bend: against the true plane
they err by it, and no estimate of the depth can remove it (the 61-px plane of a real
plane's own points leaves the whole plane by as much as the estimate errs where the map
predicts least, section 25). In the lowest quartile of the map's prediction, the pixels of
more bend than the quartile's median err more against their map than those of less on 10 of
the 13 real frames (Kinect v1, KITTI's lidar, Azure Kinect time of flight, RealSense D435;
up to 2.3x against 0.9-1.2x); on the synthetic kinect_v1 and realsense_d4xx depth, which has
no such deformation, the pixels of more bend (their mean normals' residual noise) err more
too (0.99-1.30x against 0.76-0.82x). The measured support's map adds :data:`BEND_SHARE` of the bend in
quadrature (chosen on numpy dumps of the real frames and the synthetic columns together,
0.5-0.8 tried: from 0.7 the real frames pooled lose their decile 7).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["BEND_SHARE", "BOX", "GATE_DEG", "SPAN", "STEP", "bend_grid", "bend_grid_by_rows",
           "bend_row", "bend_term", "chord_angle"]

#: Grid spacing (pixels) of the cells.
STEP = 8
#: Half width (cells) of the box the normals are averaged over: ``2 BOX + 1`` cells, the nine
#: normals of a 17 x 17 px square at :data:`STEP` 8.
BOX = 1
#: Distance (cells) between the two mean normals compared: 48 px at :data:`STEP` 8.
SPAN = 6
#: The chord between the two cells' points must lie within this angle (deg) of both mean
#: tangent planes (the two lie on one near-plane; a chord across a crease or a jump fails).
GATE_DEG = 3.0
#: A box's mean normal counts where its resultant is at least this share of its valid
#: normals (one orientation, not a crease averaged away) and at least half the box is valid.
RESULTANT = 0.9
#: The map's bend term: ``BEND_SHARE`` times the bend, added in quadrature.
BEND_SHARE = 0.6


@nb.njit(cache=True, error_model="numpy", inline="always")
def chord_angle(k2):
    """The angle (radians) between two unit vectors whose difference has squared length
    ``k2``: ``2 asin(k / 2) ~ k + k^3 / 24 + 3 k^5 / 640`` (exact to 1e-6 deg below 10 deg, 0.8 %
    low at 90 deg), without a transcendental call."""
    k = math.sqrt(k2)
    return k + k * k2 * (1.0 / 24.0 + k2 * (3.0 / 640.0))


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _cells(planar, z, step, cam, out_n, out_x):
    """The sampled normals (``planar`` (H, 3, W), by row) and points of the cells (NaN where
    invalid)."""
    fx, fy, cx, cy = cam
    hc, wc = out_x.shape[:2]
    for i in range(hc):
        v = i * step
        for j in range(wc):
            u = j * step
            zz = z[v, u]
            n0 = planar[v, 0, u]
            ok = zz == zz and n0 == n0
            for k in range(3):
                out_n[i, j, k] = planar[v, k, u] if ok else 0.0
            if ok:
                out_x[i, j, 0] = (u - cx) / fx * zz
                out_x[i, j, 1] = (v - cy) / fy * zz
                out_x[i, j, 2] = zz
            else:
                out_x[i, j, 0] = np.nan
                out_x[i, j, 1] = np.nan
                out_x[i, j, 2] = np.nan


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _box_means(cn, cx, box, resultant, out):
    """Each cell's mean normal over the ``(2 box + 1)^2`` cells around it (those inside the
    grid; a summed-area table), unit length; NaN where under half of a full box is valid, the
    resultant is short of ``resultant`` times the valid count, or the cell's own point is
    invalid."""
    hc, wc = cx.shape[:2]
    s = np.zeros((hc + 1, wc + 1, 4))
    for i in range(hc):
        for j in range(wc):
            c = 1.0 if cx[i, j, 2] == cx[i, j, 2] else 0.0
            for k in range(3):
                s[i + 1, j + 1, k] = cn[i, j, k] + s[i, j + 1, k] + s[i + 1, j, k] - s[i, j, k]
            s[i + 1, j + 1, 3] = c + s[i, j + 1, 3] + s[i + 1, j, 3] - s[i, j, 3]
    half = 0.5 * (2 * box + 1) ** 2
    for i in range(hc):
        i0 = max(0, i - box)
        i1 = min(hc, i + box + 1)
        for j in range(wc):
            j0 = max(0, j - box)
            j1 = min(wc, j + box + 1)
            m0 = s[i1, j1, 0] - s[i0, j1, 0] - s[i1, j0, 0] + s[i0, j0, 0]
            m1 = s[i1, j1, 1] - s[i0, j1, 1] - s[i1, j0, 1] + s[i0, j0, 1]
            m2 = s[i1, j1, 2] - s[i0, j1, 2] - s[i1, j0, 2] + s[i0, j0, 2]
            m3 = s[i1, j1, 3] - s[i0, j1, 3] - s[i1, j0, 3] + s[i0, j0, 3]
            L = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            if m3 < half or L < resultant * m3 or not (cx[i, j, 2] == cx[i, j, 2]):
                out[i, j, 0] = np.nan
                out[i, j, 1] = np.nan
                out[i, j, 2] = np.nan
            else:
                out[i, j, 0] = m0 / L
                out[i, j, 1] = m1 / L
                out[i, j, 2] = m2 / L


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _bend(mn, cx, span, gate, out):
    """Each cell's mean angle (deg) to the mean normals ``span`` cells away (right, left,
    below, above) on its near-plane (:func:`bend_grid`; ``gate`` the sine of
    :data:`GATE_DEG`); 0 where none qualifies. Each pair is read once (to the right and
    below) and counts for both its cells; the angle from the chord (:func:`chord_angle`)."""
    hc, wc = cx.shape[:2]
    g2 = gate * gate
    cnt = np.zeros((hc, wc))
    out[:] = 0.0
    for i in range(hc):
        for j in range(wc):
            if not (mn[i, j, 0] == mn[i, j, 0]):
                continue
            for d in range(2):
                ii = i + span * d
                jj = j + span * (1 - d)
                if ii >= hc or jj >= wc or not (mn[ii, jj, 0] == mn[ii, jj, 0]):
                    continue
                dx = cx[ii, jj, 0] - cx[i, j, 0]
                dy = cx[ii, jj, 1] - cx[i, j, 1]
                dz = cx[ii, jj, 2] - cx[i, j, 2]
                l2 = g2 * (dx * dx + dy * dy + dz * dz)
                pa = mn[i, j, 0] * dx + mn[i, j, 1] * dy + mn[i, j, 2] * dz
                pb = mn[ii, jj, 0] * dx + mn[ii, jj, 1] * dy + mn[ii, jj, 2] * dz
                if not (pa * pa < l2 and pb * pb < l2):
                    continue
                ex = mn[i, j, 0] - mn[ii, jj, 0]
                ey = mn[i, j, 1] - mn[ii, jj, 1]
                ez = mn[i, j, 2] - mn[ii, jj, 2]
                a = chord_angle(ex * ex + ey * ey + ez * ez)
                out[i, j] += a
                out[ii, jj] += a
                cnt[i, j] += 1.0
                cnt[ii, jj] += 1.0
    for i in range(hc):
        for j in range(wc):
            out[i, j] = math.degrees(out[i, j] / cnt[i, j]) if cnt[i, j] > 0.0 else 0.0


def bend_grid(normals: np.ndarray, z: np.ndarray, cam: tuple, *, step: int = STEP,
              box: int = BOX, span: int = SPAN, gate_deg: float = GATE_DEG) -> np.ndarray:
    """The bend (deg) of every ``step``-th pixel's surface (module doc), float64 ``(ceil(H /
    step), ceil(W / step))``; cell ``(i, j)`` is pixel ``(i step, j step)``; 0 where no cell
    ``span`` away lies on its near-plane.

    ``normals`` (H, W, 3) unit (NaN invalid), ``z`` (H, W) planar depth (NaN invalid),
    ``cam`` ``(fx, fy, cx, cy)`` in pixels."""
    planar = np.ascontiguousarray(np.asarray(normals, dtype=np.float32).transpose(0, 2, 1))
    return bend_grid_by_rows(planar, z, cam, step=step, box=box, span=span, gate_deg=gate_deg)


def bend_grid_by_rows(planar: np.ndarray, z: np.ndarray, cam: tuple, *, step: int = STEP,
                      box: int = BOX, span: int = SPAN, gate_deg: float = GATE_DEG) -> np.ndarray:
    """:func:`bend_grid` of normals laid out by row, ``planar`` (H, 3, W) float32 C-contiguous
    (the uncertainty map's layout: no copy)."""
    fx, fy, cx, cy = (float(c) for c in cam)
    return _bend_grid(planar, z, step, (fx, fy, cx, cy), box, RESULTANT, span,
                      math.sin(math.radians(gate_deg)))


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _bend_grid(planar, z, step, cam, box, resultant, span, gate):
    """:func:`bend_grid_by_rows` in one compiled call (one dispatch)."""
    h, w = z.shape
    hc, wc = -(-h // step), -(-w // step)
    cn = np.empty((hc, wc, 3))
    cx = np.empty((hc, wc, 3))
    _cells(planar, z, step, cam, cn, cx)
    mn = np.empty((hc, wc, 3))
    _box_means(cn, cx, box, resultant, mn)
    out = np.empty((hc, wc))
    _bend(mn, cx, span, gate, out)
    return out


def bend_term(grid: np.ndarray, step: int, share: float, w: int) -> tuple:
    """What a map's grid of ``w`` columns reads of ``grid`` (:func:`bend_grid` of every
    ``step``-th point of that grid, in its units), each term ``share`` times the bend: ``(grid,
    step, share, cols)``, ``cols`` the nearest cell of each column (:func:`bend_row`)."""
    cols = np.minimum((np.arange(w) + step // 2) // step, grid.shape[1] - 1).astype(np.int64)
    return grid, step, float(share), cols


@nb.njit(cache=True, error_model="numpy", inline="always")
def bend_row(bend, v, sq, out):
    """The squared bend term of row ``v`` of a map's grid, into ``out`` (float32, one per
    column): ``(share b)^2``, ``b`` the bend of the cell nearest to the grid point ``(v, u)``
    (``bend`` from :func:`bend_term`; ``sq`` scratch, one per cell of a grid row)."""
    grid, step, share, cols = bend
    hc, wc = grid.shape
    g = grid[min((v + step // 2) // step, hc - 1)]
    for j in range(wc):
        t = np.float32(share * g[j])
        sq[j] = t * t
    for u in range(out.size):
        out[u] = sq[cols[u]]
