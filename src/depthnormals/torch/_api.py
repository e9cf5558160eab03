"""The public torch API: :func:`estimate_normals`, :func:`normals_mask` and the module twin."""

from __future__ import annotations

import inspect
import numbers
from typing import Any

import torch
from torch import nn

from .._validate import check_int, check_real
from ._auto import frames_of, in_order, noisy_frames, noisy_select
from ._common import Camera, Grid, finish, prepare
from ._d2nt import VARIANTS, d2nt
from ._ddm import refine
from ._planes import plane_select
from ._threefn import AGGREGATES, KERNELS, sne_roadseg, three_filters_to_normal

__all__ = ["METHODS", "TORCH_MODULE_DEFAULTS", "EstimateNormals", "estimate_normals", "method_defaults",
           "normals_mask"]

_BASES = ("3f2n", "d2nt", "sne-roadseg")
#: where :func:`estimate_normals` computes: ``"auto"`` (the numba library for CPU tensors
#: without gradients, torch otherwise), ``"torch"``, ``"numba"``
BACKENDS = ("auto", "torch", "numba")
#: names accepted by :func:`estimate_normals` (``"<name>+"``: the estimator, then the DDM)
METHODS = (*_BASES, *(b + "+" for b in _BASES))
_CURVATURES = ("mean", "max", "normal", "gauss", "pixel-mean", "none")
_CHOICES = {
    "kernel": tuple(KERNELS), "aggregate": AGGREGATES, "variant": VARIANTS,
    "curvature": _CURVATURES, "correlation": ("kendall", "kendall-prose", "pearson", "none"),
    "derivatives": ("inverse-depth", "depth"), "slope": ("min", "central"),
    "footprint": ("pixel", "neighbours"), "neighbourhood": ("square", "cross"),
    "selection": ("curvature", "plane-fit", "box-fit", "planes", "auto"),
}
_MODULE_OPTIONS = ("curvature", "correlation", "crf", "sigma", "lambda_", "crf_iterations",
                   "neighbourhood", "derivatives", "slope", "footprint", "selection", "fit_radius",
                   "self_weight", "consistency")


def _numba_function(base: str):
    import depthnormals as dn

    return {"3f2n": dn.three_filters_to_normal, "d2nt": dn.d2nt, "sne-roadseg": dn.sne_roadseg}[base]


def _read_defaults() -> dict[str, dict[str, Any]]:
    """The numba estimators' and module's options with their defaults, read from their
    signatures once, at import (not inside a traced call)."""
    from depthnormals.ddm import module_defaults

    out = {}
    for base in _BASES:
        params = inspect.signature(_numba_function(base)).parameters.values()
        out[base] = {p.name: p.default for p in params
                     if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name != "depth_scale"}
    out["+"] = {**module_defaults(), **TORCH_MODULE_DEFAULTS}
    return out


#: Where the torch module's defaults differ from the numba module's: the margin of an
#: explicit ``selection="curvature"`` (0 here, 0.1 in numba; the torch default was the
#: curvature selection at margin 0 until session 6). ``selection="auto"`` (the default of
#: both) is the same rule in both (noise estimate, then the plane hypotheses, the box-fit or
#: the measured support), whose clean branch with the CRF or a correlation uses margin 0.
TORCH_MODULE_DEFAULTS = {"consistency": 0.0}


_DEFAULTS = _read_defaults()


def method_defaults(method: str) -> dict[str, Any]:
    """The options of ``method`` and their defaults: those of the numba library, read from
    its signatures (so the torch path follows when they change), except the module's
    ``consistency`` (:data:`TORCH_MODULE_DEFAULTS`).

    Examples
    --------
    >>> from depthnormals.torch import method_defaults
    >>> method_defaults("3f2n")
    {'kernel': 'fd', 'kernel_size': 3, 'aggregate': 'median'}
    """
    base = _check_method(method)
    opts = dict(_DEFAULTS[base])
    if method.endswith("+"):
        opts.update(_DEFAULTS["+"])
    return opts


def _check_method(method: Any) -> str:
    if not isinstance(method, str):
        raise TypeError(f"method must be a string, one of {', '.join(METHODS)}; got {method!r}")
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r} for depthnormals.torch; valid methods: "
                         f"{', '.join(METHODS)} (the numba library has more: depthnormals.methods())")
    return method.rstrip("+")


