"""The discontinuity discrimination module (DDM) of 3F2N+: the public entry point."""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import check_choice, check_normals, check_real
from ..kernels.depth import prepare, row_dtype
from .auto import refine_auto
from .correlation import CORRELATIONS, kendall_map
from .crf import crf_step
from .curvature import CURVATURES, DERIVATIVES, FOOTPRINTS, SLOPES, curvature_map
from .planefit import plane_fit_select
from .selection import CROSS, SQUARE, select_min

__all__ = ["NEIGHBOURHOODS", "RENAMED", "ModuleOptions", "discontinuity_discrimination",
           "module_defaults", "renamed_option_error"]

NEIGHBOURHOODS = ("square", "cross")
_CURV = (*CURVATURES, "none")


SELECTIONS = ("curvature", "plane-fit", "box-fit", "planes", "auto")

#: Module options renamed so that no "+" form has two options of one name: old -> new.
RENAMED = {"iterations": "crf_iterations"}


@dataclass(frozen=True)
class ModuleOptions:
    """The options of the discontinuity discrimination module, validated on construction.

    The fields and their meaning are those of :func:`discontinuity_discrimination`'s
    parameters (same names, same defaults).
    """

    curvature: str = "mean"
    correlation: str = "none"
    crf: bool = False
    sigma: float = 1.0
    lambda_: float = 0.01
    crf_iterations: int = 1
    neighbourhood: str | None = None
    derivatives: str = "inverse-depth"
    slope: str = "min"
    footprint: str = "pixel"
    selection: str = "auto"
    fit_radius: int = 2
    self_weight: float = 0.8
    consistency: float | None = 0.1

    def __post_init__(self) -> None:
        self.normalised()

    def normalised(self) -> dict[str, Any]:
        """The options checked and normalised, as the kernels take them (``lam``,
        ``iterations``, floats)."""
        return _options(**{f.name: getattr(self, f.name) for f in dataclasses.fields(self)})


def _empty(shape: tuple[int, ...]) -> np.ndarray:
    return np.empty((shape[0], shape[1], 3), dtype=np.float32)  # the kernels write every pixel


