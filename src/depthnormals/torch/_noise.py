"""The noise estimate of the default 3F2N+ in torch: the same samples, the same order
statistics, the same numbers as :func:`depthnormals.ddm.noise.noise_pass`.

Read :mod:`depthnormals.ddm.noise` for the method (ours, not the paper's). Here every sample
of every frame is computed at once on the device, in float64 from the depth's own values
(as the numba pass reads them): second differences of inverse depth on the sampled rows and
columns, kept by 64 x 64 tile, and the plateau search of quantised depth. The medians are
exact order statistics (a sort with the missing samples at +inf, then the k-th of the
present ones), so each frame's level is the numba level to the last bit. Only the four
numbers per frame that decide the branch go to the host (one transfer per batch); the tile
levels stay on the device until the i.i.d. box-fit asks for them. No gradients.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..ddm.noise import (
    _MAD,
    _SQRT6,
    GRID_TOL,
    QUANT_EDGE,
    QUANT_SPAN,
    QUANT_STRIDE,
    TILE,
    TILE_MIN,
    TILE_STRIDE,
    combined_level,
    grid_from_counts,
    iid_level,
    quant_step_of,
    quantisation_from_counts,
)

__all__ = ["FrameNoise", "noise_pass"]

@dataclass(frozen=True)
class FrameNoise:
    """One frame's noise levels (host floats), as :class:`depthnormals.ddm.noise.NoiseSamples`
    names them: ``iid`` (second differences), ``quant_share``, ``quant_step``, ``quant``
    (rounding noise), ``sigma`` (the two in quadrature), ``grid`` (the depth grid's quantum),
    ``plateaus`` (the step is the plateaus')."""

    iid: float
    quant_share: float
    quant_step: float
    quant: float
    sigma: float
    grid: float = 0.0
    plateaus: bool = False


def _kth_present(x: torch.Tensor, ok: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
    """The ``k``-th smallest (0-based, per row of the last axis) of the entries of ``x`` where
    ``ok``; +inf where there are not enough."""
    s = torch.sort(torch.where(ok, x, torch.full_like(x, float("inf"))), dim=-1).values
    return torch.gather(s, -1, k.clamp(min=0, max=x.shape[-1] - 1).unsqueeze(-1)).squeeze(-1)


def _second(a, b, c, f):
    """The samples ``|1/a - 2/b + 1/c| f b`` (module doc of ddm.noise, times sqrt 6) and where
    they exist."""
    ok = ~(torch.isnan(a) | torch.isnan(b) | torch.isnan(c))
    return (1.0 / a - 2.0 / b + 1.0 / c).abs() * f * b, ok


def _tile_rows(h: int, tile: int) -> tuple[list[int], list[list[int]]]:
    """The sampled rows (every TILE_STRIDE-th from TILE_STRIDE // 2 in each tile, within
    1 .. h - 2) and, per tile row, the indices of its rows in that list."""
    rows, per = [], []
    for i in range((h + tile - 1) // tile):
        mine = []
        for v in range(max(i * tile + TILE_STRIDE // 2, 1), min((i + 1) * tile, h - 1), TILE_STRIDE):
            mine.append(len(rows))
            rows.append(v)
        per.append(mine)
    return rows, per


def _padded_index(groups: list[list[int]], missing: int) -> torch.Tensor:
    width = max([len(g) for g in groups] + [1])
    return torch.tensor([g + [missing] * (width - len(g)) for g in groups], dtype=torch.long)


class _Samples:
    """The second-difference samples of a batch, laid out by tile: ``x`` (B, TY, TX, S)
    float64 and ``ok`` where a sample exists (ddm.noise._tile_samples' samples, the same
    multiset per tile)."""

    def __init__(self, z: torch.Tensor, valid: torch.Tensor, fx: torch.Tensor, fy: torch.Tensor,
                 tile: int):
        b, h, w = z.shape
        dev = z.device
        ty, tx = (h + tile - 1) // tile, (w + tile - 1) // tile
        rows, per = _tile_rows(h, tile)
        nr = len(rows)
        if nr == 0 or w < 3:
            self.x = torch.zeros((b, ty, tx, 1), dtype=torch.float64, device=dev)
            self.ok = torch.zeros((b, ty, tx, 1), dtype=torch.bool, device=dev)
            return
        rv = torch.tensor(rows, device=dev)
        # horizontal triples at every column 1 .. w - 2 of the sampled rows
        zr = _nan64(z[:, rv], valid[:, rv])  # (B, R, W)
        xh, okh = _second(zr[:, :, :-2], zr[:, :, 1:-1], zr[:, :, 2:], fx)
        pad = tx * tile - w
        xh = torch.nn.functional.pad(xh, (1, pad + 1))
        okh = torch.nn.functional.pad(okh, (1, pad + 1), value=False)
        # vertical triples at every TILE_STRIDE-th column of those rows
        cols, cper = [], []
        for j in range(tx):
            mine = []
            for u in range(max(j * tile + TILE_STRIDE // 2, 1), min((j + 1) * tile, w - 1), TILE_STRIDE):
                mine.append(len(cols))
                cols.append(u)
            cper.append(mine)
        rows_t = _padded_index(per, nr).to(dev)  # (TY, r) into the rows (nr: missing)
        cv = torch.tensor(cols if cols else [0], device=dev)
        zc = _nan64(z[:, :, cv], valid[:, :, cv])  # (B, H, C)
        xv, okv = _second(zc[:, rv - 1], zc[:, rv], zc[:, rv + 1], fy)  # (B, R, C)
        if not cols:
            okv = torch.zeros_like(okv)
        xh = torch.nn.functional.pad(xh, (0, 0, 0, 1))  # a missing row at index nr
        okh = torch.nn.functional.pad(okh, (0, 0, 0, 1), value=False)
        xv = torch.nn.functional.pad(xv, (0, 1, 0, 1))  # a missing row and column
        okv = torch.nn.functional.pad(okv, (0, 1, 0, 1), value=False)
        cols_t = _padded_index(cper, len(cols) if cols else 1).to(dev)  # (TX, c)
        rt = rows_t.shape[1]
        # (B, TY, r, TX, tile) -> (B, TY, TX, r * tile)
        hx = xh[:, rows_t].reshape(b, ty, rt, tx, tile).permute(0, 1, 3, 2, 4).reshape(b, ty, tx, -1)
        ho = okh[:, rows_t].reshape(b, ty, rt, tx, tile).permute(0, 1, 3, 2, 4).reshape(b, ty, tx, -1)
        vx = xv[:, rows_t][:, :, :, cols_t].permute(0, 1, 3, 2, 4).reshape(b, ty, tx, -1)
        vo = okv[:, rows_t][:, :, :, cols_t].permute(0, 1, 3, 2, 4).reshape(b, ty, tx, -1)
        self.x = torch.cat((hx, vx), dim=-1)
        self.ok = torch.cat((ho, vo), dim=-1)


def _nan64(z: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """``z`` in float64 with NaN where not ``valid`` (the numba pass's prepared depth), for
    the sampled rows and columns only."""
    return torch.where(valid, z.to(torch.float64), float("nan"))


def _plateaus(z: torch.Tensor, valid: torch.Tensor, fx: torch.Tensor, fy: torch.Tensor):
    """The plateau search of ddm.noise (``_plateau_samples``) on every frame: (steps, raw,
    step_ok) with steps (B, N) float64 (footprints) and raw the same in depth units."""
    span, edge = QUANT_SPAN, QUANT_EDGE
    b = z.shape[0]
    parts = []
    k = slice(QUANT_STRIDE // 2, None, QUANT_STRIDE)
    for lines, f in ((_nan64(z[:, k, :], valid[:, k, :]), fx),
                     (_nan64(z[:, :, k], valid[:, :, k]).transpose(1, 2), fy)):
        n = lines.shape[-1]
        if n <= 2 * span or lines.shape[1] == 0:
            continue
        a = lines[:, :, :n - 2 * span]
        bb = lines[:, :, 2 * span:]
        c = lines[:, :, span:n - span]
        d = lines[:, :, span + 1:n - span + 1]
        if d.shape[-1] < c.shape[-1]:  # j + 1 past the end only when span = 0
            d = torch.nn.functional.pad(d, (0, 1), value=float("nan"))
        ok = ~(torch.isnan(a) | torch.isnan(bb) | torch.isnan(c) | torch.isnan(d)) & (a != bb)
        fq = f.reshape(-1, 1, 1)
        ok = ok & ((bb - a).abs() * fq / c < 2.0 * span * edge)
        raw = (d - c).abs()
        step = raw * fq / c
        ok = ok & (step < edge)
        parts.append((step.reshape(b, -1), raw.reshape(b, -1), ok.reshape(b, -1)))
    if not parts:
        zero = torch.zeros((b, 1), dtype=torch.float64, device=z.device)
        return zero, zero, zero.bool()
    return tuple(torch.cat([p[i] for p in parts], 1) for i in range(3))


class BatchNoise:
    """The noise pass of a batch (:func:`noise_pass`): ``frames`` (host :class:`FrameNoise`
    per frame) and the tile samples, kept for :meth:`tiles`."""

    def __init__(self, frames: list[FrameNoise], samples: _Samples, shape: tuple[int, int]):
        self.frames = frames
        self._samples = samples
        self._shape = shape

    def tiles(self, index: torch.Tensor | None = None) -> torch.Tensor:
        """Every tile's level (B', TY, TX) float64 of the frames ``index`` (default all), as
        :meth:`depthnormals.ddm.noise.NoiseSamples.tiles`: the tile's second-difference level
        (NaN below TILE_MIN samples) and the frame's rounding noise in quadrature."""
        x, ok = self._samples.x, self._samples.ok
        if index is not None:
            x, ok = x[index], ok[index]
        m = ok.sum(-1)
        kth = _kth_present(x, ok, m // 2)
        lev = torch.where(m >= TILE_MIN, kth, torch.full_like(kth, float("nan"))) / (_MAD * _SQRT6)
        frames = self.frames if index is None else [self.frames[i] for i in index.tolist()]
        q = torch.tensor([f.quant for f in frames], dtype=lev.dtype, device=lev.device).reshape(-1, 1, 1)
        return torch.where(q > 0.0, torch.hypot(lev, q), lev)


def noise_pass(z: torch.Tensor, valid: torch.Tensor, fx: torch.Tensor, fy: torch.Tensor, *,
               tile: int = TILE) -> BatchNoise:
    """The noise of every frame of depth ``z`` (B, H, W), valid where ``valid``; ``fx``, ``fy``
    (B or 1, 1, 1). The sampled rows and columns are read in float64 (as the numba pass reads
    its prepared depth). One host transfer of six numbers per frame."""
    with torch.no_grad():
        b, h, w = z.shape
        fxb = fx.reshape(-1, 1, 1, 1).to(torch.float64)
        fyb = fy.reshape(-1, 1, 1, 1).to(torch.float64)
        samples = _Samples(z, valid, fxb[:, 0], fyb[:, 0], tile)
        x = samples.x.reshape(b, -1)
        ok = samples.ok.reshape(b, -1)
        n = ok.sum(-1)
        iid_kth = _kth_present(x, ok, n // 2)
        steps, raw, sok = _plateaus(z, valid, fxb.reshape(-1), fyb.reshape(-1))
        tested = sok.sum(-1)
        zero_ok = sok & (steps == 0.0)
        zero = zero_ok.sum(-1)
        nz_ok = sok & (steps != 0.0)
        nn = nz_ok.sum(-1)
        step_kth = _kth_present(steps, nz_ok, nn // 2)
        # the depth grid (ddm.noise.grid_quantum): the least non-zero difference, how many
        # differences lie on its multiples, the upper median of q f / z
        q = torch.where(nz_ok, raw, torch.full_like(raw, float("inf"))).amin(-1, keepdim=True)
        r = raw / q
        on = (nz_ok & ((r - torch.round(r)).abs() < GRID_TOL)).sum(-1)
        grid_kth = _kth_present(steps * (q / raw), nz_ok, nn // 2)
        f64 = torch.float64
        host = torch.stack([iid_kth, n.to(f64), tested.to(f64), zero.to(f64), nn.to(f64), step_kth,
                            q[:, 0], on.to(f64), grid_kth], 1).cpu().tolist()
    frames = []
    for kth, cnt, tst, zr, nnz, skth, qmin, ong, gkth in host:
        iid = iid_level(kth, cnt)
        share, plateau_step = quantisation_from_counts(tst, zr, nnz, lambda skth=skth: skth)
        grid = grid_from_counts(int(nnz), qmin if nnz else 0.0, int(ong), lambda gkth=gkth: gkth)
        step = quant_step_of(iid, plateau_step, grid)
        quant, sigma = combined_level(iid, step)
        frames.append(FrameNoise(iid, share, step, quant, sigma, grid, plateau_step > 0.0))
    return BatchNoise(frames, samples, ((h + tile - 1) // tile, (w + tile - 1) // tile))

