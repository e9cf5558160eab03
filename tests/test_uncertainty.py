"""The expected-error map of ``estimate_normals(..., return_uncertainty=True)`` and the vMF
conversions (:mod:`depthnormals.ddm.uncertainty`)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import tilted_plane
from depthnormals.ddm.uncertainty import UNCERTAINTY_METHODS


def _plane(noise: float, seed: int = 0, shape=(120, 160)):
    r = tilted_plane((0.0, -0.6, -0.8), 2.0).render(shape=shape)
    fx = dn.as_intrinsics(r.K).fx
    rng = np.random.default_rng(seed)
    return r, r.depth * (1.0 + noise * rng.standard_normal(r.depth.shape) / fx)


@pytest.mark.parametrize("method", UNCERTAINTY_METHODS)
def test_nan_pattern_matches_normals_with_holes(method):
    r, d = _plane(0.1)
    d = d.copy()
    d[30:50, 40:70] = 0.0
    d[::7, ::11] = np.nan
    n, u = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True)
    assert u.dtype == np.float32 and u.shape == d.shape
    np.testing.assert_array_equal(np.isnan(u), np.isnan(n[..., 0]))
    assert np.all(u[np.isfinite(u)] >= 0.0)


@pytest.mark.parametrize("method", ["3f2n+", "fals", "pcl-covariance-matrix"])
def test_iid_plane_mean_prediction_within_20_percent(method):
    r, d = _plane(0.2, shape=(240, 320))
    n, u = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True)
    e = dn.angular_error(n, r.normals)
    ok = np.isfinite(e)
    pred, obs = float(np.mean(u[ok])), float(np.mean(e[ok]))
    assert abs(pred - obs) <= 0.2 * obs, (pred, obs)


def test_monotonic_in_noise_level():
    means = []
    for s in (0.02, 0.1, 0.4):
        r, d = _plane(s)
        _, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
        means.append(float(np.nanmean(u)))
    assert means[0] < means[1] < means[2]


def test_measured_support_branch_on_quantised_depth():
    r = tilted_plane((0.0, -0.6, -0.8), 2.0).render(shape=(240, 320))
    disparity = np.round(580 * 0.075 / r.depth * 8) / 8
    d = 580 * 0.075 / disparity
    assert dn.noise_profile(d, r.K).branch == "measured-support"
    n, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
    np.testing.assert_array_equal(np.isnan(u), np.isnan(n[..., 0]))
    assert np.nanmean(u) > 0.0


def test_normals_unchanged_by_the_flag():
    r, d = _plane(0.1)
    for m in UNCERTAINTY_METHODS:
        n, _ = dn.estimate_normals(d, r.K, method=m, return_uncertainty=True)
        np.testing.assert_array_equal(n, dn.estimate_normals(d, r.K, method=m))


def test_unsupported_methods_raise():
    r, d = _plane(0.1)
    with pytest.raises(ValueError, match="supported for methods 3f2n\\+, fals"):
        dn.estimate_normals(d, r.K, method="d2nt", return_uncertainty=True)
    with pytest.raises(ValueError, match="default options"):
        dn.estimate_normals(d, r.K, method="3f2n+", crf=True, return_uncertainty=True)
    with pytest.raises(ValueError, match="unknown method"):
        dn.estimate_normals(d, r.K, method="nope", return_uncertainty=True)
    with pytest.raises(TypeError, match="return_uncertainty"):
        dn.estimate_normals(d, r.K, return_uncertainty="yes")
    # a stack is no refusal: one map per frame (estimate_normals_batch)
    _, u = dn.estimate_normals(np.stack([d, d]), r.K, return_uncertainty=True)
    assert u.shape == (2, *d.shape) and u.dtype == np.float32


def test_kappa_round_trip():
    e = np.array([0.1, 1.0, 5.0, 20.0])
    np.testing.assert_allclose(dn.kappa_to_uncertainty(dn.uncertainty_to_kappa(e)), e, rtol=1e-12)
    assert float(dn.uncertainty_to_kappa(1.0)) == pytest.approx(math.pi / 2 / math.radians(1.0) ** 2)
    with pytest.raises(ValueError):
        dn.kappa_to_uncertainty(0.0)
    with pytest.raises(ValueError):
        dn.uncertainty_to_kappa(-1.0)


@pytest.mark.parametrize("err", [1.0, 5.0, 15.0])
def test_kappa_matches_sampled_vmf(err):
    kappa = float(dn.uncertainty_to_kappa(err))
    rng = np.random.default_rng(1)
    # vMF on S^2 around +z: cos(theta) = 1 + log(u + (1 - u) exp(-2 kappa)) / kappa
    u = rng.random(200_000)
    w = 1.0 + np.log(u + (1.0 - u) * np.exp(-2.0 * kappa)) / kappa
    mean = float(np.degrees(np.arccos(np.clip(w, -1.0, 1.0))).mean())
    assert mean == pytest.approx(err, rel=0.02)


def test_import_stays_light():
    code = ("import sys, depthnormals; "
            "print(any(m in sys.modules for m in ('torch', 'matplotlib')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def _cli_inputs(tmp_path):
    import json

    r, d = _plane(0.1, shape=(48, 64))
    K = dn.as_intrinsics(r.K)
    (tmp_path / "k.json").write_text(json.dumps({"fx": K.fx, "fy": K.fy, "cx": K.cx, "cy": K.cy}))
    (tmp_path / "in").mkdir()
    np.save(tmp_path / "in" / "a.npy", d.astype(np.float32))
    np.save(tmp_path / "in" / "b.npy", d.astype(np.float32))
    return r, d


def test_cli_single_file_writes_uncertainty(tmp_path):
    from depthnormals.cli import main

    r, d = _cli_inputs(tmp_path)
    out = tmp_path / "out" / "a.vis.png"
    assert main(["estimate", str(tmp_path / "in" / "a.npy"), "-K", str(tmp_path / "k.json"),
                 "-o", str(out), "--uncertainty"]) == 0
    u = np.load(tmp_path / "out" / "a.uncertainty.npy")
    _, want = dn.estimate_normals(d.astype(np.float32), r.K, return_uncertainty=True)
    np.testing.assert_array_equal(u, want)


def test_cli_many_records_the_flag(tmp_path):
    import json

    from depthnormals.cli import main
    from depthnormals.jobs import MANIFEST

    _cli_inputs(tmp_path)
    out = tmp_path / "many"
    assert main(["estimate", str(tmp_path / "in"), "-K", str(tmp_path / "k.json"), "-o", str(out),
                 "--uncertainty", "-q"]) == 0
    assert sorted(p.name for p in out.rglob("*.uncertainty.npy")) == ["a.uncertainty.npy",
                                                                      "b.uncertainty.npy"]
    settings = json.loads((out / MANIFEST).read_text())["settings"]
    assert settings["uncertainty"] is True
    # without the flag the manifest differs: a resumed run is refused
    assert main(["estimate", str(tmp_path / "in"), "-K", str(tmp_path / "k.json"), "-o", str(out),
                 "-q"]) != 0


def test_cli_unsupported_method(tmp_path):
    from depthnormals.cli import main

    _cli_inputs(tmp_path)
    assert main(["estimate", str(tmp_path / "in"), "-K", str(tmp_path / "k.json"), "-o",
                 str(tmp_path / "x"), "--uncertainty", "-m", "d2nt", "-q"]) != 0


def test_covariance_in_the_tangent_plane():
    r, d = _plane(0.1, shape=(24, 32))
    n, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
    c = dn.uncertainty_to_covariance(n, u).astype(np.float64)
    assert c.shape == (24, 32, 3, 3)
    ok = np.isfinite(u)
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", c, n)[ok], 0.0, atol=1e-9)
    s2 = np.radians(u[ok].astype(np.float64)) ** 2 / (math.pi / 2)
    np.testing.assert_allclose(np.trace(c, axis1=-2, axis2=-1)[ok], 2 * s2, rtol=1e-4)
    with pytest.raises(ValueError, match="shape"):
        dn.uncertainty_to_covariance(n, u[:2])


@pytest.mark.parametrize("seed", [0, 1])
def test_correlated_quantised_plane_mean_prediction_within_25_percent(seed):
    """Kinect-like depth (disparity noise correlated over a 9x9 box, 1/8 px steps): the
    measured-support map, self-calibrated by the interior pairs of its own normals, predicts
    the mean error (measured 0.59 / 0.64 and 0.60 / 0.67 deg, predicted / observed)."""
    r = tilted_plane((0.0, -0.6, -0.8), 2.0).render(shape=(240, 320))
    rng = np.random.default_rng(seed)
    e = rng.standard_normal((240 + 8, 320 + 8))
    k = np.ones(9) / 3.0
    e = np.apply_along_axis(lambda x: np.convolve(x, k, "valid"), 0, e)
    e = np.apply_along_axis(lambda x: np.convolve(x, k, "valid"), 1, e)
    disp = 580 * 0.075 / r.depth + 0.05 * e
    d = 580 * 0.075 / (np.round(disp * 8) / 8)
    assert dn.noise_profile(d, r.K).branch == "measured-support"
    n, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
    err = dn.angular_error(n, r.normals)
    ok = np.isfinite(err)
    pred, obs = float(np.mean(u[ok])), float(np.mean(err[ok]))
    assert abs(pred - obs) <= 0.25 * obs, (pred, obs)