def _check_options(method: str, options: dict[str, Any]) -> dict[str, Any]:
    """Options of ``method`` merged over its defaults, validated and normalised."""
    defaults = method_defaults(method)
    unknown = sorted(set(options) - set(defaults))
    if method.endswith("+"):
        from depthnormals.ddm import renamed_option_error

        for name in unknown:
            err = renamed_option_error(name, f"method {method!r}")
            if err is not None:
                raise err
    if unknown:
        raise TypeError(f"method {method!r} got unknown option(s) {unknown}; valid options: "
                        f"{', '.join(sorted(defaults)) or '(none)'}, depth_scale, invalid")
    lag = sorted(set(defaults) - set(_CHOICES) - set(_MODULE_OPTIONS) - {"kernel_size"})
    if lag:
        raise ValueError(f"the numba library has option(s) {lag} that depthnormals.torch does not "
                         "implement yet; use depthnormals.estimate_normals")
    o = {**defaults, **options}
    for name, choices in _CHOICES.items():
        if name not in o:
            continue
        if name == "neighbourhood" and o[name] is None:
            o[name] = "cross"
        value = o[name]
        if not isinstance(value, str):
            raise TypeError(f"{name} must be a string, one of {', '.join(choices)}; got {value!r}")
        if value not in choices:
            raise ValueError(f"unknown {name} {value!r}; valid choices: {', '.join(choices)}")
    if "kernel_size" in o:
        ks = o["kernel_size"]
        if isinstance(ks, bool) or not isinstance(ks, numbers.Integral):
            raise TypeError(f"kernel_size must be an odd integer in 3..11; got {ks!r}")
        if int(ks) not in (3, 5, 7, 9, 11):
            raise ValueError(f"kernel_size must be one of 3, 5, 7, 9, 11; got {ks}")
        o["kernel_size"] = int(ks)
    if method.endswith("+"):
        _check_module(o)
    return o


def _check_module(o: dict[str, Any]) -> None:
    if not isinstance(o["crf"], bool):
        raise TypeError(f"crf must be True or False; got {o['crf']!r}")
    o["sigma"] = check_real(o["sigma"], "sigma", minimum=0.0)
    o["lam"] = check_real(o.pop("lambda_"), "lambda_", minimum=0.0)
    o["iterations"] = check_int(o.pop("crf_iterations"), "crf_iterations", minimum=1, maximum=10**6)
    o["fit_radius"] = check_int(o["fit_radius"], "fit_radius", minimum=1, maximum=3)
    sw = check_real(o["self_weight"], "self_weight", minimum=0.0)
    if not 0.0 < sw <= 1.0:
        raise ValueError(f"self_weight must be in (0, 1]; got {o['self_weight']!r}")
    o["self_weight"] = sw
    if o["consistency"] is not None:
        o["consistency"] = check_real(o["consistency"], "consistency", minimum=0.0)
    if o["crf"] and o["curvature"] == "none":
        raise ValueError("the CRF weights its edges by the depth curvature k_q: pass a curvature "
                         "other than 'none', or crf=False for a correlation-only selection")
    if o["selection"] == "plane-fit":
        raise ValueError("selection='plane-fit' is not implemented in depthnormals.torch (every other "
                         "selection is: 'auto', 'box-fit', 'planes', 'curvature'); use "
                         "depthnormals.estimate_normals for it")
    if o["selection"] == "planes" and (o["crf"] or o["correlation"] != "none"):
        raise ValueError("the CRF and the correlations need the curvature selection: pass "
                         "selection='curvature' (or 'auto'), not 'planes'")


def _pad(base: str, o: dict[str, Any], refined: bool) -> int:
    pad = 1
    if base == "3f2n" and o["kernel"] != "roberts":
        pad = o["kernel_size"] // 2
    if (base == "d2nt" and o["variant"] != "basic") or refined:
        pad = max(pad, 2)
    return pad


