"""``selection="auto"`` / ``"box-fit"`` of the module in torch: which branch each frame
takes, and the noisy branches, as :mod:`depthnormals.ddm.auto` decides them.

Per frame: the noise pass (:mod:`._noise`) reads the level; below
:data:`~depthnormals.ddm.auto.PLANES_NOISE` (:data:`~depthnormals.ddm.auto.NOISE_CLEAN` with
the paper's CRF or a correlation) the clean branch runs (the caller's plane hypotheses or
curvature selection); above it the support profile (:mod:`._support`) decides between the
tuned box-fit of independent noise (:func:`depthnormals.ddm.auto.box_select`) and the
measured support of real sensors (:func:`depthnormals.ddm.support.support_select`). Frames of
a batch that take the same branch and window size run together. The branch is a host
decision: one transfer of a few numbers per frame after the noise pass, one more for the
profile when a frame is noisy (a ``torch.compile``'d caller breaks its graph there).
"""

from __future__ import annotations

import math

import torch

from ..ddm.auto import (
    GATE,
    KEEP_CHI2,
    NOISE_CLEAN,
    big_radius,
    box_radius,
    branch_at,
    needs_measured_support,
)
from ..ddm.faceswitch import SPAN as SWITCH_SPAN
from ..ddm.noise import TILE
from ..ddm.support import BIG_FACTOR, HALF_RADIUS
from ..ddm.support import GATE as SUPPORT_GATE
from ..ddm.support import MAX_RADIUS as SUPPORT_MAX
from ._boxfit import box_fits, choose_least, choose_local, choose_plain, keep_estimator, upsample_half
from ._faceswitch import switch_faces
from ._noise import BatchNoise, noise_pass
from ._support import support_profiles

__all__ = ["frames_of", "in_order", "noisy_frames", "noisy_select"]


def noisy_frames(z: torch.Tensor, valid: torch.Tensor, cam64, o: dict) -> tuple[BatchNoise, list[int]]:
    """The noise pass of every frame (depth ``z``, valid where ``valid``) and the frames that
    take a noisy branch."""
    noise = noise_pass(z, valid, cam64[0], cam64[1], tile=TILE)
    return noise, [i for i, f in enumerate(noise.frames) if branch_at(o, f.sigma) == "box-fit"]


def _col(values, like: torch.Tensor) -> torch.Tensor:
    return torch.tensor(values, dtype=torch.float64, device=like.device).reshape(-1, 1, 1)


def frames_of(cam64, idx: torch.Tensor):
    """The camera tensors (B or 1, ...) of the frames ``idx`` (a shared one stays as it is)."""
    return tuple(c if c.shape[0] == 1 else c[idx] for c in cam64)


def _half(cam64, k: int = 2):
    return tuple(c / k for c in cam64)


def _iid(z64, valid, cam, noise: BatchNoise, idx, frames, r: int, big_r: int):
    """:func:`depthnormals.ddm.auto.box_select` on the frames ``idx`` (all of radius ``r``
    and large radius ``big_r``)."""
    sig = [f.sigma for f in frames]
    noisy = sig[0] == sig[0] and sig[0] > 0.0  # the same for every frame of a group
    zs = torch.where(valid, z64, torch.ones_like(z64))
    fits = box_fits(zs, valid, r, cam)
    big = box_fits(zs, valid, big_r, cam) if big_r > r else None
    if not noisy:  # explicit "box-fit" on clean depth: the least residual (box_fit_from_prepared)
        return choose_plain(valid, fits, big, r, 0.0, 0.0, 1.0, cam)
    s = _col(sig, z64)
    gate = GATE * s * s
    t = noise.tiles(idx).clamp(min=NOISE_CLEAN)  # NaN stays NaN
    scale = torch.where(torch.isfinite(t), (t / s) ** 2, torch.ones_like(t))
    h, w = z64.shape[-2:]
    scale = scale.repeat_interleave(TILE, -2).repeat_interleave(TILE, -1)[:, :h, :w]
    return choose_local(zs, valid, fits, big, r, gate, gate, 1.0 / (s * s), scale, cam)


