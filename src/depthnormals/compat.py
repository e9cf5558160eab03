"""Drop-in replacements for the depth-to-normal functions other projects call.

Each function keeps the signature of the function it replaces (positional arguments in the same
order, the same shapes, units and layout) and returns **our default's normals** (3F2N+,
``method="3f2n+"``) in that caller's conventions: orientation, layout, units and the value
where no normal exists.

- :func:`depth_to_normals` replaces kornia's ``kornia.geometry.depth.depth_to_normals``
  (needs torch);
- :func:`gsplat_depth_to_normal` replaces gsplat's ``gsplat.utils.depth_to_normal``, and
  through a documented mapping 2DGS's ``utils.point_utils.depth_to_normal`` (needs torch);
- :func:`depth_normal` replaces FFB6D's ``normalSpeed.depth_normal`` (numpy only).

The torch drop-ins call :func:`depthnormals.torch.estimate_normals` (imported when called, so
``import depthnormals.compat`` does not import torch), whose default is the numba default on
every kind of depth, noisy and quantised sensor depth included (docs/torch.md).
:func:`depth_normal` calls the numba default :func:`depthnormals.estimate_normals`.
The conventions of each original were read from its source (named in each docstring) and are
pinned by ``tests/test_compat.py``.
"""

from __future__ import annotations

import numbers
from typing import TYPE_CHECKING, Any

import numpy as np

from ._validate import unmasked
from .registry import estimate_normals as _estimate_numba

if TYPE_CHECKING:  # pragma: no cover
    import torch

__all__ = ["depth_normal", "depth_to_normals", "gsplat_depth_to_normal"]


def _shape(x: Any) -> str:
    return str(tuple(x.shape)) if hasattr(x, "shape") else type(x).__name__


def _float_dtype(*tensors: torch.Tensor) -> torch.dtype:
    """The promoted dtype of ``tensors`` if floating, else torch's default float dtype."""
    import torch

    dtype = tensors[0].dtype
    for t in tensors[1:]:
        dtype = torch.promote_types(dtype, t.dtype)
    return dtype if dtype.is_floating_point else torch.get_default_dtype()


def _require_tensor(x: Any, name: str) -> None:
    import torch

    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name} must be a torch.Tensor; got {type(x).__name__} "
                        "(use torch.as_tensor)")
    if x.dtype == torch.bool or x.is_complex():
        raise TypeError(f"{name} must hold real numbers; got {x.dtype}")


def _ray_norm(h: int, w: int, fx: torch.Tensor, fy: torch.Tensor, cx: torch.Tensor,
              cy: torch.Tensor) -> torch.Tensor:
    """|((u - cx) / fx, (v - cy) / fy, 1)| per pixel, (B, H, W); intrinsics (B, 1, 1)."""
    import torch

    u = torch.arange(w, dtype=fx.dtype, device=fx.device).reshape(1, 1, w)
    v = torch.arange(h, dtype=fx.dtype, device=fx.device).reshape(1, h, 1)
    a, b = (u - cx) / fx, (v - cy) / fy
    return torch.sqrt(a * a + b * b + 1.0)


