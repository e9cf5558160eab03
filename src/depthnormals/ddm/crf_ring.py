"""The 3F2N+ CRF over the cross candidates, one row at a time from ring buffers.

Used by the generic :func:`depthnormals.ddm.crf.crf_step` (cross candidates, Kendall or no
correlation) and by the fused 3F2N+ pipeline (:mod:`depthnormals.ddm.threefn_plus`), which calls
the same row functions on rows it has just selected, so both give identical results.

Rings hold padded planar rows (column ``u`` at index ``u + 1``; the padding and the slot of
rows outside the image are NaN for depth and normals, 0 for similarities):

- ``sel`` (5, 3, W + 2) float32: the current normals, slot ``row % 4`` (slot 4: outside);
- ``sim`` (5, W + 2) float32: the similarity ``s`` of every pixel (0 at invalid depth), slot
  ``row % 4``; ``hsum`` (5, W) float32: its horizontal 3-sums.

Per pixel ``q`` (``depthnormals.ddm.crf.crf_step`` gives the energy):

1. **Exact shortcut, vectorised over the row**: where the current normal is the anchor and
   ``sigma >= lam k_q sum_i s_i`` with the sum bounded above by the 3x3 sums of ``s`` (every
   neighbour of valid depth counted, plus 1e-5 for float32 rounding: the sums are <= 8), no
   candidate can beat the anchor (triangle inequality): the pixel keeps it.
2. **The others** are compacted; their 8 neighbours are gathered once into a batch of
   ``_CHUNK`` pixels that fills across rows, and the five candidates' energies are computed
   in float32 as vectors over the batch (the sum over the neighbours in raster order; ties
   go to the first candidate, so a repeated normal never wins twice).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..kernels.orient import store_normal

__all__ = ["crf_flush", "crf_ring_row", "ring_slots", "scratch", "sim_coefficients",
           "similarity_ring_row", "similarity_row"]

_BIG = 1e6  # k_q is clamped to it (inf and NaN too): a valid pixel always has a finite energy
_CHUNK = 64  # hard pixels per batch; scratch rows of _CHUNK + 4 floats (no 4K aliasing)
_DCOL = (-1, 0, 1, -1, 1, -1, 0, 1)  # column offsets of the 8 neighbours, raster order
_CANDS = (8, 1, 3, 4, 6)  # candidates in the public code's order: self (SELF), up, left, right, down
#: Rows of the scratch ``g`` (:func:`scratch`), one column per pending pixel. Blocks of 8 are
#: the 8 neighbours in raster order (zeros where a neighbour is invalid).
G_NX, G_NY, G_NZ = 0, 8, 16  # the neighbours' normals, x / y / z blocks
G_WEIGHT = 24  # their similarity weights
G_VALID = 32  # their validity (1 or 0)
G_ANCHOR = 40  # 40-42: the anchor normal x, y, z
G_LAM_K = 43  # lam k_q (k_q clamped to _BIG)
G_OWN = 45  # 45-47: the pixel's own current normal x, y, z (zeros where invalid)
G_OWN_VALID = 48  # its validity (1 or 0)
G_ENERGY = 49  # 49-53: the five candidates' energies (order _CANDS)
G_ROWS = 54
#: Candidate index of the pixel itself in ``_CANDS`` (neighbours are 0..7).
SELF = 8
_INL = {"cache": True, "error_model": "numpy", "inline": "always"}
_JIT = {"cache": True, "error_model": "numpy"}


def sim_coefficients(sim_mode: int) -> tuple[float, float]:
    """(a, b) with similarity ``s = a + b tau``: 1 (mode 0), ``1 - tau`` (1), ``tau`` (2)."""
    return {0: (1.0, 0.0), 1: (1.0, -1.0), 2: (0.0, 1.0)}[sim_mode]


@nb.njit(**_JIT)
def scratch(w):
    """The scratch arrays ``idx, g, pos`` of :func:`crf_ring_row` for rows of ``w`` pixels.

    ``g`` (:data:`G_ROWS`, ...): the rows named ``G_*`` above, one column per pending pixel.
    ``pos``: (row, column) of each pending pixel.
    """
    return (np.empty(w, dtype=np.int64), np.empty((G_ROWS, _CHUNK + 4), dtype=np.float32),
            np.empty((2, _CHUNK), dtype=np.int64))


@nb.njit(**_INL)
def ring_slots(q, h):
    """Slots of rows q - 1, q, q + 1 in a 4-row ring (slot 4: rows outside the image)."""
    return ((q - 1) % 4 if q > 0 else 4), q % 4, ((q + 1) % 4 if q + 1 < h else 4)


@nb.njit(**_JIT)
def similarity_row(zp, zc, zn, a, b, srow, hrow):
    """Similarity ``a + b tau`` of one row (0 at invalid depth) and its horizontal 3-sums.

    ``zp, zc, zn``: padded depth rows above, at and below (NaN padding and outside rows);
    ``tau`` is Kendall's of :mod:`depthnormals.ddm.correlation` (invalid neighbours compare
    false, so they are ignored), in float32 (within 6e-8 of
    :func:`depthnormals.ddm.correlation.kendall_map`). ``srow`` padded (W + 2) and ``hrow``
    (W): float32.
    """
    w = hrow.size
    one = np.float32(1.0)
    zero = np.float32(0.0)
    a = np.float32(a)
    b = np.float32(b)
    for u in range(w):  # branch-free; the counts are exact in float32
        i = u + 1
        z0 = zc[i]
        mc = ((one if zp[i - 1] > z0 else zero) + (one if zp[i] > z0 else zero)
              + (one if zp[i + 1] > z0 else zero) + (one if zc[i - 1] > z0 else zero)
              + (one if zc[i + 1] > z0 else zero) + (one if zn[i - 1] > z0 else zero)
              + (one if zn[i] > z0 else zero) + (one if zn[i + 1] > z0 else zero))
        md = ((one if zp[i - 1] < z0 else zero) + (one if zp[i] < z0 else zero)
              + (one if zp[i + 1] < z0 else zero) + (one if zc[i - 1] < z0 else zero)
              + (one if zc[i + 1] < z0 else zero) + (one if zn[i - 1] < z0 else zero)
              + (one if zn[i] < z0 else zero) + (one if zn[i + 1] < z0 else zero))
        n = mc + md
        t = a + b * (abs(mc - md) / (n if n > zero else one))
        srow[i] = t if z0 == z0 else zero
    srow[0] = zero
    srow[w + 1] = zero
    for u in range(w):
        hrow[u] = srow[u] + srow[u + 1] + srow[u + 2]


@nb.njit(**_JIT)
def similarity_ring_row(t, h, zb, a, b, sim, hsum):
    """:func:`similarity_row` of row ``t`` from a ring of padded depth rows (slot
    ``row % 3``, slot 3: outside the image) into slot ``t % 4`` of ``sim`` and ``hsum``."""
    similarity_row(zb[(t - 1) % 3] if t > 0 else zb[3], zb[t % 3],
                   zb[(t + 1) % 3] if t + 1 < h else zb[3], a, b, sim[t % 4], hsum[t % 4])


@nb.njit(**_INL)
def _norm3(a, b, c):
    return math.sqrt(a * a + b * b + c * c)


@nb.njit(**_INL)
def _dist(g, n, j, qx, qy, qz):
    return g[G_WEIGHT + n, j] * _norm3(g[G_NX + n, j] - qx, g[G_NY + n, j] - qy, g[G_NZ + n, j] - qz)


@nb.njit(**_INL)
def _energies(g, c, nh, sigma, e_out):
    """Energy of candidate ``c`` (a neighbour index; 8: the pixel itself) at every hard
    pixel, vectorised over them; +inf where the candidate is invalid. The edge sum runs over
    the neighbours in raster order, as the energy's definition."""
    gx = g[G_NX + c] if c < SELF else g[G_OWN]
    gy = g[G_NY + c] if c < SELF else g[G_OWN + 1]
    gz = g[G_NZ + c] if c < SELF else g[G_OWN + 2]
    gok = g[G_VALID + c] if c < SELF else g[G_OWN_VALID]
    inf = np.float32(np.inf)
    zero = np.float32(0.0)
    sigma = np.float32(sigma)
    for j in range(nh):
        qx = gx[j]
        qy = gy[j]
        qz = gz[j]
        ax = g[G_ANCHOR, j]
        e = sigma * _norm3(qx - ax, qy - g[G_ANCHOR + 1, j], qz - g[G_ANCHOR + 2, j])
        e = e if ax == ax else zero
        acc = _dist(g, 0, j, qx, qy, qz)
        acc += _dist(g, 1, j, qx, qy, qz)
        acc += _dist(g, 2, j, qx, qy, qz)
        acc += _dist(g, 3, j, qx, qy, qz)
        acc += _dist(g, 4, j, qx, qy, qz)
        acc += _dist(g, 5, j, qx, qy, qz)
        acc += _dist(g, 6, j, qx, qy, qz)
        acc += _dist(g, 7, j, qx, qy, qz)
        e += g[G_LAM_K, j] * acc
        e_out[j] = e if gok[j] > zero else inf


