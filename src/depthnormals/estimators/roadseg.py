"""The surface normal estimator of SNE-RoadSeg, in its general form."""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..registry import register
from ._common import new_output, prepare, store_normal
from ._stencils import gradient_kernels, stencil_derivative

__all__ = ["sne_roadseg"]

_NB = np.array([[-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0], [1, 1]],
               dtype=np.int64)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _roadseg_rows(v0, v1, z, D, fx, fy, cx, cy, deriv, smooth, nb_off, out):
    h, w = z.shape
    for v in range(v0, v1):
        for u in range(w):
            zq = z[v, u]
            if not (zq == zq):
                continue
            gu = stencil_derivative(D, v, u, 0, 1, deriv, smooth)
            gv = stencil_derivative(D, v, u, 1, 0, deriv, smooth)
            if not (gu == gu and gv == gv):
                continue
            nx = fx * gu
            ny = fy * gv
            xq = (u - cx) * zq / fx
            yq = (v - cy) * zq / fy
            if nx == 0.0 and ny == 0.0:
                store_normal(out, v, u, 0.0, 0.0, -1.0, xq, yq, zq)
                continue
            # sum of the unit vectors (nx, ny, nz_i) / |.|: only its z over its xy matters
            sw = 0.0
            sz = 0.0
            for k in range(8):
                r = v + nb_off[k, 0]
                c = u + nb_off[k, 1]
                if r < 0 or r >= h or c < 0 or c >= w:
                    continue
                zn = z[r, c]
                if not (zn == zn):
                    continue
                dz = zn - zq
                if dz == 0.0:
                    continue
                dx = (c - cx) * zn / fx - xq
                dy = (r - cy) * zn / fy - yq
                nzi = -(nx * dx + ny * dy) / dz
                inv = 1.0 / math.sqrt(nx * nx + ny * ny + nzi * nzi)
                sw += inv
                sz += nzi * inv
            if sw == 0.0:
                store_normal(out, v, u, 0.0, 0.0, -1.0, xq, yq, zq)
                continue
            # theta = -atan((sum nx_i cos phi + sum ny_i sin phi) / sum nz_i), phi = atan(ny/nx)
            # reduces to n ~ (nx, ny, sum(nz_i w_i) / sum(w_i)), w_i = 1 / |(nx, ny, nz_i)|
            store_normal(out, v, u, nx, ny, sz / sw, xq, yq, zq)


@register("sne-roadseg")
def sne_roadseg(depth: Any, K: Any, *, depth_scale: float | None = None) -> np.ndarray:
    """SNE-RoadSeg's estimator: inverse-depth gradients and a spherical mean of 8 candidates.

    ``nx = fx d(1/z)/du`` and ``ny = fy d(1/z)/dv`` (central differences), the azimuth
    ``phi = atan(ny / nx)``; each of the 8 neighbours gives ``nz_i`` from the plane equation
    (as in 3F2N), the candidate ``(nx, ny, nz_i)`` is normalised, and the polar angle is
    ``theta = -atan((sum nx_i cos phi + sum ny_i sin phi) / sum nz_i)``, giving
    ``n = (sin theta cos phi, sin theta sin phi, cos theta)`` oriented to the camera.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN at invalid depth and where no gradient exists.

    Notes
    -----
    The angle formulas reduce exactly to ``n ~ (nx, ny, sum_i w_i nz_i / sum_i w_i)`` with
    ``w_i = 1 / |(nx, ny, nz_i)|``: the third filter of 3F2N replaced by a weighted mean that
    down-weights steep candidates; this closed form is what is computed (no trigonometry).

    Interpretation (ours), the general form asked of a library: ``fy`` is used for ``ny``
    and ``Y`` (the public code uses ``fx`` for both, harmless only when ``fx == fy``), and
    nothing is masked (the public code zeroes the upper half of the image, ``Y <= 0``, a
    road-scene prior). Neighbours with ``dz = 0`` and invalid neighbours give no candidate;
    when none is left, or the gradient is zero, the normal is ``(0, 0, -1)`` as in the
    public code. Gradients fall back to one-sided differences next to invalid pixels.

    References
    ----------
    R. Fan, H. Wang, P. Cai and M. Liu, "SNE-RoadSeg: Incorporating Surface Normal
    Information into Semantic Segmentation for Accurate Freespace Detection," European
    Conference on Computer Vision (ECCV), 2020, pp. 340-356.
    doi:10.1007/978-3-030-58577-8_21

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import sne_roadseg
    >>> v, u = np.mgrid[0:6, 0:8]
    >>> z = 1.0 / (0.5 + 0.001 * u)          # a plane: inverse depth linear in u
    >>> n = sne_roadseg(z, (500.0, 500.0, 3.5, 2.5))
    >>> bool(np.allclose(np.linalg.norm(n, axis=-1), 1.0))
    True
    """
    z, cam = prepare(depth, K, depth_scale)
    deriv, smooth = gradient_kernels("fd", 3)
    out = new_output(z.shape)
    D = np.divide(1.0, z, dtype=np.float64)
    run_rows(_roadseg_rows, z.shape[0], z, D, cam.fx, cam.fy, cam.cx, cam.cy, deriv, smooth, _NB,
             out)
    return out
