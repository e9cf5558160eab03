"""The measured support of the default 3F2N+ in torch: the adjacent-window pairs of
:func:`depthnormals.ddm.support.support_profile`, fitted on the device for every frame and
radius at once (the radii of a group of :data:`GROUPS` in one call, the sampled windows'
places laid out once per image size and device); the statistics (medians, the radius, the
depth exponent) are the numba library's own on the few hundred pair rows per radius
(:func:`depthnormals.ddm.support.profiles_from_pair_tables`: the medians of every frame
together, then the choices frame by frame, as :func:`~depthnormals.ddm.support.profile_from_pairs`
takes them), so both take the same decisions. No gradients (the profile only chooses).
"""

from __future__ import annotations

import numpy as np
import torch

from ..ddm.noise import TILE
from ..ddm.support import (
    MIN_VALID,
    SupportProfile,
    profiles_from_pair_tables,
    sample_every,
    sample_step,
)
from ._boxfit import _solve

__all__ = ["support_profiles"]


#: Radii whose sampled windows are fitted in one call, each window's offsets padded to the
#: group's largest: few kernel launches (eager on a GPU this step was launch-bound, eight
#: calls of ~190 operations), and two groups keep the padded reads to 1.5x the windows' own.
GROUPS = ((1, 2, 3, 4, 6, 8), (11, 16))