def depth_to_normals(depth: torch.Tensor, camera_matrix: torch.Tensor,
                     normalize_points: bool = False) -> torch.Tensor:
    """kornia's ``depth_to_normals``, computed by 3F2N+: (B, 3, H, W) in kornia's conventions.

    Replaces ``kornia.geometry.depth.depth_to_normals(depth, camera_matrix,
    normalize_points=False)`` (kornia 0.9.0, read from its source).

    Parameters
    ----------
    depth : Tensor, shape (B, 1, H, W)
        Depth per pixel, H >= 2 and W >= 2 (kornia's shape rule). Planar depth z, or with
        ``normalize_points=True`` the Euclidean distance along the ray (kornia's reading).
        Integer depth is taken as it is, in its own units (as kornia does).
    camera_matrix : Tensor, shape (B, 3, 3)
        Intrinsics per frame; only fx, fy, cx, cy are read (as kornia does: no skew), pixel
        centres on integers.
    normalize_points : bool, default False
        True: ``depth`` is the ray length r, converted to z = r / |((u - cx) / fx,
        (v - cy) / fy, 1)| before estimating.

    Returns
    -------
    normals : Tensor, shape (B, 3, H, W)
        Unit normals in the camera frame (x right, y down, z forward) with **kornia's
        orientation**: the cross product d/du x d/dv of the back-projected points, pointing
        **away** from the camera (a fronto-parallel wall gives (0, 0, +1); depth growing to
        the right gives n_x < 0): the negation of :func:`depthnormals.torch.estimate_normals`.
        dtype: the promoted dtype of ``depth`` and ``camera_matrix`` (torch's default float
        dtype if both are integer), as kornia's.

    Notes
    -----
    Where kornia and this function differ, on purpose:

    - **no estimate** (invalid depth: 0, negative, NaN, inf): kornia back-projects 0 as a
      point at the camera centre and returns finite but wrong normals there and on the 3x3
      neighbourhood (NaN depth: NaN on the 3x3 neighbourhood). Here invalid depth never
      enters a stencil; the pixel itself gets the **zero vector** (finite, like kornia's
      output, and recognisable: ``normals.abs().sum(1) == 0``), its neighbours their normal;
    - **image border**: kornia's Sobel filter replicates the border (a plane's normal is
      still right there, other surfaces' biased); here one-sided differences;
    - **edges**: 3F2N+ picks the normal of the smoother side at a discontinuity, kornia's
      3x3 Sobel smears every occlusion edge.

    Differentiable like :func:`depthnormals.torch.estimate_normals` (finite gradients
    everywhere).

    Examples
    --------
    >>> import torch
    >>> from depthnormals.compat import depth_to_normals
    >>> K = torch.tensor([[[500.0, 0.0, 2.0], [0.0, 500.0, 1.5], [0.0, 0.0, 1.0]]])
    >>> n = depth_to_normals(torch.full((1, 1, 4, 5), 2.0), K)
    >>> n[0, :, 1, 2].round(decimals=6).tolist()  # (unit length to float32's last bit)
    [0.0, 0.0, 1.0]
    """
    import torch

    from depthnormals.torch import estimate_normals

    _require_tensor(depth, "depth")
    _require_tensor(camera_matrix, "camera_matrix")
    if depth.ndim != 4 or depth.shape[1] != 1:
        raise ValueError(f"depth must be (B, 1, H, W) as for kornia's depth_to_normals; got "
                         f"shape {_shape(depth)}")
    h, w = depth.shape[-2:]
    if h < 2 or w < 2:
        raise ValueError(f"depth_to_normals needs H >= 2 and W >= 2 (two tangent directions); "
                         f"got H={h}, W={w}")
    if camera_matrix.ndim != 3 or camera_matrix.shape[1:] != (3, 3) \
            or camera_matrix.shape[0] != depth.shape[0]:
        raise ValueError(f"camera_matrix must be (B, 3, 3) with B = {depth.shape[0]} (depth's "
                         f"batch); got shape {_shape(camera_matrix)}")
    if not isinstance(normalize_points, (bool, np.bool_)):
        raise TypeError(f"normalize_points must be True or False; got {normalize_points!r}")
    dtype = _float_dtype(depth, camera_matrix)
    work = torch.float64 if dtype == torch.float64 else torch.float32
    z = depth.to(work)
    K = camera_matrix.to(device=depth.device, dtype=work)
    if normalize_points:
        fx, fy, cx, cy = (K[:, i, j].reshape(-1, 1, 1) for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)))
        z = z / _ray_norm(h, w, fx, fy, cx, cy)[:, None]
    n = estimate_normals(z, K, method="3f2n+", invalid="zero")
    return (0.0 - n).to(dtype)  # 0 - n, not -n: no -0.0 in the zero vectors


