"""Seeded depth-sensor noise models.

Every model takes the clean planar depth (metres; 0 = no surface), and where it needs them
the ground-truth normals (camera frame, facing the camera) and intrinsics, plus a
``numpy.random.Generator``; it returns a new float64 depth map with 0 where the sensor
returns nothing. The incidence angle ``theta`` is the angle between the pixel's viewing ray
and the surface normal.

Models
------
``gaussian``
    ``z + N(0, s)`` with ``s = sigma`` (metres) or ``s = sigma_px * z / f`` (a multiple of
    the pixel footprint; ``f = (fx + fy) / 2``). The 3F2N+ paper's noisy SSN variants are
    mild, about ``sigma_px <= 0.1``.
``kinect_v1``
    Nguyen, Izadi, Lovell, "Modeling Kinect sensor noise for improved 3D reconstruction and
    tracking", 3DIMPVT 2012: axial ``sigma_z = 0.0012 + 0.0019 (z - 0.4)^2`` m, plus
    ``0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2`` for ``theta > 60 deg``; lateral
    ``sigma_L = 0.8 + 0.035 theta / (pi/2 - theta)`` px (a pixel reads the depth at a
    position shifted by ``N(0, sigma_L)`` in u and v, nearest neighbour, where that position
    lies across a depth edge, so edges stay sharp but jagged). The axial noise is added to the
    disparity ``d = f b / z`` (``f = 580`` px, ``b = 0.075`` m) and correlated over a 9 x 9
    window (the block matching); then the disparity is quantised to 1/8 px as in Khoshelham &
    Elberink, "Accuracy and resolution of Kinect depth data", Sensors 2012: depth in plateaus
    with steps ``z^2 / (8 f b)``.
``kinect_v2``
    Fankhauser et al., "Kinect v2 for mobile robot navigation: evaluation and modeling",
    ICAR 2015: axial ``sigma [mm] = 1.5 - 0.5 z + 0.3 z^2 + 0.1 z^1.5 theta^2 /
    (pi/2 - theta)^2``; flying pixels from 3x3 supersampling (a time-of-flight pixel mixes
    the returns of its footprint: the depth is the ``1/z^2``-weighted mean of the 3x3
    sub-samples that hit a surface; sub-samples are rendered only near discontinuities,
    :func:`discontinuity_mask`, elsewhere the pixel keeps its exact depth); rounding to
    1 mm; range limits 0.5-4.5 m; dropout at
    grazing incidence with probability ``1 / (1 + exp(-(theta - 78 deg) / 3 deg))``.

``realsense_d4xx``
    Active stereo (:func:`realsense_d4xx_noise`): disparity ``d = f b / z`` (``b = 50`` mm,
    D435) plus ``N(0, 0.08 px)`` correlated over a 5 x 5 matching window, rounded to 1/32
    px, so the depth std grows as ``z^2 * 0.08 / (f b)`` (Intel's D400 tuning white paper);
    edge fattening (the foreground spreads ``fatten_px`` pixels into the background); holes
    where the second imager cannot see (left-right occlusion, :func:`stereo_occlusion`),
    nearer than ``f b / 126`` (the disparity search range) or farther than 10 m, and where the
    projected pattern is weak (far or grazing).
``tof``
    Continuous-wave time of flight (:func:`tof_noise`): flying pixels at depth jumps (mixed
    returns), random error ``sigma ~ 1/sqrt(amplitude)`` (correlated over a Gaussian of
    0.5 px), amplitude ``albedo cos(theta) / z^2`` (Frank et al. 2009), scaled to the Azure
    Kinect specification (17 mm for 15 % reflectivity at 3.86 m); low-amplitude pixels
    invalidated; 0.5 m minimum; 1 mm rounding.

:func:`noise_std` gives the predicted standard deviation of the residual on a plane
(rounding and quantisation included through Sheppard's correction ``step^2 / 12``).

Examples
--------
>>> import numpy as np
>>> from depthnormals.render import KINECT_V2
>>> z = np.full((4, 5), 2.0)
>>> noisy = gaussian_noise(z, KINECT_V2, sigma=0.01, rng=np.random.default_rng(0))
>>> noisy.shape, bool(np.all(noisy != z))
((4, 5), True)
"""

from __future__ import annotations

import functools
from typing import Any

import numba as nb
import numpy as np

from .._validate import check_int, check_real
from ..camera import Intrinsics, as_intrinsics

__all__ = ["MODELS", "discontinuity_mask", "gaussian_noise", "incidence_angle", "kinect_v1_noise",
           "kinect_v2_noise",
           "mix_supersampled", "noise_std", "parse_noise_spec", "realsense_d4xx_noise", "stereo_occlusion",
           "tof_noise"]

#: Known model names, in a fixed order (the order seeds derive from; do not reorder, only append).
MODELS = ("gaussian", "kinect_v1", "kinect_v2", "realsense_d4xx", "tof")

_DEFAULTS: dict[str, dict[str, Any]] = {
    "gaussian": {"sigma": None, "sigma_px": 0.1},
    "kinect_v1": {"focal": 580.0, "baseline": 0.075, "subpixel": 0.125, "window": 9},
    "kinect_v2": {"min_range": 0.5, "max_range": 4.5, "dropout_deg": 78.0, "dropout_width_deg": 3.0,
                  "rounding": 0.001, "supersample": 3},
    "realsense_d4xx": {"baseline": 0.050, "focal": None, "subpixel": 0.08, "quantum": 1.0 / 32.0,
                       "max_disparity": 126.0, "max_range": 10.0, "fatten_px": 2, "fatten_jump": 0.05,
                       "hole_range": 6.0, "hole_width": 0.6, "hole_blob": 4, "window": 5},
    "tof": {"albedo": 0.5, "sigma_ref": 0.017, "ref_range": 3.86, "ref_albedo": 0.15, "cutoff": 1.0,
            "min_range": 0.5, "rounding": 0.001, "flying_jump": 0.02, "supersample": 3, "blur": 0.5},
}