def _layout(h: int, w: int, radii: tuple[int, ...]) -> dict[str, np.ndarray]:
    """Where the sampled windows of ``radii`` on an ``h x w`` image read (the grid of
    ``ddm.support._pairs``), as flat host arrays. Per fitted window (radius by radius: the
    sampled windows, their neighbours to the right, those below; a neighbour past the image
    is the window itself): ``idx`` the pixels of its offsets (padded with 0 past ``k``),
    ``du``, ``dv`` the offsets (0 past ``k``), ``k`` how many, ``least`` the valid count a fit
    needs, ``cv``, ``cu`` its centre. Per pair row (radius by radius, right neighbours then
    those below): ``first`` and ``second`` its windows in that list, ``inside`` whether the
    neighbour lies in the image, ``centre`` the first window's centre pixel, ``tile`` its
    noise tile; ``counts`` the rows of each radius."""
    kmax = max(((2 * r) // sample_every(r) + 1) ** 2 for r in radii)
    tw = (w + TILE - 1) // TILE
    parts: dict[str, list[np.ndarray]] = {k: [] for k in (
        "idx", "du", "dv", "k", "least", "cv", "cu", "first", "second", "inside", "centre", "tile")}
    counts, base = [], 0
    for r in radii:
        step, every, d = sample_step(h, w, r), sample_every(r), 2 * r + 1
        gv, gu = (a.reshape(-1) for a in np.meshgrid(np.arange(r, h - r, step),
                                                     np.arange(r, w - r, step), indexing="ij"))
        n = gv.size
        counts.append(2 * n)
        off = np.arange(-r, r + 1, every)
        dv, du = (a.reshape(-1) for a in np.meshgrid(off, off, indexing="ij"))
        k = du.size
        ins = [(gv + d * o < h - r) & (gu + d * (1 - o) < w - r) for o in range(2)]
        cv = np.concatenate([gv] + [np.where(i, gv + d * o, gv) for o, i in enumerate(ins)])
        cu = np.concatenate([gu] + [np.where(i, gu + d * (1 - o), gu) for o, i in enumerate(ins)])
        for name, val in (("idx", (cv[:, None] + dv) * w + cu[:, None] + du),
                          ("du", np.broadcast_to(du, (3 * n, k))),
                          ("dv", np.broadcast_to(dv, (3 * n, k)))):
            a = np.zeros((3 * n, kmax), np.int64)
            a[:, :k] = val
            parts[name].append(a)
        parts["k"].append(np.full(3 * n, k))
        parts["cv"].append(cv)
        parts["cu"].append(cu)
        parts["least"].append(np.full(3 * n, MIN_VALID * ((2 * r) // every + 1) ** 2))
        for o in range(2):
            parts["first"].append(base + np.arange(n))
            parts["second"].append(base + n * (o + 1) + np.arange(n))
            parts["inside"].append(ins[o])
            parts["centre"].append(gv * w + gu)
            parts["tile"].append((gv // TILE) * tw + gu // TILE)
        base += 3 * n
    out = {name: np.concatenate(v) for name, v in parts.items()}
    out["counts"] = np.array(counts, np.int64)
    return out


_ON_DEVICE: dict[tuple, tuple[dict[str, torch.Tensor], tuple[int, ...]]] = {}


def _device_layout(h: int, w: int, radii: tuple[int, ...], dev: torch.device,
                   dtype: torch.dtype) -> tuple[dict[str, torch.Tensor], tuple[int, ...]]:
    """:func:`_layout` on ``dev`` (offsets in ``dtype``), kept per device, and where each
    radius's pair rows end (but the last)."""
    key = (h, w, radii, str(dev), dtype)
    got = _ON_DEVICE.get(key)
    if got is None:
        host = _layout(h, w, radii)
        lay = {name: torch.from_numpy(np.ascontiguousarray(a)).to(dev) for name, a in host.items()}
        for name in ("du", "dv", "least", "cv", "cu"):
            lay[name] = lay[name].to(dtype)
        lay["pad"] = torch.arange(host["idx"].shape[1], device=dev) < lay["k"][:, None]
        if len(_ON_DEVICE) > 32:
            _ON_DEVICE.clear()
        got = _ON_DEVICE[key] = (lay, tuple(int(c) for c in np.cumsum(host["counts"])[:-1]))
    return got


def _fit(zf: torch.Tensor, lay: dict[str, torch.Tensor], cam):
    """Least-squares planes of ``1 / z`` over the windows of ``lay`` (:func:`_layout`) of
    every frame of ``zf`` (B, H * W) float64, NaN at invalid pixels: (residual variance in
    footprints^2 (B, N), unit normal (B, N, 3)), NaN where no fit (``ddm.support._fit``)."""
    fx, fy, cx, cy = cam  # (B, 1) each
    zz = zf[:, lay["idx"]]  # (B, N, k)
    ok = ~torch.isnan(zz) & lay["pad"]
    x = torch.where(ok, 1.0 / torch.where(ok, zz, 1.0), 0.0)
    m = ok.to(zf.dtype)
    fu, fv = lay["du"], lay["dv"]
    n = m.sum(-1)
    sums = (n, (m * fu).sum(-1), (m * fv).sum(-1), (m * fu * fu).sum(-1), (m * fu * fv).sum(-1),
            (m * fv * fv).sum(-1), x.sum(-1), (x * fu).sum(-1), (x * fv).sum(-1), (x * x).sum(-1))
    pa, pb, c, rss, good = _solve(*sums)
    good = good & (n >= lay["least"]) & (c > 0.0)
    cv, cu = lay["cv"], lay["cu"]
    nx = fx * pa
    ny = fy * pb
    nz = c - pa * (cu - cx) - pb * (cv - cy)
    s = 1.0 / torch.sqrt(nx * nx + ny * ny + nz * nz)
    res = rss * fx * fx / ((n - 3.0) * c * c)
    nan = torch.full_like(res, float("nan"))
    normal = torch.stack((nx * s, ny * s, nz * s), -1)
    return torch.where(good, res, nan), torch.where(good[..., None], normal, nan[..., None])


def _pairs(zf: torch.Tensor, h: int, w: int, radii: tuple[int, ...], cam) -> list[tuple]:
    """The rows of ``ddm.support._pairs`` of every frame for each of ``radii``, on the host:
    ``(rows (B, P, 4), ok (B, P))`` (angle in degrees, the larger residual variance, the first
    window's depth, the index of its noise tile; where a row exists), one transfer."""
    lay, cuts = _device_layout(h, w, radii, zf.device, zf.dtype)
    s_all, n_all = _fit(zf, lay, cam)
    i0, i1 = lay["first"], lay["second"]
    s0, s1 = s_all[:, i0], s_all[:, i1]
    zc = zf[:, lay["centre"]]
    ok = ~torch.isnan(zc) & ~torch.isnan(s0) & lay["inside"] & ~torch.isnan(s1)
    dot = torch.clamp((n_all[:, i0] * n_all[:, i1]).sum(-1), -1.0, 1.0)
    ang = torch.rad2deg(torch.acos(torch.where(ok, dot, 1.0)))
    tile = lay["tile"].to(zf.dtype)[None].expand_as(zc)
    rows = torch.stack((ang, torch.maximum(s0, s1), zc, tile), -1).cpu().numpy()
    oks = ok.cpu().numpy()
    return list(zip(np.split(rows, cuts, axis=1), np.split(oks, cuts, axis=1), strict=True))


@torch.compiler.disable  # read on the host and chosen in numpy: a compiled caller breaks here
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
        host = [t for radii in GROUPS for t in _pairs(zf, h, w, radii, c)]
    lev = None if tiles is None else tiles.cpu().numpy()
    return profiles_from_pair_tables(host, sigmas, tiles=lev)

