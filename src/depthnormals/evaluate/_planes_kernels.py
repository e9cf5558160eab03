"""Compiled image-region helpers of the plane reference (:mod:`._planes`).

Two kernels, both serial and ``nogil``: 8-connected component labelling of a mask (one
breadth-first flood fill per component over an explicit queue) and the chessboard distance
to the nearest pixel outside a label region (two raster passes). Each has a short NumPy
reference in ``tests/test_plane_reference.py`` that it is checked against.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["chessboard_inside", "label_8connected"]


@nb.njit(cache=True, nogil=True)
def label_8connected(mask: np.ndarray, out_labels: np.ndarray) -> np.ndarray:
    """Label the 8-connected components of ``mask``.

    Reads ``mask`` (H, W) bool; writes ``out_labels`` (H, W) int32: ``-1`` outside the mask,
    ``0 .. n-1`` per component in raster order of each component's first pixel. Returns the
    component sizes (n,) int64.
    """
    h, w = mask.shape
    out_labels[:, :] = -1
    queue = np.empty(h * w, np.int64)
    sizes = np.empty(h * w // 2 + 1, np.int64)
    n = 0
    for v0 in range(h):
        for u0 in range(w):
            if not mask[v0, u0] or out_labels[v0, u0] >= 0:
                continue
            out_labels[v0, u0] = n
            head = 0
            tail = 1
            queue[0] = v0 * w + u0
            while head < tail:
                p = queue[head]
                head += 1
                v = p // w
                u = p - v * w
                for dv in range(-1, 2):
                    vv = v + dv
                    if vv < 0 or vv >= h:
                        continue
                    for du in range(-1, 2):
                        uu = u + du
                        if uu < 0 or uu >= w:
                            continue
                        if mask[vv, uu] and out_labels[vv, uu] < 0:
                            out_labels[vv, uu] = n
                            queue[tail] = vv * w + uu
                            tail += 1
            if n >= sizes.size:  # pragma: no cover - at most h*w/2+1 8-components exist
                grown = np.empty(sizes.size * 2, np.int64)
                grown[:n] = sizes[:n]
                sizes = grown
            sizes[n] = tail
            n += 1
    return sizes[:n].copy()


@nb.njit(cache=True, nogil=True)
def chessboard_inside(labels: np.ndarray, out_dist: np.ndarray) -> None:
    """Chessboard (Chebyshev) distance from each labelled pixel to its region's outside.

    Reads ``labels`` (H, W) int32 (``< 0`` = no region); writes ``out_dist`` (H, W) int32:
    0 where ``labels < 0``; else the smallest ``max(|dv|, |du|)`` to a pixel of another label
    (or of none), counting the pixels beyond the image border as outside. So a region's
    boundary pixels get 1. Two passes of the classic chamfer recursion with unit weights
    (exact for the chessboard metric).
    """
    h, w = labels.shape
    big = h + w + 2
    for v in range(h):
        for u in range(w):
            lab = labels[v, u]
            if lab < 0:
                out_dist[v, u] = 0
                continue
            d = big
            for dv, du in ((-1, -1), (-1, 0), (-1, 1), (0, -1)):
                vv = v + dv
                uu = u + du
                if vv < 0 or uu < 0 or uu >= w:
                    d = 1
                    break
                if labels[vv, uu] != lab:
                    d = 1
                    break
                cand = out_dist[vv, uu] + 1
                if cand < d:
                    d = cand
            out_dist[v, u] = d
    for v in range(h - 1, -1, -1):
        for u in range(w - 1, -1, -1):
            lab = labels[v, u]
            if lab < 0:
                continue
            d = out_dist[v, u]
            for dv, du in ((1, 1), (1, 0), (1, -1), (0, 1)):
                vv = v + dv
                uu = u + du
                if vv >= h or uu >= w or uu < 0:
                    d = 1
                    break
                if labels[vv, uu] != lab:
                    d = 1
                    break
                cand = out_dist[vv, uu] + 1
                if cand < d:
                    d = cand
            out_dist[v, u] = d
