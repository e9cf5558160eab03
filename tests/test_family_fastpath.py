"""The vectorised fast paths of the comparison family agree with their per-pixel general paths,
and degenerate input gives NaN or a unit normal, never an exception."""

from __future__ import annotations

import math

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.estimators import pointcloud, range_image
from depthnormals.kernels.eig3 import smallest_eigenvector, smallest_eigenvector_newton

FAMILY = ("sda-sne", "sne-roadseg", "fals", "sri", "line-mod", "plane-svd", "plane-pca",
          "vector-svd", "area-weighted", "angle-weighted")
K = (131.25, 131.25, 79.5, 59.5)  # conftest.ROUGH_K: the rough scene's intrinsics


@pytest.fixture(scope="module")
def rough(rough_sphere):
    """A curved scene with noise and holes: every branch of the fast paths is exercised."""
    z = rough_sphere(7, 0.002)
    return np.where(z > 0, z, np.nan)


def _general(pixel, z, *args):
    out = np.full((*z.shape, 3), np.nan, np.float32)
    for v in range(z.shape[0]):
        for u in range(z.shape[1]):
            pixel(z, v, u, *args, out)
    return out


def _same(a, b, atol):
    na, nb = np.isnan(a[..., 0]), np.isnan(b[..., 0])
    assert (na == nb).all()
    assert np.abs(a[~na] - b[~nb]).max() < atol