def estimate_normals(depth: torch.Tensor, K: Any, *, method: str = "3f2n+",
                     depth_scale: float | None = None, invalid: str = "nan",
                     backend: str = "auto", return_uncertainty: bool = False,
                     **options: Any) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """Surface normals of a batch of depth images, in torch: batched, differentiable, on the
    device of the input.

    Parameters
    ----------
    depth : Tensor, shape (B, 1, H, W) or (B, H, W)
        Planar depth z (any length unit). float32/float64 are computed in their own dtype,
        float16/bfloat16 in float32; integer depth needs ``depth_scale``. Invalid depth
        (0, negative, NaN, inf) never enters a stencil and gives no normal.
    K : Tensor (3, 3), (B, 3, 3), (4,) or (B, 4); Intrinsics; 3x3 array; (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres; one for the batch or one per frame.
        Tensor values are not checked (checking would synchronise with the device).
    method : {"3f2n", "d2nt", "sne-roadseg", "3f2n+", "d2nt+", "sne-roadseg+"}, default "3f2n+"
        The estimator; ``"<name>+"`` adds the discontinuity discrimination module of 3F2N+.
    depth_scale : float, optional
        Metres per unit of integer depth (e.g. 0.001 for millimetres).
    invalid : {"nan", "zero"}, default "nan"
        What pixels without an estimate hold: NaN (the library's convention) or the zero
        vector (safe to feed a network). :func:`normals_mask` recovers the mask from either.
    backend : {"auto", "torch", "numba"}, default "auto"
        Where the normals are computed. ``"torch"``: this package's implementation (any
        device, differentiable). ``"numba"``: the numba library, frame by frame on the CPU
        (the same bits as :func:`depthnormals.estimate_normals`; no gradient; a CUDA tensor
        is copied to the host and back). ``"auto"``: numba for a CPU tensor when no gradient
        is asked for (it is 5-40x faster there and gives the same answer), torch otherwise.
    return_uncertainty : bool, default False
        Also return the expected angular error of every normal (degrees; the numba library's
        map, :mod:`depthnormals.ddm.uncertainty`, computed on the host from the same depth:
        it carries no gradient), as a (B, 1, H, W) float32 tensor on the depth's device, NaN
        (0 with ``invalid="zero"``) exactly where the normal has none. With ``backend="auto"``
        and no gradient asked for, the normals are then the numba library's too, computed with
        the map (on a GPU tensor as well: the same answer, without a second pass on the
        device). For ``"3f2n+"`` with its default module options; anything else raises
        ValueError.
    **options
        The options of the numba estimator of the same name, with the same defaults
        (:func:`method_defaults`): ``kernel``, ``kernel_size``, ``aggregate`` (3F2N),
        ``variant`` (D2NT) and, for ``"<name>+"``, those of
        :func:`depthnormals.discontinuity_discrimination` with ``selection`` one of
        ``"auto"``, ``"box-fit"``, ``"planes"``, ``"curvature"`` (``"plane-fit"`` raises
        ValueError). Module defaults: the numba module's, except
        :data:`TORCH_MODULE_DEFAULTS` (``consistency=0.0``, which only an explicit
        ``selection="curvature"`` reads). ``selection="auto"`` is the numba default's rule,
        frame by frame: the noise estimate, then the plane hypotheses on clean depth, the
        box-fit of independent noise or the measured support of real sensor depth
        (docs/3f2n-plus.md), with the same normals (float64 parity <= 1e-6 deg mean on
        analytic, synthetic-sensor and real frames: tests/test_torch_default_parity.py).

    Returns
    -------
    normals : Tensor, shape (B, 3, H, W)
        Unit normals in the OpenCV camera frame (x right, y down, z forward), facing the
        camera (``dot(n, X) < 0``: a fronto-parallel wall gives (0, 0, -1)); NaN (or 0) where
        no estimate exists. dtype: that of a floating input (float16/bfloat16 computed in
        float32 and rounded), float32 for integer depth.
    uncertainty : Tensor, shape (B, 1, H, W), float32
        Only with ``return_uncertainty=True``: the expected angular error, degrees.

    Notes
    -----
    Same results as :func:`depthnormals.estimate_normals` up to float32 rounding (parity
    tests: <= 0.01 deg mean, <= 0.1 deg at the 99.9th percentile). Differentiable with
    respect to depth (and tensor intrinsics); the selections (median, DAG switch, curvature
    selection, CRF, the plane hypotheses, the choice of box-fit window) are piecewise, so the
    gradient flows through the chosen candidate (for the box-fit: the chosen window's
    least-squares plane; from radius 6 the measured support fits every second row and column,
    so only those pixels get a gradient), and it is finite wherever the output is.

    Host synchronisation: none for the estimators and an explicit ``selection``; the default
    ``selection="auto"`` reads each frame's noise level on the host once (a few numbers per
    frame) to choose its branch, and once more for the support profile when a frame is
    noisy, so a ``torch.compile``'d call breaks its graph there (measured on an H200:
    compiled default 18,300 frames/s at batch 64, docs/torch.md).

    Examples
    --------
    >>> import torch
    >>> from depthnormals.torch import estimate_normals
    >>> depth = torch.full((1, 1, 4, 5), 2.0)
    >>> n = estimate_normals(depth, (500.0, 500.0, 2.0, 1.5), method="3f2n")
    >>> n[0, :, 1, 2].round(decimals=6).tolist()  # (unit length to float32's last bit)
    [0.0, 0.0, -1.0]
    """
    base = _check_method(method)
    if not isinstance(invalid, str) or invalid not in ("nan", "zero"):
        raise ValueError(f"invalid must be 'nan' or 'zero'; got {invalid!r}")
    if not isinstance(backend, str) or backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}; got {backend!r}")
    if not isinstance(return_uncertainty, bool):
        raise TypeError(f"return_uncertainty must be True or False; got {return_uncertainty!r}")
    o = _check_options(method, options)
    on_numba = backend == "numba" or (backend == "auto" and _numba_suits(depth, K))
    if return_uncertainty or on_numba:
        out_dtype = prepare(depth, K, depth_scale)[3]  # (and the inputs checked)
    if return_uncertainty:
        if method != "3f2n+":
            raise ValueError(f"return_uncertainty=True needs method '3f2n+' in depthnormals.torch; got "
                             f"{method!r} (the numba library also maps fals, PCL's modes and the box "
                             "plane fits)")
        n, unc = _numba_backend(depth, K, method, depth_scale, invalid, options, out_dtype, True)
        # the numba normals came with the map: the torch pass only where it was asked for or a
        # gradient is (a CUDA batch of 8 640x480 frames: 105 -> 59 ms on an H200, docs/torch.md)
        if not on_numba and (backend == "torch" or _grad_wanted(depth, K)):
            n = estimate_normals(depth, K, method=method, depth_scale=depth_scale, invalid=invalid,
                                 backend="torch", **options)
        n, unc = n.to(depth.device), unc.to(depth.device)
        none = unc.new_tensor(float("nan") if invalid == "nan" else 0.0)
        return n, torch.where(normals_mask(n), unc, none)
    if on_numba:
        return _numba_backend(depth, K, method, depth_scale, invalid, options, out_dtype)
    auto = method.endswith("+") and o["selection"] in ("auto", "box-fit")
    noise, noisy = _noise_first(depth, K, depth_scale, o) if auto else (None, [])
    # prepared after the host read of the noise pass: a torch.compile'd call then traces the
    # clean branch from the inputs, as for an explicit selection (measured: with the prepared
    # tensors carried across the graph break, inductor's graph ran 65 instead of 44 ms a frame
    # on one CPU thread)
    z, valid, cam, out_dtype = prepare(depth, K, depth_scale)
    if noisy:  # the noisy branches read float64 depth, NaN at invalid pixels
        cam64 = tuple(c.to(torch.float64) for c in (cam.fx, cam.fy, cam.cx, cam.cy))
        z64 = torch.where(valid, z.to(torch.float64), float("nan"))
        return finish(*_mixed(z, valid, cam, z64, cam64, noise, noisy, base, method, o),
                      invalid, out_dtype)
    return finish(*_clean(z, valid, cam, base, method, o), invalid, out_dtype)