def _leading(name: str, x: torch.Tensor, n: int) -> tuple[int, ...]:
    """The leading dimensions of ``x`` of shape (..., n, n)."""
    if x.ndim < 2 or tuple(x.shape[-2:]) != (n, n):
        raise ValueError(f"{name} must be (..., {n}, {n}); got shape {_shape(x)}")
    return tuple(x.shape[:-2])


def gsplat_depth_to_normal(depths: torch.Tensor, camtoworlds: torch.Tensor, Ks: torch.Tensor,
                           z_depth: bool = True, *, keep_border: bool = False) -> torch.Tensor:
    """gsplat's ``depth_to_normal``, computed by 3F2N+: world-frame normals (..., H, W, 3).

    Replaces ``gsplat.utils.depth_to_normal(depths, camtoworlds, Ks, z_depth=True)`` as of
    gsplat 1.x (``gsplat/utils.py`` at nerfstudio-project/gsplat commit 0d64b82, read from
    its source). Its conventions, which this function keeps:

    - a ray through pixel (u, v) (column, row) is ``((u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy,
      1)``: **pixel centres at half-integers** (we pass cx - 0.5, cy - 0.5 to our estimator,
      whose centres are integers), rotated to the world by ``camtoworlds[..., :3, :3]``;
    - the normal is ``normalize(cross(P[v+1] - P[v-1], P[u+1] - P[u-1]))`` (their ``dx`` is
      the difference along the rows), i.e. d/dv x d/du: it **faces the camera** (a
      fronto-parallel wall gives (0, 0, -1) in the camera frame), and is returned in the
      **world frame**, ``R @ n_cam``;
    - a one-pixel **border of zero vectors** (their ``F.pad(..., value=0)``).

    The older signature ``depth_to_normal(depths, camtoworlds, Ks, near_plane, far_plane)``
    (commented out in that file: a port of 2DGS's) computed the same cross product with the
    principal point at (W/2, H/2) and integer pixel centres; near and far planes did not
    change the normals. 2DGS's ``utils.point_utils.depth_to_normal(view, depth)`` ((1, H, W)
    depth, (H, W, 3) world normals, same sign and zero border) is this function with
    ``depths = depth[..., None]``, ``camtoworlds = inverse(view.world_view_transform.T)[None]``
    and ``Ks[None]`` with ``cx = W / 2 + 0.5``, ``cy = H / 2 + 0.5`` (2DGS's principal point
    W/2, H/2 with integer centres, in gsplat's half-integer reading), then ``[0]``.

    Parameters
    ----------
    depths : Tensor, shape (..., H, W, 1)
        Depth maps: planar z (``z_depth=True``) or the distance along the ray
        (``z_depth=False``), in the units of the camera translation.
    camtoworlds : Tensor, shape (..., 4, 4)
        Camera-to-world transforms (OpenCV camera frame: x right, y down, z forward), the
        same leading dimensions as ``depths``. Only the rotation ``[..., :3, :3]`` acts on
        normals.
    Ks : Tensor, shape (..., 3, 3)
        Intrinsics per camera (fx, fy, cx, cy read, as gsplat does), the same leading
        dimensions.
    z_depth : bool, default True
        Whether ``depths`` is planar z (True) or ray length (False), as in gsplat.
    keep_border : bool, default False
        Keep our estimates on the one-pixel image border instead of gsplat's zero vectors
        (ours are one-sided differences there).

    Returns
    -------
    normals : Tensor, shape (..., H, W, 3)
        Unit normals in the world frame, facing the camera; the **zero vector** on the border
        (unless ``keep_border``) and where no estimate exists (invalid depth: 0, negative,
        NaN, inf; gsplat has no invalid depth and back-projects 0 to the camera centre).
        dtype: the promoted floating dtype of the inputs.

    Examples
    --------
    >>> import torch
    >>> from depthnormals.compat import gsplat_depth_to_normal
    >>> K = torch.tensor([[50.0, 0.0, 3.0], [0.0, 50.0, 2.5], [0.0, 0.0, 1.0]])
    >>> n = gsplat_depth_to_normal(torch.full((5, 6, 1), 2.0), torch.eye(4), K)
    >>> n[2, 3].tolist(), n[0, 0].tolist()
    ([0.0, 0.0, -1.0], [0.0, 0.0, 0.0])
    """
    import torch

    from depthnormals.torch import estimate_normals

    for name, x in (("depths", depths), ("camtoworlds", camtoworlds), ("Ks", Ks)):
        _require_tensor(x, name)
    if depths.ndim < 3 or depths.shape[-1] != 1:
        raise ValueError(f"depths must be (..., H, W, 1) as for gsplat's depth_to_normal; got "
                         f"shape {_shape(depths)}")
    lead = tuple(depths.shape[:-3])
    lead_c = _leading("camtoworlds", camtoworlds, 4)
    lead_k = _leading("Ks", Ks, 3)
    if not lead == lead_c == lead_k:
        raise ValueError(f"leading dimensions differ: depths {_shape(depths)}, camtoworlds "
                         f"{_shape(camtoworlds)}, Ks {_shape(Ks)}; gsplat needs depths[..., H, W, 1], "
                         "camtoworlds[..., 4, 4] and Ks[..., 3, 3] with the same '...'")
    if not isinstance(z_depth, (bool, np.bool_)):
        raise TypeError(f"z_depth must be True or False; got {z_depth!r}")
    if not isinstance(keep_border, (bool, np.bool_)):
        raise TypeError(f"keep_border must be True or False; got {keep_border!r}")
    h, w = depths.shape[-3:-1]
    dtype = _float_dtype(depths, camtoworlds, Ks)
    work = torch.float64 if dtype == torch.float64 else torch.float32
    z = depths.to(work).reshape(-1, h, w)
    K = Ks.to(device=depths.device, dtype=work).reshape(-1, 3, 3)
    R = camtoworlds.to(device=depths.device, dtype=work).reshape(-1, 4, 4)[:, :3, :3]
    fx, fy = K[:, 0, 0], K[:, 1, 1]
    cx, cy = K[:, 0, 2] - 0.5, K[:, 1, 2] - 0.5  # gsplat's half-integer pixel centres
    if not z_depth:
        z = z / _ray_norm(h, w, *(c.reshape(-1, 1, 1) for c in (fx, fy, cx, cy)))
    n = estimate_normals(z, torch.stack((fx, fy, cx, cy), dim=1), method="3f2n+", invalid="zero")
    n = torch.einsum("bij,bjhw->bhwi", R, n)  # (B, H, W, 3), world frame
    if not keep_border:
        n = torch.nn.functional.pad(n[:, 1:-1, 1:-1], (0, 0, 1, 1, 1, 1), value=0.0)
    return n.reshape(*lead, h, w, 3).to(dtype)


