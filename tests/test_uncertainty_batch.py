"""``return_uncertainty=True`` on a stack (N, H, W): each frame's map equals its single call."""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.batch import estimate_normals_batch

ROUGH_K = (131.25, 131.25, 79.5, 59.5)  # the intrinsics conftest's rough_sphere renders with


@pytest.fixture(scope="module")
def stack(rough_sphere):
    """Three frames: clean (the plane branch of 3f2n+), noisy (box-fit), quantised to 1 mm
    (measured support), each with holes; so every branch of the map is in one stack."""
    clean = rough_sphere(0, 0.0)
    noisy = rough_sphere(1, 0.004)
    quantised = np.round(rough_sphere(2, 0.0) * 1000.0) / 1000.0
    return np.stack([clean, noisy, quantised]).astype(np.float32)


@pytest.mark.parametrize("method", ["3f2n+", "fals", "pcl-covariance-matrix"])
def test_stack_equals_single_calls(stack, method, two_threads):
    n, u = dn.estimate_normals(stack, ROUGH_K, method=method, return_uncertainty=True)
    assert n.shape == (*stack.shape, 3) and u.shape == stack.shape
    assert n.dtype == np.float32 and u.dtype == np.float32
    for i in range(stack.shape[0]):
        n1, u1 = dn.estimate_normals(stack[i], ROUGH_K, method=method, return_uncertainty=True)
        np.testing.assert_array_equal(n[i], n1)
        np.testing.assert_array_equal(u[i], u1)
        np.testing.assert_array_equal(np.isnan(u[i]), np.isnan(n[i, ..., 0]))
    # the frames differ (noise raises the expected error): not one map copied three times
    med = [float(np.nanmedian(u[i])) for i in range(3)]
    assert med[1] > 2.0 * med[0], med
    # the normals are those of the plain stack call
    np.testing.assert_array_equal(n, dn.estimate_normals(stack, ROUGH_K, method=method))


def test_stack_per_frame_intrinsics(stack):
    Ks = [dn.Intrinsics(131.25 * s, 131.25 * s, 79.5, 59.5) for s in (1.0, 1.3, 0.8)]
    n, u = dn.estimate_normals(stack, Ks, return_uncertainty=True)
    for i, k in enumerate(Ks):
        n1, u1 = dn.estimate_normals(stack[i], k, return_uncertainty=True)
        np.testing.assert_array_equal(u[i], u1)
        np.testing.assert_array_equal(n[i], n1)


def test_stack_errors_and_empty_frames(stack):
    with pytest.raises(ValueError, match="supported for methods"):
        dn.estimate_normals(stack, ROUGH_K, method="d2nt", return_uncertainty=True)
    with pytest.raises(ValueError, match="unknown method"):
        dn.estimate_normals(stack, ROUGH_K, method="nope", return_uncertainty=True)
    z = stack.copy()
    z[1] = 0.0
    with pytest.warns(dn.NoValidNormalWarning, match="1 of 3 frames"):
        n, u = dn.estimate_normals(z, ROUGH_K, return_uncertainty=True)
    assert np.isnan(u[1]).all() and np.isnan(n[1]).all()
    assert np.isfinite(u[0]).mean() > 0.8


def test_batch_function_without_the_registry(stack):
    """estimate_normals_batch unpacks (normals, uncertainty) from any per-frame callable."""
    def fake(depth, K, *, method, depth_scale=None):
        return np.full((*depth.shape, 3), float(depth[0, 0])), np.full(depth.shape, 7.0)

    n, u = estimate_normals_batch(fake, stack, ROUGH_K, method="x", return_uncertainty=True)
    assert u.shape == stack.shape and np.all(u == 7.0)
    assert n[2, 5, 5, 1] == np.float32(stack[2, 0, 0])