def _noise_first(depth, K, depth_scale, o: dict[str, Any]):
    """The noise pass of every frame and the frames that take a noisy branch
    (:func:`._auto.noisy_frames`), from the inputs (its result is read on the host: a compiled
    call breaks its graph after it)."""
    z, valid, cam, _ = prepare(depth, K, depth_scale)
    cam64 = tuple(c.to(torch.float64) for c in (cam.fx, cam.fy, cam.cx, cam.cy))
    return noisy_frames(z, valid, cam64, o)


def _estimator(grid: Grid, cam: Camera, base: str, o: dict[str, Any]):
    if base == "3f2n":
        return three_filters_to_normal(grid, cam, o["kernel"], o["kernel_size"], o["aggregate"])
    if base == "d2nt":
        return d2nt(grid, cam, o["variant"])
    return sne_roadseg(grid, cam)


def _clean(z, valid, cam: Camera, base: str, method: str, o: dict[str, Any]):
    """The estimator and, for ``"<name>+"``, the module's clean branch (or the selection
    asked for): (nx, ny, nz, ok)."""
    grid = Grid(z, valid, _pad(base, o, method.endswith("+")))
    planes = method.endswith("+") and (o["selection"] == "planes" or (
        o["selection"] in ("auto", "box-fit") and not o["crf"] and o["correlation"] == "none"))
    if planes and base == "3f2n":  # 3F2N never abstains at valid depth: nothing of it is kept
        return plane_select(grid, cam, valid)
    n = _estimator(grid, cam, base, o)
    if planes:
        return plane_select(grid, cam, n[3])
    if method.endswith("+"):
        if o["selection"] in ("auto", "box-fit"):  # with the CRF / a correlation: margin min(consistency, 0)
            eps = o["consistency"]
            o = {**o, "selection": "curvature", "consistency": None if eps is None else min(eps, 0.0)}
        return refine(grid, cam, n[:3], n[3], o)
    return n


