"""3F2N and SNE-RoadSeg in torch: validity-aware inverse-depth gradients, the 8 plane-equation
candidates and the third filter (mean, median, trimean, trimmed mean) by sorting networks.

Same arithmetic as :func:`depthnormals.three_filters_to_normal` and
:func:`depthnormals.sne_roadseg` (the numba estimators), written as whole-map tensor
operations: one stencil row or one neighbour at a time over the whole batch.
"""

from __future__ import annotations

import torch

from ._common import Camera, Grid, oriented

__all__ = ["AGGREGATES", "KERNELS", "gradient_kernels", "inverse_depth_gradient", "sne_roadseg",
           "three_filters_to_normal"]

AGGREGATES = ("median", "mean", "trimean", "trimmed-mean")
#: smoothing taps of the named kernels (None: no smoothing); Scharr (3, 10, 3), Prewitt (1, 1, 1)
KERNELS: dict[str, tuple[float, ...] | None] = {
    "fd": None, "sobel": (1.0, 2.0, 1.0), "scharr": (3.0, 10.0, 3.0), "prewitt": (1.0, 1.0, 1.0),
    "roberts": None,
}
KERNEL_SIZES = (3, 5, 7, 9, 11)
#: the 8-neighbourhood (dv, du), row by row
NEIGHBOURS8 = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
# Batcher's odd-even merge sort of 8 values: 19 compare-exchanges
_SORT8 = ((0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (1, 2), (5, 6),
          (0, 4), (1, 5), (2, 6), (3, 7), (2, 4), (3, 5), (1, 2), (3, 4), (5, 6))


def _convolve(a: list[float], b: tuple[float, ...]) -> list[float]:
    out = [0.0] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i + j] += x * y
    return out


def gradient_kernels(kernel: str, size: int) -> tuple[list[float], list[float]]:
    """Derivative and smoothing taps of a named kernel of odd ``size`` (3..11), scaled so that
    the derivative of a linear function is its slope per pixel and the smoothing sums to 1.

    The construction of :mod:`depthnormals.estimators` (least-squares slope for ``fd``;
    ``(-1, 0, 1) * s^(m-1)`` and ``s^m`` for the smoothed kernels).
    """
    if isinstance(size, bool) or not isinstance(size, int):
        raise TypeError(f"kernel_size must be an odd integer in 3..11; got {size!r}")
    if size not in KERNEL_SIZES:
        raise ValueError(f"kernel_size must be one of 3, 5, 7, 9, 11; got {size}")
    m = (size - 1) // 2
    base = KERNELS[kernel]
    if base is None:
        deriv = [float(i) for i in range(-m, m + 1)]
        smooth = [1.0]
    else:
        smooth = [1.0]
        for _ in range(m):
            smooth = _convolve(smooth, base)
        deriv = [-1.0, 0.0, 1.0]
        for _ in range(m - 1):
            deriv = _convolve(deriv, base)
    md = len(deriv) // 2
    scale = sum((i - md) * d for i, d in enumerate(deriv))
    total = sum(smooth)
    return [d / scale for d in deriv], [s / total for s in smooth]


class _Inverse:
    """Inverse depth relative to the pixel's own: ``at(dv, du) = 1/z(dv, du) - 1/z_q``,
    computed as ``(z_q - z) / (z z_q)`` (no cancellation of two large inverse depths; the
    stencils only take differences, so the offset ``1/z_q`` cancels exactly). Invalid pixels
    read the safe depth 1; ``Grid.ok`` says which are valid."""

    def __init__(self, grid: Grid):
        self.g = grid

    def at(self, dv: int, du: int) -> torch.Tensor:
        zq = self.g.zs
        z = self.g.z(dv, du)
        return (zq - z) / (z * zq)


