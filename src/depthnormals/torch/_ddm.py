"""The discontinuity discrimination module (DDM) of 3F2N+ in torch.

Same rules as :func:`depthnormals.discontinuity_discrimination`: depth curvature (every kind,
footprint, slope and discretisation), the curvature selection with ``self_weight`` and the
one-sided tangent consistency test, Kendall / Pearson similarities, the Kendall-only
selection and the per-pixel CRF minimisation. The keys (curvature, tau, energies) only choose
a candidate: they are computed without gradients, and the chosen normal carries the gradient
of the candidate it came from (a piecewise selection).

Not in the torch path: ``selection="plane-fit"`` (a ValueError says so).
"""

from __future__ import annotations

import math

import torch

from ._common import Camera, Grid, oriented, shift

__all__ = ["CROSS", "SQUARE", "curvature", "kendall_tau", "refine"]

CROSS = ((0, 0), (-1, 0), (0, -1), (0, 1), (1, 0))  # self, up, left, right, down
SQUARE = ((0, 0), (-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
_N8 = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))  # raster order
_R2 = 1.0 / math.sqrt(2.0)
_BIG = 1e6  # the CRF's clamp of k_q


def _inf_like(x: torch.Tensor) -> torch.Tensor:
    return torch.full_like(x, float("inf"))


def _pow15(t: torch.Tensor) -> torch.Tensor:
    return t * torch.sqrt(t)


class _Five:
    """The 5-point stencil of every pixel (detached): samples, validity, offsets."""

    def __init__(self, grid: Grid, cam: Camera, v: int = 0, u: int = 0):
        z = lambda dv, du: grid.z(v + dv, u + du).detach()  # noqa: E731
        ok = lambda dv, du: grid.ok(v + dv, u + du)  # noqa: E731
        self.z0, self.zl, self.zr, self.zt, self.zb = z(0, 0), z(0, -1), z(0, 1), z(-1, 0), z(1, 0)
        self.ok0 = ok(0, 0)
        self.oku = ok(0, -1) & ok(0, 1) & self.ok0
        self.okv = ok(-1, 0) & ok(1, 0) & self.ok0
        self.A = cam.a + u  # u - cx at the stencil's centre
        self.B = cam.b + v


def _line(zm, z0, zp, off, inverse, minslope):
    """(z_u, numerator N_u, A = z + off z_u) along one line, as the numba ``_line``."""
    zd = 0.5 * (zp - zm)
    gl = z0 - zm
    gr = zp - z0
    if minslope:
        zd = torch.where(gl.abs() < zd.abs(), gl, zd)
        zd = torch.where(gr.abs() < zd.abs(), gr, zd)
    if inverse:
        num = z0 * z0 * (gl / zm - gr / zp)
    else:
        num = 2.0 * zd * zd - z0 * (gr - gl)
    return zd, num, z0 + off * zd


def _four(s: _Five, cam: Camera, inverse: bool, minslope: bool):
    """Directional curvatures k_u, k_v, k_g, k_b of the stencil's centre (inf where undefined)."""
    zu, nu, a = _line(s.zl, s.z0, s.zr, s.A, inverse, minslope)
    zv, nv, b = _line(s.zt, s.z0, s.zb, s.B, inverse, minslope)
    fx2, fy2 = cam.fx * cam.fx, cam.fy * cam.fy
    su = a * a + fx2 * zu * zu
    sv = b * b + fy2 * zv * zv
    ku = fx2 * nu.abs() / _pow15(su)
    kv = fy2 * nv.abs() / _pow15(sv)
    ia, ib = 1.0 / a, 1.0 / b
    c_x, c_y = cam.fx * zu * ia, cam.fy * zv * ib
    c_xx, c_yy = -fx2 * nu * ia * ia * ia, -fy2 * nv * ib * ib * ib
    kg = (_R2 * (c_xx + c_yy)).abs() / _pow15(1.0 + (_R2 * (c_x + c_y)) ** 2)
    kb = (_R2 * (c_xx - c_yy)).abs() / _pow15(1.0 + (_R2 * (c_x - c_y)) ** 2)
    okd = s.oku & s.okv & (a != 0) & (b != 0)
    inf = _inf_like(ku)
    return (torch.where(s.oku, ku, inf), torch.where(s.okv, kv, inf),
            torch.where(okd, kg, inf), torch.where(okd, kb, inf))