def _check_number(x: Any, name: str, *, integer: bool = False) -> float:
    kind = numbers.Integral if integer else numbers.Real
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, kind):
        raise TypeError(f"{name} must be {'an integer' if integer else 'a real number'}; got {x!r}")
    value = float(x)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be finite and > 0; got {x!r}")
    return value


def depth_normal(depth_mm: Any, fx: float, fy: float, k_size: int = 5,
                 distance_threshold: float = 2000, difference_threshold: float = 20,
                 point_into_surface: bool = False, *, cx: float | None = None,
                 cy: float | None = None) -> np.ndarray:
    """FFB6D's ``normalSpeed.depth_normal``, computed by 3F2N+: (H, W, 3) float32 normals.

    Replaces ``normalSpeed.depth_normal(depth, fx, fy, k_size, distance_threshold,
    difference_threshold, point_into_surface)`` of hfutcgncas/normalSpeed (``normal.cpp`` at
    commit 2e73483, read from its source; FFB6D calls it as ``depth_normal(dpt_mm, K[0][0],
    K[1][1], 5, 2000, 20, False)``, the defaults here). normalSpeed is LINE-MOD's normal
    (:func:`depthnormals.line_mod`): a least-squares depth gradient from 8 neighbours at
    distance ``k_size``, ``n ~ (fx dz/du, fy dz/dv, -z)`` (no principal point), then a 3x3
    median filter. Needs numpy only (the numba library; no torch).

    Parameters
    ----------
    depth_mm : array_like, shape (H, W)
        Planar depth in **millimetres**: uint16 (as normalSpeed takes it) or float; 0 is
        invalid. Scaled to metres (``depth_scale=0.001``) for our estimator.
    fx, fy : float
        Focal lengths in pixels.
    k_size : int, default 5
        normalSpeed: the distance in pixels of its 8 neighbours (the stencil spans
        2 k_size + 1 pixels). **Checked, not used**: 3F2N+ chooses its own stencils.
    distance_threshold : float, default 2000
        normalSpeed: depth in mm at and beyond which a pixel gets no normal (its far cut).
        **Used** the same way: the zero vector where ``depth_mm >= distance_threshold``.
    difference_threshold : float, default 20
        normalSpeed: neighbours whose depth differs from the centre's by this many mm or more
        are left out of the fit (its discontinuity test). **Checked, not used**: 3F2N+'s
        discontinuity module does this job without a threshold.
    point_into_surface : bool, default False
        False: normals face the camera (n_z < 0 for a visible surface), normalSpeed's default
        and ours. True: the opposite (into the surface, n_z > 0).
    cx, cy : float, optional (keyword only; not in normalSpeed)
        The principal point in pixels (0-based centres). normalSpeed has none (it ignores the
        principal point); default: the image centre ((W - 1) / 2, (H - 1) / 2).

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals in the camera frame (x right, y down, z forward); the **zero vector**
        where no normal exists (invalid depth, beyond ``distance_threshold``, no valid
        neighbour), as normalSpeed returns zeros there. normalSpeed also returns zeros on a
        border of ``k_size`` pixels (``k_size + 1`` on the right and bottom); we give normals
        there (one-sided differences).

    Notes
    -----
    The unused arguments raise no warning: they tune the method this replaces, and callers
    pass them on every frame (FFB6D's data loader); their meaning is the one above.

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals.compat import depth_normal
    >>> n = depth_normal(np.full((8, 10), 1500, np.uint16), 500.0, 500.0, 5, 2000, 20, False)
    >>> n.shape, n.dtype, n[4, 5].tolist()
    ((8, 10, 3), dtype('float32'), [0.0, 0.0, -1.0])
    """
    d = np.asarray(unmasked(depth_mm))
    if d.ndim != 2:
        raise ValueError(f"depth_mm must be (H, W) depth in millimetres; got shape {d.shape}")
    if d.dtype == np.bool_ or not (np.issubdtype(d.dtype, np.integer)
                                   or np.issubdtype(d.dtype, np.floating)):
        raise TypeError(f"depth_mm must hold integers (uint16) or floats in millimetres; got {d.dtype}")
    fx_, fy_ = _check_number(fx, "fx"), _check_number(fy, "fy")
    _check_number(k_size, "k_size", integer=True)
    far = _check_number(distance_threshold, "distance_threshold")
    _check_number(difference_threshold, "difference_threshold")
    if not isinstance(point_into_surface, (bool, np.bool_)):
        raise TypeError(f"point_into_surface must be True or False; got {point_into_surface!r}")
    h, w = d.shape
    cx_ = (w - 1) / 2.0 if cx is None else float(cx)
    cy_ = (h - 1) / 2.0 if cy is None else float(cy)
    n = _estimate_numba(d, (fx_, fy_, cx_, cy_), depth_scale=0.001)
    n = np.nan_to_num(n, nan=0.0)
    n[~(d < far)] = 0.0
    if point_into_surface:
        n = -n
    return n.astype(np.float32) + np.float32(0.0)  # + 0 turns -0.0 into 0.0