def discontinuity_discrimination(normals: Any, depth: Any, K: Any, *,
                                 options: ModuleOptions | None = None,
                                 depth_scale: float | None = None,
                                 **module_options: Any) -> np.ndarray:
    """Refine any estimator's normals near discontinuities: the DDM of 3F2N+.

    The options are the fields of :class:`ModuleOptions`, given either as ``options=`` or as
    keywords (``correlation="kendall", crf=True``), never both; unknown names raise TypeError.
    Three stages, each optional:

    1. **Curvature selection** (section III-A): every pixel takes the normal of the candidate
       with the least depth curvature among itself and its neighbours
       (``r = argmin_{r in P+} k_r``, ``n_q = n_r``; the pixel itself wins ties). By default
       (``selection="auto"``) only on clean depth: noisy depth takes the box-fit instead
       (``selection`` below).
    2. **Correlation** (section III-B): Kendall's tau or Pearson's coefficient, read as a
       similarity ``s`` in [0, 1] between a neighbour and the surface of ``q``. Without the
       CRF it is a selection of its own (``argmax s`` over the candidates, the paper's
       Table II); with the CRF it weights the edges.
    3. **CRF** (section III-C): the energy
       ``E(n^_q) = sigma |n^_q - n_q| + lambda k_q sum_i s_i |n_{p_i} - n^_q|``
       (the paper's ``exp(sigma f + sum lambda g)`` read as an energy to minimise; with
       Kendall, ``s_i = 1 - tau_i`` is literally the paper's ``1 - tau``) is minimised per
       pixel over the candidate normals of the neighbourhood, ``n_q`` being the output of
       stage 1. ``crf_iterations > 1`` repeats it synchronously (ICM-like), the anchor staying
       the stage-1 normal.

    Parameters
    ----------
    normals : array_like, shape (H, W, 3)
        Normals of any estimator (float; NaN where it gave none). Need not be unit length.
    depth : array_like, shape (H, W)
        The planar depth they were estimated from. float32/float64; integers need
        ``depth_scale``. Invalid depth (0, negative, NaN, inf) gives NaN and never gives a
        candidate.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels, 0-based pixel centres.
    options : ModuleOptions, optional
        All the options below in one frozen value (default: ``ModuleOptions()``).
    curvature : {"mean", "max", "normal", "gauss", "pixel-mean", "none"}, default "mean"
        Depth curvature (:func:`depthnormals.ddm.depth_curvature`). ``"pixel-mean"`` with
        ``self_weight=1.0, consistency=None`` and no correlation reproduces the authors'
        public code.
    correlation : {"kendall", "kendall-prose", "pearson", "none"}, default "none"
        ``"kendall"``: tau high = discontinuity (``s = 1 - tau``, the CRF formula's reading);
        ``"kendall-prose"``: tau high = same plane (``s = tau``, the prose's arg-max);
        ``"pearson"``: |correlation| of the 3x3 depth patches of the neighbour and of ``q``.
        As a selection on its own Pearson is the identity under this reading (the centre's
        patch correlates perfectly with itself); it acts through the CRF weights.
    crf : bool, default False
        Run stage 3 (needs a curvature). False with a correlation: stage 2 is a selection.
        The paper's full module is ``correlation="kendall", crf=True``; it is not the
        default because, under every reading we implemented, it measured worse than the
        curvature selection alone on the 3F2N torus-knot frame (``docs/3f2n-plus.md``).
    sigma, lambda_ : float, default 1.0 and 0.01
        Node and edge weights of the CRF (``lambda_``: the paper's lambda). Only their ratio
        matters. ``k_q`` enters as ``k_q z_q`` (dimensionless) for ``"mean"`` and ``"max"``,
        and as is for the other kinds. The default lambda was chosen by measurement
        (``docs/3f2n-plus.md``).
    crf_iterations : int, default 1
        CRF passes (1 = the per-pixel minimisation the paper's runtimes suggest). Spelled
        ``iterations`` before 0.2; that name now raises TypeError (``sda-sne+`` has an
        ``iterations`` of its own).
    neighbourhood : {"square", "cross"}, optional
        Candidates: the 3x3 square (the paper's P+) or self + 4-neighbours (the public
        code). Default ``"cross"`` (measured better: diagonal copies shift the normal by
        sqrt 2 pixels on curved surfaces).
    slope : {"min", "central"}, default "min"
        First derivative in the curvature denominators: the smallest of the central and the
        two one-sided differences (as the public code), or the paper's central difference.
        ``"central"`` makes a depth jump look *flat* (its huge slope damps the curvature).
    footprint : {"pixel", "neighbours"}, default "pixel"
        ``"mean"`` / ``"max"`` over the four directional curvatures of the pixel itself, or
        over the eight the neighbours point at it (the paper's ``k_u1 .. k_b2`` reading,
        a 5x5 footprint).
    derivatives : {"inverse-depth", "depth"}, default "inverse-depth"
        Discretisation of the metric curvatures (see :func:`depth_curvature`).
    selection : {"auto", "curvature", "plane-fit", "box-fit", "planes"}, default "auto"
        Stage 1. ``"auto"`` (ours, issue 13; the default since then): estimate the depth noise
        (:func:`depthnormals.estimate_noise`, in pixel footprints ``z / f``); below 0.001
        (clean depth: renders, simulation; float32 renders read ~1e-5) ``"planes"``,
        otherwise ``"box-fit"``; the estimator's abstentions are kept (NaN stays NaN). With
        the paper's CRF or a correlation (``crf=True`` or ``correlation != "none"``) depth
        below 0.03 takes the curvature selection with the consistency margin
        ``min(consistency, 0)`` instead. So ``estimate_normals(depth, K, method="3f2n+")``
        adapts to the depth it is given: on the SSN-like synthetic benchmark with Gaussian
        noise 0.1 z/f it gives 1.20 / 0.32 deg (indoor / outdoor) against 4.67 / 3.92 for
        the curvature selection, and on the clean torus-knot frame 1.251 against 1.396.
        ``"planes"`` (clean depth): nine one-sided planes of inverse depth per pixel, scored
        by how far the pixels each relies on are from one plane (second differences of
        ``1 / z`` in footprints), then four passes in which a pixel takes a neighbour's
        plane wherever it passes through the pixel with a lower score
        (:mod:`depthnormals.ddm.planes`; exact on every facet two pixels wide). The
        estimator's own normals are not used, except that it keeps its abstentions.
        ``"curvature"`` is the paper's (Tables I and II pass it). ``"box-fit"``:
        least-squares planes of inverse depth over box windows (running sums, box-filter
        cost; :mod:`depthnormals.ddm.boxfit`), sized from the noise, edge-aware by a choice
        among the nine windows containing each pixel; the estimator's own normal kept where
        it agrees within the fit's noise (NaN where it abstained); for ``"3f2n+"`` the
        box-fit alone. Measured in docs/3f2n-plus.md ("The noise-aware selection", "Plane
        hypotheses for clean depth").
        ``"plane-fit"`` (our earlier extension, for noisy depth): each pixel takes the
        candidate normal, within ``fit_radius``, whose plane through the candidate's point
        best explains the 5x5 points around the pixel (residuals in pixel footprints
        ``z / fx``, truncated at 1, the pixel itself weighted 3;
        :mod:`depthnormals.ddm.planefit`). Superseded by the box-fit (more accurate under
        noise, ~20x faster); ~0.27 s per 640x480 frame on one core with the default radius.
    fit_radius : int, default 2
        Candidate radius of the plane-fit selection (1..3; (2 r + 1)^2 candidates).
    self_weight : float in (0, 1], default 0.8
        The curvature selection multiplies the pixel's own curvature by this before the
        arg-min, so a neighbour replaces the pixel's normal only when it is clearly smoother.
        ``1.0`` is the paper's plain arg-min (the pixel winning ties). Ours: on smooth curved
        surfaces every candidate's curvature is alike and copying a neighbour's normal only
        shifts it by a pixel (measured in docs/3f2n-plus.md: torus-knot 1.3958 vs 1.3973 at
        1.0; clean sphere-before-wall error ratio to 3F2N 0.065 vs 0.388; noisy ratios
        +0.005).
    consistency : float >= 0 or None, default 0.1
        Ours: the margin of ``selection="curvature"`` (the default ``"auto"`` uses the
        curvature selection only with the paper's CRF or a correlation, on clean depth, at
        ``min(consistency, 0)``).
        The curvature selection takes a neighbour's normal only if that normal fits the
        pixel's own depth about as well as the pixel's normal does. The fit is the one-sided
        tangent inconsistency ``S = min(rho_l, rho_r)^2 + min(rho_u, rho_d)^2``: ``rho_p`` is
        the residual of the 4-neighbour point ``X_p`` to the plane with that normal through
        the pixel's point, along p's ray, in pixel footprints ``z / fx``. The candidate must
        have ``S < S_own + consistency`` (footprints^2). It is small when the normal is
        tangent to the depth on at least one side of each axis, which is right at creases and
        occlusions. This stops the copies across an edge that noise curvature otherwise
        invites. The test is skipped where ``S_own`` is infinite. ``None`` gives the paper's
        plain selection. Measured in docs/3f2n-plus.md: it is what makes ``d2nt+`` beat
        ``d2nt`` on every analytic scene; for ``3f2n+`` it gives torus knot 1.391 vs 1.396
        and noisy error ratios 0.46-0.50 vs 0.57-0.58.
    depth_scale : float, optional
        Metres per unit of integer depth.

    Returns
    -------
    normals : ndarray, shape (H, W, 3), float32
        Unit normals facing the camera, NaN at invalid depth (and where no candidate has a
        normal).

    Notes
    -----
    Interpretations of the paper (each measured in ``docs/3f2n-plus.md``): the guard-free
    curvature formulas; the directional terms taken at the neighbours pointing at ``q``;
    Kendall's two readings; Pearson as a patch correlation; the energy form of the CRF;
    candidates = the 3x3 neighbourhood; ``k_q z_q`` as the curvature weight. ``"pixel-mean"``
    is in raw depth units, as in the public code, so it is not invariant to the depth unit;
    the metric kinds are.

    References
    ----------
    J. Yang, B. Xue, Y. Feng, D. Wang, R. Fan and Q. Chen, "Three-Filters-to-Normal+:
    Revisiting Discontinuity Discrimination in Depth-to-Normal Translation," IEEE
    Transactions on Automation Science and Engineering.

    Examples
    --------
    >>> import numpy as np, depthnormals as dn
    >>> from depthnormals.analytic import box_on_floor
    >>> r = box_on_floor().render(shape=(60, 80), K=(66.0, 66.0, 39.5, 29.5))
    >>> n0 = dn.estimate_normals(r.depth, r.K, method="3f2n")
    >>> n1 = dn.discontinuity_discrimination(n0, r.depth, r.K)
    >>> e0 = dn.normal_metrics(n0, r.normals).mean
    >>> e1 = dn.normal_metrics(n1, r.normals).mean
    >>> bool(e1 < e0)
    True
    """
    opts = _module_options(options, module_options).normalised()
    z, cam = prepare(depth, K, depth_scale)
    z = row_dtype(z, cam.fx, cam.fy, cam.cx, cam.cy)
    n_in = check_normals(normals, shape=z.shape)
    n_in = np.ascontiguousarray(n_in, dtype=np.float32)
    return _refine(z, cam.fx, cam.fy, cam.cx, cam.cy, n_in, None, None, opts)


