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
    ``sigma_L = 0.8 + 0.035 theta / (pi/2 - theta)`` px (each pixel reads the depth at a
    position shifted by ``N(0, sigma_L)`` in u and v, nearest neighbour, so edges stay
    sharp but jagged). Then disparity quantisation as in Khoshelham & Elberink, "Accuracy
    and resolution of Kinect depth data", Sensors 2012: disparity ``d = f b / z`` with
    ``f = 580`` px, ``b = 0.075`` m, rounded to 1/8 px.
``kinect_v2``
    Fankhauser et al., "Kinect v2 for mobile robot navigation: evaluation and modeling",
    ICAR 2015: axial ``sigma [mm] = 1.5 - 0.5 z + 0.3 z^2 + 0.1 z^1.5 theta^2 /
    (pi/2 - theta)^2``; flying pixels from 3x3 supersampling (a time-of-flight pixel mixes
    the returns of its footprint: the depth is the ``1/z^2``-weighted mean of the 3x3
    sub-samples that hit a surface; sub-samples are rendered only near discontinuities,
    :func:`discontinuity_mask`, elsewhere the pixel keeps its exact depth); rounding to
    1 mm; range limits 0.5-4.5 m; dropout at
    grazing incidence with probability ``1 / (1 + exp(-(theta - 78 deg) / 3 deg))``.

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

import numpy as np

from ..camera import Intrinsics, as_intrinsics

__all__ = ["MODELS", "discontinuity_mask", "gaussian_noise", "incidence_angle", "kinect_v1_noise",
           "kinect_v2_noise",
           "mix_supersampled", "noise_std", "parse_noise_spec"]

#: Known model names, in a fixed order (the order seeds derive from; do not reorder).
MODELS = ("gaussian", "kinect_v1", "kinect_v2")

_DEFAULTS: dict[str, dict[str, Any]] = {
    "gaussian": {"sigma": None, "sigma_px": 0.1},
    "kinect_v1": {"focal": 580.0, "baseline": 0.075, "subpixel": 0.125},
    "kinect_v2": {"min_range": 0.5, "max_range": 4.5, "dropout_deg": 78.0, "dropout_width_deg": 3.0,
                  "rounding": 0.001, "supersample": 3},
}


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
    if name == "kinect_v2":
        settings["supersample"] = int(settings["supersample"])
        if settings["supersample"] not in (1, 3, 5):
            raise ValueError("kinect_v2 supersample must be 1 (off), 3 or 5")
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


def kinect_v1_noise(depth: np.ndarray, normals: np.ndarray, K: Any, *, rng: np.random.Generator,
                    focal: float = 580.0, baseline: float = 0.075, subpixel: float = 0.125) -> np.ndarray:
    """Kinect v1 (structured light): lateral jitter, axial noise, disparity quantisation.

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

    Returns
    -------
    noisy : ndarray (H, W) float64, 0 where nothing is returned.

    References
    ----------
    Nguyen, Izadi, Lovell, 3DIMPVT 2012; Khoshelham, Elberink, Sensors 12(2), 2012.
    """
    z = np.asarray(depth, dtype=np.float64)
    h, w = z.shape
    theta = np.nan_to_num(incidence_angle(normals, K), nan=0.0)
    sl = 0.8 + 0.035 * theta / np.maximum(np.pi / 2 - theta, 1e-3)
    du = np.rint(rng.standard_normal((h, w)) * sl).astype(np.int64)
    dv = np.rint(rng.standard_normal((h, w)) * sl).astype(np.int64)
    uu = np.clip(np.arange(w)[None, :] + du, 0, w - 1)
    vv = np.clip(np.arange(h)[:, None] + dv, 0, h - 1)
    zs = z[vv, uu]
    ts = theta[vv, uu]
    ok = _valid(zs)
    zs = np.where(ok, zs, 1.0)
    noisy = zs + rng.standard_normal((h, w)) * _kinect_v1_axial(zs, ts)
    fb = focal * baseline
    disp = np.rint(fb / np.maximum(noisy, 1e-6) / subpixel) * subpixel
    with np.errstate(divide="ignore"):
        out = np.where(disp > 0, fb / disp, 0.0)
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


def noise_std(name: str, z: Any, theta: Any = 0.0, *, K: Any = None, **settings: Any) -> np.ndarray:
    """Predicted standard deviation (metres) of the depth residual of model ``name`` on a plane.

    Parameters
    ----------
    name : str
        ``"gaussian"``, ``"kinect_v1"`` or ``"kinect_v2"``.
    z : array_like
        Depth, metres.
    theta : array_like
        Incidence angle, radians.
    K : intrinsics, keyword-only
        Needed for ``gaussian`` with ``sigma_px``.
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
    return np.sqrt(_kinect_v2_axial(z, theta) ** 2 + s["rounding"] ** 2 / 12.0)