def _cam_sub(cam: Camera, idx: torch.Tensor) -> Camera:
    return Camera(*frames_of((cam.fx, cam.fy, cam.cx, cam.cy, cam.a, cam.b), idx))


def _mixed(z, valid, cam: Camera, z64, cam64, noise, noisy: list[int], base: str, method: str,
           o: dict[str, Any]):
    """Frames ``noisy`` through the noisy branch, the others through the clean one; (nx, ny,
    nz, ok) in the batch's order."""
    b = z.shape[0]
    dev = z.device
    clean = [i for i in range(b) if i not in set(noisy)]
    nt = torch.tensor(noisy, device=dev)
    est = None
    if base != "3f2n":  # the estimator's normals are kept where the fit agrees (ddm.auto._keep_rows)
        sub = _cam_sub(cam, nt)
        est = _estimator(Grid(z[nt], valid[nt], _pad(base, o, True)), sub, base, o)
        est = tuple(q.to(torch.float64) if q.dtype.is_floating_point else q for q in est)
    parts = [tuple(q.to(z.dtype) if q.dtype.is_floating_point else q
                   for q in noisy_select(z64, valid, cam64, noise, noisy, base=est))]
    order = list(noisy)
    if clean:
        ct = torch.tensor(clean, device=dev)
        parts.append(_clean(z[ct], valid[ct], _cam_sub(cam, ct), base, method, o))
        order += clean
    return in_order(parts, order, dev)


def _numba_suits(depth: torch.Tensor, K: Any) -> bool:
    """``backend="auto"``: the numba library computes where it gives the same answer faster
    and nothing is lost: a CPU tensor, no gradient asked for (of the depth or of tensor
    intrinsics)."""
    if not isinstance(depth, torch.Tensor) or depth.device.type != "cpu":
        return False  # (not a tensor: the torch path's checks say what is accepted)
    if _grad_wanted(depth, K):
        return False
    return not (isinstance(K, torch.Tensor) and K.device.type != "cpu")


def _grad_wanted(depth: Any, K: Any) -> bool:
    """A gradient is asked for: of the depth or of tensor intrinsics, with autograd on."""
    return torch.is_grad_enabled() and any(
        isinstance(t, torch.Tensor) and t.requires_grad for t in (depth, K))


