"""The plain cross-product normal map (OpenCV 5's RGBD_NORMALS_METHOD_CROSS_PRODUCT, Open3D's
``t.geometry.Image.create_normal_map``), in its forward and central forms."""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from .._validate import check_choice
from ..kernels.depth import prepare
from ..kernels.orient import store_normal

__all__ = ["DIFFERENCES", "cross_product"]

#: ``"central"``: (P(u+1) - P(u-1)) x (P(v+1) - P(v-1)); ``"forward"``: OpenCV 5 / Open3D.
DIFFERENCES = ("central", "forward")

_NUMPY = "numpy"


@nb.njit(cache=True, nogil=True, error_model=_NUMPY)
def _cross_rows(v0, v1, z, fx, fy, cx, cy, central, out):
    """Rows [v0, v1): n = (P(v + 1, u) - P(v - b, u)) x (P(v, u + 1) - P(v, u - b)) with b = 1
    (central) or 0 (forward), float64, oriented toward the camera; NaN where a point it
    needs is outside the image or invalid."""
    h, w = z.shape
    b = 1 if central else 0
    for v in range(v0, v1):
        for u in range(w):
            out[v, u, 0] = np.nan
            out[v, u, 1] = np.nan
            out[v, u, 2] = np.nan
            zq = np.float64(z[v, u])
            if not (zq == zq) or v - b < 0 or u - b < 0 or v + 1 >= h or u + 1 >= w:
                continue
            zd = np.float64(z[v + 1, u])
            zu = np.float64(z[v - b, u])
            zr = np.float64(z[v, u + 1])
            zl = np.float64(z[v, u - b])
            if not (zd == zd and zu == zu and zr == zr and zl == zl):
                continue
            # down - up (the column direction) and right - left (the row direction)
            ax = (u - cx) * (zd - zu) / fx
            ay = ((v + 1 - cy) * zd - (v - b - cy) * zu) / fy
            az = zd - zu
            bx = ((u + 1 - cx) * zr - (u - b - cx) * zl) / fx
            by = (v - cy) * (zr - zl) / fy
            bz = zr - zl
            store_normal(out, v, u, ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx,
                         (u - cx) * zq / fx, (v - cy) * zq / fy, zq)


def cross_product(depth: Any, K: Any, *, difference: str = "central",
                  depth_scale: float | None = None) -> np.ndarray:
    """The plain cross-product normal map: one 3-D difference per image axis, crossed.

    ``difference="forward"`` is what OpenCV 5 (``cv::RgbdNormals`` with
    ``RGBD_NORMALS_METHOD_CROSS_PRODUCT``) and Open3D's tensor API
    (``t.geometry.Image.create_vertex_map(...).create_normal_map()``) compute:
    ``n = (P(v+1, u) - P(v, u)) x (P(v, u+1) - P(v, u))``, NaN on the last row and column.
    The default ``"central"`` crosses central differences,
    ``n = (P(v+1, u) - P(v-1, u)) x (P(v, u+1) - P(v, u-1))``: the normal of the pixel itself
    rather than of the cell half a pixel down and right of it (NaN on a 1-pixel frame).

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (any length unit). float32/float64; integers need ``depth_scale``.
        Invalid depth (0, negative, NaN, inf) gives NaN.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    difference : {"central", "forward"}, default "central"
        Which neighbours the differences use (see above).
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera; NaN where a point the differences need is invalid or
        outside the image.

    Notes
    -----
    Interpretation (ours): the points are back-projected and differenced in float64, and
    the normal is turned toward the camera. OpenCV and Open3D work in float32 and do not
    orient (their forward cross product faces the camera on every surface seen from the
    front; it can face away across a depth jump). The default is the central form because
    it is the pixel's own normal (the forward form is off by half a pixel on curved
    surfaces, and is not symmetric under a 180-degree rotation of the image).

    References
    ----------
    OpenCV 5, module 3d, ``cv::RgbdNormals`` (modules/3d/src/rgbd/normal.cpp, class
    ``CrossProduct``). Open3D 0.17+, ``open3d.t.geometry.Image.create_normal_map``
    (cpp/open3d/t/geometry/kernel/ImageImpl.h, ``CreateNormalMapCPU``).

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals import cross_product
    >>> n = cross_product(np.full((4, 5), 2.0), (500.0, 500.0, 2.0, 1.5))
    >>> n[1, 2].tolist()
    [0.0, 0.0, -1.0]
    >>> bool(np.isnan(n[0, 2]).all() and np.isnan(n[3, 2]).all())  # the 1-pixel frame
    True
    """
    difference = check_choice(difference, "difference", DIFFERENCES)
    z, cam = prepare(depth, K, depth_scale)
    out = np.empty((*z.shape, 3), dtype=np.float32)
    run_rows(_cross_rows, z.shape[0], z, cam.fx, cam.fy, cam.cx, cam.cy,
             difference == "central", out)
    return out
