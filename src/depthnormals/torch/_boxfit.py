"""The noisy branches of the default 3F2N+ in torch: box-fit windows and their choices.

The same rules, constants and order of decisions as :mod:`depthnormals.ddm.boxfit`,
:func:`depthnormals.ddm.auto.box_select` (independent noise) and
:func:`depthnormals.ddm.support.support_select` (the measured support of real sensors); read
them for the method (ours, not the paper's).

The ten window sums of every pixel are separable, in float64: a row pass (the count, ``1 / z``
and ``1 / z^2`` against ``1, du, du^2``), then a column pass (against ``1, dv, dv^2``), each a
cumulative sum along its own axis (:func:`_sums`): nothing loops over windows, and the
partial sums stay within one row or column, so their rounding is of the order of the numba
running sums'. The planes are solved for every pixel at once
(the adjugate of the 3x3 normal equations). What the numba kernels store in float32 and
compare (residual variances, planes, gates) is rounded to float32 here before it is compared,
so both libraries take the same decisions; the normals themselves are computed in float64
from the float64 planes and carry gradients.

Gradients: the normal of a window is a smooth function of the depths in it (a least-squares
plane), so the output is differentiable with respect to depth wherever it is finite; the
choice of the window (residual tests, the least score of nine, the large window's gate) is
discrete and has no gradient: the chosen window's plane carries the gradient of its pixels.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..ddm.auto import _slopes as _auto_slopes
from ..ddm.boxfit import LOCAL_CAP, MIN_POINTS, SHIFTS
from ..ddm.support import DEVIATION, FALLBACK_RADIUS
from ..kernels.eig3 import sym3_adjugate_apply
from ._common import first_least, shifted_views, stack_width, take_at

__all__ = ["Fits", "box_fits", "choose_least", "choose_local", "choose_plain", "keep_estimator",
           "upsample_half"]

_SHIFTS = [tuple(int(x) for x in s) for s in SHIFTS]  # (dv, du), the centred window first
#: the numba kernel's adjugate of the normal equations, its Python body run on tensors (the same
#: formula, elementwise; read once here, so torch.compile traces a plain function)
_ADJUGATE = sym3_adjugate_apply.py_func
#: the inverse-depth slopes of a normal (:func:`depthnormals.ddm.auto._slopes`), likewise
_SLOPES = _auto_slopes.py_func


def _f32(x: torch.Tensor) -> torch.Tensor:
    """``x`` rounded to float32 and back (what the numba kernels store), no gradient."""
    return x.detach().float().double()


class Fits:
    """Centred-window fits of radius ``r`` on (B, H, W) depth: the plane ``w = a du + b dv +
    c`` of ``1 / z`` around every pixel (float64, with gradients), the normal
    ``(fx a, fy b, c - a (u - cx) - b (v - cy))`` (not unit, not turned), whether the window
    has a fit (``good``) and its residual variance in footprints^2 as the numba kernels
    store it (float32 values in float64, inf where no fit; no gradient)."""

    def __init__(self, a, b, c, good, score, cam):
        self.a, self.b, self.c, self.good, self.score = a, b, c, good, score
        self.cam = cam

    def normal(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        fx, fy, cx, cy = self.cam
        h, w = self.a.shape[-2:]
        au = torch.arange(w, dtype=self.a.dtype, device=self.a.device).reshape(1, 1, w) - cx
        bv = torch.arange(h, dtype=self.a.dtype, device=self.a.device).reshape(1, h, 1) - cy
        return fx * self.a, fy * self.b, self.c - self.a * au - self.b * bv


def _box(x: torch.Tensor, r: int, dim: int) -> torch.Tensor:
    """Sums of ``x`` over ``[i - r, i + r]`` along ``dim`` (-1 or -2), zero outside: a
    cumulative sum along that one axis (rows of W, or columns of H, so its partial sums stay
    small) and one difference."""
    n = x.shape[dim]
    pad = (r + 1, r) if dim == -1 else (0, 0, r + 1, r)
    c = torch.cumsum(F.pad(x, pad), dim=dim)
    return c.narrow(dim, 2 * r + 1, n) - c.narrow(dim, 0, n)


def _sums(x: torch.Tensor, m: torch.Tensor, r: int) -> list[torch.Tensor]:
    """The ten window sums (count, du, dv, du^2, du dv, dv^2, w, du w, dv w, w^2) of every
    pixel's ``(2 r + 1)^2`` window, float64 (B, H, W) each; ``x`` is ``1 / z`` (0 at invalid
    pixels), ``m`` the validity as 0 / 1.

    Separable: a row pass (six sums over du), then a column pass (ten over dv), each a
    cumulative sum along its own axis. Moments in the window's own offsets come from those in
    image coordinates (``sum du x = sum u' x - u sum x``): exact for the counts (integers
    below 2^53), rounding ~1e-16 of the row's or column's partial sums for the depth terms
    (the numba kernels' running sums round alike; tests/test_torch_default_parity.py)."""
    h, w = x.shape[-2:]
    u = torch.arange(w, dtype=x.dtype, device=x.device).reshape(1, 1, w)
    v = torch.arange(h, dtype=x.dtype, device=x.device).reshape(1, h, 1)
    # row pass
    n0 = _box(m, r, -1)
    s1 = _box(m * u, r, -1)
    s2 = _box(m * (u * u), r, -1)
    rw = _box(x, r, -1)
    ruw = _box(x * u, r, -1) - u * rw
    rww = _box(x * x, r, -1)
    ru = s1 - u * n0
    ruu = s2 - 2.0 * u * s1 + (u * u) * n0
    # column pass
    n = _box(n0, r, -2)
    su = _box(ru, r, -2)
    suu = _box(ruu, r, -2)
    sw = _box(rw, r, -2)
    suw = _box(ruw, r, -2)
    sww = _box(rww, r, -2)
    vn = _box(v * n0, r, -2)
    sv = vn - v * n
    svv = _box((v * v) * n0, r, -2) - 2.0 * v * vn + (v * v) * n
    suv = _box(v * ru, r, -2) - v * su
    svw = _box(v * rw, r, -2) - v * sw
    return [n, su, sv, suu, suv, svv, sw, suw, svw, sww]


def _solve(n, su, sv, suu, suv, svv, sw, suw, svw, sww):
    """:func:`depthnormals.ddm.boxfit.solve_window` elementwise: (a, b, c, rss, ok)."""
    x, y, t, det = _ADJUGATE(suu, suv, su, svv, sv, n, suw, svw, sw)
    ok = (n >= MIN_POINTS) & (det > 1e-9 * n * n * n)
    inv = 1.0 / torch.where(ok, det, torch.ones_like(det))
    a, b, c = x * inv, y * inv, t * inv
    rss = sww - (a * suw + b * svw + c * sw)
    return a, b, c, torch.clamp(rss, min=0.0), ok


def box_fits(zs: torch.Tensor, valid: torch.Tensor, r: int, cam) -> Fits:
    """The centred ``(2 r + 1)^2`` window fits of every pixel (:func:`ddm.boxfit.box_fit_windows`).

    ``zs`` (B, H, W) float64 depth with a safe value (1) at invalid pixels, ``valid`` its
    mask, ``cam`` ``(fx, fy, cx, cy)`` as (B or 1, 1, 1) float64 tensors."""
    m = valid.to(zs.dtype)
    x = torch.where(valid, 1.0 / zs, torch.zeros_like(zs))
    s = _sums(x, m, r)
    a, b, c, rss, ok = _solve(*s)
    fx = cam[0]
    n = s[0]
    good = ok & (c > 0.0)
    den = torch.where(good, (n - 3.0) * c * c, torch.ones_like(c))
    with torch.no_grad():
        score = torch.where(good, _f32(rss * (fx * fx) / den), torch.full_like(c, float("inf")))
    return Fits(a, b, c, good, score, cam)


def _ray_facing(nx, ny, nz, cam, ok):
    """(nx, ny, nz) normalised and turned toward each pixel's ray where ``ok`` (NaN
    elsewhere is applied by the caller): as ``store_normal``; safe for gradients."""
    fx, fy, cx, cy = cam
    h, w = nx.shape[-2:]
    rx = (torch.arange(w, dtype=nx.dtype, device=nx.device).reshape(1, 1, w) - cx) / fx
    ry = (torch.arange(h, dtype=nx.dtype, device=nx.device).reshape(1, h, 1) - cy) / fy
    n2 = nx * nx + ny * ny + nz * nz
    ok = ok & (n2 > 0) & torch.isfinite(n2)
    inv = torch.rsqrt(torch.where(ok, n2, torch.ones_like(n2)))
    dot = nx * rx + ny * ry + nz  # the plane's inverse depth: no tie (as the numba box fit)
    inv = torch.where(ok, torch.where(dot > 0, -inv, inv), torch.zeros_like(inv))
    return nx * inv, ny * inv, nz * inv, ok


def _gather_plane(f: Fits, k: torch.Tensor, shift: int):
    """The plane (a, b, c) and centre offset (dv, du) of window ``k`` (index into SHIFTS) per
    pixel; every chooser picks only windows inside the image (those outside score inf)."""
    d = torch.tensor(_SHIFTS, dtype=torch.long, device=k.device) * shift
    dvs, dus = d[k, 0], d[k, 1]
    a, b, c = take_at(dvs, dus, f.a, f.b, f.c)
    return a, b, c, dvs, dus


def _shifted(s0: torch.Tensor, shift: int, shifts) -> torch.Tensor:
    """``s0`` read at each of the offsets ``shifts`` (times ``shift``; inf outside the image),
    stacked (K, B, H, W): the candidates of the numba kernels' running ``sk < best`` over the
    windows in order (:func:`._common.first_least`)."""
    return torch.stack(shifted_views(s0, [(shift * dv, shift * du) for dv, du in shifts], float("inf")))


def _plane_normal(a, b, c, dvs, dus, cam):
    """The normal of the plane ``w = a du + b dv + c`` around the window centre (v + dvs,
    u + dus), in camera coordinates (not unit)."""
    fx, fy, cx, cy = cam
    h, w = a.shape[-2:]
    u = torch.arange(w, dtype=a.dtype, device=a.device).reshape(1, 1, w)
    v = torch.arange(h, dtype=a.dtype, device=a.device).reshape(1, h, 1)
    return fx * a, fy * b, c - a * (u + dus - cx) - b * (v + dvs - cy)


def _chosen(fits: Fits, big: Fits | None, kbest, found, take_big, valid, shift: int, cam):
    """The normal of each pixel's chosen window ``kbest`` (index into SHIFTS; none where not
    ``found``), the large window's where ``take_big``; (nx, ny, nz, ok) facing the camera."""
    a, b, c, dvs, dus = _gather_plane(fits, kbest, shift)
    nx, ny, nz = _plane_normal(a, b, c, dvs, dus, cam)
    ok = valid & found
    if big is not None:
        bx, by, bz = big.normal()
        nx, ny, nz = (torch.where(take_big, q, p) for p, q in ((nx, bx), (ny, by), (nz, bz)))
        ok = torch.where(take_big, big.good, ok)
    return _ray_facing(nx, ny, nz, cam, ok)


def choose_local(zs, valid, fits: Fits, big: Fits | None, shift: int, gate: torch.Tensor,
                 big_gate: torch.Tensor, inv_var: torch.Tensor, scale: torch.Tensor, cam):
    """:func:`depthnormals.ddm.boxfit._choose_local_rows` for a batch: the large window where
    its residual is within ``big_gate f``, else the centred one within ``gate f``, else the
    one of the nine whose plane explains the pixel's own 3x3 best (squared residuals in noise
    units ``f / inv_var``, each capped at LOCAL_CAP). ``scale`` (B, H, W) is ``f``, the tile's
    variance over the frame's; ``gate``, ``big_gate``, ``inv_var`` (B, 1, 1) float64.
    Returns (nx, ny, nz, ok), facing the camera."""
    fx = cam[0]
    h, w = zs.shape[-2:]
    zd = zs.detach()
    with torch.no_grad():
        fsd = fx * torch.sqrt(inv_var) / torch.sqrt(scale)
        take_big = valid & (big.score <= big_gate * scale) if big is not None else \
            torch.zeros_like(valid)
        centred = fits.score <= gate * scale
        pa, pb, pc = _f32(fits.a), _f32(fits.b), _f32(fits.c)
        u = torch.arange(w, dtype=zs.dtype, device=zs.device).reshape(1, 1, w)
        v = torch.arange(h, dtype=zs.dtype, device=zs.device).reshape(1, h, 1)
        kc_all = pc - pa * u - pb * v  # the plane in image coordinates, at its own window
        # the 3x3 stacked (9, B, H, W): z fsd, u, v, ok, its residuals computed ``g`` at a
        # time (:func:`._common.stack_width`) and added in the numba kernel's order
        nine = [(dv, du) for dv in (-1, 0, 1) for du in (-1, 0, 1)]
        g = stack_width(zd, 9)
        zi = torch.stack(shifted_views(zd, nine, 1.0)) * fsd
        oki = torch.stack(shifted_views(valid, nine, False))
        ui = torch.stack([u + du for _, du in nine])
        vi = torch.stack([v + dv for dv, _ in nine])
        offsets = [(shift * dv, shift * du) for dv, du in _SHIFTS]
        views = [shifted_views(q, offsets, f) for q, f in
                 ((pa, 0.0), (pb, 0.0), (kc_all, 0.0), (fits.score, float("inf")))]
        best = torch.full_like(zd, float("inf"))
        kbest = torch.zeros(zd.shape, dtype=torch.long, device=zd.device)
        for i in range(len(_SHIFTS)):
            ka, kb, kc, sc = (q[i] for q in views)
            exists = sc < float("inf")
            sk = torch.zeros_like(zd)
            for j in range(0, 9, g):
                sl = slice(j, j + g)
                res = fsd - zi[sl] * (ka * ui[sl] + kb * vi[sl] + kc)
                for t in torch.where(oki[sl], torch.clamp(res * res, max=LOCAL_CAP), 0.0):
                    sk = sk + t
            sk = torch.where(exists, sk, float("inf"))
            take = sk < best
            best = torch.where(take, sk, best)
            kbest = torch.where(take, i, kbest)
        kbest = torch.where(centred, 0, kbest)
        found = centred | (best < float("inf"))
    return _chosen(fits, big, kbest, found, take_big, valid, shift, cam)


def choose_plain(valid, fits: Fits, big: Fits | None, shift: int, gate: float, big_gate: float,
                 self_weight: float, cam):
    """:func:`depthnormals.ddm.boxfit._choose_rows` (no noise level): the large window within
    ``big_gate``, else the centred one within ``gate``, else the least residual of the nine
    (the centred one's times ``self_weight``). Returns (nx, ny, nz, ok) facing the camera."""
    with torch.no_grad():
        s0 = fits.score
        best = s0 * self_weight
        kbest = torch.zeros(s0.shape, dtype=torch.long, device=s0.device)
        search = ~(s0 <= gate)
        cand = torch.where(search, _shifted(s0, shift, _SHIFTS[1:]), float("inf"))
        best, kbest = first_least(cand, best, kbest, 1)
        found = best < float("inf")
        take_big = valid & (big.score <= big_gate) if big is not None else torch.zeros_like(valid)
    return _chosen(fits, big, kbest, found, take_big, valid, shift, cam)


def _growth(zs: torch.Tensor, zref: torch.Tensor, half: torch.Tensor) -> torch.Tensor:
    """:func:`depthnormals.ddm.support._gate_growth` in float32: ``(z / zref)^(half / 2)``
    (``half`` 0..4 per frame, (B, 1, 1); 0: 1)."""
    izref = torch.where(zref > 0, 1.0 / zref, torch.zeros_like(zref)).float()
    t = zs.float() * izref
    q = torch.sqrt(t)
    g = torch.where(half == 4, t * t, torch.where(half == 3, t * q, torch.where(half == 2, t, q)))
    return torch.where(half > 0, g, torch.ones_like(g))


def _fallback(n, dev, zreal, vreal, cam):
    """:func:`depthnormals.ddm.support._fallback_rows`: where ``dev`` exceeds
    :data:`~depthnormals.ddm.support.DEVIATION`, the least residual (float32, as the numba
    kernels store it) of the nine windows of radius
    :data:`~depthnormals.ddm.support.FALLBACK_RADIUS` that hold the pixel (on the depth
    ``zreal``, valid where ``vreal``); ``n`` elsewhere."""
    rs = FALLBACK_RADIUS
    flag = dev > DEVIATION
    if not bool(flag.any()):
        return n
    small = box_fits(torch.where(vreal, zreal, torch.ones_like(zreal)), vreal, rs, cam)
    score = small.score
    zero = torch.zeros_like(score, dtype=torch.long)
    fx_, fy_, fz_ = _plane_normal(small.a, small.b, small.c, zero, zero, cam)
    # in order: the first of equal scores wins
    best, k = first_least(_shifted(score, rs, _SHIFTS), torch.full_like(score, float("inf")),
                          torch.zeros(score.shape, dtype=torch.long, device=score.device), 0)
    found = best < float("inf")
    d = torch.tensor(_SHIFTS, dtype=torch.long, device=k.device) * rs
    bx, by, bz = (torch.where(found, q, 0.0) for q in take_at(d[k, 0], d[k, 1], fx_, fy_, fz_))
    use = flag & found
    fb = _ray_facing(bx, by, bz, cam, use)
    return (*tuple(torch.where(use, q, p) for p, q in zip(n[:3], fb[:3], strict=True)), n[3])


def _deviation(zs, a, b, c, du, dv, unit, fac, cam):
    """:func:`depthnormals.ddm.support._deviation`: how many standard deviations (``unit``
    the inverse plane residual variance at ``zref``, growing with ``fac``) the depth ``zs``
    lies off the plane ``w = a du + b dv + c`` (the pixel ``(du, dv)`` from its centre),
    float32 as that kernel stores it."""
    with torch.no_grad():
        w = (c + a * du + b * dv).detach()
        d = ((1.0 / zs - w) * cam[0] / w).abs() * torch.sqrt(unit / fac.double())
        return torch.where(torch.isfinite(d), d, torch.zeros_like(d)).float()


def choose_least(zs, valid, fits: Fits, big: Fits | None, shift: int, gate: torch.Tensor,
                 zref: torch.Tensor, half: torch.Tensor, cam, big_scale: int = 2,
                 fallback: tuple | None = None):
    """:func:`depthnormals.ddm.support._choose_least_rows` for a batch: the large window
    (fitted on every second row and column, ``big``; a pixel reads cell (v // 2, u // 2))
    where its score is within the gate, else the centred window within the gate, else the
    least score of the nine (the centred one wins ties); gates (B, 1, 1) in float32 grow
    with depth as ``(z / zref)^(half / 2)``. ``fallback = (unit, zreal, vreal)``: then the
    pixels whose depth deviates from their window's plane (``unit`` (B, 1, 1) the inverse
    plane residual variance at ``zref``, footprints of this grid) take small windows on the
    depth ``zreal`` (valid where ``vreal``; ``zs`` may fill it), as
    :func:`depthnormals.ddm.support._choose` (where ``shift`` exceeds its radius). Returns
    (nx, ny, nz, ok) facing the camera."""
    h, w = zs.shape[-2:]
    with torch.no_grad():
        fac = _growth(zs.detach(), zref, half)
        g0 = gate.float() * fac
        s0 = fits.score.float()
        best = torch.where(s0 <= g0, torch.full_like(s0, -1.0), s0)
        best, kbest = first_least(_shifted(s0, shift, _SHIFTS[1:]), best,
                                  torch.zeros(s0.shape, dtype=torch.long, device=s0.device), 1)
        found = best < float("inf")
        if big is not None:
            bs = big.score.float().repeat_interleave(big_scale, -2).repeat_interleave(big_scale, -1)
            take_big = bs[:, :h, :w] <= g0
    a, b, c, dvs, dus = _gather_plane(fits, kbest, shift)
    nx, ny, nz = _plane_normal(a, b, c, dvs, dus, cam)
    ok = valid & found
    want = fallback is not None and shift > FALLBACK_RADIUS
    if want:
        dev = _deviation(zs, a, b, c, -dus, -dvs, fallback[0], fac, cam)
    if big is not None:
        def up(q):
            return q.repeat_interleave(big_scale, -2).repeat_interleave(big_scale, -1)[:, :h, :w]

        bx, by, bz = (up(q) for q in big.normal())
        bgood = up(big.good)
        nx, ny, nz = (torch.where(take_big, q, p) for p, q in ((nx, bx), (ny, by), (nz, bz)))
        ok = ok & torch.where(take_big, bgood, torch.ones_like(ok))
        if want:  # the pixel from its large window's centre, in cells of that grid
            u = torch.arange(w, device=zs.device).reshape(1, 1, w)
            v = torch.arange(h, device=zs.device).reshape(1, h, 1)
            bdu = (u - big_scale * (u // big_scale)).to(zs.dtype) / big_scale
            bdv = (v - big_scale * (v // big_scale)).to(zs.dtype) / big_scale
            bdev = _deviation(zs, up(big.a), up(big.b), up(big.c), bdu, bdv, fallback[0], fac,
                              cam)
            dev = torch.where(take_big, bdev, dev)
    n = _ray_facing(nx, ny, nz, cam, ok)
    if not want:
        return n
    dev = torch.where(ok & fallback[2], dev, torch.zeros_like(dev))
    return _fallback(n, dev, fallback[1], fallback[2], cam)


def upsample_half(n, valid_full, cam_full):
    """Every pixel takes the normal of its 2x2 cell (``n`` = (nx, ny, nz, ok) on every second
    row and column), turned toward its own ray; not ok where its depth is invalid."""
    h, w = valid_full.shape[-2:]
    up = [q.repeat_interleave(2, -2).repeat_interleave(2, -1)[:, :h, :w] for q in n]
    return _ray_facing(up[0], up[1], up[2], cam_full, up[3] & valid_full)


def keep_estimator(base, out, zs, kappa: torch.Tensor, cam):
    """:func:`depthnormals.ddm.auto._keep_rows`: where the estimator's normal ``base``
    (nx, ny, nz, ok) agrees with the box-fit's ``out`` within ``kappa`` (squared distance of
    their inverse-depth slopes, (B, 1, 1)), the estimator's normal; not ok where the
    estimator has none."""
    fx, fy, cx, cy = cam
    h, w = zs.shape[-2:]
    A = torch.arange(w, dtype=zs.dtype, device=zs.device).reshape(1, 1, w) - cx
    B = torch.arange(h, dtype=zs.dtype, device=zs.device).reshape(1, h, 1) - cy
    with torch.no_grad():
        ifx, ify = 1.0 / fx, 1.0 / fy
        # both as the numba kernels store them (float32), their slopes by the kernel's formula
        # (a zero denominator gives inf / NaN there as here: never kept)
        pa, pb = _SLOPES(*(q.detach().float().to(zs.dtype) for q in base[:3]), A, B, ifx, ify)
        qa, qb = _SLOPES(*(q.detach().float().to(zs.dtype) for q in out[:3]), A, B, ifx, ify)
        keep = base[3] & out[3] & ((pa - qa) ** 2 + (pb - qb) ** 2 < kappa)
    nx, ny, nz = (torch.where(keep, p.to(q.dtype), q) for p, q in zip(base[:3], out[:3], strict=True))
    return _ray_facing(nx, ny, nz, cam, base[3] & out[3])