@nb.njit(**_JIT)
def crf_ring_row(q, slots, z, kq, ring, anc, anchored, weights, work, pend, cam, out):
    """One CRF row ``q`` into ``out[q]`` from the ring slots ``slots = (a, m, s)`` of rows
    q - 1, q and q + 1 (:func:`ring_slots`) of ``ring = (sel, sim, hsum)`` (the module
    docstring gives their layout); returns the number of pixels pending in ``work``.

    ``z`` (H, W): the depth (NaN invalid; the normals in ``sel`` are NaN there too); ``kq``
    (W) float64: row q's ``k_q`` as the energy uses it (NaN or inf: clamped to 1e6); ``anc``
    (3, W + 2) float32: row q's anchors; ``anchored``: the current normals are the anchors
    (skips the comparison). ``weights = (sigma, lam)``; ``work = (idx, g, pos)``:
    :func:`scratch`; ``pend``: the pixels pending in it (0 at the start of a band;
    :func:`crf_flush` after its last row). ``cam``: :class:`depthnormals.kernels.depth.Pinhole`.

    The pixels the shortcut cannot settle are compacted into a list and their neighbours
    gathered into ``g``; every ``_CHUNK`` of them (across rows) the five candidates' energies
    are computed as vectors over the batch, so the per-pixel work has no data-dependent
    branches and the vector loops run full.
    """
    a, m, s = slots
    sel, sim, hsum = ring
    sigma, lam = weights
    idx, g, pos = work
    w = kq.size
    zrow = z[q]
    hp = hsum[a]
    hc = hsum[m]
    hn = hsum[s]
    sc = sim[m]
    x0 = sel[m, 0]
    y0 = sel[m, 1]
    t0 = sel[m, 2]
    for u in range(w):  # the shortcut's test, vectorised
        i = u + 1
        k = kq[u]
        k = k if k < _BIG else _BIG
        bound = np.float64(hp[u] + hc[u] + hn[u] - sc[i]) + 1e-5  # >= float32 rounding
        x = x0[i]
        keep = (sigma >= lam * k * bound) & (x == x)
        zq = zrow[u]
        idx[u] = (zq == zq) & ~keep
    if not anchored:
        for u in range(w):
            i = u + 1
            x = x0[i]
            zq = zrow[u]
            idx[u] |= (zq == zq) & ~((x == anc[0, i]) & (y0[i] == anc[1, i])
                                     & (t0[i] == anc[2, i]))
    for u in range(w):  # the current normals (NaN at invalid depth) stand where kept
        i = u + 1
        out[q, u, 0] = x0[i]
        out[q, u, 1] = y0[i]
        out[q, u, 2] = t0[i]
    nh = 0
    for u in range(w):  # compaction (branch-free)
        f = idx[u]
        idx[nh] = u
        nh += f
    zero = np.float32(0.0)
    one = np.float32(1.0)
    for jj in range(nh):
        u = idx[jj]
        i = u + 1
        j = pend
        for n in range(8):  # neighbours in raster order
            sl = a if n < 3 else (m if n < 5 else s)
            col = i + _DCOL[n]
            x = sel[sl, 0, col]
            ok = x == x  # an invalid one: zero normal and weight, its term is +0 in every sum
            g[G_NX + n, j] = x if ok else zero
            g[G_NY + n, j] = sel[sl, 1, col] if ok else zero
            g[G_NZ + n, j] = sel[sl, 2, col] if ok else zero
            g[G_WEIGHT + n, j] = sim[sl, col] if ok else zero
            g[G_VALID + n, j] = one if ok else zero
        g[G_ANCHOR, j] = anc[0, i]
        g[G_ANCHOR + 1, j] = anc[1, i]
        g[G_ANCHOR + 2, j] = anc[2, i]
        k = kq[u]
        g[G_LAM_K, j] = lam * (k if k < _BIG else _BIG)
        x = x0[i]
        ok = x == x
        g[G_OWN, j] = x if ok else zero
        g[G_OWN + 1, j] = y0[i] if ok else zero
        g[G_OWN + 2, j] = t0[i] if ok else zero
        g[G_OWN_VALID, j] = one if ok else zero
        pos[0, j] = q
        pos[1, j] = u
        pend += 1
        if pend == _CHUNK:
            crf_flush(z, work, pend, sigma, cam, out)
            pend = 0
    return pend