def _fundamental(s: _Five, cam: Camera, inverse: bool, minslope: bool, gauss: bool):
    zu, nu, a = _line(s.zl, s.z0, s.zr, s.A, inverse, minslope)
    zv, nv, b = _line(s.zt, s.z0, s.zb, s.B, inverse, minslope)
    fx2, fy2 = cam.fx * cam.fx, cam.fy * cam.fy
    c_x, c_y = cam.fx * zu / a, cam.fy * zv / b
    c_xx, c_yy = -fx2 * nu / (a * a * a), -fy2 * nv / (b * b * b)
    c_ll, c_tt = _R2 * (c_xx + c_yy), _R2 * (c_xx - c_yy)
    ll, mm, nn = c_xx * c_yy, c_xx * c_ll, c_tt * c_yy
    if gauss:
        val = (ll * nn - mm * mm).abs()
    else:
        num = ll * zu * zu + 2.0 * mm * zu * zv + nn * zv * zv
        den = (c_x * zu + c_y * zv) ** 2
        val = torch.where(den > 0, num.abs() / den,
                          torch.where(num == 0, torch.zeros_like(num), _inf_like(num)))
    ok = s.oku & s.okv & (a != 0) & (b != 0)
    return torch.where(ok, val, _inf_like(val))


def _pixel_line(zm, z0, zp):
    gc = 0.5 * (zp - zm)
    gl = z0 - zm
    gr = zp - z0
    g2 = torch.minimum(gc * gc, torch.minimum(gl * gl, gr * gr))
    return (gr - gl).abs() / _pow15(1.0 + g2)


def curvature(grid: Grid, cam: Camera, kind: str, derivatives: str, slope: str,
              footprint: str) -> torch.Tensor:
    """Depth curvature (B, H, W) of 3F2N+ (lower = smoother, inf where undefined), as
    :func:`depthnormals.ddm.depth_curvature`; no gradients."""
    with torch.no_grad():
        inverse = derivatives == "inverse-depth"
        minslope = slope == "min"
        if kind == "none":
            return torch.zeros_like(grid.zs)
        if kind in ("mean", "max") and footprint == "neighbours":
            # the eight directional values the neighbours point at q
            terms = []
            for (dv, du), which in (((0, -1), 0), ((0, 1), 0), ((-1, 0), 1), ((1, 0), 1),
                                    ((-1, -1), 2), ((1, 1), 2), ((-1, 1), 3), ((1, -1), 3)):
                s = _Five(grid, cam, dv, du)
                k = _four(s, cam, inverse, minslope)[which]
                terms.append(torch.where(s.ok0, k, _inf_like(k)))
            stack = torch.stack(terms)
            k = stack.amax(0) if kind == "max" else 0.125 * stack.sum(0)
            return torch.where(grid.valid, k, _inf_like(k))
        s = _Five(grid, cam)
        if kind in ("mean", "max"):
            ku, kv, kg, kb = _four(s, cam, inverse, minslope)
            if kind == "max":
                return torch.maximum(torch.maximum(ku, kv), torch.maximum(kg, kb))
            return 0.25 * (ku + kv + kg + kb)
        if kind == "pixel-mean":
            val = 0.5 * (_pixel_line(s.zl, s.z0, s.zr) + _pixel_line(s.zt, s.z0, s.zb))
            return torch.where(s.oku & s.okv, val, _inf_like(val))
        return _fundamental(s, cam, inverse, minslope, kind == "gauss")


def kendall_tau(grid: Grid) -> torch.Tensor:
    """Kendall's tau of the paper in each 3x3 patch: ``|mu_c - mu_d| / (mu_c + mu_d)`` over
    the valid neighbours deeper / shallower than the centre (0 when all tie; NaN at invalid
    depth); no gradients."""
    with torch.no_grad():
        z0 = grid.zs.detach()
        mc = torch.zeros_like(z0)
        md = torch.zeros_like(z0)
        for dv, du in _N8:
            zi, ok = grid.z(dv, du).detach(), grid.ok(dv, du)
            mc = mc + (ok & (zi > z0)).to(z0.dtype)
            md = md + (ok & (zi < z0)).to(z0.dtype)
        n = mc + md
        tau = (mc - md).abs() / torch.where(n > 0, n, torch.ones_like(n))
        return torch.where(grid.valid, tau, torch.full_like(tau, float("nan")))