_SIM_MODES = {"none": 0, "kendall": 1, "kendall-prose": 2, "pearson": 3}  # crf_step's sim_mode


def _options(*, curvature: str, correlation: str, crf: bool, sigma: float, lambda_: float,
             crf_iterations: int, neighbourhood: str | None, derivatives: str, slope: str,
             footprint: str, selection: str, fit_radius: int, self_weight: float,
             consistency: float | None) -> dict[str, Any]:
    """Validate the module's options; return them normalised."""
    check_choice(curvature, "curvature", _CURV)
    check_choice(correlation, "correlation", CORRELATIONS)
    check_choice(derivatives, "derivatives", DERIVATIVES)
    check_choice(slope, "slope", SLOPES)
    check_choice(footprint, "footprint", FOOTPRINTS)
    if not isinstance(crf, (bool, np.bool_)):
        raise TypeError(f"crf must be True or False; got {crf!r}")
    sigma = check_real(sigma, "sigma", minimum=0.0)
    lam = check_real(lambda_, "lambda_", minimum=0.0)
    if isinstance(crf_iterations, bool) or not isinstance(crf_iterations, numbers.Integral):
        raise TypeError(f"crf_iterations must be an integer >= 1; got {crf_iterations!r}")
    if crf_iterations < 1:
        raise ValueError(f"crf_iterations must be >= 1; got {crf_iterations}")
    if neighbourhood is None:
        neighbourhood = "cross"
    check_choice(neighbourhood, "neighbourhood", NEIGHBOURHOODS)
    if crf and curvature == "none":
        raise ValueError("the CRF weights its edges by the depth curvature k_q: pass a curvature "
                         "other than 'none', or crf=False for a correlation-only selection")
    check_choice(selection, "selection", SELECTIONS)
    if selection in ("planes", "box-fit") and (crf or correlation != "none"):
        raise ValueError(f"the CRF and the correlations need the curvature selection: pass "
                         f"selection='curvature' (or 'auto', which takes it on clean depth), not "
                         f"{selection!r}")
    sw = check_real(self_weight, "self_weight", minimum=0.0)
    if not 0.0 < sw <= 1.0:
        raise ValueError(f"self_weight must be in (0, 1]; got {self_weight!r}")
    if isinstance(fit_radius, bool) or not isinstance(fit_radius, numbers.Integral):
        raise TypeError(f"fit_radius must be an integer in 1..3; got {fit_radius!r}")
    if not 1 <= fit_radius <= 3:
        raise ValueError(f"fit_radius must be in 1..3; got {fit_radius}")
    if consistency is not None:
        consistency = check_real(consistency, "consistency", minimum=0.0)
    return {"curvature": curvature, "correlation": correlation, "crf": bool(crf),
            "sigma": sigma, "lam": lam, "iterations": int(crf_iterations),
            "neighbourhood": neighbourhood, "derivatives": derivatives, "slope": slope,
            "footprint": footprint, "selection": selection, "fit_radius": int(fit_radius),
            "self_weight": sw, "consistency": consistency}