#: Settings that must be whole numbers (parsed from the spec as floats, then checked).
_INTEGER = {"kinect_v1": ("window",), "kinect_v2": ("supersample",),
            "realsense_d4xx": ("fatten_px", "hole_blob", "window"), "tof": ("supersample",)}


def parse_noise_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"kinect_v2"`` or ``"gaussian:sigma=0.002"`` -> ``(name, full settings)``.

    Settings not given take the model's defaults; unknown keys raise ValueError.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"noise model spec must be a non-empty string; got {spec!r}")
    name, *items = spec.strip().split(":")
    if name not in MODELS:
        raise ValueError(f"unknown noise model {name!r}; valid: {', '.join(MODELS)}")
    settings = dict(_DEFAULTS[name])
    given = set()
    for item in items:
        if "=" not in item:
            raise ValueError(f"noise setting {item!r} must look like KEY=VALUE")
        key, value = item.split("=", 1)
        if key not in settings:
            raise ValueError(f"noise model {name} has no setting {key!r}; valid: {', '.join(settings)}")
        given.add(key)
        try:
            settings[key] = None if value.lower() == "none" else float(value)
        except ValueError as exc:
            raise ValueError(f"noise setting {key} must be a number; got {value!r}") from exc
    if name == "gaussian":
        if "sigma" in given and "sigma_px" not in given:
            settings["sigma_px"] = None
        if (settings["sigma"] is None) == (settings["sigma_px"] is None):
            raise ValueError("gaussian noise needs exactly one of sigma (metres) or sigma_px")
    for key in _INTEGER.get(name, ()):
        value = settings[key]
        if value is None or not float(value).is_integer():
            raise ValueError(f"noise setting {name}:{key} must be a whole number; got {value!r}")
        settings[key] = int(value)
    if name in ("kinect_v2", "tof") and settings["supersample"] not in (1, 3, 5):
        raise ValueError(f"{name} supersample must be 1 (off), 3 or 5; got {settings['supersample']}")
    if name == "kinect_v1":
        check_int(settings["window"], "kinect_v1 window", minimum=1, maximum=63)
    if name == "realsense_d4xx":
        _check_realsense(settings)
    if name == "tof":
        _check_tof({k: v for k, v in settings.items() if k != "supersample"})
    return name, settings


@functools.lru_cache(maxsize=4)
def _rays(shape: tuple[int, int], cam: Intrinsics) -> np.ndarray:
    """Unit viewing rays (H, W, 3), read-only; cached: every view of a dataset has the same
    camera (recomputing them cost 12-19 ms of a 512 x 424 view's Kinect v2 noise)."""
    h, w = shape
    u = (np.arange(w) - cam.cx) / cam.fx
    v = (np.arange(h) - cam.cy) / cam.fy
    r = np.stack(np.broadcast_arrays(u[None, :], v[:, None], np.ones((h, w))), axis=-1)
    r = r / np.linalg.norm(r, axis=-1, keepdims=True)
    r.flags.writeable = False
    return r


def incidence_angle(normals: np.ndarray, K: Any) -> np.ndarray:
    """Angle (radians, 0..pi/2) between each pixel's ray and its normal; NaN without normal."""
    cam = as_intrinsics(K)
    n = np.asarray(normals, dtype=np.float64)
    c = -np.einsum("...i,...i->...", n, _rays(n.shape[:2], cam))
    return np.arccos(np.clip(np.abs(c), 0.0, 1.0))


def _valid(depth: np.ndarray) -> np.ndarray:
    return np.isfinite(depth) & (depth > 0)


def gaussian_noise(depth: np.ndarray, K: Any, *, rng: np.random.Generator, sigma: float | None = None,
                   sigma_px: float | None = None) -> np.ndarray:
    """Additive Gaussian depth noise, sigma in metres or as ``sigma_px * z / f``.

    Parameters
    ----------
    depth : ndarray (H, W)
        Clean planar depth, metres; 0 = no surface (kept 0).
    K : intrinsics
        Camera (``f = (fx + fy) / 2`` for ``sigma_px``).
    rng : numpy.random.Generator, keyword-only
    sigma : float, keyword-only
        Standard deviation in metres.
    sigma_px : float, keyword-only
        Standard deviation as a multiple of the pixel footprint ``z / f``.

    Returns
    -------
    noisy : ndarray (H, W) float64
    """
    cam = as_intrinsics(K)
    if (sigma is None) == (sigma_px is None):
        raise ValueError("pass exactly one of sigma (metres) or sigma_px (multiple of z / f)")
    z = np.asarray(depth, dtype=np.float64)
    ok = _valid(z)
    s = sigma if sigma is not None else sigma_px * z / (0.5 * (cam.fx + cam.fy))
    out = z + rng.standard_normal(z.shape) * s
    return np.where(ok & (out > 0), out, 0.0)


def _kinect_v1_axial(z, theta):
    s = 0.0012 + 0.0019 * (z - 0.4) ** 2
    big = theta > np.radians(60.0)
    extra = 0.0001 / np.sqrt(np.maximum(z, 1e-9)) * theta ** 2 / np.maximum(np.pi / 2 - theta, 1e-3) ** 2
    return np.where(big, s + extra, s)


def _kinect_v2_axial(z, theta):
    t = theta ** 2 / np.maximum(np.pi / 2 - theta, 1e-3) ** 2
    return 1e-3 * (1.5 - 0.5 * z + 0.3 * z ** 2 + 0.1 * z ** 1.5 * t)


@nb.njit(cache=True, nogil=True)
def _separable_kernel(x, kern, out):  # pragma: no cover - compiled
    """Reads ``x`` (H + n - 1, W + n - 1) and the 1-D kernel ``kern`` (n); writes ``out`` (H, W):
    ``out[v, u] = sum_ij kern[i] kern[j] x[v + i, u + j]``, summed in the order of
    :func:`_separable_reference` (rows first, taps in order), so the two agree bit for bit."""
    n = kern.size
    h, w = out.shape
    rows = np.empty((x.shape[0], w))
    for v in range(x.shape[0]):
        for u in range(w):
            acc = kern[0] * x[v, u]
            for i in range(1, n):
                acc += kern[i] * x[v, u + i]
            rows[v, u] = acc
    for v in range(h):
        for u in range(w):
            acc = kern[0] * rows[v, u]
            for i in range(1, n):
                acc += kern[i] * rows[v + i, u]
            out[v, u] = acc