def _numba_backend(depth, K, method: str, depth_scale, invalid: str, options: dict[str, Any],
                   out_dtype: torch.dtype, uncertainty: bool = False):
    """Every frame through :func:`depthnormals.estimate_normals` (same method and options, the
    torch defaults where they differ): (B, 3, H, W) on the CPU in ``out_dtype``; with
    ``uncertainty`` also the expected-error maps (B, 1, H, W) float32 (``return_uncertainty``)."""
    import numpy as np

    import depthnormals as dn

    d = depth.detach().cpu()
    if d.ndim == 4:
        d = d[:, 0]
    if d.dtype in (torch.float16, torch.bfloat16):
        d = d.to(torch.float32)
    arr = d.numpy()
    b = arr.shape[0]
    if isinstance(K, torch.Tensor):
        kk = K.detach().to(torch.float64).cpu().numpy()
        per_frame = kk.ndim == 3 or (kk.ndim == 2 and kk.shape[-1] == 4)
        Ks = [kk[0 if kk.shape[0] == 1 else i] if per_frame else kk for i in range(b)]
    else:
        Ks = [K] * b
    opts = dict(options)
    if method.endswith("+") and not uncertainty:  # (the map takes the default options only)
        for name, value in TORCH_MODULE_DEFAULTS.items():
            opts.setdefault(name, value)
    # one stack call: the frames spread over the library's threads, each computed exactly as
    # its single call (depthnormals.batch)
    res = dn.estimate_normals(arr, Ks, method=method, depth_scale=depth_scale, stack=True,
                              return_uncertainty=uncertainty, **opts)
    out, unc = (res[0], torch.from_numpy(res[1])[:, None]) if uncertainty else (res, None)
    if invalid == "zero":
        out = np.where(np.isnan(out), np.float32(0.0), out)
    n = torch.from_numpy(out).permute(0, 3, 1, 2).to(out_dtype)
    return (n, unc) if uncertainty else n


def normals_mask(normals: torch.Tensor) -> torch.Tensor:
    """Where a normal map from :func:`estimate_normals` holds an estimate: (B, 1, H, W) bool.

    Works for either ``invalid`` convention (finite and of non-zero length).
    """
    if not isinstance(normals, torch.Tensor) or normals.ndim != 4 or normals.shape[1] != 3:
        raise ValueError("normals must be a (B, 3, H, W) tensor from estimate_normals; got "
                         f"{getattr(normals, 'shape', type(normals).__name__)}")
    finite = torch.isfinite(normals).all(dim=1, keepdim=True)
    return finite & (normals.abs().sum(dim=1, keepdim=True) > 0)


class EstimateNormals(nn.Module):
    """:func:`estimate_normals` as an ``nn.Module`` (for a model or a data transform).

    Parameters
    ----------
    method : str, default "3f2n+"
        As :func:`estimate_normals`.
    K : optional
        Intrinsics to use when ``forward`` gets none; a tensor is kept as a buffer (it follows
        ``.to(device)``).
    depth_scale, invalid, backend, **options
        As :func:`estimate_normals`; checked here, at construction.

    Examples
    --------
    >>> import torch
    >>> from depthnormals.torch import EstimateNormals
    >>> net = EstimateNormals("3f2n", K=torch.tensor([500.0, 500.0, 2.0, 1.5]), invalid="zero")
    >>> net(torch.full((2, 1, 4, 5), 2.0)).shape
    torch.Size([2, 3, 4, 5])
    """

    def __init__(self, method: str = "3f2n+", K: Any = None, *, depth_scale: float | None = None,
                 invalid: str = "nan", backend: str = "auto", **options: Any):
        super().__init__()
        _check_options(method, options)
        if not isinstance(invalid, str) or invalid not in ("nan", "zero"):
            raise ValueError(f"invalid must be 'nan' or 'zero'; got {invalid!r}")
        if not isinstance(backend, str) or backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}; got {backend!r}")
        self.backend = backend
        self.method = method
        self.depth_scale = depth_scale
        self.invalid = invalid
        self.options = dict(options)
        if isinstance(K, torch.Tensor):
            self.register_buffer("K", K.clone())
        else:
            self.K = K

    def forward(self, depth: torch.Tensor, K: Any = None) -> torch.Tensor:
        """Normals (B, 3, H, W) of ``depth`` (B, 1, H, W) or (B, H, W)."""
        K = self.K if K is None else K
        if K is None:
            raise ValueError("no intrinsics: pass K to forward or to the constructor")
        return estimate_normals(depth, K, method=self.method, depth_scale=self.depth_scale,
                                invalid=self.invalid, backend=self.backend, **self.options)

    def extra_repr(self) -> str:
        opts = "".join(f", {k}={v!r}" for k, v in self.options.items())
        return f"method={self.method!r}, invalid={self.invalid!r}{opts}"
