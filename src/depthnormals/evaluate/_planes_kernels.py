"""Compiled image-region helpers of the plane reference (:mod:`._planes`).

Serial ``nogil`` kernels: 8-connected component labelling of a mask (one breadth-first flood
fill per component over an explicit queue), the chessboard distance to the outside of a label
region and to a mask (two raster passes each), and the point-to-plane ratio / inlier mask of
a plane over the back-projected image (one pass, instead of NumPy's temporaries). Each has a
short NumPy reference in ``tests/test_plane_reference.py`` that it is checked against.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["chessboard_inside", "chessboard_to", "label_8connected", "plane_inliers", "plane_ratio"]


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


@nb.njit(cache=True, nogil=True)
def plane_ratio(pts: np.ndarray, thr: np.ndarray, plane: np.ndarray, out_ratio: np.ndarray) -> None:
    """``|n . X + d| / threshold`` per pixel.

    Reads ``pts`` (H, W, 3) float64 (NaN = no point), ``thr`` (H, W) float64, ``plane``
    ``(nx, ny, nz, d)``; writes ``out_ratio`` (H, W) float64 (``inf`` where there is no point).
    """
    h, w = thr.shape
    nx, ny, nz, d = plane[0], plane[1], plane[2], plane[3]
    for v in range(h):
        for u in range(w):
            r = abs(pts[v, u, 0] * nx + pts[v, u, 1] * ny + pts[v, u, 2] * nz + d) / thr[v, u]
            out_ratio[v, u] = r if r == r else np.inf


@nb.njit(cache=True, nogil=True)
def plane_inliers(pts: np.ndarray, thr: np.ndarray, allowed: np.ndarray, plane: np.ndarray,
                  out_mask: np.ndarray) -> None:
    """``allowed & (|n . X + d| <= threshold)`` per pixel (see :func:`plane_ratio`).

    Writes ``out_mask`` (H, W) bool.
    """
    h, w = thr.shape
    nx, ny, nz, d = plane[0], plane[1], plane[2], plane[3]
    for v in range(h):
        for u in range(w):
            if allowed[v, u]:
                r = abs(pts[v, u, 0] * nx + pts[v, u, 1] * ny + pts[v, u, 2] * nz + d)
                out_mask[v, u] = r <= thr[v, u]
            else:
                out_mask[v, u] = False


@nb.njit(cache=True, nogil=True)
def chessboard_to(mask: np.ndarray, out_dist: np.ndarray) -> None:
    """Chessboard distance from each pixel to the nearest pixel of ``mask`` (0 on it).

    Reads ``mask`` (H, W) bool; writes ``out_dist`` (H, W) int32 (``H + W`` when the mask is
    empty). Two chamfer passes with unit weights (exact for the chessboard metric); ``dist
    <= r`` is the chessboard dilation of the mask by ``r``.
    """
    h, w = mask.shape
    big = h + w
    for v in range(h):
        for u in range(w):
            if mask[v, u]:
                out_dist[v, u] = 0
                continue
            d = big
            if v > 0:
                d = min(d, out_dist[v - 1, u] + 1)
                if u > 0:
                    d = min(d, out_dist[v - 1, u - 1] + 1)
                if u < w - 1:
                    d = min(d, out_dist[v - 1, u + 1] + 1)
            if u > 0:
                d = min(d, out_dist[v, u - 1] + 1)
            out_dist[v, u] = d
    for v in range(h - 1, -1, -1):
        for u in range(w - 1, -1, -1):
            d = out_dist[v, u]
            if d == 0:
                continue
            if v < h - 1:
                d = min(d, out_dist[v + 1, u] + 1)
                if u > 0:
                    d = min(d, out_dist[v + 1, u - 1] + 1)
                if u < w - 1:
                    d = min(d, out_dist[v + 1, u + 1] + 1)
            if u < w - 1:
                d = min(d, out_dist[v, u + 1] + 1)
            out_dist[v, u] = min(d, big)