def _fd3(grid: Grid, av: int, au: int) -> tuple[torch.Tensor, torch.Tensor]:
    """d(1/z) along (av, au) by the 3-tap central difference, else one-sided; (value, ok).

    One expression for the three cases, without the cancellation of ``1/z_f - 1/z_b``:
    ``s (z_b - z_f) / (z_b z_f)`` with a missing side replaced by the pixel itself and
    ``s = 1/2`` when both sides are there.
    """
    zq = grid.zs
    okf, okb = grid.ok(av, au), grid.ok(-av, -au)
    zf = torch.where(okf, grid.z(av, au), zq)
    zb = torch.where(okb, grid.z(-av, -au), zq)
    both = okf & okb
    g = (zb - zf) / (zb * zf)
    return torch.where(both, 0.5 * g, g), okf | okb


def _stencil(grid: Grid, inv: _Inverse, av: int, au: int, deriv: list[float],
             smooth: list[float]) -> tuple[torch.Tensor, torch.Tensor]:
    """Validity-aware separable derivative of 1/z along (av, au), smoothed across it.

    Per smoothing row: the full derivative stencil where every tap is valid, else the central,
    then a one-sided 1-pixel difference; rows with none are left out and the smoothing
    weights renormalised; (value, ok) with ok False where no row gives a difference.
    """
    md, ms = len(deriv) // 2, len(smooth) // 2
    bv, bu = au, av
    acc = None
    wsum = None
    for j in range(-ms, ms + 1):
        s = smooth[j + ms]
        if s == 0.0:
            continue
        pv, pu = j * bv, j * bu
        full_ok = None
        full = None
        for i in range(-md, md + 1):
            d = deriv[i + md]
            if d == 0.0:
                continue
            ok = grid.ok(pv + i * av, pu + i * au)
            term = d * inv.at(pv + i * av, pu + i * au)
            full_ok = ok if full_ok is None else full_ok & ok
            full = term if full is None else full + term
        fwd, okf = inv.at(pv + av, pu + au), grid.ok(pv + av, pu + au)
        bwd, okb = inv.at(pv - av, pu - au), grid.ok(pv - av, pu - au)
        c, okc = inv.at(pv, pu), grid.ok(pv, pu)
        both = okf & okb
        g = torch.where(okc & okf, fwd - c, c - bwd)
        g = torch.where(both, 0.5 * (fwd - bwd), g)
        g = torch.where(full_ok, full, g)
        row_ok = full_ok | both | (okc & (okf | okb))
        term = torch.where(row_ok, s * g, 0.0)
        wt = row_ok.to(g.dtype) * s
        acc = term if acc is None else acc + term
        wsum = wt if wsum is None else wsum + wt
    ok = wsum > 0
    return acc / torch.where(ok, wsum, 1.0), ok


def _roberts(grid: Grid, inv: _Inverse) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(d/du, d/dv, ok) of 1/z from the first fully valid 2x2 Roberts cross around the pixel
    (blocks at (v, u), (v, u - 1), (v - 1, u), (v - 1, u - 1) in that order), the diagonal
    differences rotated back: d/du = (d1 - d2) / 2, d/dv = (d1 + d2) / 2."""
    gu = gv = ok = None
    for k in reversed(range(4)):
        r0, c0 = -(k // 2), -(k % 2)
        okk = grid.ok(r0, c0) & grid.ok(r0, c0 + 1) & grid.ok(r0 + 1, c0) & grid.ok(r0 + 1, c0 + 1)
        d1 = inv.at(r0 + 1, c0 + 1) - inv.at(r0, c0)
        d2 = inv.at(r0 + 1, c0) - inv.at(r0, c0 + 1)
        u_, v_ = 0.5 * (d1 - d2), 0.5 * (d1 + d2)
        if gu is None:
            gu, gv, ok = u_, v_, okk
        else:
            gu = torch.where(okk, u_, gu)
            gv = torch.where(okk, v_, gv)
            ok = ok | okk
    return gu, gv, ok


def inverse_depth_gradient(grid: Grid, kernel: str, kernel_size: int
                           ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(d(1/z)/du, d(1/z)/dv, ok) per pixel, by the named kernel (validity-aware)."""
    if kernel == "fd" and kernel_size == 3:
        gu, oku = _fd3(grid, 0, 1)
        gv, okv = _fd3(grid, 1, 0)
        return gu, gv, oku & okv
    inv = _Inverse(grid)
    if kernel == "roberts":
        return _roberts(grid, inv)
    deriv, smooth = gradient_kernels(kernel, kernel_size)
    gu, oku = _stencil(grid, inv, 0, 1, deriv, smooth)
    gv, okv = _stencil(grid, inv, 1, 0, deriv, smooth)
    return gu, gv, oku & okv


