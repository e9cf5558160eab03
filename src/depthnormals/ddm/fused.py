"""3F2N+ in one pass: 3F2N, depth curvature and the cross selection fused row by row.

The separate stages of :func:`depthnormals.ddm.discontinuity_discrimination` write and re-read
two full-size maps (the 3F2N normals, interleaved, and the curvature) and select with strided
loads. Here every row of 3F2N normals and of curvature goes into small planar ring buffers
(three rows, padded by one NaN/inf column each side) and row ``v - 1`` is selected as soon as
row ``v`` exists, so all of it stays in L1 and every inner loop vectorises (8 lanes for
float32 depth). Same kernels, same arithmetic as the separate stages: the results are equal
(``tests/test_ddm_fused.py``).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..estimators._common import NEIGHBOURS8
from ..estimators.threefn import row_normals, row_setup
from .crf import select_ring_row
from .curvature import mean_max_row, row_constants

__all__ = ["fused_3f2n_plus"]


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _plus_rows(v0, v1, z, R, c, acol, bcol, fx, fy, cx, cy, mode, kc, use_max, selfw, eps,
               deriv, smooth, nb_off, out, kout, want_k):
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
    prev = -1
    for r in range(max(v0 - 1, 0), min(v1 + 1, h) + 1):
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
        if v0 <= r - 1 < v1:
            select_ring_row(r - 1, h, zbuf, nbuf, kbuf, acol, bcol, c, selfw, eps, bx, by, bz,
                            out)


def fused_3f2n_plus(z: np.ndarray, fx: float, fy: float, cx: float, cy: float, *, mode: int,
                    use_max: bool, self_weight: float, consistency: float | None,
                    want_curvature: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """3F2N (FD, 3x3, ``mode`` 0 median / 1 mean) + the metric mean (or max) curvature +
    the cross selection on prepared depth ``z`` (NaN at invalid pixels), as
    :func:`depthnormals.estimators._common.row_dtype` gives it.

    Returns the selected normals (H, W, 3) float32 and, with ``want_curvature``, the
    curvature map (H, W) float64 (for the CRF), as :func:`curvature_map` gives it.
    """
    h, w = z.shape
    _, R, c, acol, bcol = row_setup(z, fx, fy, cx, cy, True)
    with np.errstate(over="ignore", under="ignore"):  # row_setup checked the range
        kc = row_constants(z.dtype, fx, fy)
    out = np.empty((h, w, 3), dtype=np.float32)
    kout = np.empty((h, w) if want_curvature else (1, 1), dtype=np.float64)
    run_rows(_plus_rows, h, z, R, c, acol, bcol, float(fx), float(fy), float(cx), float(cy),
             mode, kc, use_max, float(self_weight),
             -1.0 if consistency is None else float(consistency), np.array([-0.5, 0.0, 0.5]), np.ones(1),
             NEIGHBOURS8, out, kout, want_curvature)
    return out, (kout if want_curvature else None)
