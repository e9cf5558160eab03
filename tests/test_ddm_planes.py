"""The clean-depth selection: one-sided plane hypotheses and their propagation (issue 13)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import depthnormals as dn
from depthnormals.analytic import make_scene
from depthnormals.ddm.planes import ITERATIONS, _planes_rows, plane_normals
from depthnormals.kernels.depth import prepare

K_SMALL = (160.0, 160.0, 79.5, 59.5)


def _plane_depth(n, dist, shape, K):
    """Exact planar depth of the plane with normal n through the point (0, 0, dist)."""
    fx, fy, cx, cy = K
    v, u = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    ray = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], -1)
    n = np.asarray(n, np.float64)
    return dist * n[2] / (ray @ n)


def _roof(shape, K, n1, n2, dist=2.0):
    """Two planes through the same point (0, 0, dist): the farther one visible (a valley
    seen from the camera), with its exact normal per pixel."""
    z1 = _plane_depth(n1, dist, shape, K)
    z2 = _plane_depth(n2, dist, shape, K)
    first = z1 >= z2
    z = np.where(first, z1, z2)
    gt = np.where(first[..., None], np.asarray(n1, np.float64), np.asarray(n2, np.float64))
    return z, gt / np.linalg.norm(gt, axis=-1, keepdims=True)


def _err_deg(n, gt):
    c = np.clip(np.abs(np.sum(n.astype(np.float64) * gt, -1)), -1.0, 1.0)
    s = np.linalg.norm(np.cross(n.astype(np.float64), gt), axis=-1)
    return np.degrees(np.arctan2(s, c))


def test_exact_on_a_tilted_plane_float64_and_float32():
    n = np.array([0.3, -0.2, -1.0])
    n /= np.linalg.norm(n)
    z = _plane_depth(n, 2.0, (60, 80), K_SMALL)
    for depth, tol in ((z, 1e-6), (z.astype(np.float32), 5e-3)):
        out = plane_normals(depth, K_SMALL)
        assert out.dtype == np.float32 and out.shape == (60, 80, 3)
        e = _err_deg(out, n)
        assert np.nanmax(e) < tol, (depth.dtype, np.nanmax(e))
        assert np.isfinite(out).all()
        assert np.allclose(out, n, atol=1e-4)  # n faces the camera here (n_z < 0, at z > 0)


@pytest.mark.parametrize("n2", [(0.0, 0.6, -1.0), (0.5, 0.5, -1.0), (-0.8, 0.1, -1.0)])
def test_exact_at_every_pixel_of_a_crease(n2):
    """A crease along an image axis (first case: the mixed difference cannot see it) or at
    an angle: every pixel, including both sides of the crease, gets its own plane's normal.
    FALS (a 5x5 window) straddles it."""
    n1 = np.array([0.0, -0.4, -1.0])
    K = (80.0, 80.0, 39.3, 29.6)  # the crease passes near the image centre
    z, gt = _roof((60, 80), K, n1 / np.linalg.norm(n1), np.asarray(n2) / np.linalg.norm(n2))
    out = plane_normals(z, K)
    e = _err_deg(out, gt)[1:-1, 1:-1]
    assert np.nanmax(e) < 1e-5, np.nanmax(e)
    central = dn.estimate_normals(z, K, method="fals")
    assert np.nanmax(_err_deg(central, gt)[1:-1, 1:-1]) > 1.0


@given(nx=st.floats(-0.8, 0.8), ny=st.floats(-0.8, 0.8), dist=st.floats(0.3, 20.0),
       f32=st.booleans())
@settings(max_examples=40, deadline=None)
def test_any_plane_in_front_of_the_camera_is_exact(nx, ny, dist, f32):
    n = np.array([nx, ny, -1.0])
    n /= np.linalg.norm(n)
    z = _plane_depth(n, dist, (24, 32), (40.0, 40.0, 15.5, 11.5))
    if f32:
        z = z.astype(np.float32)
    out = plane_normals(z, (40.0, 40.0, 15.5, 11.5))
    assert np.isfinite(out).all()
    assert np.nanmax(_err_deg(out, n)) < (0.05 if f32 else 1e-5)
    # camera-facing: n . X < 0 at every pixel
    pts = dn.backproject(z, (40.0, 40.0, 15.5, 11.5))
    assert (np.einsum("...i,...i->...", out, pts) < 0).all()


def test_invalid_depth_and_isolated_pixels_are_nan():
    z = _plane_depth(np.array([0.0, 0.0, -1.0]), 2.0, (20, 20), K_SMALL)
    z[5, 5] = 0.0
    z[8, 3] = np.nan
    z[12, 12] = -1.0
    z[15:20, 15:20] = np.inf
    z[0:3, 10:13] = 0.0
    z[1, 11] = 2.0  # a valid pixel with no valid neighbour
    out = plane_normals(z, K_SMALL)
    bad = ~(np.isfinite(z) & (z > 0))
    assert np.isnan(out[bad]).all()
    assert np.isnan(out[1, 11]).all()
    ok = ~bad
    ok[1, 11] = False
    assert np.isfinite(out[ok]).all()
    assert np.allclose(out[ok], (0.0, 0.0, -1.0), atol=1e-6)


def test_depth_unit_does_not_matter():
    r = make_scene("box-on-floor").render(shape=(120, 160), K=K_SMALL)
    a = plane_normals(r.depth, r.K)
    b = plane_normals(r.depth * 1024.0, r.K)  # a power of two: every step exact
    np.testing.assert_array_equal(a, b)


def test_bands_and_threads_give_the_same_normals():
    r = make_scene("demo-room").render(shape=(96, 128), K=(110.0, 110.0, 63.5, 47.5))
    d = r.depth.astype(np.float32)
    prev = dn.get_num_threads()
    try:
        dn.set_num_threads(1)
        one = plane_normals(d, r.K)
        dn.set_num_threads(2)
        two = plane_normals(d, r.K)
    finally:
        dn.set_num_threads(prev)
    np.testing.assert_array_equal(one, two)
    z, cam = prepare(d, r.K, None)
    out = np.full((*z.shape, 3), 7.0, np.float32)
    f = np.float32
    for v0, v1 in ((0, 1), (1, 40), (40, 41), (41, 96)):  # bands of one row included
        _planes_rows(v0, v1, z, f(cam.fx), f(cam.fy), f(cam.cx), f(cam.cy), f(0.5), f(1e-4),
                     ITERATIONS, out)
    np.testing.assert_array_equal(one, out)


def test_propagation_helps_and_iterations_are_checked():
    r = make_scene("demo-room").render(shape=(120, 160), K=K_SMALL)
    errs = [dn.normal_metrics(plane_normals(r.depth, r.K, iterations=i), r.normals).mean
            for i in (0, 1, 3)]
    assert errs[2] < errs[1] < errs[0], errs
    with pytest.raises(ValueError, match="iterations"):
        plane_normals(r.depth, r.K, iterations=-1)
    with pytest.raises(TypeError, match="iterations"):
        plane_normals(r.depth, r.K, iterations=1.5)


@pytest.mark.parametrize("scene", ["box-on-floor", "stairs", "sphere-before-wall"])
def test_more_accurate_than_the_curvature_selection_on_clean_scenes(scene):
    r = make_scene(scene).render(shape=(120, 160), K=K_SMALL)
    new = dn.normal_metrics(plane_normals(r.depth, r.K), r.normals).mean
    old = dn.normal_metrics(dn.estimate_normals(r.depth, r.K, selection="curvature"),
                            r.normals).mean
    assert new <= old, (new, old)