def _separable_reference(x: np.ndarray, kern: np.ndarray) -> np.ndarray:
    """The readable form of :func:`_separable_kernel`: one shifted slice per tap, rows then
    columns (a "valid" separable correlation)."""
    n = kern.size
    h, w = x.shape[0] - n + 1, x.shape[1] - n + 1
    rows = kern[0] * x[:, :w]
    for i in range(1, n):
        rows += kern[i] * x[:, i:i + w]
    out = kern[0] * rows[:h]
    for i in range(1, n):
        out += kern[i] * rows[i:i + h]
    return out


def _correlation_kernel(window: int, blur: float) -> np.ndarray:
    """1-D kernel ``box(window) * gauss(blur)`` scaled so that the sum of its squares is 1."""
    kern = np.ones(int(window))
    if blur > 0:
        t = np.arange(-int(np.ceil(3.0 * blur)), int(np.ceil(3.0 * blur)) + 1, dtype=np.float64)
        kern = np.convolve(kern, np.exp(-0.5 * (t / blur) ** 2))
    return kern / np.sqrt(np.sum(kern ** 2))


def _correlated_normal(rng: np.random.Generator, shape: tuple[int, int], *, window: int = 1,
                       blur: float = 0.0) -> np.ndarray:
    """Spatially correlated standard normal noise: every pixel ``N(0, 1)``, neighbours correlated.

    White noise filtered with the separable kernel ``box(window) * gauss(blur)`` (a
    ``window x window`` mean, the block-matching window of a stereo or structured-light sensor,
    then a Gaussian of standard deviation ``blur`` px), scaled so that the variance is exactly 1
    (so the models' ``noise_std`` is unchanged). Drawn with margins, so no pixel sees a border:
    one draw of ``(H + n - 1, W + n - 1)`` normals, ``n = window + 2 ceil(3 blur)`` the
    kernel's length. With ``window = 1`` and ``blur = 0`` this is ``rng.standard_normal(shape)``.
    Compiled (:func:`_separable_kernel`: 1.4 ms for 512 x 424 with the 9 x 9 box, the numpy
    form :func:`_separable_reference` 8.7 ms, on the shared 2-core VM; drawing the normals
    takes 4 ms).

    The correlation at lag ``k`` along a row or column is the kernel's autocorrelation
    ``sum_i kern[i] kern[i + k]``: ``max(0, 1 - k / window)`` for the box alone, 0.26 at lag 1
    for the sampled Gaussian of ``blur = 0.5`` (``exp(-k^2 / (4 blur^2))`` for wide ones).
    """
    h, w = shape
    kern = _correlation_kernel(window, blur)
    n = kern.size
    x = rng.standard_normal((h + n - 1, w + n - 1))
    if n == 1:
        return x
    out = np.empty((h, w))
    _separable_kernel(x, kern, out)
    return out


def kinect_v1_noise(depth: np.ndarray, normals: np.ndarray, K: Any, *, rng: np.random.Generator,
                    focal: float = 580.0, baseline: float = 0.075, subpixel: float = 0.125,
                    window: int = 9) -> np.ndarray:
    """Kinect v1 (structured light): lateral jitter at edges, correlated axial noise, disparity
    quantisation.

    Parameters
    ----------
    depth : ndarray (H, W)
        Clean planar depth, metres, 0 = no surface.
    normals : ndarray (H, W, 3)
        Ground-truth camera-frame normals (for the incidence angle).
    K : intrinsics
        Camera of ``depth``.
    rng : numpy.random.Generator, keyword-only
    focal, baseline, subpixel : float, keyword-only
        Disparity model: ``d = focal * baseline / z`` px, rounded to ``subpixel`` px.
    window : int, keyword-only
        Side (px) of the correlation window: the disparity noise is the mean of white noise
        over a ``window x window`` box (the sensor's block matching), so neighbours share it
        (:func:`_correlated_normal`); 9 (matched to real Kinect v1 frames, docs/synthetic.md
        "Sensor models against real frames"); 1 = independent per pixel.

    Returns
    -------
    noisy : ndarray (H, W) float64, 0 where nothing is returned.

    Notes
    -----
    1. Lateral noise: each pixel reads the depth at a position shifted by ``N(0, sigma_L)`` px in
       u and v (nearest neighbour), ``sigma_L = 0.8 + 0.035 theta / (pi/2 - theta)``, where that
       position lies across a depth edge (no surface on one side only, or a jump of more than
       2 %): edges come out jagged; on a smooth surface the matching window absorbs the shift.
    2. Axial noise in disparity: ``d' = f b / z + e sigma_z f b / z^2``, ``sigma_z`` of Nguyen et
       al., ``e`` unit-variance noise correlated over the ``window`` box.
    3. Quantisation after the noise: ``d'`` rounded to ``subpixel`` (1/8 px), ``z' = f b / d'``.
       Depth comes in plateaus (exactly equal values, zero second differences) separated by
       steps ``z^2 subpixel / (f b)`` (11.5 mm at 2 m, 46 mm at 4 m).

    The residual standard deviation on a plane stays ``noise_std("kinect_v1", z, theta)``.

    References
    ----------
    Nguyen, Izadi, Lovell, 3DIMPVT 2012; Khoshelham, Elberink, Sensors 12(2), 2012.

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals.render import KINECT_V2
    >>> z = 2.0 + 0.002 * np.arange(64)[None, :] + np.zeros((32, 1))   # a slanted plane at ~2 m
    >>> n = np.broadcast_to([0.0, 0.0, -1.0], (32, 64, 3))
    >>> out = kinect_v1_noise(z, n, KINECT_V2, rng=np.random.default_rng(0))
    >>> d2 = out[:, :-2] - 2 * out[:, 1:-1] + out[:, 2:]
    >>> bool(np.mean(d2 == 0) > 0.3)   # plateaus: a naive second-difference noise estimate reads 0
    True
    """
    check_int(window, "kinect_v1 window", minimum=1, maximum=63)
    z = np.asarray(depth, dtype=np.float64)
    h, w = z.shape
    theta = np.nan_to_num(incidence_angle(normals, K), nan=0.0)
    sl = 0.8 + 0.035 * theta / np.maximum(np.pi / 2 - theta, 1e-3)
    du = np.rint(rng.standard_normal((h, w)) * sl).astype(np.int64)
    dv = np.rint(rng.standard_normal((h, w)) * sl).astype(np.int64)
    u0 = np.arange(w)[None, :]
    v0 = np.arange(h)[:, None]
    uu = np.clip(u0 + du, 0, w - 1)
    vv = np.clip(v0 + dv, 0, h - 1)
    ok0 = _valid(z)
    zs = z[vv, uu]
    oks = _valid(zs)
    across = (ok0 != oks) | (ok0 & oks & (np.abs(zs - z) > 0.02 * np.where(ok0, z, 1.0)))
    uu = np.where(across, uu, u0)
    vv = np.where(across, vv, v0)
    zs = z[vv, uu]
    ts = theta[vv, uu]
    ok = _valid(zs)
    zs = np.where(ok, zs, 1.0)
    fb = focal * baseline
    e = _correlated_normal(rng, (h, w), window=int(window))
    noisy = fb / zs + e * (_kinect_v1_axial(zs, ts) * fb / zs ** 2)
    disp = np.rint(noisy / subpixel) * subpixel
    with np.errstate(divide="ignore"):
        out = np.where(disp > 0, fb / np.where(disp > 0, disp, 1.0), 0.0)
    return np.where(ok, out, 0.0)


