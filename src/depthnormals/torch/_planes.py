"""The clean-depth selection of the module in torch: plane hypotheses and their propagation.

The same rules, constants and order of operations as :mod:`depthnormals.ddm.planes` (read
there for the method): five planes of inverse depth per pixel (central and the four
one-sided quadrants), scored by second differences of ``w = 1 / z`` in pixel footprints, then
:data:`~depthnormals.ddm.planes.ITERATIONS` synchronous passes in which a pixel takes a
neighbour's plane where it passes through the pixel with a lower score. The scores only
choose: they are computed without gradients, and the chosen plane's slopes and value carry
the gradient of the depth they came from (a piecewise selection).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..ddm.planes import CENTRE_WEIGHT, ITERATIONS, LAPLACE_WEIGHT
from ._common import Camera, Grid, oriented

__all__ = ["plane_select"]

_MISSING = 1e12
# neighbour offsets (dv, du) of a propagation pass, in the numba kernel's order
_OFFERS = ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))


def _term(x: torch.Tensor, ok: torch.Tensor) -> torch.Tensor:
    """``|x|`` where its pixels exist, capped at (and :data:`_MISSING` where they do not)."""
    return torch.where(ok, torch.clamp(x.abs(), max=_MISSING), _MISSING)


def plane_select(grid: Grid, cam: Camera, ok: torch.Tensor, iterations: int = ITERATIONS):
    """Normals (nx, ny, nz, ok) of the plane hypotheses on ``grid`` (padded by 2 or more);
    ``ok`` is the estimator's (its abstentions are kept)."""
    w = {(dv, du): 1.0 / grid.z(dv, du) for dv in (-2, -1, 0, 1, 2) for du in (-2, -1, 0, 1, 2)
         if abs(dv) + abs(du) <= 2}
    g = {k: grid.ok(*k) for k in w}
    wp, wl, wr, wt, wb = w[0, 0], w[0, -1], w[0, 1], w[-1, 0], w[1, 0]
    ol, orr, ot, ob = g[0, -1], g[0, 1], g[-1, 0], g[1, 0]
    with torch.no_grad():
        d = {k: v.detach() for k, v in w.items()}
        p, lft, rgt, top, bot = d[0, 0], d[0, -1], d[0, 1], d[-1, 0], d[1, 0]
        m_ll = _term(p - lft - top + d[-1, -1], ol & ot & g[-1, -1])
        m_rl = _term(p - rgt - top + d[-1, 1], orr & ot & g[-1, 1])
        m_lr = _term(p - lft - bot + d[1, -1], ol & ob & g[1, -1])
        m_rr = _term(p - rgt - bot + d[1, 1], orr & ob & g[1, 1])
        cu_m = LAPLACE_WEIGHT * _term(d[0, -2] - 2.0 * lft + p, ol & g[0, -2])
        cu_0 = LAPLACE_WEIGHT * _term(lft - 2.0 * p + rgt, ol & orr)
        cu_p = LAPLACE_WEIGHT * _term(p - 2.0 * rgt + d[0, 2], orr & g[0, 2])
        cv_m = LAPLACE_WEIGHT * _term(d[-2, 0] - 2.0 * top + p, ot & g[-2, 0])
        cv_0 = LAPLACE_WEIGHT * _term(top - 2.0 * p + bot, ot & ob)
        cv_p = LAPLACE_WEIGHT * _term(p - 2.0 * bot + d[2, 0], ob & g[2, 0])
        costs = (CENTRE_WEIGHT * (0.25 * (m_ll + m_rl + m_lr + m_rr) + cu_0 + cv_0),
                 m_ll + cu_m + cv_m, m_lr + cu_m + cv_p, m_rl + cu_p + cv_m, m_rr + cu_p + cv_p)
    # slopes of w per candidate (central, then the quadrants), with gradients
    slopes = ((0.5 * (wr - wl), 0.5 * (wb - wt), ol & orr, ot & ob),
              (wp - wl, wp - wt, ol, ot), (wp - wl, wb - wp, ol, ob),
              (wr - wp, wp - wt, orr, ot), (wr - wp, wb - wp, orr, ob))
    inf = torch.full_like(wp, float("inf")).detach()
    best = inf
    a = torch.zeros_like(wp)
    b = torch.zeros_like(wp)
    for c, (ga, gb, oa, ob_) in zip(costs, slopes, strict=True):
        take = (c < best) & oa & ob_ & grid.valid
        best = torch.where(take, c, best)
        a = torch.where(take, ga, a)
        b = torch.where(take, gb, b)
    zd = grid.zs.detach()
    with torch.no_grad():
        best = best * (cam.fx / p)  # footprints
    cval = wp
    h, w = wp.shape[-2:]
    for _ in range(iterations):
        nbest, na, nb, nc = best, a, b, cval
        # each map padded once per pass; every offer reads a view of it (one copy, not eight)
        pa_ = F.pad(a, (1, 1, 1, 1), value=0.0)
        pb_ = F.pad(b, (1, 1, 1, 1), value=0.0)
        pc_ = F.pad(cval, (1, 1, 1, 1), value=1.0)
        with torch.no_grad():
            ps_ = F.pad(best, (1, 1, 1, 1), value=float("inf"))
        for dv, du in _OFFERS:
            aq = pa_[:, 1 + dv:1 + dv + h, 1 + du:1 + du + w]
            bq = pb_[:, 1 + dv:1 + dv + h, 1 + du:1 + du + w]
            pred = pc_[:, 1 + dv:1 + dv + h, 1 + du:1 + du + w] - aq * du - bq * dv
            with torch.no_grad():
                s = (1.0 - pred.detach() * zd).abs() * cam.fx + ps_[:, 1 + dv:1 + dv + h, 1 + du:1 + du + w]
                take = (s < nbest) & grid.valid
                nbest = torch.where(take, s, nbest)
            na = torch.where(take, aq, na)
            nb = torch.where(take, bq, nb)
            nc = torch.where(take, pred, nc)
        best, a, b, cval = nbest, na, nb, nc
    found = ok & grid.valid & (best < float("inf"))
    return oriented(cam.fx * a, cam.fy * b, cval - a * cam.a - b * cam.b, cam, found)