@pytest.mark.parametrize("window", [3, 5])
def test_fals_fast_path_equals_general_path(rough, window):
    fast = dn.fals(rough, K, window=window)
    slow = _general(range_image._fals_pixel, rough, *K, window // 2)
    _same(fast, slow, 1e-4)   # ill-conditioned M (window 3): rounding, ~0.005 deg at most


def test_sri_fast_path_equals_general_path(rough):
    from depthnormals.kernels.stencils import gradient_kernels
    deriv, smooth = gradient_kernels("sobel", 5)
    R = np.empty(rough.shape)
    range_image._range_rows(0, rough.shape[0], rough, *K, R)
    fast = dn.sri(rough, K)
    out = np.full((*rough.shape, 3), np.nan, np.float32)
    for v in range(rough.shape[0]):
        for u in range(rough.shape[1]):
            range_image._sri_pixel(rough, R, v, u, *K, deriv, smooth, out)
    _same(fast, out, 1e-6)


@pytest.mark.parametrize(("fn", "centred"), [(dn.plane_svd, True), (dn.vector_svd, False)])
def test_scatter_fast_path_equals_general_path(rough, fn, centred):
    _same(fn(rough, K), _general(pointcloud._scatter_pixel, rough, *K, 1, centred), 1e-5)


@pytest.mark.parametrize(("fn", "angle"), [(dn.area_weighted, False), (dn.angle_weighted, True)])
def test_fan_fast_path_equals_general_path(rough, fn, angle):
    _same(fn(rough, K), _general(pointcloud._fan_pixel, rough, *K, pointcloud._RING, angle),
          1e-6)


def test_angle_between_matches_atan2():
    rng = np.random.default_rng(1)
    s = np.abs(rng.normal(size=20000)) * 10.0 ** rng.uniform(-8, 8, 20000)
    c = rng.normal(size=20000) * 10.0 ** rng.uniform(-8, 8, 20000)
    s[:3] = [0.0, 1.0, 1.0]
    c[:3] = [1.0, 0.0, -1.0]
    for si, ci in zip(s, c, strict=True):
        assert abs(pointcloud.angle_between(si, ci) - math.atan2(si, ci)) <= 4e-16 * math.pi


def test_newton_eigenvector_matches_the_trigonometric_one():
    rng = np.random.default_rng(2)
    checked = 0
    for _ in range(2000):
        P = rng.normal(size=(9, 3)) * rng.uniform(0.01, 1.0, 3)
        P -= P.mean(0)
        A = P.T @ P
        args = (A[0, 0], A[0, 1], A[0, 2], A[1, 1], A[1, 2], A[2, 2])
        x, y, z, ok = smallest_eigenvector_newton(*args)
        ref = np.linalg.eigh(A)[1][:, 0]
        if ok:
            assert abs(abs(np.dot([x, y, z], ref)) - 1.0) < 1e-10
            t = smallest_eigenvector(*args)
            assert abs(abs(np.dot([x, y, z], t)) - 1.0) < 1e-8
            checked += 1
    assert checked > 1900
    # rank 1 (collinear points): not ok, left to the general solver (NaN there)
    assert not smallest_eigenvector_newton(1.0, 1.0, 1.0, 1.0, 1.0, 1.0)[3]
    assert not smallest_eigenvector_newton(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)[3]


@pytest.mark.parametrize("method", FAMILY)
@pytest.mark.filterwarnings("ignore::depthnormals.NoValidNormalWarning")  # all-NaN shapes: warned, by design
@pytest.mark.parametrize("shape", [(1, 9), (9, 1), (2, 2), (3, 40)])
def test_degenerate_shapes_and_extreme_depths_never_raise(method, shape):
    rng = np.random.default_rng(3)
    z = 10.0 ** rng.uniform(-30, 30, shape)
    n = dn.estimate_normals(z, (1e-3, 1e3, 0.0, 0.0), method=method)
    assert n.shape == (*shape, 3) and n.dtype == np.float32
    ok = np.isfinite(n).all(axis=-1)
    assert (np.isnan(n[~ok]).all(axis=-1)).all()
    assert np.allclose(np.linalg.norm(n[ok], axis=-1), 1.0, atol=1e-5)
    if shape in ((1, 9), (9, 1)) and method == "fals":
        assert not ok.any()   # the rays of one image row or column are coplanar: M singular


def test_sne_roadseg_fast_path_equals_general_path(rough):
    from depthnormals.estimators import roadseg
    from depthnormals.kernels.stencils import gradient_kernels
    deriv, smooth = gradient_kernels("fd", 3)
    D = np.divide(1.0, rough)
    out = np.full((*rough.shape, 3), np.nan, np.float32)
    cand = np.empty(8)
    for v in range(rough.shape[0]):
        for u in range(rough.shape[1]):
            roadseg._roadseg_pixel(rough, D, v, u, *K, deriv, smooth, roadseg.NEIGHBOURS8, cand, out)
    _same(dn.sne_roadseg(rough, K), out, 1e-6)


@pytest.mark.parametrize("method", FAMILY)
def test_row_bands_give_the_single_thread_result(rough, method):
    """Bands start their rings and running sums afresh: threads change nothing."""
    before = dn.get_num_threads()
    try:
        dn.set_num_threads(1)
        one = dn.estimate_normals(rough, K, method=method)
        dn.set_num_threads(3)   # 120 rows: bands of 40, 40, 40
        three = dn.estimate_normals(rough, K, method=method)
    finally:
        dn.set_num_threads(before)
    np.testing.assert_array_equal(one, three)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("aggregate", ["median", "mean"])
def test_3f2n_fast_row_pass_equals_general_path(rough, dtype, aggregate):
    """The FD row pass (shared reciprocal depth steps, run in the dtype of z) against the
    per-pixel float64 path on a noisy scene with holes: same NaN pattern, same normals.

    Sign flips are allowed only where the normal is perpendicular to the ray (the facing
    rule is then decided by rounding)."""
    from depthnormals.estimators import threefn
    from depthnormals.kernels.threefn_rows import NEIGHBOURS8, generic_normal

    z = rough.astype(dtype)
    fast = dn.three_filters_to_normal(z, K, aggregate=aggregate)
    mode = threefn.AGGREGATES.index(aggregate)
    slow = np.full((*z.shape, 3), np.nan, np.float32)
    for v in range(z.shape[0]):
        for u in range(z.shape[1]):
            slow[v, u] = generic_normal(z, z, True, v, u, *K, np.array([-0.5, 0.0, 0.5]),
                                       np.ones(1), False, mode, NEIGHBOURS8, np.empty(8))
    na, nb_ = np.isnan(fast[..., 0]), np.isnan(slow[..., 0])
    assert (na == nb_).all()
    err = dn.angular_error(fast, slow, folded=True)[~na]
    # float32 arithmetic on sensor-like depth: well under a hundredth of a degree
    assert np.percentile(err, 99.9) < (5e-4 if dtype == np.float32 else 1e-6)
    assert err.max() < (5e-3 if dtype == np.float32 else 1e-6)
    flipped = dn.angular_error(fast, slow)[~na] > 90
    X = dn.backproject(z, K)[~na]
    cos_ray = np.abs(np.einsum("ij,ij->i", slow[~na].astype(np.float64), X)) / np.linalg.norm(X, axis=1)
    assert (cos_ray[flipped] < 1e-3).all()