@nb.njit(**_JIT)
def crf_flush(z, work, nh, sigma, cam, out):
    """Minimise the energy at the ``nh`` pixels pending in ``work = (idx, g, pos)`` (at
    ``pos``) and store into ``out`` the winners that are not the pixel's own normal (which
    ``out`` holds already)."""
    _, g, pos = work
    fx, fy, cx, cy = cam
    if nh == 0:
        return
    # one call per candidate, each with a constant index (its rows fold at compile time)
    _energies(g, _CANDS[0], nh, sigma, g[G_ENERGY])
    _energies(g, _CANDS[1], nh, sigma, g[G_ENERGY + 1])
    _energies(g, _CANDS[2], nh, sigma, g[G_ENERGY + 2])
    _energies(g, _CANDS[3], nh, sigma, g[G_ENERGY + 3])
    _energies(g, _CANDS[4], nh, sigma, g[G_ENERGY + 4])
    nan = np.float32(np.nan)
    zero = np.float32(0.0)
    for j in range(nh):
        q = pos[0, j]
        u = pos[1, j]
        wsum = zero
        for n in range(8):
            wsum += g[G_WEIGHT + n, j]
        ax = g[G_ANCHOR, j]
        if ((ax == ax) & (g[G_OWN, j] == ax) & (g[G_OWN + 1, j] == g[G_ANCHOR + 1, j])
                & (g[G_OWN + 2, j] == g[G_ANCHOR + 2, j]) & (sigma >= g[G_LAM_K, j] * wsum)):
            continue  # the anchor, exactly (out[q, u] holds it)
        best = np.inf
        c = -1
        for n in range(5):  # the first of equal energies wins
            e = g[G_ENERGY + n, j]
            if e < best:
                best = e
                c = n
        if c == 0:
            continue  # the pixel's own normal (out[q, u] holds it)
        if c < 0:
            out[q, u, 0] = nan
            out[q, u, 1] = nan
            out[q, u, 2] = nan
            continue
        nbr = _CANDS[c]
        zq = z[q, u]
        store_normal(out, q, u, np.float64(g[G_NX + nbr, j]), np.float64(g[G_NY + nbr, j]),
                     np.float64(g[G_NZ + nbr, j]), (u - cx) * zq / fx, (q - cy) * zq / fy, zq)
