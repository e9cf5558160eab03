"""Hypothesis properties of every registered estimator.

Random depth maps (sizes 1..12, every kind of invalid pixel, random scales and cameras):
no exception, (H, W, 3) float32, NaN at every invalid pixel, every finite normal unit and
facing the camera. On analytic scenes: invariance to the depth unit (scale-invariant
estimators) and equivariance under transposition and 180-degree rotation of the image.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import depthnormals as dn
from depthnormals.analytic import DEFAULT_K, make_scene

METHODS = dn.methods()
BASE = [m for m in METHODS if not m.endswith("+")]
# the "+" forms add the DDM, whose scale invariance the registry does not record
SCALE_INVARIANT = [m for m in BASE if dn.get_estimator(m).scale_invariant]
INVALID = [0.0, -1.0, -0.0, np.nan, np.inf, -np.inf]
SETTINGS = settings(deadline=None, max_examples=15, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])


@st.composite
def depth_maps(draw):
    h = draw(st.integers(1, 12))
    w = draw(st.integers(1, 12))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    scale = 10.0 ** draw(st.floats(-3, 3))
    kind = draw(st.sampled_from(["noise", "plane", "steps"]))
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    if kind == "noise":
        z = rng.uniform(0.5, 2.0, (h, w))
    elif kind == "plane":
        a, b = rng.uniform(-0.05, 0.05, 2)
        z = 1.0 / np.clip(1.0 + a * u + b * v, 0.2, None)
    else:
        z = np.where(u + v > (h + w) / 2, 1.0, 1.7) + 0.01 * rng.random((h, w))
    z = z * scale
    p_bad = draw(st.sampled_from([0.0, 0.1, 0.4, 0.9]))
    bad = rng.random((h, w)) < p_bad
    z[bad] = rng.choice(INVALID, size=int(bad.sum()))
    dtype = draw(st.sampled_from([np.float32, np.float64]))
    fx = 10.0 ** draw(st.floats(0, 3))
    fy = fx * draw(st.floats(0.5, 2.0))
    cx = draw(st.floats(-2.0, w + 1.0))
    cy = draw(st.floats(-2.0, h + 1.0))
    return z.astype(dtype), (fx, fy, cx, cy)


@pytest.mark.parametrize("method", METHODS)
@SETTINGS
@given(case=depth_maps())
def test_random_depth_maps(method, case):
    z, K = case
    with np.errstate(all="raise"), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", dn.NoValidNormalWarning)  # no other warning leaks out
        n = dn.estimate_normals(z, K, method=method)
    assert bool(caught) == bool(np.isnan(n).all())  # warned exactly when no normal is finite
    assert n.shape == (*z.shape, 3) and n.dtype == np.float32
    invalid = ~(np.isfinite(z) & (z > 0))
    assert np.isnan(n[invalid]).all()
    ok = np.isfinite(n).all(axis=-1)
    assert np.array_equal(ok, ~np.isnan(n).any(axis=-1))  # all three NaN or none
    n64 = n.astype(np.float64)[ok]
    np.testing.assert_allclose(np.linalg.norm(n64, axis=-1), 1.0, atol=1e-5)
    pts = dn.backproject(z, K)[ok]
    dots = np.einsum("ij,ij->i", n64, pts)
    assert (dots <= 1e-6 * np.linalg.norm(pts, axis=-1)).all()


@pytest.fixture(scope="module")
def scenes():
    K = DEFAULT_K.scaled(0.125)
    return [make_scene(name).render(K, (60, 80)) for name in ("box-on-floor", "sphere-before-wall")]


def _assert_same_normals(a, b, render, atol=1e-4):
    """Equal NaN pattern; equal vectors, allowing a sign flip only where the normal is
    (numerically) perpendicular to the ray, where the orientation is undetermined."""
    assert np.array_equal(np.isnan(a), np.isnan(b))
    ok = np.isfinite(a).all(axis=-1)
    a, b = a[ok].astype(np.float64), b[ok].astype(np.float64)
    pts = dn.backproject(render.depth, render.K)[ok]
    cos = np.abs(np.einsum("ij,ij->i", a, pts)) / np.linalg.norm(pts, axis=-1)
    same = np.abs(a - b).max(axis=-1) < atol
    flipped = np.abs(a + b).max(axis=-1) < atol
    assert (same | (flipped & (cos < 1e-2))).all()
    assert same.mean() > 0.99


@pytest.mark.parametrize("method", SCALE_INVARIANT)
@settings(deadline=None, max_examples=6, derandomize=True)
@given(exponent=st.floats(-3, 3), which=st.integers(0, 1))
def test_scale_invariance(scenes, method, exponent, which):
    r = scenes[which]
    s = 10.0 ** exponent
    a = dn.estimate_normals(r.depth, r.K, method=method)
    b = dn.estimate_normals(r.depth * s, r.K, method=method)
    _assert_same_normals(a, b, r)


# The "+" forms are left out: the DDM breaks ties between neighbours with equal curvature
# in a fixed scan order, so a few edge pixels (2 of 4800 for plane-svd+ on box-on-floor)
# pick a different neighbour's normal in the mirrored image.
@pytest.mark.parametrize("method", BASE)
@pytest.mark.parametrize("which", [0, 1])
def test_transpose_swaps_nx_and_ny(scenes, method, which):
    """Transposing the image (fx <-> fy, cx <-> cy) mirrors the scene in x = y."""
    r = scenes[which]
    K = r.K
    a = dn.estimate_normals(r.depth, K, method=method)
    t = dn.estimate_normals(r.depth.T, (K.fy, K.fx, K.cy, K.cx), method=method)
    _assert_same_normals(a, t.transpose(1, 0, 2)[..., [1, 0, 2]], r)


@pytest.mark.parametrize("method", BASE)
@pytest.mark.parametrize("which", [0, 1])
def test_rotation_by_180_degrees(scenes, method, which):
    """Rotating the image by 180 deg about the principal point negates nx and ny."""
    r = scenes[which]
    K = r.K
    h, w = r.depth.shape
    a = dn.estimate_normals(r.depth, K, method=method)
    rot = dn.estimate_normals(r.depth[::-1, ::-1], (K.fx, K.fy, w - 1 - K.cx, h - 1 - K.cy),
                              method=method)
    _assert_same_normals(a, rot[::-1, ::-1] * np.array([-1, -1, 1], np.float32), r)