def _refine(z: np.ndarray, fx: float, fy: float, cx: float, cy: float,
            n_in: np.ndarray | None, n0: np.ndarray | None, k: np.ndarray | None,
            o: dict[str, Any]) -> np.ndarray:
    """The three stages on prepared depth (as ``row_dtype`` gives it); ``n0``/``k`` given:
    stage 1 already done."""
    if n0 is None and o["selection"] in ("auto", "box-fit", "planes"):  # ddm/auto.py
        return refine_auto(z, fx, fy, cx, cy, n_in, o,
                           lambda oc: _refine(z, fx, fy, cx, cy, n_in, None, None, oc))
    curvature, correlation, crf = o["curvature"], o["correlation"], o["crf"]
    offs = CROSS if o["neighbourhood"] == "cross" else SQUARE
    if n0 is None:
        # stage 1: curvature selection (or a plain re-orientation when there is none), or
        # the plane-fit selection (our noise-robust extension; the curvature then only
        # weights a CRF)
        if curvature == "none" or (o["selection"] == "plane-fit" and not crf):
            k = np.zeros(z.shape)
        else:
            k = curvature_map(z, fx, fy, cx, cy, curvature, o["derivatives"], o["slope"],
                              o["footprint"])
        n0 = _empty(z.shape)
        if o["selection"] == "plane-fit":
            plane_fit_select(z, n_in, fx, fy, cx, cy, o["fit_radius"], 2, n0)
        else:
            select_min(z, n_in, k, offs, fx, fy, cx, cy, n0, self_weight=o["self_weight"],
                       consistency=o["consistency"])

    tau = np.zeros((1, 1))
    if correlation in ("kendall", "kendall-prose"):
        tau = kendall_map(z)
    if not crf:
        if correlation in ("kendall", "kendall-prose"):
            key = tau if correlation == "kendall" else -tau
            key = np.where(np.isnan(key), np.inf, key)
            out = _empty(z.shape)
            select_min(z, n0, key, offs, fx, fy, cx, cy, out)
            return out
        return n0

    # stage 3: the CRF, anchored at the stage-1 normals
    mode = _SIM_MODES[correlation]
    kq = k * z if curvature in ("mean", "max") else k
    cur = n0
    for _ in range(o["iterations"]):
        out = _empty(z.shape)
        crf_step(z, cur, n0, kq, mode, tau, o["sigma"], o["lam"], offs, fx, fy, cx, cy, out)
        cur = out
    return cur