def pearson_similarity(grid: Grid, dv: int, du: int) -> torch.Tensor:
    """|Pearson correlation| between the 3x3 depth patches of the neighbour at (dv, du) and of
    the pixel (pairs at equal offsets, both valid), as the numba ``pearson_pair``; no gradients."""
    with torch.no_grad():
        a0 = grid.z(dv, du).detach()
        b0 = grid.zs.detach()
        zero = torch.zeros_like(b0)
        n = zero
        sa = sb = saa = sbb = sab = zero
        for ov in (-1, 0, 1):
            for ou in (-1, 0, 1):
                ok = grid.ok(dv + ov, du + ou) & grid.ok(ov, ou)
                a = torch.where(ok, grid.z(dv + ov, du + ou).detach() - a0, zero)
                b = torch.where(ok, grid.z(ov, ou).detach() - b0, zero)
                n = n + ok.to(b0.dtype)
                sa, sb = sa + a, sb + b
                saa, sbb, sab = saa + a * a, sbb + b * b, sab + a * b
        nn = torch.clamp(n, min=1.0)
        va = saa - sa * sa / nn
        vb = sbb - sb * sb / nn
        scale = 1e-20 * (a0 * a0 + b0 * b0)
        flat_a, flat_b = va <= scale, vb <= scale
        r = (sab - sa * sb / nn).abs() / torch.sqrt(torch.where(flat_a | flat_b, torch.ones_like(va),
                                                                va * vb))
        r = torch.clamp(r, max=1.0)
        r = torch.where(flat_a | flat_b, zero, r)
        r = torch.where(flat_a & flat_b, torch.ones_like(r), r)
        return torch.where(n < 2, zero, r)


def _ratios(grid: Grid) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """(z_p / z_q, valid) of the left, right, up and down neighbours (detached)."""
    iz = 1.0 / grid.zs.detach()
    return [(grid.z(dv, du).detach() * iz, grid.ok(dv, du))
            for dv, du in ((0, -1), (0, 1), (-1, 0), (1, 0))]


def _side(r, ok, d, step):
    den = d + step
    num = r * den - d
    return torch.where(ok, num.abs(), torch.ones_like(num)), torch.where(ok, den.abs(),
                                                                          torch.zeros_like(den))


def _axis(m, p, d, step):
    nm, dm = _side(m[0], m[1], d, -step)
    np_, dp = _side(p[0], p[1], d, step)
    take_m = nm * dp < np_ * dm
    return torch.where(take_m, nm, np_), torch.where(take_m, dm, dp)


def inconsistency_pq(n: tuple[torch.Tensor, ...], ratios, cam: Camera):
    """One-sided tangent inconsistency ``S = P / Q`` of the normal ``n`` at each pixel
    (``min(rho_l, rho_r)^2 + min(rho_u, rho_d)^2`` in footprints^2, as the numba
    ``inconsistency_pq``); ``Q = 0`` means infinite."""
    a, b, t = n
    sa = a / cam.fx
    sb = b / cam.fy
    d = sa * cam.a + sb * cam.b + t
    nu, du = _axis(ratios[0], ratios[1], d, sa)
    nv, dv = _axis(ratios[2], ratios[3], d, sb)
    du2, dv2 = du * du, dv * dv
    return cam.fx * cam.fx * (nu * nu * dv2 + nv * nv * du2), du2 * dv2


def select_min(grid: Grid, cam: Camera, normals, ok, key, offs, self_weight: float,
               consistency: float | None):
    """Each valid pixel takes the normal of the candidate (``offs``, self first) with the
    least key: keys clamped to the dtype's largest float (a valid candidate always beats
    none), the pixel's own times ``self_weight``, a neighbour taken only when strictly
    smaller and (``consistency``) passing the tangent test ``S_c < S_own + consistency``
    unless ``S_own`` is undefined. NaN where no candidate has a normal."""
    nx, ny, nz = normals
    key = key.detach()
    big = torch.finfo(key.dtype).max
    inf = _inf_like(key)
    test = consistency is not None
    if test:
        ratios = _ratios(grid)
        det = tuple(c.detach() for c in normals)
        p0, q0 = inconsistency_pq(det, ratios, cam)
        lim = p0 / q0 + consistency
        free = ~(ok & (lim < float("inf")))
    best = inf
    bx, by, bz = nx, ny, nz
    for i, (dv, du) in enumerate(offs):
        cok = shift(ok, dv, du, False)
        cx, cy, cz = (shift(c, dv, du, 0.0) for c in (nx, ny, nz))
        k = torch.clamp(shift(key, dv, du, float("inf")), max=big)
        k = torch.where(torch.isnan(k), torch.full_like(k, big), k)
        if i == 0:
            k = k * self_weight
        k = torch.where(cok, k, inf)
        take = k < best
        if test and i > 0:
            pc, qc = inconsistency_pq((cx.detach(), cy.detach(), cz.detach()), ratios, cam)
            take = take & (free | (pc < lim * qc))
        best = torch.where(take, k, best)
        bx, by, bz = torch.where(take, cx, bx), torch.where(take, cy, by), torch.where(take, cz, bz)
    return oriented(bx, by, bz, cam, grid.valid & (best < float("inf")))