def candidate_terms(grid: Grid, gu: torch.Tensor, gv: torch.Tensor
                    ) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """The 8 plane-equation terms ``t_i = (gu du_i + gv dv_i) z_i / (z_i - z_q)`` and whether
    each is kept (neighbour valid, ``z_i != z_q``).

    3F2N's candidate is ``nz_i = -(gu (u - cx) + gv (v - cy)) - t_i`` (in units where
    ``nx = fx gu``): the candidate ``-(nx dx_i + ny dy_i) / dz_i`` with X and Y eliminated.
    """
    zq = grid.zs
    terms, keep = [], []
    for dv, du in NEIGHBOURS8:
        zi = grid.z(dv, du)
        dz = zi - zq
        k = grid.ok(dv, du) & (dz != 0)
        dz = torch.where(k, dz, 1.0)
        if dv == 0:
            lin = gu * du
        elif du == 0:
            lin = gv * dv
        else:
            lin = gu * du + gv * dv
        terms.append(lin * zi / dz)
        keep.append(k)
    return terms, keep


def _cx(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.minimum(a, b), torch.maximum(a, b)


def _median_fast(terms: list[torch.Tensor], keep: list[torch.Tensor]) -> torch.Tensor:
    """Median of the kept terms: dropped ones alternate +inf / -inf (so the middle of the
    sorted 8 is the middle of the kept ones), then a pruned sorting network gives the 4th and
    5th values; an odd number dropped takes the 4th."""
    inf = float("inf")
    parity = torch.zeros_like(keep[0])
    a = []
    for t, k in zip(terms, keep):  # noqa: B905
        fill = torch.where(parity, -inf, inf)
        a.append(torch.where(k, t, fill))
        parity = parity ^ ~k
    a0, a1, a2, a3, a4, a5, a6, a7 = a
    a0, a2 = _cx(a0, a2)
    a1, a3 = _cx(a1, a3)
    a4, a6 = _cx(a4, a6)
    a5, a7 = _cx(a5, a7)
    a0, a4 = _cx(a0, a4)
    a1, a5 = _cx(a1, a5)
    a2, a6 = _cx(a2, a6)
    a3, a7 = _cx(a3, a7)
    a1 = torch.maximum(a0, a1)
    a2, a3 = _cx(a2, a3)
    a4, a5 = _cx(a4, a5)
    a6 = torch.minimum(a6, a7)
    a4 = torch.maximum(a2, a4)
    a3 = torch.minimum(a3, a5)
    a4 = torch.maximum(a1, a4)
    a3 = torch.minimum(a3, a6)
    lo, hi = _cx(a3, a4)
    mid = 0.5 * (lo + hi)
    return torch.where(parity, lo, mid)


def sort8(values: list[torch.Tensor]) -> list[torch.Tensor]:
    """The 8 maps sorted elementwise (ascending) by a 19-comparator network."""
    a = list(values)
    for i, j in _SORT8:
        a[i], a[j] = _cx(a[i], a[j])
    return a


def _quantile(stack: torch.Tensor, n: torch.Tensor, q: float) -> torch.Tensor:
    """Linearly interpolated quantile ``q`` of the first ``n`` sorted values of ``stack``
    (B, 8, H, W): position ``q (n - 1)``, as numpy's default."""
    pos = q * (n - 1.0)
    lo = torch.floor(pos).clamp(0, 7)
    hi = torch.where(lo + 1 < n, lo + 1, lo)
    f = pos - lo
    vlo = torch.gather(stack, 1, lo.long()[:, None])[:, 0]
    vhi = torch.gather(stack, 1, hi.long()[:, None])[:, 0]
    return vlo * (1.0 - f) + vhi * f


def aggregate(terms: list[torch.Tensor], keep: list[torch.Tensor], mode: str) -> torch.Tensor:
    """The third filter over the kept terms (value undefined where none is kept)."""
    if mode == "median":
        return _median_fast(terms, keep)
    n = torch.stack(keep).sum(0).to(terms[0].dtype)
    if mode == "mean":
        s = sum(torch.where(k, t, 0.0) for t, k in zip(terms, keep))  # noqa: B905
        return s / torch.clamp(n, min=1.0)
    srt = sort8([torch.where(k, t, float("inf")) for t, k in zip(terms, keep)])  # noqa: B905
    if mode == "trimean":
        stack = torch.stack(srt, dim=1)
        return 0.25 * (_quantile(stack, n, 0.25) + 2.0 * _quantile(stack, n, 0.5)
                       + _quantile(stack, n, 0.75))
    # trimmed mean: drop the smallest and the largest when at least 3 remain
    trim = n >= 3
    lo = trim.to(n.dtype)
    hi = torch.where(trim, n - 1, n)
    s = torch.zeros_like(terms[0])
    for i, t in enumerate(srt):
        s = s + torch.where((lo <= i) & (i < hi), t, 0.0)
    return s / torch.clamp(hi - lo, min=1.0)


def three_filters_to_normal(grid: Grid, cam: Camera, kernel: str, kernel_size: int, aggregate_: str
                            ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """3F2N normals (nx, ny, nz, ok) of a prepared grid; see :func:`depthnormals.torch.estimate_normals`."""
    gu, gv, ok = inverse_depth_gradient(grid, kernel, kernel_size)
    terms, keep = candidate_terms(grid, gu, gv)
    m = aggregate(terms, keep, aggregate_)
    any_kept = keep[0]
    for k in keep[1:]:
        any_kept = any_kept | k
    has = any_kept & ((gu != 0) | (gv != 0))
    nz = torch.where(has, -(gu * cam.a + gv * cam.b) - m, -1.0)
    nx = torch.where(has, cam.fx * gu, 0.0)
    ny = torch.where(has, cam.fy * gv, 0.0)
    return oriented(nx, ny, nz, cam, ok & grid.valid)


def sne_roadseg(grid: Grid, cam: Camera
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """SNE-RoadSeg normals: ``n ~ (nx, ny, sum_i w_i nz_i / sum_i w_i)``,
    ``w_i = 1 / |(nx, ny, nz_i)|`` (the closed form of its angle formulas)."""
    gu, gv, ok = inverse_depth_gradient(grid, "fd", 3)
    nx = cam.fx * gu
    ny = cam.fy * gv
    c = -(gu * cam.a + gv * cam.b)
    n2 = nx * nx + ny * ny
    terms, keep = candidate_terms(grid, gu, gv)
    sw = torch.zeros_like(gu)
    sz = torch.zeros_like(gu)
    for t, k in zip(terms, keep):  # noqa: B905
        nzi = c - t
        k = k & (n2 > 0)  # a zero gradient gives (0, 0, -1) below: keep rsqrt's operand > 0
        w = torch.rsqrt(torch.where(k, n2 + nzi * nzi, 1.0))
        sw = sw + torch.where(k, w, 0.0)
        sz = sz + torch.where(k, nzi * w, 0.0)
    has = ((nx != 0) | (ny != 0)) & (sw != 0)
    mz = torch.where(has, sz / torch.where(has, sw, 1.0), -1.0)
    return oriented(torch.where(has, nx, 0.0), torch.where(has, ny, 0.0), mz, cam, ok & grid.valid)