def module_defaults() -> dict[str, Any]:
    """The options of :func:`discontinuity_discrimination` (the fields of
    :class:`ModuleOptions`) and their defaults."""
    return {f.name: f.default for f in dataclasses.fields(ModuleOptions)}


def renamed_option_error(name: str, where: str) -> TypeError | None:
    """The TypeError for a module option spelled the old way (:data:`RENAMED`), else None."""
    if name in RENAMED:
        return TypeError(f"{where}: the module option {name!r} is now {RENAMED[name]!r} "
                         f"(pass {RENAMED[name]}=...)")
    return None


def _module_options(options: ModuleOptions | None, given: dict[str, Any]) -> ModuleOptions:
    """``options`` or the keywords ``given``, as one validated :class:`ModuleOptions`."""
    if options is not None:
        if given:
            raise TypeError("pass the module options either as options=ModuleOptions(...) or as "
                            f"keywords, not both; got options= and {sorted(given)}")
        if not isinstance(options, ModuleOptions):
            raise TypeError(f"options must be a ModuleOptions; got {type(options).__name__}")
        return options
    valid = module_defaults()
    for name in given:
        err = renamed_option_error(name, "discontinuity_discrimination")
        if err is not None:
            raise err
    unknown = sorted(set(given) - set(valid))
    if unknown:
        raise TypeError(f"discontinuity_discrimination got unknown option(s) {unknown}; valid "
                        f"options: {', '.join(sorted(valid))}")
    return ModuleOptions(**given)
