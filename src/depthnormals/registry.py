"""The estimator registry and the one dispatcher over it.

Every estimator is a public function ``f(depth, K, *, option=..., depth_scale=None)`` in
:mod:`depthnormals.estimators`; :data:`ESTIMATORS` below names each one, in plain imports (the
estimators know nothing of the registry). ``estimate_normals(depth, K, method=name)`` looks the
name up; ``"<name>+"`` is estimator ``<name>`` followed by the discontinuity discrimination
module (:func:`depthnormals.ddm.discontinuity_discrimination`), or its fused one-pass form
where :data:`FUSED_PLUS` has one (``"3f2n+"``: :mod:`depthnormals.ddm.threefn_plus`).

Adding an estimator: write its function in ``estimators/<file>.py``, export it from
``estimators/__init__.py`` and add one line to :data:`ESTIMATORS`.
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import ddm
from ._validate import NoValidNormalWarning, check_depth, no_valid_normal_message
from .ddm.threefn_plus import fused_plus as _fused_3f2n_plus
from .ddm.uncertainty import normals_with_uncertainty
from .estimators import (
    angle_weighted,
    area_weighted,
    cross_product,
    d2nt,
    fals,
    line_mod,
    pcl_average_3d_gradient,
    pcl_average_depth_change,
    pcl_covariance_matrix,
    pcl_simple_3d_gradient,
    plane_pca,
    plane_svd,
    sda_sne,
    sne_roadseg,
    sri,
    three_filters_to_normal,
    vector_svd,
)

__all__ = ["EstimatorInfo", "compute_normals", "estimate_normals", "get_estimator", "methods", "register"]

DEFAULT_METHOD = "3f2n+"


@dataclass(frozen=True)
class EstimatorInfo:
    """What the registry knows of one estimator.

    Attributes
    ----------
    name : str
        Registered name (lower case, hyphenated).
    func : callable
        The public function ``func(depth, K, *, **options)``.
    options : tuple of str
        Its keyword-only options (``depth_scale`` excluded).
    scale_invariant : bool
        True when scaling depth by a constant leaves the normals unchanged.
    summary : str
        First line of the docstring.
    """

    name: str
    func: Callable[..., np.ndarray]
    options: tuple[str, ...]
    scale_invariant: bool
    summary: str


#: Every estimator: (name, function, scale invariant). Scale invariant: scaling depth by a
#: constant leaves the normals unchanged (tested in tests/test_properties.py).
ESTIMATORS: tuple[tuple[str, Callable[..., np.ndarray], bool], ...] = (
    ("3f2n", three_filters_to_normal, True),
    ("angle-weighted", angle_weighted, True),
    ("area-weighted", area_weighted, True),
    ("cross-product", cross_product, True),
    ("d2nt", d2nt, False),
    ("fals", fals, True),
    ("line-mod", line_mod, False),
    # PCL's integral-image modes: metric depth-change thresholds, so not scale invariant
    ("pcl-average-3d-gradient", pcl_average_3d_gradient, False),
    ("pcl-average-depth-change", pcl_average_depth_change, False),
    ("pcl-covariance-matrix", pcl_covariance_matrix, False),
    ("pcl-simple-3d-gradient", pcl_simple_3d_gradient, False),
    ("plane-pca", plane_pca, True),
    ("plane-svd", plane_svd, True),
    ("sda-sne", sda_sne, False),
    ("sne-roadseg", sne_roadseg, True),
    ("sri", sri, True),
    ("vector-svd", vector_svd, True),
)

#: ``"<name>+"`` in one fused pass: ``f(depth, K, depth_scale, estimator_options,
#: module_options)`` returns the normals, or None where the options have no fused form.
FUSED_PLUS: dict[str, Callable[..., np.ndarray | None]] = {"3f2n": _fused_3f2n_plus}

_REGISTRY: dict[str, EstimatorInfo] = {}


def register(name: str, func: Callable[..., np.ndarray], *, scale_invariant: bool = True) -> None:
    """Add ``func`` as estimator ``name`` (for estimators outside this package).

    ``func(depth, K, *, option=..., depth_scale=None)``; its keyword-only options must not
    reuse a name of the module's options (:func:`depthnormals.ddm.module_defaults`), so that
    ``"<name>+"`` gives every option one meaning.
    """
    if not isinstance(name, str) or not name or name in _REGISTRY or name.endswith("+"):
        raise ValueError(f"estimator name {name!r} is taken or reserved")
    params = inspect.signature(func).parameters
    options = tuple(
        p.name for p in params.values()
        if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name != "depth_scale"
    )
    clash = sorted(set(options) & set(ddm.module_defaults()))
    if clash:
        raise ValueError(f"estimator {name!r}: option(s) {clash} are also options of the "
                         f"discontinuity module, so {name + '+'!r} would give them two meanings; "
                         "rename them")
    doc = (func.__doc__ or "").strip().splitlines()
    _REGISTRY[name] = EstimatorInfo(name, func, options, scale_invariant, doc[0] if doc else "")


for _name, _func, _invariant in ESTIMATORS:
    register(_name, _func, scale_invariant=_invariant)


def methods(*, refined: bool = True) -> tuple[str, ...]:
    """Names accepted by :func:`estimate_normals`, sorted.

    Parameters
    ----------
    refined : bool, default True
        Also list the ``"<name>+"`` forms (estimator followed by the discontinuity
        discrimination module).
    """
    base = sorted(_REGISTRY)
    if refined:
        return tuple(sorted(base + [n + "+" for n in base]))
    return tuple(base)


def get_estimator(name: str) -> EstimatorInfo:
    """The :class:`EstimatorInfo` of a base name; ValueError listing the valid ones otherwise."""
    if not isinstance(name, str):
        raise TypeError(f"method must be a string; got {type(name).__name__}")
    if name not in _REGISTRY:
        raise ValueError(f"unknown method {name!r}; valid methods: {', '.join(methods())}")
    return _REGISTRY[name]


def _split_options(method: str, info: EstimatorInfo, options: dict[str, Any],
                   extra: tuple[str, ...] = ()) -> tuple[dict[str, Any], dict[str, Any]]:
    own = {k: v for k, v in options.items() if k in info.options}
    rest = {k: v for k, v in options.items() if k not in info.options}
    unknown = [k for k in rest if k not in extra]
    for k in unknown if extra else ():
        err = ddm.renamed_option_error(k, f"method {method!r}")
        if err is not None:
            raise err
    if unknown:
        valid = sorted(info.options + extra)
        raise TypeError(
            f"method {method!r} got unknown option(s) {unknown}; valid options: "
            f"{', '.join(valid) if valid else '(none)'}"
        )
    return own, rest


def estimate_normals(depth: Any, K: Any, *, method: str = DEFAULT_METHOD,
                     depth_scale: float | None = None, stack: bool | None = None,
                     return_uncertainty: bool = False,
                     **options: Any) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Surface normals from a depth image by any registered estimator.

    Parameters
    ----------
    depth : array_like, shape (H, W), (H, W, 1) or (N, H, W)
        Planar depth z. float32/float64; integers need ``depth_scale``. Invalid depth
        (0, negative, NaN, inf) gives a NaN normal. A stack of N frames is spread over the
        threads, one frame per thread (:func:`depthnormals.batch.estimate_normals_batch`).
    K : Intrinsics, array (3, 3) or (3, 4), (fx, fy, cx, cy), mapping, or Open3D intrinsics
        Camera intrinsics in pixels, 0-based pixel centres (:func:`depthnormals.as_intrinsics`);
        for a stack also (N, 3, 3) or N of those.
    method : str
        A name from :func:`methods`; ``"<name>+"`` adds the discontinuity discrimination
        module of 3F2N+ after estimator ``<name>``.
    depth_scale : float, optional
        Metres per unit of integer depth (e.g. 0.001 for millimetres).
    stack : bool, optional
        How a 3-D ``depth`` is read. None (default): ``(H, W, 1)`` is one single-channel
        image; ``(H, W, 3)`` and ``(H, W, 4)`` are refused as colour images (ValueError);
        any other ``(N, H, W)`` is a stack of N frames. True: a 3-D ``depth`` is always a
        stack (N frames of width 3 or 4, or 1, included). False: one image only.
    return_uncertainty : bool, default False
        Also return the expected angular error of every normal (degrees, float32 (H, W), NaN
        exactly where the normal is NaN; :mod:`depthnormals.ddm.uncertainty`): for
        ``"3f2n+"`` (default options, every branch), ``"fals"``, PCL's four modes and the
        box plane fits ``"plane-svd"``, ``"plane-pca"``; any other method raises
        ValueError. A stack gives one map per frame, (N, H, W), each
        equal to the frame's single call. Calibrated on the procedural synthetic scenes (at 80
        frames a sensor model, every decile within 25 %) and on the real frames' planes; in
        clutter narrower than the estimator's windows (shelves of books) it reads low: within
        3 px of faces at most 5 px across (risers, board edges, legs) the normals err 1.1-1.3x
        the map on Gaussian depth and 1.5-2.5x on sensor depth, where no estimator resolves
        such faces (on Kinect v1, time-of-flight and active stereo depth every one errs by
        28-63 deg there), and on relief shallower than the sensor's depth step (pleats,
        corrugation) they take the surface's mean normal, not the facets' (docs/benchmarks.md,
        sections 17 and 30).
    **options
        Keyword options of the chosen estimator (and, for ``"<name>+"``, of
        :func:`depthnormals.ddm.discontinuity_discrimination`). Unknown names raise TypeError.

    Returns
    -------
    normals : ndarray, shape (H, W, 3) or (N, H, W, 3), float32
        Unit normals in the OpenCV camera frame facing the camera (``dot(n, X) < 0``),
        NaN where no estimate is possible.
    uncertainty : ndarray, shape (H, W) or (N, H, W), float32
        Only with ``return_uncertainty=True``: the expected angular error in degrees, at most
        90 (the error of a normal that carries no information).

    Warns
    -----
    NoValidNormalWarning
        (a ``RuntimeWarning``) when the output, or a frame of a stack, holds no finite
        normal: no valid depth, or no valid pixel with a valid neighbour (a 1x1 image).

    Examples
    --------
    >>> import numpy as np, depthnormals as dn
    >>> n = dn.estimate_normals(np.full((4, 5), 2.0), (500, 500, 2, 1.5), method="3f2n")
    >>> n[1, 2].tolist()
    [0.0, 0.0, -1.0]
    """
    if not isinstance(method, str):
        raise TypeError(f"method must be a string; got {type(method).__name__}")
    if stack is not None and not isinstance(stack, bool):
        raise TypeError(f"stack must be True, False or None; got {stack!r}")
    ndim = np.ndim(depth)
    if stack and ndim != 3:
        raise ValueError(f"stack=True needs a 3-D depth (N, H, W); got shape {np.shape(depth)}")
    if not isinstance(return_uncertainty, bool):
        raise TypeError(f"return_uncertainty must be True or False; got {return_uncertainty!r}")
    if return_uncertainty:
        get_estimator(method[:-1] if method.endswith("+") else method)  # unknown names first
    if ndim == 3 and _is_stack(np.shape(depth), stack):
        from .batch import estimate_normals_batch

        result = estimate_normals_batch(_with_uncertainty if return_uncertainty else compute_normals,
                                        depth, K, method=method, depth_scale=depth_scale,
                                        return_uncertainty=return_uncertainty, **options)
        out = result[0] if return_uncertainty else result
        empty = [i for i in range(out.shape[0]) if not np.isfinite(out[i, ..., 0]).any()]
        if empty:
            shown = ", ".join(map(str, empty[:10])) + (", ..." if len(empty) > 10 else "")
            warnings.warn(f"{len(empty)} of {out.shape[0]} frames of the stack hold no finite normal "
                          f"(frames {shown}): no valid depth, no valid pixel with a valid neighbour, "
                          "or the method's own rules refused every neighbourhood",
                          NoValidNormalWarning, stacklevel=2)
        return result
    if return_uncertainty:
        out, unc = _with_uncertainty(depth, K, method=method, depth_scale=depth_scale, **options)
        if not _has_finite(out):
            z = check_depth(depth, depth_scale=depth_scale)
            warnings.warn(no_valid_normal_message(z), NoValidNormalWarning, stacklevel=2)
        return out, unc
    out = compute_normals(depth, K, method=method, depth_scale=depth_scale, **options)
    if not _has_finite(out):
        z = check_depth(depth, depth_scale=depth_scale)
        warnings.warn(no_valid_normal_message(z), NoValidNormalWarning, stacklevel=2)
    return out


