"""The estimator registry and the one dispatcher over it.

Every estimator is a public function ``f(depth, K, *, option=..., depth_scale=None)`` that
registers itself here with :func:`register`. ``estimate_normals(depth, K, method=name)`` looks
the name up; ``"<name>+"`` is estimator ``<name>`` followed by the discontinuity
discrimination module (:func:`depthnormals.ddm.discontinuity_discrimination`).
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["EstimatorInfo", "estimate_normals", "get_estimator", "methods", "register"]

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


_REGISTRY: dict[str, EstimatorInfo] = {}


def register(name: str, *, scale_invariant: bool = True) -> Callable[[Callable], Callable]:
    """Class the decorated function as estimator ``name`` (decorator)."""

    def deco(func: Callable) -> Callable:
        if name in _REGISTRY or name.endswith("+"):
            raise ValueError(f"estimator name {name!r} is taken or reserved")
        params = inspect.signature(func).parameters
        options = tuple(
            p.name for p in params.values()
            if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name != "depth_scale"
        )
        doc = (func.__doc__ or "").strip().splitlines()
        _REGISTRY[name] = EstimatorInfo(name, func, options, scale_invariant, doc[0] if doc else "")
        return func

    return deco


def _load() -> None:
    importlib.import_module("depthnormals.estimators")


def _has_ddm() -> bool:
    return importlib.util.find_spec("depthnormals.ddm") is not None


def methods(*, refined: bool = True) -> tuple[str, ...]:
    """Names accepted by :func:`estimate_normals`, sorted.

    Parameters
    ----------
    refined : bool, default True
        Also list the ``"<name>+"`` forms (estimator followed by the discontinuity
        discrimination module).
    """
    _load()
    base = sorted(_REGISTRY)
    if refined and _has_ddm():
        return tuple(sorted(base + [n + "+" for n in base]))
    return tuple(base)


def get_estimator(name: str) -> EstimatorInfo:
    """The :class:`EstimatorInfo` of a base name; ValueError listing the valid ones otherwise."""
    _load()
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
    if unknown:
        valid = sorted(info.options + extra)
        raise TypeError(
            f"method {method!r} got unknown option(s) {unknown}; valid options: "
            f"{', '.join(valid) if valid else '(none)'}"
        )
    return own, rest


def estimate_normals(depth: Any, K: Any, *, method: str = DEFAULT_METHOD,
                     depth_scale: float | None = None, **options: Any) -> np.ndarray:
    """Surface normals from a depth image by any registered estimator.

    Parameters
    ----------
    depth : array_like, shape (H, W) or (N, H, W)
        Planar depth z. float32/float64; integers need ``depth_scale``. Invalid depth
        (0, negative, NaN, inf) gives a NaN normal. A stack of N frames is spread over the
        threads, one frame per thread (:func:`depthnormals.batch.estimate_normals_batch`).
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy); for a stack also (N, 3, 3) or N of those
        Camera intrinsics in pixels, 0-based pixel centres.
    method : str
        A name from :func:`methods`; ``"<name>+"`` adds the discontinuity discrimination
        module of 3F2N+ after estimator ``<name>``.
    depth_scale : float, optional
        Metres per unit of integer depth (e.g. 0.001 for millimetres).
    **options
        Keyword options of the chosen estimator (and, for ``"<name>+"``, of
        :func:`depthnormals.ddm.discontinuity_discrimination`). Unknown names raise TypeError.

    Returns
    -------
    normals : ndarray, shape (H, W, 3) or (N, H, W, 3), float32
        Unit normals in the OpenCV camera frame facing the camera (``dot(n, X) < 0``),
        NaN where no estimate is possible.

    Examples
    --------
    >>> import numpy as np, depthnormals as dn
    >>> n = dn.estimate_normals(np.full((4, 5), 2.0), (500, 500, 2, 1.5), method="3f2n")
    >>> n[1, 2].tolist()
    [0.0, 0.0, -1.0]
    """
    if not isinstance(method, str):
        raise TypeError(f"method must be a string; got {type(method).__name__}")
    if np.ndim(depth) == 3:  # a stack of frames (N, H, W): one frame per thread
        from .batch import estimate_normals_batch

        return estimate_normals_batch(depth, K, method=method, depth_scale=depth_scale, **options)
    _load()
    if method.endswith("+") and method[:-1] in _REGISTRY and _has_ddm():
        ddm = importlib.import_module("depthnormals.ddm")
        info = _REGISTRY[method[:-1]]
        refine = ddm.discontinuity_discrimination
        ddm_opts = tuple(ddm.module_defaults())
        own, rest = _split_options(method, info, options, ddm_opts)
        fused = ddm.fused_plus(method[:-1], depth, K, depth_scale, own, rest)
        if fused is not None:
            return fused
        normals = info.func(depth, K, depth_scale=depth_scale, **own)
        return refine(normals, depth, K, depth_scale=depth_scale, **rest)
    info = get_estimator(method)
    own, _ = _split_options(method, info, options)
    return info.func(depth, K, depth_scale=depth_scale, **own)
