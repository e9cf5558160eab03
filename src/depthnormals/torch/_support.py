"""The measured support of the default 3F2N+ in torch: the adjacent-window pairs of
:func:`depthnormals.ddm.support.support_profile`, fitted on the device for every frame and
radius at once; the statistics (medians, the radius, the depth exponent) are the numba
library's own on the few hundred pair rows per radius
(:func:`depthnormals.ddm.support.profiles_from_pair_tables`: the medians of every frame
together, then the choices frame by frame, as :func:`~depthnormals.ddm.support.profile_from_pairs`
takes them), so both take the same decisions. No gradients (the profile only chooses).
"""

from __future__ import annotations

import torch

from ..ddm.noise import TILE
from ..ddm.support import (
    MIN_VALID,
    RADII,
    SupportProfile,
    profiles_from_pair_tables,
    sample_every,
    sample_step,
)
from ._boxfit import _solve

__all__ = ["support_profiles"]


def _fit(zf: torch.Tensor, centres: torch.Tensor, r: int, every: int, w: int, cam):
    """Least-squares planes of ``1 / z`` over the windows of radius ``r`` (read on every
    ``every``-th row and column) centred at ``centres`` (N, 2) (v, u), all inside the image,
    of every frame of ``zf`` (B, H * W) float64, NaN at invalid pixels: (residual variance in
    footprints^2, unit normal (B, N, 3)), NaN where no fit (``ddm.support._fit``)."""
    fx, fy, cx, cy = cam  # (B, 1) each
    off = torch.arange(-r, r + 1, every, device=zf.device)
    dv, du = torch.meshgrid(off, off, indexing="ij")
    dv, du = dv.reshape(-1), du.reshape(-1)
    idx = (centres[:, 0:1] + dv) * w + centres[:, 1:2] + du  # (N, k)
    zz = zf[:, idx]  # (B, N, k)
    ok = ~torch.isnan(zz)
    x = torch.where(ok, 1.0 / torch.where(ok, zz, 1.0), 0.0)
    m = ok.to(zf.dtype)
    fu, fv = du.to(zf.dtype), dv.to(zf.dtype)
    n = m.sum(-1)
    sums = (n, (m * fu).sum(-1), (m * fv).sum(-1), (m * fu * fu).sum(-1), (m * fu * fv).sum(-1),
            (m * fv * fv).sum(-1), x.sum(-1), (x * fu).sum(-1), (x * fv).sum(-1), (x * x).sum(-1))
    pa, pb, c, rss, good = _solve(*sums)
    good = good & (n >= MIN_VALID * ((2 * r) // every + 1) ** 2) & (c > 0.0)
    cv = centres[:, 0].to(zf.dtype)
    cu = centres[:, 1].to(zf.dtype)
    nx = fx * pa
    ny = fy * pb
    nz = c - pa * (cu - cx) - pb * (cv - cy)
    s = 1.0 / torch.sqrt(nx * nx + ny * ny + nz * nz)
    res = rss * fx * fx / ((n - 3.0) * c * c)
    nan = torch.full_like(res, float("nan"))
    normal = torch.stack((nx * s, ny * s, nz * s), -1)
    return torch.where(good, res, nan), torch.where(good[..., None], normal, nan[..., None])


def _pairs(zf: torch.Tensor, h: int, w: int, r: int, cam) -> tuple[torch.Tensor, torch.Tensor]:
    """The rows of ``ddm.support._pairs`` for every frame: (B, P, 4) (angle in degrees, the
    larger residual variance, the first window's depth, the index of its noise tile) and (B,
    P) where a row exists."""
    step = sample_step(h, w, r)
    every = sample_every(r)
    d = 2 * r + 1
    dev = zf.device
    vs = torch.tensor(list(range(r, h - r, step)), dtype=torch.long, device=dev)
    us = torch.tensor(list(range(r, w - r, step)), dtype=torch.long, device=dev)
    if vs.numel() == 0 or us.numel() == 0:  # the image is smaller than one window
        return zf.new_zeros((zf.shape[0], 0, 4)), torch.zeros((zf.shape[0], 0), dtype=torch.bool, device=dev)
    gv, gu = torch.meshgrid(vs, us, indexing="ij")
    c0 = torch.stack((gv.reshape(-1), gu.reshape(-1)), 1)
    n = c0.shape[0]
    shifted = [c0 + torch.tensor([d * o, d * (1 - o)], device=dev) for o in range(2)]
    insides = [(c1[:, 0] < h - r) & (c1[:, 1] < w - r) for c1 in shifted]
    # the window, its neighbour to the right and the one below, in one call (a third of the
    # kernel launches: eager on a GPU this step was launch-bound)
    cs = torch.cat([c0] + [torch.where(i[:, None], c1, c0) for c1, i in zip(shifted, insides, strict=True)])
    s_all, n_all = _fit(zf, cs, r, every, w, cam)
    s0, n0 = s_all[:, :n], n_all[:, :n]
    zc = zf[:, c0[:, 0] * w + c0[:, 1]]
    tw = (w + TILE - 1) // TILE
    tile = ((c0[:, 0] // TILE) * tw + c0[:, 1] // TILE).to(zf.dtype)[None]
    first = ~torch.isnan(zc) & ~torch.isnan(s0)
    rows, oks = [], []
    for o in range(2):
        inside = insides[o]
        s1, n1 = s_all[:, n * (o + 1):n * (o + 2)], n_all[:, n * (o + 1):n * (o + 2)]
        ok = first & inside & ~torch.isnan(s1)
        dot = torch.clamp((n0 * n1).sum(-1), -1.0, 1.0)
        ang = torch.rad2deg(torch.acos(torch.where(ok, dot, 1.0)))
        rows.append(torch.stack((ang, torch.maximum(s0, s1), zc, tile.expand_as(zc)), -1))
        oks.append(ok)
    return torch.cat(rows, 1), torch.cat(oks, 1)


def support_profiles(z: torch.Tensor, cam, sigmas: list[float],
                     tiles: torch.Tensor | None = None) -> list[SupportProfile]:
    """The support profile of every frame of prepared depth ``z`` (B, H, W) float64 (NaN at
    invalid pixels), ``cam`` ``(fx, fy, cx, cy)`` (B or 1, 1, 1), ``sigmas`` the frames'
    noise levels, ``tiles`` their tile levels (B, TY, TX), for the profiles' ``local``
    excess: :func:`depthnormals.ddm.support.support_profile` per frame, the pairs fitted
    here for every radius (one host transfer)."""
    b, h, w = z.shape
    with torch.no_grad():
        zf = z.reshape(b, -1)
        c = tuple(q.reshape(-1, 1).to(z.dtype).expand(b, 1) for q in cam)
        per_radius = [_pairs(zf, h, w, r, c) for r in RADII]
        host = [(rows.cpu().numpy(), ok.cpu().numpy()) for rows, ok in per_radius]
    lev = None if tiles is None else tiles.cpu().numpy()
    return profiles_from_pair_tables(host, sigmas, tiles=lev)

