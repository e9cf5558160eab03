"""3F2N+ in one pass: 3F2N, depth curvature, the cross selection and the CRF fused row by row.

``estimate_normals(depth, K, method="3f2n+")`` lands here (:func:`fused_plus`) whenever the
options have a fused form; otherwise 3F2N is followed by
:func:`depthnormals.ddm.discontinuity_discrimination`.

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

from collections import namedtuple
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..kernels.depth import Pinhole, prepare, row_dtype
from ..kernels.threefn_rows import NEIGHBOURS8, Filters, RowScratch, row_normals, row_setup
from ._module import _SIM_MODES, ModuleOptions, _refine
from .auto import auto_fused
from .crf_ring import crf_flush, crf_ring_row, ring_slots, scratch, sim_coefficients, similarity_ring_row
from .curvature import mean_max_row, row_constants
from .selection import select_ring_row

__all__ = ["PlusCrf", "PlusSelection", "fused_3f2n_plus", "fused_plus"]

#: The selection stage of the fused pass: curvature constants
#: (:func:`depthnormals.ddm.curvature.row_constants`), max instead of mean, the self weight,
#: the consistency margin (< 0: off).
PlusSelection = namedtuple("PlusSelection", ["kc", "use_max", "self_weight", "eps"])
#: The CRF stage of the fused pass: on/off, similarity ``a + b tau`` coefficients
#: (:func:`depthnormals.ddm.crf_ring.sim_coefficients`), ``sigma``, ``lam``.
PlusCrf = namedtuple("PlusCrf", ["on", "sa", "sb", "sigma", "lam"])


@nb.njit(cache=True, error_model="numpy", inline="always")
def _plus_body(v0, v1, rows, cam, filters, select, crf_args, out, kout, want_k, crf, consistent):
    """3F2N+ of rows [v0, v1) into ``out`` (H, W, 3) float32 and, with ``want_k``, the
    curvature into ``kout`` (H, W) float64.

    ``rows``: :data:`RowInputs` (``D`` is ``z``: the FD pass); ``cam``: :class:`Pinhole`;
    ``filters``: :data:`Filters` of 3F2N; ``select``: :data:`PlusSelection`; ``crf_args``:
    :data:`PlusCrf`. ``crf`` (the CRF stage) and ``consistent`` (the consistency test) are
    compile-time constants of the four kernels below, so a call compiles only the stages it
    runs (the first run of the default ``3f2n+`` compiles no CRF).
    """
    z, _, R, c, acol, bcol = rows
    kc, use_max, selfw, eps = select
    _, sa, sb, sigma, lam = crf_args
    h, w = z.shape
    nbuf = np.full((4, 3, w + 2), np.nan, dtype=z.dtype)  # rows r % 3; slot 3: outside image
    kbuf = np.full((4, w + 2), np.inf, dtype=z.dtype)
    zbuf = np.full((4, w + 2), np.nan, dtype=z.dtype)
    row_work = RowScratch(np.empty((7, w), dtype=z.dtype), np.empty(w, dtype=np.bool_),
                          np.empty(8))
    bx = np.empty(w, dtype=z.dtype)
    by = np.empty(w, dtype=z.dtype)
    bz = np.empty(w, dtype=z.dtype)
    if crf:  # CRF stage: selected rows (slot r % 4; slot 4: outside), similarities, k_q of a
        # row (under the constant flag: the first run without the CRF compiles none of it)
        sel = np.full((5, 3, w + 2), np.nan, dtype=np.float32)
        sim = np.zeros((5, w + 2), dtype=np.float32)
        hsum = np.zeros((5, w), dtype=np.float32)
        kq = np.empty(w)
        work = scratch(w)
    pend = 0
    lag = 2 if crf else 1  # rows between computing a row and finishing one
    prev = np.int64(-1)  # not the literal -1: row_normals would compile twice
    for r in range(max(v0 - lag, 0), min(v1 + lag, h + lag)):
        if r < h:
            s = r % 3
            zr = zbuf[s]
            for u in range(w):
                zr[u + 1] = z[r, u]
            prev = row_normals(r, rows, cam, filters, row_work, prev,
                               (nbuf[s, 0, 1:w + 1], nbuf[s, 1, 1:w + 1], nbuf[s, 2, 1:w + 1]))
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
                select_ring_row(t, h, (zbuf, nbuf, kbuf), acol, bcol, c, selfw, eps, consistent,
                                (bx, by, bz))
                for u in range(w):
                    out[t, u, 0] = bx[u]
                    out[t, u, 1] = by[u]
                    out[t, u, 2] = bz[u]
            continue
        if max(v0 - 1, 0) <= t < h:  # into the float32 ring, as the separate path stores it
            st = sel[t % 4]
            select_ring_row(t, h, (zbuf, nbuf, kbuf), acol, bcol, c, selfw, eps, consistent,
                            (st[0, 1:w + 1], st[1, 1:w + 1], st[2, 1:w + 1]))
            similarity_ring_row(t, h, zbuf, sa, sb, sim, hsum)
        q = r - 2  # CRF of row q (selected rows q - 1 .. q + 1 done)
        if v0 <= q < v1:
            kr = kbuf[q % 3]
            for u in range(w):
                kq[u] = np.float64(kr[u + 1]) * np.float64(z[q, u])
            slots = ring_slots(q, h)
            pend = crf_ring_row(q, slots, z, kq, (sel, sim, hsum), sel[slots[1]], True,
                                (sigma, lam), work, pend, cam, out)
    if crf:
        crf_flush(z, work, pend, sigma, cam, out)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _plus_rows_select(v0, v1, rows, cam, filters, select, crf_args, out, kout, want_k):
    """:func:`_plus_body` without the CRF, without the consistency test."""
    _plus_body(v0, v1, rows, cam, filters, select, crf_args, out, kout, want_k, False, False)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _plus_rows_select_consistent(v0, v1, rows, cam, filters, select, crf_args, out, kout, want_k):
    """:func:`_plus_body` without the CRF, with the consistency test (the default 3f2n+)."""
    _plus_body(v0, v1, rows, cam, filters, select, crf_args, out, kout, want_k, False, True)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _plus_rows_crf(v0, v1, rows, cam, filters, select, crf_args, out, kout, want_k):
    """:func:`_plus_body` with the CRF, without the consistency test."""
    _plus_body(v0, v1, rows, cam, filters, select, crf_args, out, kout, want_k, True, False)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _plus_rows_crf_consistent(v0, v1, rows, cam, filters, select, crf_args, out, kout, want_k):
    """:func:`_plus_body` with the CRF and the consistency test."""
    _plus_body(v0, v1, rows, cam, filters, select, crf_args, out, kout, want_k, True, True)


#: The fused kernels by (CRF, consistency test).
_PLUS_ROWS = {(False, False): _plus_rows_select, (False, True): _plus_rows_select_consistent,
              (True, False): _plus_rows_crf, (True, True): _plus_rows_crf_consistent}


def fused_3f2n_plus(z: np.ndarray, fx: float, fy: float, cx: float, cy: float, *, mode: int,
                    use_max: bool, self_weight: float, consistency: float | None,
                    want_curvature: bool = False, crf: int | None = None, sigma: float = 1.0,
                    lam: float = 0.01) -> tuple[np.ndarray, np.ndarray | None]:
    """3F2N (FD, 3x3, ``mode`` 0 median / 1 mean) + the metric mean (or max) curvature +
    the cross selection on prepared depth ``z`` (NaN at invalid pixels), as
    :func:`depthnormals.kernels.depth.row_dtype` gives it; with ``crf`` (the similarity
    mode of :func:`depthnormals.ddm.crf.crf_step`: 0 none, 1 Kendall, 2 Kendall-prose), one
    pass of the CRF (weights ``sigma``, ``lam``) anchored at the selection, in the same pass.

    Returns the normals (H, W, 3) float32 and, with ``want_curvature`` (not with ``crf``),
    the curvature map (H, W) float64 (for a separate CRF), as :func:`curvature_map` gives it.
    """
    if crf is not None and want_curvature:
        raise ValueError("the fused CRF does not return the curvature")
    h, w = z.shape
    rows = row_setup(z, fx, fy, cx, cy, True)
    with np.errstate(over="ignore", under="ignore"):  # row_setup checked the range
        kc = row_constants(z.dtype, fx, fy)
    out = np.empty((h, w, 3), dtype=np.float32)
    kout = np.empty((h, w) if want_curvature else (1, 1), dtype=np.float64)
    sa, sb = sim_coefficients(0 if crf is None else crf)
    filters = Filters(np.array([-0.5, 0.0, 0.5]), np.ones(1), False, mode, True, NEIGHBOURS8)
    select = PlusSelection(kc, use_max, float(self_weight),
                           -1.0 if consistency is None else float(consistency))
    crf_args = PlusCrf(crf is not None, sa, sb, float(sigma), float(lam))
    kernel = _PLUS_ROWS[(crf is not None, consistency is not None)]
    run_rows(kernel, h, rows, Pinhole(float(fx), float(fy), float(cx), float(cy)), filters,
             select, crf_args, out, kout, want_curvature)
    return out, (kout if want_curvature else None)


def _is_str(value: Any, *allowed: str) -> bool:
    return isinstance(value, str) and value in allowed


def fused_plus(depth: Any, K: Any, depth_scale: float | None, estimator_options: dict[str, Any],
               module_options: dict[str, Any]) -> np.ndarray | None:
    """``"3f2n+"`` in one fused pass where the options have a fused form (3F2N with its FD
    kernel and the metric mean or max curvature with the cross selection); None otherwise.

    Same results as the estimator followed by :func:`discontinuity_discrimination`
    (``tests/test_ddm_fused.py``), about twice as fast: the 3F2N normals and the curvature
    never leave the cache.
    """
    if set(estimator_options) - {"kernel", "kernel_size", "aggregate"}:
        return None
    ks = estimator_options.get("kernel_size", 3)
    agg = estimator_options.get("aggregate", "median")
    if not (_is_str(estimator_options.get("kernel", "fd"), "fd") and type(ks) is int
            and ks == 3 and _is_str(agg, "median", "mean")):
        return None
    o = ModuleOptions(**module_options).normalised()
    if o["selection"] in ("auto", "box-fit", "planes"):  # noise-aware (ddm/auto.py)
        return auto_fused(fused_plus, depth, K, depth_scale, estimator_options, module_options, o)
    if not (o["curvature"] in ("mean", "max") and o["derivatives"] == "inverse-depth"
            and o["slope"] == "min" and o["footprint"] == "pixel"
            and o["selection"] == "curvature" and o["neighbourhood"] == "cross"):
        return None
    z, cam = prepare(depth, K, depth_scale)
    z = row_dtype(z, cam.fx, cam.fy, cam.cx, cam.cy)
    agg_mode = ("median", "mean").index(agg)
    sim_mode = _SIM_MODES[o["correlation"]]
    if o["crf"] and o["iterations"] == 1 and sim_mode != 3:  # the CRF in the same pass
        out, _ = fused_3f2n_plus(z, cam.fx, cam.fy, cam.cx, cam.cy, mode=agg_mode,
                                 use_max=o["curvature"] == "max", self_weight=o["self_weight"],
                                 consistency=o["consistency"], crf=sim_mode, sigma=o["sigma"],
                                 lam=o["lam"])
        return out
    n0, k = fused_3f2n_plus(z, cam.fx, cam.fy, cam.cx, cam.cy, mode=agg_mode,
                            use_max=o["curvature"] == "max", self_weight=o["self_weight"],
                            consistency=o["consistency"], want_curvature=o["crf"])
    return _refine(z, cam.fx, cam.fy, cam.cx, cam.cy, None, n0, k, o)