def crf_step(grid: Grid, cam: Camera, cur, cur_ok, anchor, anchor_ok, kq, sims, offs,
             sigma: float, lam: float):
    """One synchronous pass of the per-pixel CRF minimisation (see
    :func:`depthnormals.ddm.discontinuity_discrimination`): for each candidate normal c of
    ``offs`` (self first), ``E(c) = sigma |c - anchor| + lam k_q sum_i s_i |n_i - c|`` over
    the valid 8-neighbours; the least energy wins (the first of equal ones)."""
    with torch.no_grad():
        cd = torch.stack([c.detach() for c in cur], dim=1)  # (B, 3, H, W)
        ad = torch.stack([c.detach() for c in anchor], dim=1)
        k = torch.where(kq < _BIG, kq, torch.full_like(kq, _BIG)) * lam
        nbr, wts = [], []
        for (dv, du), s in zip(_N8, sims):  # noqa: B905
            okn = shift(cur_ok, dv, du, False)
            nbr.append(torch.stack([shift(cd[:, j], dv, du, 0.0) for j in range(3)], dim=1))
            wts.append(torch.where(okn, s, torch.zeros_like(s)))
        nbr = torch.stack(nbr, dim=1)  # (B, 8, 3, H, W)
        wts = torch.stack(wts, dim=1)  # (B, 8, H, W)
        energies = []
        for dv, du in offs:
            c = torch.stack([shift(cd[:, j], dv, du, 0.0) for j in range(3)], dim=1)
            e = sigma * torch.linalg.vector_norm(c - ad, dim=1)
            e = torch.where(anchor_ok, e, torch.zeros_like(e))
            e = e + k * (wts * torch.linalg.vector_norm(nbr - c[:, None], dim=2)).sum(1)
            energies.append(torch.where(shift(cur_ok, dv, du, False), e, _inf_like(e)))
    best = energies[0]
    bx, by, bz = cur
    found = best < float("inf")
    for i, (dv, du) in enumerate(offs):
        if i == 0:
            continue
        take = energies[i] < best
        best = torch.where(take, energies[i], best)
        bx = torch.where(take, shift(cur[0], dv, du, 0.0), bx)
        by = torch.where(take, shift(cur[1], dv, du, 0.0), by)
        bz = torch.where(take, shift(cur[2], dv, du, 0.0), bz)
        found = found | take
    return oriented(bx, by, bz, cam, grid.valid & found)


def refine(grid: Grid, cam: Camera, normals, ok, o: dict):
    """The three stages of the DDM on the estimator's normals (nx, ny, nz) and their ``ok``."""
    offs = CROSS if o["neighbourhood"] == "cross" else SQUARE
    kind = o["curvature"]
    k = curvature(grid, cam, kind, o["derivatives"], o["slope"], o["footprint"])
    n0 = select_min(grid, cam, normals, ok, k, offs, o["self_weight"], o["consistency"])
    corr, crf = o["correlation"], o["crf"]
    tau = kendall_tau(grid) if corr in ("kendall", "kendall-prose") else None
    if not crf:
        if tau is None:
            return n0
        key = tau if corr == "kendall" else -tau
        key = torch.where(torch.isnan(key), _inf_like(key), key)
        return select_min(grid, cam, n0[:3], n0[3], key, offs, 1.0, None)
    kq = k * grid.zs.detach() if kind in ("mean", "max") else k
    kq = torch.where(torch.isnan(kq), torch.full_like(kq, _BIG), kq)
    with torch.no_grad():
        if corr == "kendall":
            sims = [shift(1.0 - tau, dv, du, 0.0) for dv, du in _N8]
        elif corr == "kendall-prose":
            sims = [shift(tau, dv, du, 0.0) for dv, du in _N8]
        elif corr == "pearson":
            sims = [pearson_similarity(grid, dv, du) for dv, du in _N8]
        else:
            sims = [torch.ones_like(grid.zs) for _ in _N8]
        sims = [torch.where(torch.isnan(s), torch.zeros_like(s), s).detach() for s in sims]
    cur = n0
    for _ in range(o["iterations"]):
        cur = crf_step(grid, cam, cur[:3], cur[3], n0[:3], n0[3], kq, sims, offs, o["sigma"], o["lam"])
    return cur
