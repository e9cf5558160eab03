"""Input preparation and the shared pieces of every torch estimator.

Discipline (so that gradients are finite wherever the output is): invalid depth is replaced by
a safe value (1) before any arithmetic and carried as a boolean mask; every division,
square root and exponential sees finite, safe operands; NaN enters only in the very last
``torch.where`` of :func:`finish`. No tensor that carries gradients is written in place, and
nothing reads a tensor's value on the host (no ``.item()``, no branching on data), so the
code runs asynchronously on a GPU and traces under ``torch.compile``.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F

from ..camera import Intrinsics, as_intrinsics
from ..kernels.orient import TIE_COS2

__all__ = ["STACK_ELEMENTS", "STACK_ON_CPU", "Camera", "Grid", "camera", "finish", "first_least",
           "oriented", "prepare", "shift", "shifted_views", "stack_width", "take_at"]


@dataclass(frozen=True)
class Camera:
    """Intrinsics as tensors broadcasting against (B, H, W) maps: each (B or 1, 1, 1)."""

    fx: torch.Tensor
    fy: torch.Tensor
    cx: torch.Tensor
    cy: torch.Tensor
    a: torch.Tensor  # u - cx, (B or 1, 1, W)
    b: torch.Tensor  # v - cy, (B or 1, H, 1)


def _check_scale(depth_scale: Any) -> float | None:
    if depth_scale is None:
        return None
    if isinstance(depth_scale, bool) or not isinstance(depth_scale, numbers.Real):
        raise TypeError(f"depth_scale must be a positive real number; got {type(depth_scale).__name__}")
    value = float(depth_scale)
    if not (value > 0.0 and value < float("inf")):
        raise ValueError(f"depth_scale must be finite and > 0; got {depth_scale!r}")
    return value


def _as_depth(depth: Any, depth_scale: float | None) -> tuple[torch.Tensor, torch.dtype]:
    """(depth as (B, H, W) in the compute dtype, the output dtype)."""
    if not isinstance(depth, torch.Tensor):
        raise TypeError(
            "depth must be a torch.Tensor of shape (B, 1, H, W) or (B, H, W); got "
            f"{type(depth).__name__} (use torch.as_tensor, or depthnormals.estimate_normals for numpy)"
        )
    if depth.dtype == torch.bool or depth.is_complex():
        raise TypeError(f"depth must hold real numbers (a float dtype, or integers with depth_scale); "
                        f"got {depth.dtype}")
    if depth.ndim == 4:
        if depth.shape[1] != 1:
            raise ValueError(f"depth of 4 dimensions must be (B, 1, H, W); got shape {tuple(depth.shape)}")
        depth = depth[:, 0]
    elif depth.ndim != 3:
        hint = " (add a batch dimension: depth[None])" if depth.ndim == 2 else ""
        raise ValueError(f"depth must be (B, 1, H, W) or (B, H, W); got shape {tuple(depth.shape)}{hint}")
    if depth.numel() == 0:
        raise ValueError(f"depth is empty (shape {tuple(depth.shape)}); it needs at least one pixel")
    if depth.dtype.is_floating_point:
        out_dtype = depth.dtype
        work = torch.float64 if depth.dtype == torch.float64 else torch.float32
        z = depth.to(work)
    else:
        if depth_scale is None:
            raise TypeError(f"depth has integer dtype {depth.dtype}; pass depth_scale (metres per unit, "
                            "e.g. depth_scale=0.001 for millimetres) so nothing is rescaled silently")
        out_dtype = torch.float32
        # scaled in float64 and rounded once, as the numba library does
        return (depth.to(torch.float64) * depth_scale).to(torch.float32), out_dtype
    if depth_scale is not None and depth_scale != 1.0:
        z = z * depth_scale
    return z, out_dtype


def _camera_from_tensor(K: torch.Tensor, batch: int, dtype: torch.dtype,
                        device: torch.device) -> tuple[torch.Tensor, ...]:
    if K.dtype == torch.bool or K.is_complex() or not (K.dtype.is_floating_point or K.dtype in (
            torch.int8, torch.int16, torch.int32, torch.int64, torch.uint8)):
        raise TypeError(f"K must hold real numbers; got {K.dtype}")
    K = K.to(device=device, dtype=dtype)
    if K.shape[-2:] == (3, 3) and K.ndim in (2, 3):
        M = K if K.ndim == 3 else K[None]
        vals = (M[:, 0, 0], M[:, 1, 1], M[:, 0, 2], M[:, 1, 2])
    elif K.shape[-1:] == (4,) and K.ndim in (1, 2):
        M = K if K.ndim == 2 else K[None]
        vals = (M[:, 0], M[:, 1], M[:, 2], M[:, 3])
    else:
        raise ValueError("K must be (3, 3), (B, 3, 3), (4,) or (B, 4) (fx, fy, cx, cy); "
                         f"got shape {tuple(K.shape)}")
    if M.shape[0] not in (1, batch):
        raise ValueError(f"K has a batch of {M.shape[0]} but depth has {batch}; pass one K or one per frame")
    return tuple(v.reshape(-1, 1, 1) for v in vals)


def camera(K: Any, batch: int, h: int, w: int, dtype: torch.dtype, device: torch.device) -> Camera:
    """Intrinsics (tensor, :class:`~depthnormals.Intrinsics`, 3x3 or (fx, fy, cx, cy)) as a
    :class:`Camera` on ``device`` in ``dtype``. Tensor values are not checked on the host
    (that would synchronise); other forms are checked by :func:`depthnormals.as_intrinsics`."""
    if isinstance(K, torch.Tensor):
        fx, fy, cx, cy = _camera_from_tensor(K, batch, dtype, device)
    else:
        if isinstance(K, (tuple, list)) and len(K) == 4 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in K):
            vals = K  # plain numbers: no numpy round trip (keeps torch.compile graphs whole)
            if not all(math.isfinite(x) for x in vals) or not (vals[0] > 0 and vals[1] > 0):
                raise ValueError(f"fx, fy must be finite and > 0, cx, cy finite; got {tuple(K)}")
        else:
            cam = K if isinstance(K, Intrinsics) else as_intrinsics(K)
            vals = (cam.fx, cam.fy, cam.cx, cam.cy)
        fx, fy, cx, cy = (torch.full((1, 1, 1), float(x), dtype=dtype, device=device) for x in vals)
    u = torch.arange(w, dtype=dtype, device=device).reshape(1, 1, w)
    v = torch.arange(h, dtype=dtype, device=device).reshape(1, h, 1)
    return Camera(fx, fy, cx, cy, u - cx, v - cy)


def prepare(depth: Any, K: Any, depth_scale: Any) -> tuple[torch.Tensor, torch.Tensor, Camera,
                                                            torch.dtype]:
    """Validate; return (depth (B, H, W) in the compute dtype, validity (B, H, W) bool, the
    camera, the output dtype). float16/bfloat16 compute in float32, float64 in float64."""
    z, out_dtype = _as_depth(depth, _check_scale(depth_scale))
    valid = torch.isfinite(z) & (z > 0)
    b, h, w = z.shape
    return z, valid, camera(K, b, h, w, z.dtype, z.device), out_dtype


class Grid:
    """Depth padded for stencils: ``z(dv, du)`` and ``ok(dv, du)`` are the depth and validity
    of the neighbour at offset (dv, du) of every pixel, as (B, H, W) views.

    Invalid and outside pixels read as depth 1 (a safe operand) with ``ok`` False.
    """

    def __init__(self, z: torch.Tensor, valid: torch.Tensor, pad: int):
        self.h, self.w = z.shape[-2:]
        self.p = pad
        self.valid = valid
        self.zs = torch.where(valid, z, torch.ones_like(z))
        self._zp = F.pad(self.zs, (pad, pad, pad, pad), value=1.0)
        self._vp = F.pad(valid, (pad, pad, pad, pad), value=False)

    def z(self, dv: int, du: int) -> torch.Tensor:
        p = self.p
        return self._zp[:, p + dv:p + dv + self.h, p + du:p + du + self.w]

    def ok(self, dv: int, du: int) -> torch.Tensor:
        p = self.p
        return self._vp[:, p + dv:p + dv + self.h, p + du:p + du + self.w]


#: Elements (neighbours x frames x pixels) of one stacked step on an accelerator (see
#: :func:`stack_width`).
STACK_ELEMENTS = 1 << 23
#: Stack on the CPU too (the tests run the accelerator's path so; the results are the same).
STACK_ON_CPU = False


def stack_width(x: torch.Tensor, n: int) -> int:
    """How many of ``n`` neighbours of ``x`` (B, H, W) a loop should compute stacked: on an
    accelerator as many as fit :data:`STACK_ELEMENTS` (eager torch there is launch-bound:
    a 640x480 default call launched ~4000 kernels of ~2 us, busy 1/4 of the time), on the
    CPU one (stacking there was slower: the face switch's eight directions at once 55 -> 84
    ms a 640x480 frame, the temporaries out of cache). The results are the same either way."""
    if x.device.type == "cpu" and not STACK_ON_CPU:
        return 1
    return max(1, min(n, STACK_ELEMENTS // max(1, x.numel())))


def first_least(values: torch.Tensor, least: torch.Tensor, index: torch.Tensor,
                start: int) -> tuple[torch.Tensor, torch.Tensor]:
    """One chunk of a running minimum over candidates in order, as a loop ``if v < least:
    least, index = v, k`` takes it: ``values`` (K, ...) the chunk's candidates ``start ..
    start + K - 1`` (NaN never taken), ``least`` and ``index`` the minimum and its candidate
    so far. The first of equal values wins, within the chunk (``torch.min``'s first index)
    and across chunks (a strict ``<``). Returns the new ``(least, index)``."""
    v, k = torch.where(values == values, values, math.inf).min(0)
    take = v < least
    return torch.where(take, v, least), torch.where(take, k + start, index)


def take_at(dvs: torch.Tensor, dus: torch.Tensor, *qs: torch.Tensor) -> list[torch.Tensor]:
    """Each of ``qs`` (B, H, W) read at every pixel's own offset (``dvs``, ``dus``, (B, H, W)
    integers; clamped into the image): a gather, so a gradient reaches the value read (as a
    shifted copy's would)."""
    bsz, h, w = dvs.shape
    v = (torch.arange(h, device=dvs.device).reshape(1, h, 1) + dvs).clamp(0, h - 1)
    u = (torch.arange(w, device=dus.device).reshape(1, 1, w) + dus).clamp(0, w - 1)
    src = (v * w + u).reshape(bsz, -1)
    return [torch.gather(q.reshape(bsz, -1), 1, src).reshape(dvs.shape) for q in qs]


def shift(x: torch.Tensor, dv: int, du: int, fill: float | bool) -> torch.Tensor:
    """``x`` (B, H, W) read at offset (dv, du): ``out[v, u] = x[v + dv, u + du]``, ``fill``
    outside the image (a padded copy, then a view)."""
    return x if dv == du == 0 else shifted_views(x, [(dv, du)], fill)[0]


def shifted_views(x: torch.Tensor, offsets: Sequence[tuple[int, int]],
                  fill: float | bool) -> list[torch.Tensor]:
    """``x`` (..., H, W) read at each of ``offsets`` (dv, du): ``out[k][..., v, u] = x[..., v +
    dv, u + du]``, ``fill`` outside the image; views of one padded copy (one kernel for all)."""
    h, w = x.shape[-2:]
    p = max([max(abs(dv), abs(du)) for dv, du in offsets] + [0])
    xp = F.pad(x, (p, p, p, p), value=fill) if p else x
    return [xp[..., p + dv:p + dv + h, p + du:p + du + w] for dv, du in offsets]


def oriented(nx: torch.Tensor, ny: torch.Tensor, nz: torch.Tensor, cam: Camera,
             ok: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """(nx, ny, nz) normalised and turned toward the camera (``dot(n, X) < 0``; perpendicular to
    the ray, the tie rule of :func:`faces_away`) where ``ok``.

    ``X ~ ((u - cx) / fx, (v - cy) / fy, 1)`` (the depth factor does not change the sign).
    Returns the three components (0 where not ``ok`` or of zero length) and the new ``ok``.
    Safe for gradients: the operands of the square root and division are finite and > 0.
    """
    n2 = nx * nx + ny * ny + nz * nz
    ok = ok & (n2 > 0) & torch.isfinite(n2)
    inv = torch.rsqrt(torch.where(ok, n2, 1.0))
    rx = cam.a / cam.fx
    ry = cam.b / cam.fy
    dot = nx * rx + ny * ry + nz
    away = faces_away(dot, n2, rx * rx + ry * ry + 1.0, nx, ny, nz)
    inv = torch.where(ok, torch.where(away, -inv, inv), 0.0)
    return nx * inv, ny * inv, nz * inv, ok


def faces_away(dot: torch.Tensor, n2: torch.Tensor, p2: torch.Tensor, nx: torch.Tensor,
               ny: torch.Tensor, nz: torch.Tensor) -> torch.Tensor:
    """Where the normal must be negated to face the camera: ``dot = n . X > 0``, but within
    :data:`~depthnormals.kernels.orient.TIE_COS` of perpendicular to the ray (``n2``, ``p2``
    the squared lengths of the normal and the ray) the first non-zero of ``n_z, n_y, n_x``
    decides: the numba kernels' rule (:func:`depthnormals.kernels.orient.faces_away`)."""
    key = torch.where(nz != 0, nz, torch.where(ny != 0, ny, nx))
    tie = dot * dot <= TIE_COS2 * n2 * p2
    return torch.where(tie, key > 0, dot > 0)


def finish(nx: torch.Tensor, ny: torch.Tensor, nz: torch.Tensor, ok: torch.Tensor,
           invalid: str, dtype: torch.dtype) -> torch.Tensor:
    """Stack to (B, 3, H, W) in ``dtype``: NaN (``invalid="nan"``) or 0 (``"zero"``) where not ok."""
    n = torch.stack((nx, ny, nz), dim=1)
    n = torch.where(ok[:, None], n, float("nan") if invalid == "nan" else 0.0)
    return n.to(dtype)

