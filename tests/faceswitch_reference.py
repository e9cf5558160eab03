"""A plain numpy reference of the face switch (depthnormals.ddm.faceswitch), written from the
rule as its module docstring states it: every cell's 3x3 points, its centroid and covariance,
and the eight candidate planes, one array at a time (no ring, no bounds, no pre-test)."""

from __future__ import annotations

import math

import numpy as np

DIRECTIONS = ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1))


def _shift(a: np.ndarray, dv: int, du: int) -> np.ndarray:
    """``out[v, u] = a[v + dv, u + du]`` (first two axes), NaN outside."""
    out = np.full_like(a, np.nan)
    h, w = a.shape[:2]
    out[max(-dv, 0):h + min(-dv, 0), max(-du, 0):w + min(-du, 0)] = \
        a[max(dv, 0):h + min(dv, 0), max(du, 0):w + min(du, 0)]
    return out


def reference_switch(z: np.ndarray, normals: np.ndarray, cam: tuple, span: int, *,
                     angle: float = 20.0, jump: float = 0.02,
                     margin: float = 0.7, decisions: bool = False) -> tuple[np.ndarray, ...]:
    """The switched normals (float32) and the switch mask of ``normals`` (H, W, 3) on ``z``
    (H, W, NaN invalid) of the grid ``cam = (fx, fy, cx, cy)``; with ``decisions``, also
    where a cell saw another face (every candidate plane of both faces read), ``log(other /
    same)`` and the angle (degrees) to the other face there, NaN elsewhere."""
    fx, fy, cx, cy = cam
    h, w = z.shape
    n = np.where(np.isfinite(z)[..., None], normals, np.nan).astype(np.float32)
    good = np.isfinite(z) & np.isfinite(n).all(-1)
    u = np.arange(w)[None, :]
    v = np.arange(h)[:, None]
    X = np.stack(((u - cx) / fx * z, (v - cy) / fy * z, z), -1)
    X = np.where(good[..., None], X, np.nan)
    ok = np.isfinite(X).all(-1)
    sums = np.zeros((h, w, 3))
    outer = np.zeros((h, w, 3, 3))
    cnt = np.zeros((h, w))
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            x = _shift(X, dv, du)
            m = np.isfinite(x).all(-1)
            x = np.where(m[..., None], x, 0.0)
            sums += x
            outer += x[..., :, None] * x[..., None, :]
            cnt += m
    with np.errstate(invalid="ignore", divide="ignore"):
        c = sums / cnt[..., None]
        cov = outer / cnt[..., None, None] - c[..., :, None] * c[..., None, :]
    smooth = good.copy()
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            with np.errstate(invalid="ignore"):
                smooth &= ~(np.abs(_shift(z, dv, du) - z) > jump * z)

    def msd(nq: np.ndarray, cq: np.ndarray) -> np.ndarray:
        nq = nq.astype(np.float64)
        d = np.einsum("...i,...i", nq, c - cq)
        return np.einsum("...i,...ij,...j", nq, cov, nq) + d * d

    cos_min = np.float32(math.cos(math.radians(angle)))
    same = msd(n, c)
    other = np.full((h, w), np.inf)
    best = n.copy()
    for dv, du in DIRECTIONS:
        nq = _shift(n, dv * span, du * span)
        cq = _shift(c, dv * span, du * span)
        m = msd(nq, cq)
        dot = (n * nq).sum(-1, dtype=np.float32)
        with np.errstate(invalid="ignore"):
            differ = dot < cos_min
            fin = np.isfinite(m) & np.isfinite(dot)
            same = np.where(fin & ~differ & (m < same), m, same)
            take = fin & differ & (m < other)
        other = np.where(take, m, other)
        best = np.where(take[..., None], nq, best)
    switch = smooth & ok & (other < margin * same)
    out = np.where(switch[..., None], best, normals).astype(np.float32)
    if not decisions:
        return out, switch
    seen = smooth & ok & np.isfinite(other)
    with np.errstate(invalid="ignore", divide="ignore"):
        log = np.log(np.maximum(other, 1e-300) / np.maximum(same, 1e-300))
        cosine = np.clip((n.astype(np.float64) * best).sum(-1), -1.0, 1.0)
    return (out, switch, np.where(seen, log, np.nan),
            np.where(seen, np.degrees(np.arccos(cosine)), np.nan))
