"""The noise-aware selections of the module: ``selection="auto"`` and ``selection="box-fit"``.

``"auto"`` is the module's default (and so of every ``"<name>+"`` method) since issue 13. It
estimates the depth noise (:func:`depthnormals.ddm.noise.estimate_noise`, in pixel
footprints ``z / f``) and picks the support from it:

- **clean depth** (``sigma < PLANES_NOISE``): the plane hypotheses and their propagation
  (:mod:`depthnormals.ddm.planes`): five planes of inverse depth at each pixel (central and
  one-sided),
  scored by how far the pixels they rely on are from one plane, then a neighbour's plane
  wherever it passes through the pixel with a lower score; a pixel where the estimator
  abstained (NaN at valid depth) stays NaN. With the paper's CRF or a correlation
  (``crf=True`` or ``correlation != "none"``), depth below ``NOISE_CLEAN`` takes the paper's
  curvature selection instead (stage 1 of :func:`depthnormals.discontinuity_discrimination`
  with its other options), with the consistency margin ``AUTO_CONSISTENCY`` (0): a
  neighbour's normal replaces the pixel's own only where its one-sided tangent
  inconsistency (:func:`depthnormals.ddm.crf.inconsistency`) is strictly smaller;
- **noisy depth**: the box-fit (:mod:`depthnormals.ddm.boxfit`): least-squares planes in
  inverse depth; a pixel takes the large centred window (from ``(2 BIG_RADIUS + 1)^2``,
  growing with the noise: :func:`big_radius`) where its residual variance is within ``GATE
  sigma^2`` (one plane within noise), and otherwise the best of the
  nine ``(2 r + 1)^2`` windows that contain it, ranked by how well their planes explain the
  pixel's own 3x3 (the centred one kept within ``GATE sigma^2``); ``r`` is the smallest
  radius whose fitted normal has a predicted standard deviation
  ``sigma / sqrt(N r (r + 1) / 3)`` (fronto-parallel, full window) of at most ``TARGET_STD``
  radians. With another estimator's normals, its own normal is kept where it lies within the
  fit's noise (``KEEP_CHI2``) and NaN where it abstained.

``"box-fit"`` is the noisy branch whatever the noise (the radius still follows the
estimate, at least 1), ``"planes"`` the clean one. All of it is ours (issue 13); the
constants were chosen by the measurements in docs/3f2n-plus.md ("The noise-aware selection",
"Plane hypotheses for clean depth").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np

from .._parallel import run_rows
from ..kernels.orient import store_nan, store_normal
from .boxfit import box_fit_from_prepared
from .noise import TILE, NoiseSamples, noise_pass, noise_tiles
from .planes import planes_from_prepared
from .support import SupportProfile, support_profile, support_select

__all__ = [
    "AUTO_CONSISTENCY",
    "BIG_RADIUS",
    "BIG_TARGET_STD",
    "EXCESS",
    "GATE",
    "KEEP_CHI2",
    "MAX_BIG_RADIUS",
    "MAX_RADIUS",
    "NOISE_CLEAN",
    "PLANES_NOISE",
    "TARGET_STD",
    "NoiseProfile",
    "auto_fused",
    "big_radius",
    "box_radius",
    "box_select",
    "branch_at",
    "needs_measured_support",
    "noise_profile",
    "noisy_select",
    "plane_select",
    "refine_auto",
]

#: Noise (footprints) below which ``"auto"`` takes the plane hypotheses: float32 renders read
#: ~1e-5, sensors 0.1 and more; the plane hypotheses' one-pixel stencils pass noise through,
#: and the box-fit is ahead from ~0.0005 (analytic scenes, outdoor) to ~0.003 (indoor scenes).
PLANES_NOISE = 1e-3
#: Noise (footprints) below which the paper's CRF / correlation options (which need the
#: curvature selection) still run on the curvature selection.
NOISE_CLEAN = 0.03
#: Predicted standard deviation (radians) of the box-fit normal that sets the radius of the
#: small (edge) windows.
TARGET_STD = 0.035
#: Radius of the large centred window (17x17), taken wherever it is one plane within noise; at
#: least this, larger on noisier depth (:func:`big_radius`).
BIG_RADIUS = 8
#: Predicted standard deviation (radians) of the large centred window's normal that sets its
#: radius (:func:`big_radius`): a tenth of :data:`TARGET_STD` (0.2 deg).
BIG_TARGET_STD = 0.0035
#: Largest radius of the large centred window (33x33, the measured support's largest).
MAX_BIG_RADIUS = 16
#: The centred window is kept while its residual variance is within GATE sigma^2.
GATE = 3.0
#: Largest window radius (13x13).
MAX_RADIUS = 6
#: Clean branch: the consistency margin of the curvature selection (footprints^2): a
#: neighbour's normal replaces the pixel's only if its tangent inconsistency is strictly
#: smaller ("self wins unless beaten"; the module's default 0.1 lets it be a little worse).
AUTO_CONSISTENCY = 0.0
#: Noisy branch: the measured fit errors may exceed those that the noise level predicts for
#: independent noise by this factor before the support is measured instead of predicted
#: (:meth:`depthnormals.ddm.support.SupportProfile.excess`: at most 1.12 on the analytic
#: scenes with Gaussian noise of 0.01-1 footprints, 1.9-27 on the real frames of
#: ``shared/data/real-sensors``; docs/3f2n-plus.md).
EXCESS = 2.0
#: Noisy branch: the estimator's normal is kept where it lies within this chi-square (2
#: degrees of freedom) of the box-fit's slopes.
KEEP_CHI2 = 2.0


def box_radius(sigma: float) -> int:
    """The smallest window radius whose fitted normal has a predicted standard deviation
    ``sigma / sqrt(N r (r + 1) / 3)`` (``N = (2 r + 1)^2``) of at most :data:`TARGET_STD`;
    1 for NaN or zero noise, at most :data:`MAX_RADIUS`."""
    if not sigma > 0.0:
        return 1
    for r in range(1, MAX_RADIUS + 1):
        n = (2 * r + 1) ** 2
        if sigma / math.sqrt(n * r * (r + 1) / 3.0) <= TARGET_STD:
            return r
    return MAX_RADIUS


def big_radius(sigma: float) -> int:
    """The radius of the large centred window of the box-fit: the smallest from
    :data:`BIG_RADIUS` whose fitted normal has a predicted standard deviation ``sigma /
    sqrt(N r (r + 1) / 3)`` of at most :data:`BIG_TARGET_STD`, at most
    :data:`MAX_BIG_RADIUS`; :data:`BIG_RADIUS` for NaN or zero noise (always above
    :func:`box_radius`, which stops at :data:`MAX_RADIUS`). The window is taken only where its
    residual is within the gate (one plane within the noise), so a larger one costs nothing on
    curved or cluttered depth and halves the error on the planes of noisier depth: 17x17 up to
    0.29 footprints, 33x33 from about 1 (session 30, docs/3f2n-plus.md "The large window grows
    with the noise")."""
    if not sigma > 0.0:
        return BIG_RADIUS
    for big in range(BIG_RADIUS, MAX_BIG_RADIUS):
        n = (2 * big + 1) ** 2
        if sigma / math.sqrt(n * big * (big + 1) / 3.0) <= BIG_TARGET_STD:
            return big
    return MAX_BIG_RADIUS


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _mask_rows(v0, v1, base, out):
    """NaN in ``out`` wherever ``base`` has no finite normal (the estimator abstained)."""
    w = out.shape[1]
    for v in range(v0, v1):
        for u in range(w):
            x = base[v, u, 0] + base[v, u, 1] + base[v, u, 2]
            if not (x - x == 0.0):
                store_nan(out, v, u)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _slopes(x, y, t, A, B, ifx, ify):
    """Inverse-depth slopes per unit inverse depth, ``(n_x / fx, n_y / fy) / gamma`` with
    ``gamma = n . ray``, of the plane with normal (x, y, t) through a pixel."""
    g = x * A * ifx + y * B * ify + t
    return x * ifx / g, y * ify / g


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _keep_rows(v0, v1, z, base, kappa, fx, fy, cx, cy, out):
    """Rows of the self-wins test of :func:`box_select`: ``out`` holds the box-fit normals
    and ``kappa`` is ``KEEP_CHI2 sigma^2 / (fx^2 S_uu)``; where the estimator's normal is
    within it (squared slope distance), ``out`` takes the estimator's normal; NaN where the
    estimator has none."""
    w = out.shape[1]
    ifx = 1.0 / fx
    ify = 1.0 / fy
    for v in range(v0, v1):
        for u in range(w):
            x = np.float64(base[v, u, 0])
            y = np.float64(base[v, u, 1])
            t = np.float64(base[v, u, 2])
            if not (x + y + t - (x + y + t) == 0.0):
                store_nan(out, v, u)
                continue
            fxx = np.float64(out[v, u, 0])
            if not (fxx == fxx):
                continue
            A = u - cx
            B = v - cy
            pa, pb = _slopes(x, y, t, A, B, ifx, ify)
            qa, qb = _slopes(fxx, np.float64(out[v, u, 1]), np.float64(out[v, u, 2]), A, B, ifx,
                             ify)
            d2 = (pa - qa) ** 2 + (pb - qb) ** 2
            if d2 < kappa:
                zq = np.float64(z[v, u])
                store_normal(out, v, u, x, y, t, A * zq * ifx, B * zq * ify, zq)


def box_select(z: np.ndarray, base: np.ndarray | None, fx: float, fy: float, cx: float,
               cy: float, sigma: float, *, keep_chi2: float | None = None,
               local: bool = True, levels: np.ndarray | None = None) -> np.ndarray:
    """The box-fit branch on prepared depth ``z``: normals (H, W, 3) float32.

    With ``base`` (the estimator's normals): NaN where it has none, and its normal kept
    where it agrees with the box-fit within the fit's noise: the squared distance of their
    inverse-depth slopes, in units of the fitted slope's variance ``sigma_w^2 / S_uu``
    (``sigma_w = sigma / (fx z)``, ``S_uu = N r (r + 1) / 3`` of a full window), below
    ``keep_chi2`` (default :data:`KEEP_CHI2`; a chi-square with 2 degrees of freedom).

    With ``local`` (default), the plane tests use the noise of the pixel's 64x64 tile
    (:func:`depthnormals.ddm.noise.noise_tiles`, at least :data:`NOISE_CLEAN`) instead of the
    image's ``sigma``; the window radius follows ``sigma``. ``levels``: those tiles' noise when
    already measured (:func:`depthnormals.ddm.noise.noise_levels`)."""
    r = box_radius(sigma)
    gate = GATE * sigma * sigma if sigma == sigma else 0.0
    noisy = sigma == sigma and sigma > 0.0
    tiles = None
    if noisy and local:
        t = noise_tiles(z, fx, fy, tile=TILE) if levels is None else levels
        tiles = (np.maximum(t, NOISE_CLEAN), TILE)
    out = box_fit_from_prepared(z, fx, fy, cx, cy, radius=r, shift=r, gate=gate, self_weight=1.0,
                                big_radius=big_radius(sigma), sigma=sigma if noisy else None,
                                sigma_tiles=tiles)
    if base is not None:
        k2 = KEEP_CHI2 if keep_chi2 is None else float(keep_chi2)
        suu = (2 * r + 1) ** 2 * r * (r + 1) / 3.0
        kappa = k2 * sigma * sigma / (fx * fx * suu) if sigma == sigma else 0.0
        run_rows(_keep_rows, z.shape[0], z, base, kappa, float(fx), float(fy), float(cx),
                 float(cy), out)
    return out


def needs_measured_support(noise: NoiseSamples, prof: SupportProfile) -> bool:
    """Which noisy branch: True (the measured support) where the depth's rounding noise
    exceeds its second-difference level (quantised depth) or the measured fit errors exceed
    what its level predicts for independent noise by more than :data:`EXCESS`
    (:meth:`SupportProfile.excess`); False (the tuned box-fit) for independent noise. The one
    rule of :func:`noisy_select`, :func:`noise_profile` and the uncertainty map. ``prof``
    measured with the tiles' levels reads the excess pair by pair too, each pair against its
    own tile (:func:`depthnormals.ddm.support.local_excess`): over :data:`EXCESS` there
    counts as well."""
    return ((noise.plateaus and noise.quant > noise.iid) or not prof.excess() <= EXCESS  # NaN: measured
            or prof.local > EXCESS)  # NaN (not read): not measured


def noisy_select(z: np.ndarray, base: np.ndarray | None, fx: float, fy: float, cx: float,
                 cy: float, noise: NoiseSamples, *, keep_chi2: float | None = None) -> np.ndarray:
    """The noisy branch on prepared depth ``z``, ``noise`` its noise pass. Where the noise is
    independent per pixel (its rounding noise, if quantised, below its second-difference
    level, and the fit errors measured on the depth within
    :data:`EXCESS` of those its level predicts: :meth:`SupportProfile.excess`), the box-fit
    of :func:`box_select`; otherwise (real sensor depth: quantised, or correlated over
    several pixels) the box-fit over the measured support,
    :func:`depthnormals.ddm.support.support_select`. With ``base`` (the estimator's
    normals), NaN where it has none and its normal kept where it agrees with the fit within
    the fit's error (:data:`KEEP_CHI2`; for the measured support the per-axis variance of
    the slope is ``(e / sqrt(pi / 2) / fx)^2``, ``e`` the measured mean angular error)."""
    sigma = noise.sigma
    levels = noise.tiles()
    prof = support_profile(z, fx, fy, cx, cy, sigma, tiles=levels)
    if not needs_measured_support(noise, prof):
        return box_select(z, base, fx, fy, cx, cy, sigma, keep_chi2=keep_chi2, levels=levels)
    out = support_select(z, fx, fy, cx, cy, sigma, profile=prof)
    if base is not None:
        k2 = KEEP_CHI2 if keep_chi2 is None else float(keep_chi2)
        e = prof.error[prof.radii.index(prof.radius)]
        std = math.radians(e) / math.sqrt(math.pi / 2.0) if e == e else 0.0
        kappa = k2 * (std / fx) ** 2
        run_rows(_keep_rows, z.shape[0], z, base, kappa, float(fx), float(fy), float(cx),
                 float(cy), out)
    return out


def plane_select(z: np.ndarray, base: np.ndarray | None, fx: float, fy: float, cx: float,
                 cy: float) -> np.ndarray:
    """The plane hypotheses on prepared depth ``z`` (:mod:`depthnormals.ddm.planes`); NaN
    where ``base`` (the estimator's normals) has none."""
    out = planes_from_prepared(z, fx, fy, cx, cy)
    if base is not None:
        run_rows(_mask_rows, z.shape[0], base, out)
    return out


def _branch(z: np.ndarray, fx: float, fy: float, o: dict):
    """Which selection ``o["selection"]`` runs: ``("planes" | "box-fit" | "curvature", noise
    pass)``, the curvature selection being the clean branch of the paper's CRF / correlation.
    An explicit ``"planes"`` needs no noise estimate (the pass is then None)."""
    if o["selection"] == "planes":
        return "planes", None
    p = noise_pass(z, fx, fy, tile=TILE)
    return branch_at(o, p.sigma), p


def branch_at(o: dict, sigma: float) -> str:
    """Which selection module options ``o`` run on depth of noise ``sigma`` (footprints):
    ``o["selection"]`` itself unless it is ``"auto"``; for ``"auto"``, ``"box-fit"`` from
    :data:`PLANES_NOISE` (:data:`NOISE_CLEAN` with the paper's CRF or a correlation), below
    it ``"planes"`` (``"curvature"`` with them). NaN (too few valid pixels to measure)
    counts as clean. The one rule of the numba module and of its torch port."""
    sel = o["selection"]
    if sel != "auto":
        return sel
    paper = o["crf"] or o["correlation"] != "none"
    if not sigma >= (NOISE_CLEAN if paper else PLANES_NOISE):
        return "curvature" if paper else "planes"
    return "box-fit"


def refine_auto(z: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                n_in: np.ndarray, o: dict, curvature_refine) -> np.ndarray:
    """``selection="auto"`` / ``"box-fit"`` / ``"planes"`` of the generic module path (any
    estimator's normals ``n_in``); ``curvature_refine(o)`` runs the module's curvature path
    with options ``o`` (the clean branch of the paper's CRF / correlation)."""
    branch, p = _branch(z, fx, fy, o)
    if branch == "planes":
        return plane_select(z, n_in, fx, fy, cx, cy)
    if branch == "box-fit":
        return noisy_select(z, n_in, fx, fy, cx, cy, p)
    out = curvature_refine(_clean_options(o))
    run_rows(_mask_rows, z.shape[0], n_in, out)
    return out


def _clean_options(o: dict) -> dict:
    eps = o["consistency"]
    return {**o, "selection": "curvature",
            "consistency": None if eps is None else min(eps, AUTO_CONSISTENCY)}


def auto_fused(fused_plus, depth, K, depth_scale, estimator_options: dict,
               module_options: dict, o: dict) -> np.ndarray | None:
    """``"3f2n+"`` with ``selection="auto"`` / ``"box-fit"`` / ``"planes"`` on the fused
    path: the noisy branch is the box-fit alone and the clean one the plane hypotheses alone
    (3F2N's normals are not computed: 3F2N never abstains at valid depth, so there is nothing
    to keep of it), the clean branch of the paper's CRF / correlation the fused curvature
    selection with :data:`AUTO_CONSISTENCY`. None where ``fused_plus`` has no fused form."""
    from ..kernels.depth import prepare

    z, cam = prepare(depth, K, depth_scale)
    branch, p = _branch(z, cam.fx, cam.fy, o)
    if branch == "planes":
        return plane_select(z, None, cam.fx, cam.fy, cam.cx, cam.cy)
    if branch == "box-fit":
        return noisy_select(z, None, cam.fx, cam.fy, cam.cx, cam.cy, p)
    c = _clean_options(o)
    return fused_plus(depth, K, depth_scale, estimator_options,
                      {**module_options, "selection": "curvature", "consistency": c["consistency"]})


@dataclass(frozen=True)
class NoiseProfile:
    """What the default 3F2N+ reads of a depth image's noise (:func:`noise_profile`). Every
    level is in pixel footprints ``z / f`` (the standard deviation of independent per-pixel
    noise that would give the same statistic); errors in degrees.

    Attributes
    ----------
    sigma : float
        The level every branch reads: ``iid`` and ``quantisation`` in quadrature
        (:func:`depthnormals.estimate_noise`).
    iid : float
        From second differences of inverse depth (MAD rule): independent per-pixel noise.
        Exactly 0 on quantised depth whose plateaus cover most pixels.
    quantisation : float
        Rounding noise ``step / sqrt(12)`` of quantised depth, 0 when the depth is not
        quantised; ``quant_step`` the step (footprints): the disparity plateaus' where
        ``quant_share``, the share of exactly equal neighbours on sloped surfaces, is at least
        0.3, else the depth grid's quantum ``grid`` where its rounding noise is not small
        beside ``iid`` (:func:`depthnormals.ddm.noise.quant_step_of`).
    grid : float
        The quantum (footprints) of depth stored on a grid (millimetre PNGs), 0 when the depth
        lies on none (:func:`depthnormals.ddm.noise.grid_quantum`).
    radii, residual : tuple
        Plane residual standard deviation (footprints) of windows of these radii (median of
        the better half of the sampled windows): flat with radius for independent noise,
        growing where the noise is correlated over several pixels or a staircase.
    fit_error : tuple
        Mean angular error (degrees) of a plane fitted over a window of each radius, measured
        from adjacent windows (:mod:`depthnormals.ddm.support`).
    excess : float
        How far the measured fit errors exceed those ``sigma`` predicts for independent noise
        (about 1 for independent noise, 2-9 on correlated sensor depth).
    local_excess : float
        The same read pair by pair, each sampled window pair against its own 64 x 64 tile's
        level (windows up to 9 x 9; about 1 for independent noise, 3-6 on the real frames,
        2.5-10 where active stereo's noise grows with depth and the image-wide ``excess``
        reads it low; NaN: too few pairs). Over 2 the branch is the measured support too.
    branch : str
        What ``selection="auto"`` runs on it: ``"planes"`` (clean), ``"box-fit"`` (independent
        noise: the radius predicted from ``sigma``), ``"measured-support"`` (quantised or
        correlated noise: the radius measured, ``radius``).
    radius : int
        The window radius the measured support takes (``(2 r + 1)^2`` pixels).
    depth_exponent : float
        How the plane residual variance grows with depth, ``~ z^depth_exponent`` (2 for
        Kinect-like ``sigma_z ~ z^2``); the measured support's gates follow it.
    tiles : ndarray
        The second-difference level and the rounding noise per 64 x 64 tile (NaN: too few
        samples), as :func:`depthnormals.estimate_noise_map` spreads over pixels.
    """

    sigma: float
    iid: float
    quantisation: float
    quant_step: float
    quant_share: float
    radii: tuple
    residual: tuple
    fit_error: tuple
    excess: float
    branch: str
    radius: int
    depth_exponent: float
    tiles: np.ndarray
    grid: float = 0.0
    local_excess: float = float("nan")


def noise_profile(depth: Any, K: Any, *, depth_scale: float | None = None) -> NoiseProfile:
    """Read the noise of a depth image as the default 3F2N+ does: independent, quantised and
    correlated parts, the measured fit error per window size, and the branch it takes.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth; integers need ``depth_scale``. Invalid depth (0, negative, NaN, inf)
        is skipped.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels.
    depth_scale : float, optional, keyword-only
        Metres per unit of integer depth (the levels do not depend on it).

    Returns
    -------
    NoiseProfile
        Levels in pixel footprints ``z / f``, fit errors in degrees (class doc).

    Notes
    -----
    Ours (docs/3f2n-plus.md, "The noise model of real sensors"); the 3F2N+ paper estimates no
    noise. On the real Kinect v1 frames of ``shared/data/real-sensors`` ``iid`` reads 0 and
    ``quantisation`` 0.6-1.6; on float32 renders everything is ~0.

    Examples
    --------
    >>> import numpy as np, depthnormals as dn
    >>> from depthnormals.analytic import tilted_plane
    >>> r = tilted_plane((0.0, -0.6, -0.8), 2.0).render()
    >>> disparity = np.round(580 * 0.075 / r.depth * 8) / 8        # Kinect v1: 1/8 px steps
    >>> p = dn.noise_profile(580 * 0.075 / disparity, r.K)
    >>> p.iid, p.quantisation > 0.3, p.branch
    (0.0, True, 'measured-support')
    """
    from ..kernels.depth import prepare

    z, cam = prepare(depth, K, depth_scale)
    p = noise_pass(z, cam.fx, cam.fy, tile=TILE)
    tiles = p.tiles()
    prof = support_profile(z, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma, tiles=tiles)
    if not p.sigma >= PLANES_NOISE:
        branch = "planes"
    else:
        branch = "measured-support" if needs_measured_support(p, prof) else "box-fit"
    return NoiseProfile(
        sigma=p.sigma, iid=p.iid, quantisation=p.quant, quant_step=p.quant_step,
        quant_share=p.quant_share, radii=prof.radii,
        residual=tuple(math.sqrt(x) for x in prof.residual), fit_error=prof.error,
        excess=prof.excess(), branch=branch, radius=prof.radius,
        depth_exponent=prof.exponent, tiles=tiles, grid=p.grid, local_excess=prof.local)
