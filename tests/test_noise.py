"""Noise models: measured residual std on planes against the model (within 5 %)."""

from __future__ import annotations

import numpy as np
import pytest

from depthnormals.camera import Intrinsics
from depthnormals.render import render_mesh, render_subsamples
from depthnormals.synth.noise import (
    discontinuity_mask,
    gaussian_noise,
    incidence_angle,
    kinect_v1_noise,
    kinect_v2_noise,
    noise_std,
    parse_noise_spec,
)

K = Intrinsics(365.5, 365.5, 255.5, 211.5)
H, W = 212, 256  # a quarter of the Kinect v2 image is plenty: ~54k samples per plane


def _plane(z0, tilt_deg=0.0):
    """Plane through (0, 0, z0) rotated about the camera y axis by tilt_deg."""
    a = np.radians(tilt_deg)
    n = np.array([np.sin(a), 0.0, -np.cos(a)])
    d = n @ [0, 0, z0]
    e1 = np.cross(n, [0, 1, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    c = np.array([0, 0, z0])
    V = np.array([c - 50 * e1 - 50 * e2, c + 50 * e1 - 50 * e2, c + 50 * e1 + 50 * e2, c - 50 * e1 + 50 * e2])
    r = render_mesh(V, [[0, 1, 2], [0, 2, 3]], K, width=W, height=H)
    assert np.all(r.face >= 0) and abs(d) > 0
    return r


def _ratio(noisy, r, model, **settings):
    ok = noisy > 0
    res = noisy[ok] - r.depth[ok]
    theta = incidence_angle(r.normals, K)[ok]
    pred = noise_std(model, r.depth[ok], theta, K=K, **settings)
    return np.sqrt(np.mean(res ** 2)) / np.sqrt(np.mean(pred ** 2)), np.mean(res) / np.mean(pred)


@pytest.mark.parametrize("z0", [0.8, 1.7, 3.0])
def test_kinect_v2_std_matches_model(z0):
    r = _plane(z0)
    noisy = kinect_v2_noise(r.depth, r.normals, K, rng=np.random.default_rng(1))
    ratio, bias = _ratio(noisy, r, "kinect_v2")
    assert abs(ratio - 1) < 0.05 and abs(bias) < 0.05


@pytest.mark.parametrize("z0", [1.0, 2.0, 3.5])
def test_kinect_v2_std_tilted(z0):
    r = _plane(z0, tilt_deg=55.0)
    noisy = kinect_v2_noise(r.depth, r.normals, K, rng=np.random.default_rng(2))
    ratio, _ = _ratio(noisy, r, "kinect_v2")
    assert abs(ratio - 1) < 0.05


@pytest.mark.parametrize("z0", [0.8, 1.5, 2.5, 3.5])
def test_kinect_v1_std_matches_model(z0):
    r = _plane(z0)  # fronto-parallel: the lateral jitter does not change the depth
    noisy = kinect_v1_noise(r.depth, r.normals, K, rng=np.random.default_rng(3))
    ratio, _ = _ratio(noisy, r, "kinect_v1")
    assert abs(ratio - 1) < 0.05
    # every value sits on the 1/8-pixel disparity grid
    disp8 = 580.0 * 0.075 / noisy[noisy > 0] * 8
    assert np.allclose(disp8, np.rint(disp8), atol=1e-6)


@pytest.mark.parametrize("z0", [0.7, 2.0, 6.0])
@pytest.mark.parametrize("spec", ["gaussian:sigma=0.004", "gaussian:sigma_px=0.5", "gaussian"])
def test_gaussian_std_matches_model(z0, spec):
    _, st = parse_noise_spec(spec)
    r = _plane(z0, tilt_deg=30.0)
    noisy = gaussian_noise(r.depth, K, rng=np.random.default_rng(4), **st)
    ratio, _ = _ratio(noisy, r, "gaussian", **st)
    assert abs(ratio - 1) < 0.05


def test_model_formulas_pinned():
    # Fankhauser et al. 2015 at 2 m, fronto-parallel: 1.5 - 1.0 + 1.2 = 1.7 mm (+ rounding)
    assert np.isclose(noise_std("kinect_v2", 2.0), np.sqrt(1.7e-3 ** 2 + 1e-6 / 12))
    # Nguyen et al. 2012 at 1.4 m: 0.0012 + 0.0019 * 1.0 = 3.1 mm, quantisation 1.96^2/(580*.075*8)
    step = 1.4 ** 2 / (580 * 0.075 * 8)
    assert np.isclose(noise_std("kinect_v1", 1.4), np.sqrt(0.0031 ** 2 + step ** 2 / 12))
    assert np.isclose(noise_std("gaussian", 3.655, K=K, sigma_px=0.1, sigma=None), 0.001)


def test_kinect_v2_range_and_grazing_dropout():
    far = _plane(5.0)
    assert np.all(kinect_v2_noise(far.depth, far.normals, K, rng=np.random.default_rng(0)) == 0)
    near = _plane(0.4)
    assert np.all(kinect_v2_noise(near.depth, near.normals, K, rng=np.random.default_rng(0)) == 0)
    graze = _plane(2.0, tilt_deg=84.0)
    theta = np.degrees(incidence_angle(graze.normals, K))
    noisy = kinect_v2_noise(graze.depth, graze.normals, K, rng=np.random.default_rng(0), max_range=1e9)
    sel = (theta > 83.5) & (theta < 84.5)
    p = 1 / (1 + np.exp(-(84.0 - 78.0) / 3.0))  # 0.881
    assert abs(np.mean(noisy[sel] == 0) - p) < 0.03
    front = _plane(2.0)
    kept = kinect_v2_noise(front.depth, front.normals, K, rng=np.random.default_rng(0))
    assert np.mean(kept > 0) > 0.999


def test_kinect_v2_flying_pixels():
    # a small square 1.2 m in front of a wall at 3 m: boundary pixels get mixed depths
    wall = np.array([[-9, -9, 3.0], [9, -9, 3.0], [9, 9, 3.0], [-9, 9, 3.0]])
    sq = np.array([[-0.3, -0.3, 1.2], [0.3, -0.3, 1.2], [0.3, 0.3, 1.2], [-0.3, 0.3, 1.2]])
    V = np.concatenate([wall, sq])
    F = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    r = render_mesh(V, F, K, width=W, height=H)
    mask = discontinuity_mask(r.depth)
    sub = render_subsamples(V, F, K, width=W, height=H, mask=mask)
    noisy = kinect_v2_noise(r.depth, r.normals, K, rng=np.random.default_rng(0), subsamples=sub,
                            rounding=1e-9)
    flying = (noisy > 1.3) & (noisy < 2.9)
    assert 50 < flying.sum() < 4 * mask.sum()
    assert np.all(mask[flying])  # only near the edge
    # without sub-samples there are none
    plain = kinect_v2_noise(r.depth, r.normals, K, rng=np.random.default_rng(0), rounding=1e-9)
    assert np.count_nonzero((plain > 1.3) & (plain < 2.9)) == 0


def test_seeded_and_reproducible():
    r = _plane(2.0)
    for fn in (lambda g: kinect_v2_noise(r.depth, r.normals, K, rng=g),
               lambda g: kinect_v1_noise(r.depth, r.normals, K, rng=g),
               lambda g: gaussian_noise(r.depth, K, rng=g, sigma=0.01)):
        a = fn(np.random.default_rng(7))
        b = fn(np.random.default_rng(7))
        c = fn(np.random.default_rng(8))
        assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_invalid_depth_stays_invalid():
    r = _plane(2.0)
    z = r.depth.copy()
    z[:10] = 0.0
    for noisy in (gaussian_noise(z, K, rng=np.random.default_rng(0), sigma=0.5),
                  kinect_v2_noise(z, r.normals, K, rng=np.random.default_rng(0))):
        assert np.all(noisy[:10] == 0) and np.all(noisy >= 0)


@pytest.mark.parametrize(("spec", "err"), [
    ("nope", "unknown noise model"), ("gaussian:foo=1", "no setting"), ("gaussian:sigma=x", "number"),
    ("gaussian:sigma=1:sigma_px=1", "exactly one"), ("kinect_v2:supersample=2", "supersample"),
])
def test_bad_spec(spec, err):
    with pytest.raises(ValueError, match=err):
        parse_noise_spec(spec)
