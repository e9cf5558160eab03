"""The plane-fit selection of the discontinuity module (our noise-robust extension)."""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import DEFAULT_K, make_scene, planar_interior

K = DEFAULT_K.scaled(0.5)


@pytest.fixture(scope="module")
def box():
    r = make_scene("box-on-floor").render(K, (240, 320))
    rng = np.random.default_rng(3)
    noisy = np.where(r.depth > 0, r.depth + rng.normal(size=r.depth.shape) * 0.1 * r.depth / K.fx, 0.0)
    return r, noisy


def _mean_err(n, r):
    return float(np.nanmean(dn.angular_error(n, r.normals)[r.depth > 0]))


def test_plane_fit_beats_curvature_selection_under_noise(box):
    r, noisy = box
    base = _mean_err(dn.estimate_normals(noisy, K, method="3f2n"), r)
    curv = _mean_err(dn.estimate_normals(noisy, K, method="3f2n+", selection="curvature", consistency=0.1), r)
    fit = _mean_err(dn.estimate_normals(noisy, K, method="3f2n+", selection="plane-fit"), r)
    # measured at 640x480: 3F2N 1.0, curvature selection 0.57, plane fit 0.17 (ratios)
    assert fit < 0.5 * curv
    assert fit < 0.35 * base


def test_plane_fit_exact_on_clean_planar_interiors(box):
    r, _ = box
    n = dn.estimate_normals(r.depth, K, method="3f2n+", selection="plane-fit")
    inner = planar_interior(r, 2)
    assert dn.angular_error(n, r.normals)[inner].max() < 1e-3


def test_plane_fit_contract(box):
    r, _ = box
    depth = r.depth.copy()
    depth[40:44, 60:90] = 0.0
    depth[100, 100] = np.nan
    n = dn.estimate_normals(depth, K, method="3f2n+", selection="plane-fit", fit_radius=1)
    bad = ~(np.isfinite(depth) & (depth > 0))
    assert n.dtype == np.float32 and np.isnan(n[bad]).all()
    ok = np.isfinite(n).all(axis=-1)
    assert ok[~bad].all()
    np.testing.assert_allclose(np.linalg.norm(n[ok].astype(np.float64), axis=-1), 1.0, atol=1e-5)
    pts = dn.backproject(depth, K)
    assert (np.einsum("...i,...i->...", n.astype(np.float64), pts)[ok] < 0).all()


@pytest.mark.parametrize("kwargs, exc", [
    ({"selection": "ransac"}, ValueError), ({"fit_radius": 0}, ValueError),
    ({"fit_radius": 1.5}, TypeError), ({"fit_radius": True}, TypeError),
    ({"self_weight": 0.0}, ValueError), ({"self_weight": 1.5}, ValueError),
    ({"self_weight": "high"}, TypeError),
])
def test_plane_fit_bad_options(box, kwargs, exc):
    r, _ = box
    with pytest.raises(exc):
        dn.estimate_normals(r.depth, K, method="3f2n+", **kwargs)
