"""Compiled fast paths of the synthetic generator; each has a readable numpy reference it is
tested against (tests/test_synth_ssn.py).

- :func:`discontinuity_mask`: :func:`depthnormals.synth.noise.discontinuity_mask` (the
  reference: nine shifted full-image comparisons), one pass over the image instead.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["discontinuity_mask"]


@nb.njit(cache=True, nogil=True)
def _mask_kernel(z, jump, out_mask):  # pragma: no cover - compiled
    """Reads depth ``z`` (H, W) float64; writes ``out_mask`` (H, W) bool.

    A pixel is marked when a pixel of its 3x3 neighbourhood (indices clamped at the border,
    as edge padding) differs in validity (finite and > 0), or when ``|z_n - z| > jump * z``
    (``jump * 1`` for an invalid centre), with ``z_n = 0`` for an invalid neighbour and the
    centre's raw value (a NaN centre compares False), exactly as the reference computes it.
    """
    h, w = z.shape
    for v in range(h):
        for u in range(w):
            zc = z[v, u]
            okc = np.isfinite(zc) and zc > 0.0
            tol = jump * (zc if okc else 1.0)
            hit = False
            for dv in range(-1, 2):
                vv = min(max(v + dv, 0), h - 1)
                for du in range(-1, 2):
                    uu = min(max(u + du, 0), w - 1)
                    zn = z[vv, uu]
                    okn = np.isfinite(zn) and zn > 0.0
                    if okn != okc or abs((zn if okn else 0.0) - zc) > tol:
                        hit = True
            out_mask[v, u] = hit


def discontinuity_mask(depth: np.ndarray, *, jump: float = 0.02) -> np.ndarray:
    """Compiled :func:`depthnormals.synth.noise.discontinuity_mask` (the same bool (H, W))."""
    z = np.ascontiguousarray(depth, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError(f"depth must be (H, W); got shape {z.shape}")
    out = np.empty(z.shape, dtype=bool)
    _mask_kernel(z, float(jump), out)
    return out
