"""Lens distortion undone on tensors: :func:`undistort_depth`, the torch twin of
:func:`depthnormals.undistort_depth` (the same pixels, gathered on the tensor's device)."""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import torch

from ..camera import _source_pixels, as_intrinsics, check_distortion

__all__ = ["undistort_depth"]


def undistort_depth(depth: torch.Tensor, K: Any, distortion: Any) -> torch.Tensor:
    """Resample depth from a distorting lens onto the pinhole grid of ``K``, on any device.

    The torch twin of :func:`depthnormals.undistort_depth` with its default ``"nearest"``:
    every output pixel takes the depth of the input pixel nearest to where its ray lands
    through the lens (OpenCV's model and order), NaN where it leaves the image. The pixel map
    is computed once per camera and image size (numpy, cached) and applied as a gather, so the
    result is the numpy function's to the bit and differentiable in ``depth`` (each output
    value is one input value).

    Parameters
    ----------
    depth : Tensor, shape (B, 1, H, W), (B, H, W) or (H, W)
        Depth, floating point (any device); one camera for the whole batch.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        The camera matrix of the distorted images (pixels, 0-based centres); the output uses
        the same one.
    distortion : sequence of 4, 5, 8 or 12 floats
        ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4]]])``, OpenCV's order.

    Returns
    -------
    Tensor
        The shape, dtype and device of ``depth``; NaN where the ray leaves the image.

    Examples
    --------
    >>> import torch
    >>> d = torch.arange(1.0, 21.0).reshape(1, 1, 4, 5)
    >>> undistort_depth(d, (2.0, 2.0, 2.0, 1.5), (0.3, 0.0, 0.0, 0.0))[0, 0, :2].tolist()
    [[nan, 2.0, 3.0, 4.0, nan], [nan, 7.0, 8.0, 9.0, nan]]
    """
    if not isinstance(depth, torch.Tensor):
        raise TypeError(f"depth must be a torch.Tensor; got {type(depth).__name__} (numpy arrays: "
                        "depthnormals.undistort_depth)")
    if not depth.is_floating_point():
        raise TypeError(f"depth must be a floating-point tensor; got {depth.dtype}")
    if depth.dim() not in (2, 3, 4) or (depth.dim() == 4 and depth.shape[1] != 1):
        raise ValueError(f"depth must be (B, 1, H, W), (B, H, W) or (H, W); got shape "
                         f"{tuple(depth.shape)}")
    if depth.numel() == 0:
        raise ValueError(f"depth is empty (shape {tuple(depth.shape)})")
    cam = as_intrinsics(K)
    dist = check_distortion(distortion)
    if not any(dist):
        return depth.clone()
    h, w = depth.shape[-2:]
    take, inside = _pixel_map(int(h), int(w), cam, dist, depth.device)
    out = depth.reshape(*depth.shape[:-2], h * w)[..., take].reshape(depth.shape)
    return torch.where(inside, out, torch.full_like(out, float("nan")))


@lru_cache(maxsize=4)
def _pixel_map(h: int, w: int, cam: Any, dist: tuple[float, ...],
               device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """The numpy function's pixel map on ``device`` (cached per camera, size and device, so a
    stream of frames moves it once): the flat source index of every output pixel (0 where
    none: masked) and where one exists, (H, W) bool."""
    idx = torch.as_tensor(_source_pixels(h, w, cam, dist).astype("int64"), device=device)
    return idx.clamp(min=0).reshape(-1), idx >= 0