def _with_uncertainty(depth: Any, K: Any, *, method: str, depth_scale: float | None = None,
                      **options: Any) -> tuple[np.ndarray, np.ndarray]:
    """One frame's ``(normals, uncertainty)`` (:func:`depthnormals.ddm.uncertainty.normals_with_uncertainty`
    over :func:`compute_normals`), in the call form a batch's frames use."""
    return normals_with_uncertainty(compute_normals, depth, K, method=method,
                                    depth_scale=depth_scale, options=options)


def _has_finite(out: np.ndarray) -> bool:
    """Whether a normal map (H, W, 3) holds any finite normal: its middle row first (the
    common answer, 0.4 ms saved at 640x480), the whole map only when that row has none."""
    mid = out[out.shape[0] // 2, :, 0] if out.shape[0] else out[..., 0]
    return bool(np.isfinite(mid).any() or np.isfinite(out[..., 0]).any())


def _is_stack(shape: tuple[int, ...], stack: bool | None) -> bool:
    """Whether a 3-D depth of ``shape`` is a stack of frames (see ``estimate_normals``'s ``stack``)."""
    if stack is not None:
        if not stack and shape[-1] != 1:
            raise ValueError(f"depth must be a 2-D array (H, W) or (H, W, 1) with stack=False; "
                             f"got shape {shape}")
        return stack
    if shape[-1] in (3, 4):
        raise ValueError(
            f"depth must be a 2-D array (H, W) or a stack (N, H, W); got shape {shape}, which looks "
            f"like a colour image ({shape[-1]} channels); pass the depth image itself, or "
            f"stack=True if these are {shape[0]} depth frames of {shape[1]} x {shape[2]} pixels")
    return shape[-1] != 1


def compute_normals(depth: Any, K: Any, *, method: str = DEFAULT_METHOD,
                    depth_scale: float | None = None, **options: Any) -> np.ndarray:
    """One frame (H, W) or (H, W, 1) by ``method``: :func:`estimate_normals` without its stack
    dispatch and without the all-NaN warning (front ends that report it their own way: the
    command line's exit status 3, a stack's one warning)."""
    if not isinstance(method, str):
        raise TypeError(f"method must be a string; got {type(method).__name__}")
    if np.ndim(depth) == 3 and np.shape(depth)[-1] == 1:  # a single-channel image (H, W, 1)
        # sliced, not converted: a masked array keeps its mask for check_depth
        depth = (depth if isinstance(depth, np.ndarray) else np.asarray(depth))[..., 0]
    if method.endswith("+") and method[:-1] in _REGISTRY:
        base = method[:-1]
        info = _REGISTRY[base]
        own, rest = _split_options(method, info, options, tuple(ddm.module_defaults()))
        if base in FUSED_PLUS:
            fused = FUSED_PLUS[base](depth, K, depth_scale, own, rest)
            if fused is not None:
                return fused
        normals = info.func(depth, K, depth_scale=depth_scale, **own)
        return ddm.discontinuity_discrimination(normals, depth, K, depth_scale=depth_scale,
                                                **rest)
    info = get_estimator(method)
    own, _ = _split_options(method, info, options)
    return info.func(depth, K, depth_scale=depth_scale, **own)