def _measured(z64, valid, cam, profiles, r: int):
    """:func:`depthnormals.ddm.support.support_select` on frames whose profiles chose ``r``."""
    gate = _col([SUPPORT_GATE * p.residual_at(p.radius) for p in profiles], z64)
    zref = _col([p.depth for p in profiles], z64)
    half = torch.tensor([round(2.0 * p.exponent) if p.depth == p.depth else 0 for p in profiles],
                        device=z64.device).reshape(-1, 1, 1)
    # the deviation's unit (ddm.support.choice_inputs): the inverse plane residual, footprints
    # of the choice's grid (4x the profile's on every second row and column)
    scale = 1.0 if r < HALF_RADIUS else 4.0
    res = [p.residual_at(p.radius) for p in profiles]
    unit = _col([scale / x if x > 0.0 else 0.0 for x in res], z64)
    if r < HALF_RADIUS:
        zs = torch.where(valid, z64, torch.ones_like(z64))
        fits = box_fits(zs, valid, r, cam)
        big_r = min(SUPPORT_MAX, round(BIG_FACTOR * r))
        big = None
        if big_r > r:
            vd = valid[:, ::2, ::2]
            big = box_fits(zs[:, ::2, ::2], vd, (big_r + 1) // 2, _half(cam))
            big.score = big.score * 4.0
        n = choose_least(zs, valid, fits, big, r, gate, zref, half, cam,
                         fallback=(unit, zs, valid))
        return switch_faces(torch.where(valid, z64, math.nan), n, cam, SWITCH_SPAN)[0]
    # every second row and column: windows of half the radius, then every pixel takes its cell's
    rd = round(r / 2)
    vd = valid[:, ::2, ::2]
    zd = torch.where(vd, z64[:, ::2, ::2], torch.ones_like(z64[:, ::2, ::2]))
    camd = _half(cam)
    fits = box_fits(zd, vd, rd, camd)
    fits.score = fits.score * 4.0
    big_r = min(SUPPORT_MAX, round(BIG_FACTOR * rd))
    big = None
    if big_r > rd:
        big = box_fits(zd[:, ::2, ::2], vd[:, ::2, ::2], (big_r + 1) // 2, _half(cam, 4))
        big.score = big.score * 16.0
    fill = torch.where(zref == zref, zref, torch.ones_like(zref))
    zfill = torch.where(vd, zd, fill)
    half_n = choose_least(zfill, torch.ones_like(vd), fits, big, rd, gate, zref, half, camd,
                          fallback=(unit, zd, vd))
    half_n = switch_faces(torch.where(vd, zd, math.nan), half_n, camd, SWITCH_SPAN // 2)[0]
    return upsample_half(half_n, valid, cam)


def noisy_select(z64: torch.Tensor, valid: torch.Tensor, cam64, noise: BatchNoise,
                 frames: list[int], base=None, keep_chi2: float | None = None):
    """The noisy branch (:func:`depthnormals.ddm.auto.noisy_select`) of the frames ``frames``
    of ``z64`` (B, H, W) float64 (NaN at invalid pixels). ``base``: the estimator's normals
    (nx, ny, nz, ok) of those frames (kept where they agree with the fit; none where they
    have none), None for the fused 3F2N+. Returns (nx, ny, nz, ok) float64 of those frames,
    in the order of ``frames``."""
    dev = z64.device
    fr = [noise.frames[i] for i in frames]
    idx_all = torch.tensor(frames, device=dev)
    zsub, vsub = z64[idx_all], valid[idx_all]
    csub = frames_of(cam64, idx_all)
    profiles = support_profiles(zsub, csub, [f.sigma for f in fr], noise.tiles(idx_all))
    groups: dict[tuple, list[int]] = {}
    for j, (f, p) in enumerate(zip(fr, profiles, strict=True)):
        if needs_measured_support(f, p):
            key = ("measured", p.radius, True, 0)
        else:  # one group per pair of window radii (the large one grows with the noise)
            key = ("iid", box_radius(f.sigma), f.sigma == f.sigma and f.sigma > 0.0, big_radius(f.sigma))
        groups.setdefault(key, []).append(j)
    k2 = KEEP_CHI2 if keep_chi2 is None else float(keep_chi2)
    parts, order = [], []
    for (kind, r, _, big_r), js in groups.items():
        jt = torch.tensor(js, device=dev)
        zg, vg, cg = zsub[jt], vsub[jt], frames_of(csub, jt)
        if kind == "iid":
            out = _iid(zg, vg, cg, noise, idx_all[jt], [fr[j] for j in js], r, big_r)
            suu = (2 * r + 1) ** 2 * r * (r + 1) / 3.0
            kap = [k2 * f.sigma * f.sigma / suu if f.sigma == f.sigma else 0.0 for f in (fr[j] for j in js)]
        else:
            out = _measured(zg, vg, cg, [profiles[j] for j in js], r)
            kap = []
            for j in js:
                p = profiles[j]
                e = p.error[p.radii.index(p.radius)]
                std = math.radians(e) / math.sqrt(math.pi / 2.0) if e == e else 0.0
                kap.append(k2 * std * std)
        if base is not None:
            kappa = _col(kap, z64) / (cg[0] * cg[0])
            out = keep_estimator(tuple(q[jt] for q in base), out, torch.where(vg, zg, 1.0), kappa, cg)
        parts.append(out)
        order.extend(js)
    return in_order(parts, order, dev)


def in_order(parts: list[tuple], order: list[int], device) -> tuple:
    """The outputs ``parts`` of groups of frames, concatenated and put back in frame order:
    ``order`` lists the frame (0 .. n - 1) of every concatenated row."""
    res = tuple(torch.cat(q) for q in zip(*parts, strict=True))
    if order != sorted(order):
        inv = torch.empty(len(order), dtype=torch.long)
        inv[torch.tensor(order)] = torch.arange(len(order))
        res = tuple(q[inv.to(device)] for q in res)
    return res