def discontinuity_mask(depth: np.ndarray, *, jump: float = 0.02) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood has no surface or a relative depth jump > ``jump``.

    Flying pixels can only occur there; elsewhere the sub-samples see one continuous surface.
    """
    z = np.asarray(depth, dtype=np.float64)
    ok = _valid(z)
    zp = np.pad(np.where(ok, z, 0.0), 1, mode="edge")
    okp = np.pad(ok, 1, mode="edge")
    h, w = z.shape
    out = np.zeros((h, w), dtype=bool)
    for dv in range(3):
        for du in range(3):
            zn = zp[dv:dv + h, du:du + w]
            on = okp[dv:dv + h, du:du + w]
            out |= (on != ok) | (np.abs(zn - z) > jump * np.where(ok, z, 1.0))
    return out


def mix_supersampled(depth: np.ndarray, subsamples: np.ndarray) -> np.ndarray:
    """Time-of-flight pixel mixing: ``1/z^2``-weighted mean of each pixel's sub-samples.

    Parameters
    ----------
    depth : ndarray (H, W)
        Clean depth at the pixel centres (used where ``subsamples`` is NaN: not sampled).
    subsamples : ndarray (H, W, S)
        From :func:`depthnormals.render.render_subsamples` (0 = no surface, NaN = not
        sampled).

    Returns
    -------
    mixed : ndarray (H, W) float64
        Pixels whose centre sees nothing stay 0; at discontinuities the result lies between
        the surfaces (flying pixels).
    """
    z = np.asarray(depth, dtype=np.float64)
    ss = np.asarray(subsamples, dtype=np.float64)
    if ss.ndim != 3 or ss.shape[:2] != z.shape:
        raise ValueError(f"subsamples must be (H, W, S) with (H, W) = {z.shape}; got {ss.shape}")
    out = np.where(_valid(z), z, 0.0)
    idx = np.nonzero(~np.isnan(ss[..., 0]) & _valid(z))
    sub = ss[idx]
    ok = np.isfinite(sub) & (sub > 0)
    wgt = np.where(ok, 1.0 / np.where(ok, sub, 1.0) ** 2, 0.0)
    num = (wgt * np.where(ok, sub, 0.0)).sum(axis=-1)
    den = wgt.sum(axis=-1)
    out[idx] = num / den  # den > 0: the centre sub-sample is the valid pixel itself
    return out


def kinect_v2_noise(depth: np.ndarray, normals: np.ndarray, K: Any, *, rng: np.random.Generator,
                    subsamples: np.ndarray | None = None, min_range: float = 0.5,
                    max_range: float = 4.5, dropout_deg: float = 78.0,
                    dropout_width_deg: float = 3.0, rounding: float = 0.001) -> np.ndarray:
    """Kinect v2 (time of flight): flying pixels, axial noise, 1 mm rounding, range, dropout.

    Parameters
    ----------
    depth : ndarray (H, W)
        Clean planar depth, metres, 0 = no surface.
    normals : ndarray (H, W, 3)
        Ground-truth camera-frame normals (incidence angle).
    K : intrinsics
    rng : numpy.random.Generator, keyword-only
    subsamples : ndarray (H, W, S), optional, keyword-only
        Sub-pixel depth (:func:`depthnormals.render.render_subsamples`, 3x3 per pixel near
        discontinuities); gives flying pixels (:func:`mix_supersampled`). Without it there
        are none.
    min_range, max_range : float, keyword-only
        Depth outside is not returned (0).
    dropout_deg, dropout_width_deg : float, keyword-only
        Logistic dropout probability at incidence angle theta.
    rounding : float, keyword-only
        Output step in metres (1 mm).

    Returns
    -------
    noisy : ndarray (H, W) float64, 0 where nothing is returned.

    References
    ----------
    Fankhauser, Bloesch, Rodriguez, Kaestner, Hutter, Siegwart, "Kinect v2 for mobile robot
    navigation: evaluation and modeling", ICAR 2015.
    """
    z = np.asarray(depth, dtype=np.float64)
    if subsamples is not None:
        z = mix_supersampled(z, subsamples)
    ok = _valid(z)
    theta = np.nan_to_num(incidence_angle(normals, K), nan=0.0)
    zz = np.where(ok, z, 1.0)
    noisy = zz + rng.standard_normal(z.shape) * _kinect_v2_axial(zz, theta)
    noisy = np.rint(noisy / rounding) * rounding
    p_drop = 1.0 / (1.0 + np.exp(-(np.degrees(theta) - dropout_deg) / dropout_width_deg))
    keep = ok & (rng.random(z.shape) >= p_drop) & (noisy >= min_range) & (noisy <= max_range)
    return np.where(keep, noisy, 0.0)


# --------------------------------------------------------------------------------------------
# Active stereo (Intel RealSense D4xx-like)
# --------------------------------------------------------------------------------------------

def _check_realsense(st: dict[str, Any]) -> None:
    """Range checks of the ``realsense_d4xx`` settings (shared by the spec parser and the model)."""
    b = check_real(st["baseline"], "realsense_d4xx baseline", hint="metres, sign = side of the second imager")
    if b == 0.0:
        raise ValueError("realsense_d4xx baseline must be non-zero (metres; > 0: second imager at +x)")
    if st["focal"] is not None:
        check_real(st["focal"], "realsense_d4xx focal", minimum=1e-6, hint="pixels, or None for K's fx")
    check_real(st["subpixel"], "realsense_d4xx subpixel", minimum=0.0, hint="RMS disparity error, px")
    check_real(st["quantum"], "realsense_d4xx quantum", minimum=0.0, hint="disparity step, px; 0 = off")
    check_real(st["max_disparity"], "realsense_d4xx max_disparity", minimum=1e-6, hint="px")
    check_real(st["max_range"], "realsense_d4xx max_range", minimum=0.0, finite=False, hint="metres")
    check_int(st["fatten_px"], "realsense_d4xx fatten_px", minimum=0, maximum=32)
    check_real(st["fatten_jump"], "realsense_d4xx fatten_jump", minimum=0.0, hint="relative depth jump")
    check_real(st["hole_range"], "realsense_d4xx hole_range", minimum=0.0, finite=False, hint="metres")
    check_real(st["hole_width"], "realsense_d4xx hole_width", minimum=1e-6, hint="metres")
    check_int(st["hole_blob"], "realsense_d4xx hole_blob", minimum=1, maximum=256)
    check_int(st["window"], "realsense_d4xx window", minimum=1, maximum=63)


def _shift(a: np.ndarray, dv: int, du: int, fill: float) -> np.ndarray:
    """``out[v, u] = a[v + dv, u + du]``, ``fill`` outside the image."""
    h, w = a.shape
    out = np.full_like(a, fill)
    out[max(0, -dv):h - max(0, dv), max(0, -du):w - max(0, du)] = \
        a[max(0, dv):h - max(0, -dv), max(0, du):w - max(0, -du)]
    return out


def _max_filter(a: np.ndarray, radius: int) -> np.ndarray:
    """Square ``(2 radius + 1)^2`` maximum filter (separable; 0 outside the image)."""
    out = a.copy()
    for d in range(1, radius + 1):
        out = np.maximum(out, np.maximum(_shift(a, 0, d, 0.0), _shift(a, 0, -d, 0.0)))
    rows = out.copy()
    for d in range(1, radius + 1):
        out = np.maximum(out, np.maximum(_shift(rows, d, 0, 0.0), _shift(rows, -d, 0, 0.0)))
    return out


def stereo_occlusion(disparity: np.ndarray, *, right: bool = True) -> np.ndarray:
    """Pixels of the reference image that the second imager of a rectified pair cannot see.

    Parameters
    ----------
    disparity : ndarray (H, W)
        Disparity in pixels of the reference (depth) image; 0 where there is no surface
        (a point at infinity, which never occludes).
    right : bool, keyword-only
        True: the second imager sits at ``+x`` (to the right; D4xx depth is referenced to the
        left imager), a point at column ``u`` appears there at ``u - d``. False: at ``-x``,
        ``u + d``.

    Returns
    -------
    occluded : ndarray (H, W) bool
        Hidden behind a nearer point of the same row (the left-right occlusion: a band of
        width ``d_fg - d_bg`` on the side of a foreground object away from the second imager,
        left of it for ``right=True``), or outside the second image (the invalid band of
        width ``d`` at the left image border for ``right=True``).

    Notes
    -----
    Pixel ``u`` is hidden iff a pixel ``u' > u`` of its row lands left of it in the second
    image, ``min_{u' > u} (u' - d(u')) < u - d(u)``: one reversed running minimum per row.

    Examples
    --------
    >>> import numpy as np
    >>> d = np.array([[1.0] * 8 + [4.0] * 4])  # background d = 1, foreground d = 4 from u = 8
    >>> stereo_occlusion(d).astype(int)  # border (u - d < -0.5) and the band u - 1 > 8 - 4
    array([[1, 0, 0, 0, 0, 0, 1, 1, 0, 0, 0, 0]])
    """
    d = np.asarray(disparity, dtype=np.float64)
    if not right:
        return stereo_occlusion(d[:, ::-1], right=True)[:, ::-1]
    h, w = d.shape
    xr = np.arange(w, dtype=np.float64)[None, :] - d
    # suffix minimum of the pixels strictly to the right
    after = np.minimum.accumulate(xr[:, ::-1], axis=1)[:, ::-1]
    after = np.concatenate([after[:, 1:], np.full((h, 1), np.inf)], axis=1)
    return (after < xr) | (xr < -0.5)


def realsense_d4xx_noise(depth: np.ndarray, normals: np.ndarray, K: Any, *, rng: np.random.Generator,
                         baseline: float = 0.050, focal: float | None = None, subpixel: float = 0.08,
                         quantum: float = 1.0 / 32.0, max_disparity: float = 126.0,
                         max_range: float = 10.0, fatten_px: int = 2, fatten_jump: float = 0.05,
                         hole_range: float = 6.0, hole_width: float = 0.6,
                         hole_blob: int = 4, window: int = 5) -> np.ndarray:
    """Active stereo (Intel RealSense D4xx-like): disparity noise and quantisation, edge
    fattening, left-right occlusion holes, range limits and far / low-signal holes.

    Parameters
    ----------
    depth : ndarray (H, W)
        Clean planar depth, metres, 0 = no surface. The depth image is the reference (left)
        imager's, as on the D4xx.
    normals : ndarray (H, W, 3)
        Ground-truth camera-frame normals (incidence angle of the projected pattern).
    K : intrinsics
        Camera of ``depth``.
    rng : numpy.random.Generator, keyword-only
    baseline : float, keyword-only
        Stereo baseline, metres: 0.050 (D435, D455 is 0.095), 0.055 for the D415. The sign
        says where the second imager sits: ``> 0`` at ``+x`` (right of the depth imager, the
        D4xx layout), ``< 0`` at ``-x``.
    focal : float or None, keyword-only
        Focal length in pixels of the matching; None (default) = the ``fx`` of ``K`` (the
        rendered image is the stereo image).
    subpixel : float, keyword-only
        RMS disparity error, pixels (0.08).
    quantum : float, keyword-only
        Disparity output step, pixels: 1/32 (5 fractional bits); 0 = no quantisation.
    max_disparity : float, keyword-only
        Disparity search range, pixels (126): nearer than ``focal * |baseline| / max_disparity``
        (MinZ) nothing is returned.
    max_range : float, keyword-only
        Farther than this nothing is returned, metres (10).
    fatten_px, fatten_jump : int, float, keyword-only
        Edge fattening: a pixel within ``fatten_px`` pixels (square window) of a foreground edge
        whose disparity exceeds its own by more than the relative ``fatten_jump`` takes the
        foreground disparity. A foreground edge is a pixel with a 4-neighbour more than
        ``fatten_jump`` (relative) farther, or with no surface.
    hole_range, hole_width : float, keyword-only
        Holes where the projected pattern is too weak to match: a pixel is dropped with
        probability ``1 / (1 + exp(-(z_eff - hole_range) / hole_width))``, ``z_eff = z /
        sqrt(cos theta)`` (the depth of a fronto-parallel surface receiving the same pattern
        irradiance, ``cos theta / z^2``).
    hole_blob : int, keyword-only
        Those holes come in ``hole_blob x hole_blob`` pixel blocks (one draw per block).
    window : int, keyword-only
        Side (px) of the matching window that correlates the disparity noise: ``N(0, subpixel)``
        is the mean of white noise over a ``window x window`` box (:func:`_correlated_normal`),
        5 (the window that fattens edges by ``fatten_px = 2``); 1 = independent per pixel.

    Returns
    -------
    noisy : ndarray (H, W) float64, 0 where nothing is returned.

    Notes
    -----
    ``d = focal |baseline| / z``; edge fattening on ``d``; ``d' = d + N(0, subpixel)`` (correlated
    over the ``window`` box) rounded
    to ``quantum``; ``z' = focal |baseline| / d'``. So ``std(z') ~= z^2 / (focal |baseline|) *
    sqrt(subpixel^2 + quantum^2 / 12)``. Dropped (0): no surface, hidden from the second imager
    (:func:`stereo_occlusion`, from the clean geometry), ``d' > max_disparity``, ``z' >
    max_range``, the far / low-signal holes.

    References
    ----------
    Grunnet-Jepsen, Sweetser, Winer, Takagi, Woodfill, "Best-Known-Methods for Tuning Intel
    RealSense D400 Depth Cameras for Best Performance", Intel white paper (depth RMS error
    ``= z^2 subpixel / (f b)``, subpixel < 0.1 px and approaching 0.05 px on textured targets;
    ``MinZ = f b / 126``; the invalid band at the left edge of width ``f b / z``).
    Intel RealSense D400 Series Product Family Datasheet (baselines 50 mm D435, 55 mm D415;
    range up to ~10 m). librealsense, ``src/proc/disparity-transform.cpp`` (disparity with
    5 fractional bits, 1/32 px). What is ours: see docs/synthetic.md.

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals.render import KINECT_V2
    >>> z = np.full((8, 64), 2.0)
    >>> n = np.broadcast_to([0.0, 0.0, -1.0], (8, 64, 3))
    >>> out = realsense_d4xx_noise(z, n, KINECT_V2, rng=np.random.default_rng(0))
    >>> int((out[0] == 0).sum())  # the invalid band at the left border: d = 365.5 * 0.05 / 2 = 9.1 px
    9
    >>> d = 365.5 * 0.05 / out[out > 0]
    >>> bool(np.allclose(d * 32, np.rint(d * 32)))  # disparity on the 1/32 px grid
    True
    """
    cam = as_intrinsics(K)
    st = {"baseline": baseline, "focal": focal, "subpixel": subpixel, "quantum": quantum,
          "max_disparity": max_disparity, "max_range": max_range, "fatten_px": fatten_px,
          "fatten_jump": fatten_jump, "hole_range": hole_range, "hole_width": hole_width,
          "hole_blob": hole_blob, "window": window}
    _check_realsense(st)
    z = np.asarray(depth, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError(f"depth must be (H, W); got shape {z.shape}")
    h, w = z.shape
    ok = _valid(z)
    fb = (cam.fx if focal is None else float(focal)) * abs(float(baseline))
    disp = np.where(ok, fb / np.where(ok, z, 1.0), 0.0)
    hidden = stereo_occlusion(disp, right=baseline > 0)
    # edge fattening: the foreground side of each jump spreads by fatten_px
    if fatten_px > 0:
        grow = 1.0 + fatten_jump
        edge = np.zeros((h, w), dtype=bool)
        for dv, du in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            dn = _shift(disp, dv, du, np.nan)
            edge |= (dn * grow < disp) | (dn == 0.0)
        fg = _max_filter(np.where(ok & edge, disp, 0.0), int(fatten_px))
        disp = np.where(ok & (fg > disp * grow), fg, disp)
    noisy = disp + _correlated_normal(rng, (h, w), window=int(window)) * subpixel
    if quantum > 0:
        noisy = np.rint(noisy / quantum) * quantum
    good = ok & ~hidden & (noisy > 0) & (noisy <= max_disparity)
    out = np.where(good, fb / np.where(good, noisy, 1.0), 0.0)
    good &= out <= max_range
    # far / low-signal holes, in blocks of hole_blob pixels
    theta = np.nan_to_num(incidence_angle(normals, cam), nan=0.0)
    z_eff = np.where(ok, z, 0.0) / np.sqrt(np.maximum(np.cos(theta), 1e-6))
    with np.errstate(over="ignore"):
        p_hole = 1.0 / (1.0 + np.exp(-(z_eff - hole_range) / hole_width))
    nb = int(hole_blob)
    draw = rng.random((-(-h // nb), -(-w // nb)))
    draw = np.repeat(np.repeat(draw, nb, axis=0), nb, axis=1)[:h, :w]
    good &= draw >= p_hole
    return np.where(good, out, 0.0)


# --------------------------------------------------------------------------------------------
# Continuous-wave time of flight (Azure Kinect / Kinect v2 / PMD-like)
# --------------------------------------------------------------------------------------------

def _check_tof(st: dict[str, Any]) -> None:
    """Range checks of the ``tof`` settings (shared by the spec parser and the model)."""
    check_real(st["albedo"], "tof albedo", minimum=1e-6, maximum=1.0, hint="diffuse reflectance at the NIR")
    check_real(st["sigma_ref"], "tof sigma_ref", minimum=0.0, hint="metres; 0 = no random noise")
    check_real(st["ref_range"], "tof ref_range", minimum=1e-6, hint="metres")
    check_real(st["ref_albedo"], "tof ref_albedo", minimum=1e-6, maximum=1.0)
    check_real(st["cutoff"], "tof cutoff", minimum=0.0, hint="relative amplitude; 0 = keep all")
    check_real(st["min_range"], "tof min_range", minimum=0.0, hint="metres")
    check_real(st["rounding"], "tof rounding", minimum=0.0, hint="metres; 0 = off")
    check_real(st["flying_jump"], "tof flying_jump", minimum=0.0, hint="relative depth jump")
    check_real(st["blur"], "tof blur", minimum=0.0, maximum=8.0,
               hint="px, Gaussian std of the noise correlation; 0 = off")


def _tof_amplitude(z: np.ndarray, theta: np.ndarray, albedo: float) -> np.ndarray:
    """Relative return amplitude ``albedo cos(theta) / z^2`` (Lambertian surface, m^-2)."""
    return albedo * np.cos(theta) / np.maximum(z, 1e-9) ** 2


def _tof_sigma(z, theta, st: dict[str, Any]) -> np.ndarray:
    a_ref = st["ref_albedo"] / st["ref_range"] ** 2
    a = _tof_amplitude(z, theta, st["albedo"])
    return st["sigma_ref"] * np.sqrt(a_ref / np.maximum(a, 1e-300))


def _mix_neighbours(z: np.ndarray, *, rng: np.random.Generator, jump: float) -> np.ndarray:
    """Flying pixels without sub-samples: each pixel with an 8-neighbour more than ``jump``
    (relative) away mixes its return with the most different such neighbour's, that
    neighbour's surface covering a fraction ``alpha ~ U(0, 1/2)`` of the pixel footprint
    (the centre sees its own surface, so it keeps at least half); returns weighted by
    amplitude ``~ 1/z^2`` as in :func:`mix_supersampled`."""
    ok = _valid(z)
    zc = np.where(ok, z, 0.0)
    best = np.zeros_like(zc)
    gap = np.zeros_like(zc)
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            if dv == 0 and du == 0:
                continue
            zn = _shift(zc, dv, du, 0.0)
            diff = np.where(ok & (zn > 0), np.abs(zn - zc), 0.0)
            take = (diff > gap) & (diff > jump * zc)
            best = np.where(take, zn, best)
            gap = np.where(take, diff, gap)
    alpha = 0.5 * rng.random(z.shape)
    mix = best > 0
    wc = (1.0 - alpha) / np.where(ok, zc, 1.0) ** 2
    wn = alpha / np.where(mix, best, 1.0) ** 2
    mixed = (wc * zc + wn * best) / (wc + wn)
    return np.where(mix, mixed, zc)


def tof_noise(depth: np.ndarray, normals: np.ndarray, K: Any, *, rng: np.random.Generator,
              subsamples: np.ndarray | None = None, albedo: float = 0.5, sigma_ref: float = 0.017,
              ref_range: float = 3.86, ref_albedo: float = 0.15, cutoff: float = 1.0,
              min_range: float = 0.5, rounding: float = 0.001, flying_jump: float = 0.02,
              blur: float = 0.5) -> np.ndarray:
    """Continuous-wave time of flight: flying pixels, amplitude-dependent noise, low-signal
    invalidation, range limit, rounding.

    Parameters
    ----------
    depth : ndarray (H, W)
        Clean planar depth, metres, 0 = no surface.
    normals : ndarray (H, W, 3)
        Ground-truth camera-frame normals (incidence angle).
    K : intrinsics
    rng : numpy.random.Generator, keyword-only
    subsamples : ndarray (H, W, S), optional, keyword-only
        Sub-pixel depth (:func:`depthnormals.render.render_subsamples`); the flying pixels are
        then the ``1/z^2``-weighted mean of each pixel's sub-samples (:func:`mix_supersampled`).
        Without it, each pixel next to a jump of more than ``flying_jump`` (relative) mixes with
        its most different neighbour, that neighbour covering a fraction ``U(0, 1/2)`` of it.
    albedo : float, keyword-only
        Diffuse NIR reflectance of every surface (the renderer has no materials), 0.5.
    sigma_ref, ref_range, ref_albedo : float, keyword-only
        Random error ``sigma_ref`` (17 mm) at the reference amplitude: a fronto-parallel
        surface of reflectance ``ref_albedo`` (15 %) at ``ref_range`` (3.86 m): the Azure Kinect
        NFOV-unbinned specification.
    cutoff : float, keyword-only
        Pixels whose amplitude is below ``cutoff`` times the reference amplitude are
        invalidated (1.0: where the predicted random error would exceed ``sigma_ref``).
    min_range : float, keyword-only
        Nearer than this nothing is returned, metres (0.5).
    rounding : float, keyword-only
        Output step, metres (1 mm); 0 = off.
    flying_jump : float, keyword-only
        Relative jump that makes a mixed pixel (without ``subsamples``).
    blur : float, keyword-only
        Spatial correlation of the random error: unit-variance white noise blurred by a Gaussian
        of this standard deviation, px (:func:`_correlated_normal`; 0.5: lag-1 correlation
        0.26), standing for the optics' and the depth engine's blur; 0 = independent per
        pixel.

    Returns
    -------
    noisy : ndarray (H, W) float64, 0 where nothing is returned.

    Notes
    -----
    Amplitude ``a = albedo cos(theta) / z^2``; random error ``sigma = sigma_ref sqrt(a_ref / a)``,
    ``a_ref = ref_albedo / ref_range^2``, i.e. ``sigma = sigma_ref (z / ref_range)
    sqrt(ref_albedo / (albedo cos theta))``: photon shot noise dominated, phase error ``~
    1/sqrt(a)``, correlated between neighbours through ``blur``. Multipath and systematic
    (wiggling) errors are not modelled.

    References
    ----------
    Frank, Plaue, Rapp, Koethe, Jaehne, Hamprecht, "Theoretical and experimental error analysis
    of continuous-wave time-of-flight range cameras", Optical Engineering 48(1), 013602, 2009.
    Lefloch, Nair, Lenzen, Schaefer, Streeter, Cree, Koch, Kolb, "Technical foundation and
    calibration methods for time-of-flight cameras", in Time-of-Flight and Depth Imaging,
    LNCS 8200, Springer, 2013. Microsoft, "Azure Kinect DK hardware specifications" and
    "Azure Kinect DK depth camera" (random error std <= 17 mm, systematic < 11 mm + 0.1 % of
    distance, operating ranges for 15-95 % reflectivity, low-signal invalidation).

    Examples
    --------
    >>> import numpy as np
    >>> from depthnormals.render import KINECT_V2
    >>> z = np.full((8, 8), 2.0)
    >>> z[:, 4:] = 4.0
    >>> n = np.broadcast_to([0.0, 0.0, -1.0], (8, 8, 3))
    >>> out = tof_noise(z, n, KINECT_V2, rng=np.random.default_rng(0), sigma_ref=0.0)
    >>> bool(np.all((out[:, 3:5] > 2.0) & (out[:, 3:5] < 4.0)))  # flying pixels at the jump
    True
    >>> round(float(noise_std("tof", 2.0, rounding=0.0)) * 1000, 2)  # mm, albedo 0.5, head-on
    4.82
    """
    st = {"albedo": albedo, "sigma_ref": sigma_ref, "ref_range": ref_range, "ref_albedo": ref_albedo,
          "cutoff": cutoff, "min_range": min_range, "rounding": rounding, "flying_jump": flying_jump,
          "blur": blur}
    _check_tof(st)
    cam = as_intrinsics(K)
    z = np.asarray(depth, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError(f"depth must be (H, W); got shape {z.shape}")
    if subsamples is not None:
        z = mix_supersampled(z, subsamples)
    else:
        z = _mix_neighbours(z, rng=rng, jump=flying_jump)
    ok = _valid(z)
    theta = np.nan_to_num(incidence_angle(normals, cam), nan=0.0)
    zz = np.where(ok, z, 1.0)
    noisy = zz + _correlated_normal(rng, z.shape, blur=float(blur)) * _tof_sigma(zz, theta, st)
    if rounding > 0:
        noisy = np.rint(noisy / rounding) * rounding
    a_ref = ref_albedo / ref_range ** 2
    keep = ok & (_tof_amplitude(zz, theta, albedo) >= cutoff * a_ref) & (noisy >= min_range)
    return np.where(keep, noisy, 0.0)


def noise_std(name: str, z: Any, theta: Any = 0.0, *, K: Any = None, **settings: Any) -> np.ndarray:
    """Predicted standard deviation (metres) of the depth residual of model ``name`` on a plane.

    Parameters
    ----------
    name : str
        One of :data:`MODELS`. ``realsense_d4xx``: the disparity noise and quantisation only
        (delta method, ``z^2 / (f |b|) sqrt(subpixel^2 + quantum^2 / 12)``, ``f = focal`` or
        ``K.fx``). ``tof``: the amplitude-dependent noise and rounding (no flying pixels).
    z : array_like
        Depth, metres.
    theta : array_like
        Incidence angle, radians.
    K : intrinsics, keyword-only
        Needed for ``gaussian`` with ``sigma_px`` and ``realsense_d4xx`` without ``focal``.
    **settings
        The model's settings (defaults as in :func:`parse_noise_spec`).

    Examples
    --------
    >>> round(float(noise_std("kinect_v2", 2.0)) * 1000, 3)  # mm, rounding included
    1.724
    """
    if name not in MODELS:
        raise ValueError(f"unknown noise model {name!r}; valid: {', '.join(MODELS)}")
    s = {**_DEFAULTS[name], **settings}
    z = np.asarray(z, dtype=np.float64)
    theta = np.asarray(theta, dtype=np.float64)
    if name == "gaussian":
        if s.get("sigma") is not None:
            return np.broadcast_to(float(s["sigma"]), z.shape).copy()
        cam = as_intrinsics(K)
        return s["sigma_px"] * z / (0.5 * (cam.fx + cam.fy))
    if name == "kinect_v1":
        step = z ** 2 * s["subpixel"] / (s["focal"] * s["baseline"])
        return np.sqrt(_kinect_v1_axial(z, theta) ** 2 + step ** 2 / 12.0)
    if name == "realsense_d4xx":
        if s["focal"] is None and K is None:
            raise ValueError("noise_std('realsense_d4xx') needs K (its fx) or the focal setting (pixels)")
        f = as_intrinsics(K).fx if s["focal"] is None else float(s["focal"])
        disp_std = np.sqrt(s["subpixel"] ** 2 + s["quantum"] ** 2 / 12.0)
        return z ** 2 / (f * abs(s["baseline"])) * disp_std
    if name == "tof":
        return np.sqrt(_tof_sigma(z, theta, s) ** 2 + s["rounding"] ** 2 / 12.0)
    return np.sqrt(_kinect_v2_axial(z, theta) ** 2 + s["rounding"] ** 2 / 12.0)
