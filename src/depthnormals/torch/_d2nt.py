"""D2NT in torch: basic (central differences), dag (the discontinuity-aware gradient filter)
and mnr (dag followed by the one-pass neighbour-copy refinement), as
:func:`depthnormals.d2nt` computes them."""

from __future__ import annotations

import math

import torch

from ._common import Camera, Grid, oriented, shift

__all__ = ["VARIANTS", "d2nt"]

VARIANTS = ("basic", "dag", "mnr")
_EPS = 1e-8
# refinement candidates of the public code, first minimum wins: left, right, up, down, self
_COPY = ((0, -1), (0, 1), (-1, 0), (1, 0), (0, 0))


def _central(grid: Grid, av: int, au: int) -> tuple[torch.Tensor, torch.Tensor]:
    zq, zf, zb = grid.zs, grid.z(av, au), grid.z(-av, -au)
    okf, okb = grid.ok(av, au), grid.ok(-av, -au)
    g = torch.where(okf & okb, 0.5 * (zf - zb), torch.where(okf, zf - zq, zq - zb))
    return g, okf | okb


def _laplacian_1d(grid: Grid, c: tuple[int, int], av: int, au: int) -> torch.Tensor:
    """|z(c - a) - 2 z(c) + z(c + a)| (inf where a sample is invalid)."""
    v, u = c
    ok = grid.ok(v - av, u - au) & grid.ok(v, u) & grid.ok(v + av, u + au)
    zc = grid.z(v, u)  # differences first: exact for neighbouring depths (no cancellation)
    lap = ((grid.z(v - av, u - au) - zc) + (grid.z(v + av, u + au) - zc)).abs()
    return torch.where(ok, lap, torch.full_like(lap, float("inf")))


def _dag_weights(lb: torch.Tensor, lf: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The public code's exp(-L) soft-min (epsilon 1e-8, hard switch at a ratio of e), as
    :func:`depthnormals.d2nt` evaluates it: a logistic of the Laplacian difference where the
    smaller one is <= 15, the literal formula above."""
    lo = torch.minimum(lb, lf)
    literal = lo > 15.0
    # literal branch: exp(-L) (0 for inf), normalised with the epsilon
    a = torch.exp(-lb)
    b = torch.exp(-lf)
    den = _EPS + a + b
    wb_l = (a + 0.5 * _EPS) / den
    wf_l = (b + 0.5 * _EPS) / den
    one = torch.ones_like(lb)
    zero = torch.zeros_like(lb)
    left = wb_l / (wf_l + _EPS) > math.e
    right = wf_l / (wb_l + _EPS) > math.e
    wb_lit = torch.where(left, one, torch.where(right, zero, wb_l))
    wf_lit = torch.where(left, zero, torch.where(right, one, wf_l))
    # logistic branch (safe operand where it is not taken: inf - inf)
    diff = torch.where(literal, zero, lf - lb)
    s = torch.sigmoid(diff)
    wb_s = torch.where(diff > 1.0, one, torch.where(diff < -1.0, zero, s))
    wf_s = torch.where(diff > 1.0, zero, torch.where(diff < -1.0, one, 1.0 - s))
    return torch.where(literal, wb_lit, wb_s), torch.where(literal, wf_lit, wf_s)


def _dag(grid: Grid, av: int, au: int) -> tuple[torch.Tensor, torch.Tensor]:
    zq, zf, zb = grid.zs, grid.z(av, au), grid.z(-av, -au)
    okf, okb = grid.ok(av, au), grid.ok(-av, -au)
    gb = zq - zb
    gf = zf - zq
    lb = _laplacian_1d(grid, (-av, -au), av, au)
    lf = _laplacian_1d(grid, (av, au), av, au)
    wb, wf = _dag_weights(lb, lf)
    both = wb * gb + wf * gf
    g = torch.where(okf & okb, both, torch.where(okf, gf, gb))
    return g, okf | okb


def _laplacian_4(grid: Grid) -> torch.Tensor:
    """|4-neighbour Laplacian of z| (inf where a neighbour is invalid or outside), float64
    whatever the depth's dtype (a key: no gradient)."""
    ok = grid.ok(0, -1) & grid.ok(0, 1) & grid.ok(-1, 0) & grid.ok(1, 0)
    # the numba kernel's order of operations and its float64, so that exact ties (quantised
    # depth: many Laplacians are equal) are broken alike: (left + right + up + down) - 4 z,
    # exact in float64 for float32 depths of one magnitude; in float32 the sum rounds, and
    # the copy took another neighbour's normal on 2400-2700 pixels of a 640x480 Kinect frame
    # (more than 10 deg off the numba library's, mean 0.76 deg; session 34)
    def z(dv: int, du: int) -> torch.Tensor:
        return grid.z(dv, du).detach().to(torch.float64)

    s = z(0, -1) + z(0, 1) + z(-1, 0) + z(1, 0) - 4.0 * grid.zs.detach().to(torch.float64)
    return torch.where(ok, s.abs(), torch.full_like(s, float("inf")))


def _copy_refinement(grid: Grid, cam: Camera, nx: torch.Tensor, ny: torch.Tensor,
                     nz: torch.Tensor, ok: torch.Tensor
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Each valid pixel takes the normal of whichever of {left, right, up, down, self} (with a
    normal) has the least |Laplacian| (strictly less: the first wins ties, inf never wins);
    its own normal when none does."""
    lap = _laplacian_4(grid).detach()
    inf = torch.full_like(lap, float("inf"))
    best = inf
    bx, by, bz, bok = nx, ny, nz, ok
    for dv, du in _COPY:
        cok = shift(ok, dv, du, False)
        key = torch.where(cok, shift(lap, dv, du, float("inf")), inf)
        take = key < best
        best = torch.where(take, key, best)
        bx = torch.where(take, shift(nx, dv, du, 0.0), bx)
        by = torch.where(take, shift(ny, dv, du, 0.0), by)
        bz = torch.where(take, shift(nz, dv, du, 0.0), bz)
        bok = bok | take
    return oriented(bx, by, bz, cam, bok & grid.valid)


def d2nt(grid: Grid, cam: Camera, variant: str
         ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """D2NT normals (nx, ny, nz, ok): ``n ~ (fx z_u, fy z_v, -(z + (u - cx) z_u + (v - cy) z_v))``."""
    deriv = _central if variant == "basic" else _dag
    zu, oku = deriv(grid, 0, 1)
    zv, okv = deriv(grid, 1, 0)
    nx = cam.fx * zu
    ny = cam.fy * zv
    nz = -(grid.zs + cam.a * zu + cam.b * zv)
    out = oriented(nx, ny, nz, cam, oku & okv & grid.valid)
    if variant == "mnr":
        out = _copy_refinement(grid, cam, *out)
    return out
