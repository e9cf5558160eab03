"""The face switch of the measured support in torch (:mod:`depthnormals.ddm.faceswitch`: read it
for the rule; ours, not the paper's).

The same sums in the same order as the numba kernel, in float64: each cell's points (those with
depth and a normal) summed over three columns, then over three rows; the cosines between the
normals in float32 (as the numba kernel stores the normals), the distances in float64 from the
float32 normals. The decision has no gradient; a cell that switches takes its neighbour's normal,
and with it the gradient of that normal's window.
"""

from __future__ import annotations

import math

import torch

from ..ddm.faceswitch import ANGLE, DIRECTIONS, JUMP, MARGIN
from ._common import first_least, shifted_views, stack_width, take_at
from ._common import shift as _at

__all__ = ["switch_faces"]

_DIRECTIONS = [(int(dv), int(du)) for dv, du in DIRECTIONS]


def _sum3(x: torch.Tensor) -> torch.Tensor:
    """``x`` (..., B, H, W) summed over each pixel's 3x3 (zeros outside): along the row
    (left + centre, then + right), then along the column (above + centre, then + below), as
    :func:`depthnormals.ddm.faceswitch._row_moments` and ``_sums_row`` add them."""
    z = torch.zeros_like(x[..., :1])
    left = torch.cat((z, x[..., :-1]), -1)
    right = torch.cat((x[..., 1:], z), -1)
    row = left + x + right
    z = torch.zeros_like(row[..., :1, :])
    above = torch.cat((z, row[..., :-1, :]), -2)
    below = torch.cat((row[..., 1:, :], z), -2)
    return above + row + below


def switch_faces(z: torch.Tensor, n: tuple, cam, span: int) -> tuple:
    """:func:`depthnormals.ddm.faceswitch.switch_faces` for a batch: ``z`` (B, H, W) float64
    depth (NaN where invalid), ``n = (nx, ny, nz, ok)`` the chosen normals facing the camera
    (float64; ``ok`` where there is one), ``cam`` the grid's (fx, fy, cx, cy), ``span`` in
    cells. Returns (nx, ny, nz, ok) with the switched cells' normals taken from their
    neighbours."""
    nx, ny, nz, ok = n
    fx, fy, cx, cy = cam
    h, w = z.shape[-2:]
    dev = z.device
    with torch.no_grad():
        good = ok & (z == z)
        # the normals as the numba kernel stores them (float32), NaN where not good
        nan32 = torch.full(z.shape, math.nan, dtype=torch.float32, device=dev)
        nf = [torch.where(good, q.detach().float(), nan32) for q in (nx, ny, nz)]
        zg = torch.where(good, z, torch.zeros_like(z))
        u = torch.arange(w, dtype=z.dtype, device=dev).reshape(1, 1, w)
        v = torch.arange(h, dtype=z.dtype, device=dev).reshape(1, h, 1)
        x = (u - cx) / fx * zg  # 0 where not good, as zg
        y = (v - cy) / fy * zg
        ch = torch.stack((good.to(z.dtype), x, y, zg, x * x, x * y, x * zg, y * y, y * zg,
                          zg * zg))
        s = _sum3(ch)
        ic = 1.0 / s[0]
        p = [s[1] * ic, s[2] * ic, s[3] * ic]
        cov = [s[4] * ic - p[0] * p[0], s[5] * ic - p[0] * p[1], s[6] * ic - p[0] * p[2],
               s[7] * ic - p[1] * p[1], s[8] * ic - p[1] * p[2], s[9] * ic - p[2] * p[2]]
        # a jump in the 3x3: no switch (NaN neighbours and outside are none)
        smooth = good.clone()
        for dv in (-1, 0, 1):
            for du in (-1, 0, 1):
                zq = _at(z, dv, du, math.nan)
                smooth &= ~((zq - z).abs() > JUMP * z)

        def distance(qn, qs):
            """The mean squared distance of each cell's 3x3 to the plane of the normals ``qn``
            (float32) through the centroids of the sums ``qs``."""
            qx, qy, qz = (q.double() for q in qn)
            iq = 1.0 / qs[0]
            d = qx * (p[0] - qs[1] * iq) + qy * (p[1] - qs[2] * iq) + qz * (p[2] - qs[3] * iq)
            m = (qx * qx * cov[0] + qy * qy * cov[3] + qz * qz * cov[5]
                 + 2.0 * (qx * qy * cov[1] + qx * qz * cov[2] + qy * qz * cov[4]))
            return m + d * d

        cm = torch.tensor(math.cos(math.radians(ANGLE)), dtype=torch.float32)
        inf = torch.full_like(z, math.inf)
        other, same = inf, distance(nf, s)
        best = torch.full(z.shape, -1, dtype=torch.long, device=dev)
        # the directions in chunks (:func:`._common.stack_width`: all eight at once on a GPU,
        # one by one on the CPU); the first least distance wins (:func:`._common.first_least`),
        # as the numba kernel's loop over the directions takes it
        offsets = [(span * dv, span * du) for dv, du in _DIRECTIONS]
        nfs = shifted_views(torch.stack(nf), offsets, math.nan)
        ss = shifted_views(s[:4], offsets, 0.0)
        per = stack_width(z, len(_DIRECTIONS))
        for k0 in range(0, len(_DIRECTIONS), per):
            qn = torch.stack(nfs[k0:k0 + per], 1)
            qs = torch.stack(ss[k0:k0 + per], 1)
            dot = nf[0] * qn[0] + nf[1] * qn[1] + nf[2] * qn[2]
            dot = torch.where(dot == dot, dot, torch.full_like(dot, 2.0))
            m = distance(qn, qs)
            is_other = dot < cm
            other, best = first_least(torch.where(is_other, m, math.inf), other, best, k0)
            own = torch.where(~is_other & (dot <= 1.5) & (m == m), m, math.inf).amin(0)
            same = torch.where(own < same, own, same)
        switch = smooth & (best >= 0) & (other < MARGIN * same)
    if not bool(switch.any()):
        return n, switch
    # a switched cell takes the normal of its neighbour ``best`` (inside the image: one outside
    # has no normal, so it is no other face)
    dirs = torch.tensor(_DIRECTIONS, dtype=torch.long, device=dev) * span
    k = best.clamp(min=0)
    out = take_at(torch.where(switch, dirs[k, 0], 0), torch.where(switch, dirs[k, 1], 0), nx, ny, nz)
    return (*out, ok), switch
