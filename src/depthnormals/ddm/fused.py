"""3F2N+ in one pass: 3F2N, depth curvature, the cross selection and the CRF fused row by row.

The separate stages of :func:`depthnormals.ddm.discontinuity_discrimination` write and re-read
full-size maps (the 3F2N normals, interleaved, the curvature, Kendall's tau, the selected
normals) and select with strided loads. Here every row of 3F2N normals and of curvature goes
into small planar ring buffers (three rows, padded by one NaN/inf column each side) and row
``v - 1`` is selected as soon as row ``v`` exists; with the CRF, the selected rows go into a
second ring with their Kendall similarities, and row ``v - 2`` is refined by the row kernels
of :mod:`depthnormals.ddm.crf_ring` as soon as row ``v - 1`` is selected. All of it stays in
L1 and the inner loops vectorise (8 lanes for float32 depth). Same kernels, same arithmetic
as the separate stages: the results are equal (``tests/test_ddm_fused.py``).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..estimators._common import NEIGHBOURS8
from ..estimators.threefn import row_normals, row_setup
from .crf import select_ring_row
from .crf_ring import crf_flush, crf_ring_row, ring_slots, scratch, sim_coefficients, similarity_ring_row
from .curvature import mean_max_row, row_constants

__all__ = ["fused_3f2n_plus"]


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _plus_rows(v0, v1, z, R, c, acol, bcol, fx, fy, cx, cy, mode, kc, use_max, selfw, eps,
               deriv, smooth, nb_off, crf, sa, sb, sigma, lam, out, kout, want_k):
    h, w = z.shape
    nbuf = np.full((4, 3, w + 2), np.nan, dtype=z.dtype)  # rows r % 3; slot 3: outside image
    kbuf = np.full((4, w + 2), np.inf, dtype=z.dtype)
    zbuf = np.full((4, w + 2), np.nan, dtype=z.dtype)
    steps = np.empty((7, w), dtype=z.dtype)
    flag = np.empty(w, dtype=np.bool_)
    cand = np.empty(8)
    bx = np.empty(w, dtype=z.dtype)
    by = np.empty(w, dtype=z.dtype)
    bz = np.empty(w, dtype=z.dtype)
    # CRF stage: selected rows (slot r % 4; slot 4: outside), similarities, k_q of a row
    sel = np.full((5, 3, w + 2), np.nan, dtype=np.float32)
    sim = np.zeros((5, w + 2), dtype=np.float32)
    hsum = np.zeros((5, w), dtype=np.float32)
    kq = np.empty(w)
    idx, g, pos = scratch(w)
    pend = 0
    lag = 2 if crf else 1  # rows between computing a row and finishing one
    prev = -1
    for r in range(max(v0 - lag, 0), min(v1 + lag, h + lag)):
        if r < h:
            s = r % 3
            zr = zbuf[s]
            for u in range(w):
                zr[u + 1] = z[r, u]
            prev = row_normals(r, z, z, R, c, acol, bcol, fx, fy, cx, cy, deriv, smooth, False,
                               mode, True, nb_off, steps, prev, nbuf[s, 0, 1:w + 1],
                               nbuf[s, 1, 1:w + 1], nbuf[s, 2, 1:w + 1], flag, cand)
            kb = kbuf[s]
            kb[:] = np.inf
            if 0 < r < h - 1 and w > 2:
                mean_max_row(z[r - 1], z[r], z[r + 1], R[r - 1], R[r], R[r + 1], acol, bcol[r],
                             kc, use_max, True, True, kb[1:w + 1])
                kb[1] = np.inf
                kb[w] = np.inf
            if want_k and v0 <= r < v1:
                for u in range(w):
                    kout[r, u] = kb[u + 1]
        t = r - 1  # selection of row t (rows t - 1 .. t + 1 computed)
        if not crf:
            if v0 <= t < v1:
                select_ring_row(t, h, zbuf, nbuf, kbuf, acol, bcol, c, selfw, eps, bx, by, bz,
                                out)
            continue
        if max(v0 - 1, 0) <= t < h:  # into the float32 ring, as the separate path stores it
            st = sel[t % 4]
            select_ring_row(t, h, zbuf, nbuf, kbuf, acol, bcol, c, selfw, eps, st[0, 1:w + 1],
                            st[1, 1:w + 1], st[2, 1:w + 1], None)
            similarity_ring_row(t, h, zbuf, sa, sb, sim, hsum)
        q = r - 2  # CRF of row q (selected rows q - 1 .. q + 1 done)
        if v0 <= q < v1:
            kr = kbuf[q % 3]
            for u in range(w):
                kq[u] = np.float64(kr[u + 1]) * np.float64(z[q, u])
            ra, rm, rn = ring_slots(q, h)
            pend = crf_ring_row(q, ra, rm, rn, z, kq, sel, sim, hsum, sel[rm], True, sigma, lam,
                                idx, g, pos, pend, fx, fy, cx, cy, out)
    if crf:
        crf_flush(z, g, pos, pend, sigma, fx, fy, cx, cy, out)


def fused_3f2n_plus(z: np.ndarray, fx: float, fy: float, cx: float, cy: float, *, mode: int,
                    use_max: bool, self_weight: float, consistency: float | None,
                    want_curvature: bool = False, crf: int | None = None, sigma: float = 1.0,
                    lam: float = 0.01) -> tuple[np.ndarray, np.ndarray | None]:
    """3F2N (FD, 3x3, ``mode`` 0 median / 1 mean) + the metric mean (or max) curvature +
    the cross selection on prepared depth ``z`` (NaN at invalid pixels), as
    :func:`depthnormals.estimators._common.row_dtype` gives it; with ``crf`` (the similarity
    mode of :func:`depthnormals.ddm.crf.crf_step`: 0 none, 1 Kendall, 2 Kendall-prose), one
    pass of the CRF (weights ``sigma``, ``lam``) anchored at the selection, in the same pass.

    Returns the normals (H, W, 3) float32 and, with ``want_curvature`` (not with ``crf``),
    the curvature map (H, W) float64 (for a separate CRF), as :func:`curvature_map` gives it.
    """
    if crf is not None and want_curvature:
        raise ValueError("the fused CRF does not return the curvature")
    h, w = z.shape
    _, R, c, acol, bcol = row_setup(z, fx, fy, cx, cy, True)
    with np.errstate(over="ignore", under="ignore"):  # row_setup checked the range
        kc = row_constants(z.dtype, fx, fy)
    out = np.empty((h, w, 3), dtype=np.float32)
    kout = np.empty((h, w) if want_curvature else (1, 1), dtype=np.float64)
    sa, sb = sim_coefficients(0 if crf is None else crf)
    run_rows(_plus_rows, h, z, R, c, acol, bcol, float(fx), float(fy), float(cx), float(cy),
             mode, kc, use_max, float(self_weight),
             -1.0 if consistency is None else float(consistency), np.array([-0.5, 0.0, 0.5]),
             np.ones(1), NEIGHBOURS8, crf is not None, sa, sb, float(sigma), float(lam), out, kout,
             want_curvature)
    return out, (kout if want_curvature else None)
