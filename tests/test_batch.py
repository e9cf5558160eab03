"""Batches (N, H, W): bit-for-bit equal to N single calls, frames spread over threads."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import depthnormals as dn
from depthnormals import _parallel
from depthnormals.batch import frame_intrinsics, map_threads

ROUGH_K = (131.25, 131.25, 79.5, 59.5)  # the intrinsics conftest's rough_sphere renders with

METHODS = ["3f2n", "3f2n+", "d2nt+", "plane-pca", "sri", "sda-sne"]
#: every registered name, float32 (the frames of a batch run with one row band, single calls
#: with two: any estimator whose result depended on the band split would fail here)
CASES = [(m, np.float32) for m in dn.methods()] + [(m, np.float64) for m in METHODS]


@pytest.fixture(scope="module")
def stack(rough_sphere):
    """Four different rough frames (noise, 3 % holes, a hole block, NaN and negative pixels)."""
    frames = [rough_sphere(seed, 0.002 * (seed + 1)) for seed in range(4)]
    frames[1][5:9, 100:104] = np.nan
    frames[2][70:73, 20:30] = -1.0
    return np.stack(frames)


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize(("method", "dtype"), CASES)
def test_batch_equals_single_calls(stack, method, dtype, two_threads):
    z = stack.astype(dtype)
    single = [dn.estimate_normals(f, ROUGH_K, method=method) for f in z]
    batch = dn.estimate_normals(z, ROUGH_K, method=method)
    assert batch.shape == (*z.shape, 3) and batch.dtype == np.float32
    for i, ref in enumerate(single):
        assert _same_bits(batch[i], ref), f"frame {i} differs"
    # the holes are holes and the rest is a real estimate
    assert np.isnan(batch[0, 40:47, 60:70]).all()
    # PCL abstains within its smoothing window of every invalid pixel (pcl.distance_map), and
    # this scene has 3 % random holes: about half its pixels get no normal, by design
    assert np.isfinite(batch[0, 60, 10:150]).mean() > (0.4 if method.startswith("pcl-") else 0.8)


def test_per_frame_intrinsics_and_options(stack, two_threads):
    Ks = [dn.Intrinsics(131.25 * s, 131.25 * s, 79.5, 59.5) for s in (1.0, 0.9, 1.1, 1.2)]
    as_mats = np.stack([k.matrix for k in Ks])
    opts = {"kernel": "sobel"}
    single = [dn.estimate_normals(f, k, method="3f2n+", **opts) for f, k in zip(stack, Ks, strict=True)]
    for K in (Ks, as_mats):
        batch = dn.estimate_normals(stack, K, method="3f2n+", **opts)
        assert all(_same_bits(batch[i], single[i]) for i in range(4))
    # a different camera gives a different answer: the per-frame K is really used
    assert not _same_bits(single[1], dn.estimate_normals(stack[1], Ks[0], method="3f2n+", **opts))


def test_integer_depth_with_scale(two_threads):
    mm = (np.arange(3 * 20 * 30).reshape(3, 20, 30) % 97 + 1500).astype(np.uint16)
    batch = dn.estimate_normals(mm, ROUGH_K, method="3f2n", depth_scale=0.001)
    single = dn.estimate_normals(mm[2], ROUGH_K, method="3f2n", depth_scale=0.001)
    assert _same_bits(batch[2], single)
    with pytest.raises(TypeError, match="depth_scale"):
        dn.estimate_normals(mm, ROUGH_K, method="3f2n")


def test_bad_batches():
    z = np.ones((3, 8, 9))
    with pytest.raises(ValueError, match=r"\(N, 3, 3\)"):
        dn.estimate_normals(z, np.tile(np.eye(3), (2, 1, 1)), method="3f2n")
    with pytest.raises(ValueError, match="2 cameras for 3 frames"):
        dn.estimate_normals(z, [ROUGH_K, ROUGH_K], method="3f2n")
    with pytest.raises(ValueError, match="colour image"):
        dn.estimate_normals(np.ones((8, 9, 3)), ROUGH_K, method="3f2n")
    with pytest.raises(ValueError, match="empty"):
        dn.estimate_normals(np.ones((0, 8, 9)), ROUGH_K, method="3f2n")
    with pytest.raises(TypeError, match="unknown option"):
        dn.estimate_normals(z, ROUGH_K, method="3f2n", not_an_option=1)


def test_frame_intrinsics_forms():
    cam = dn.Intrinsics(1.0, 2.0, 3.0, 4.0)
    assert frame_intrinsics((1.0, 2.0, 3.0, 4.0), 2) == [cam, cam]
    assert frame_intrinsics(cam.matrix, 3) == [cam] * 3
    assert frame_intrinsics([cam, cam.matrix], 2) == [cam, cam]


def test_workers_run_serial_inside(two_threads, monkeypatch):
    """Each worker runs its frames with row bands capped to 1; the caller keeps 2."""
    seen: list[tuple[str, int]] = []
    lock = threading.Lock()
    real = _parallel.run_rows

    def spy(kernel, h, *args, **kw):
        with lock:
            seen.append((threading.current_thread().name, getattr(_parallel._local, "limit", None)))
        return real(kernel, h, *args, **kw)

    import depthnormals.estimators.threefn as threefn

    monkeypatch.setattr(threefn, "run_rows", spy)
    z = np.full((4, 64, 80), 2.0)
    dn.estimate_normals(z, ROUGH_K, method="3f2n")
    workers = {name for name, _ in seen}
    assert len(seen) == 4 and all(limit == 1 for _, limit in seen)
    assert all(name.startswith("depthnormals") for name in workers) and len(workers) <= 2
    assert getattr(_parallel._local, "limit", None) is None  # the caller is untouched


def test_map_threads_order_progress_and_errors(two_threads):
    done = []
    out = map_threads(lambda x: x * x, list(range(10)), on_done=lambda i, r: done.append((i, r)))
    assert out == [x * x for x in range(10)]
    assert sorted(done) == [(i, i * i) for i in range(10)]

    def boom(x):
        if x == 3:
            raise ValueError("frame 3 is bad")
        return x

    with pytest.raises(ValueError, match="frame 3 is bad"):
        map_threads(boom, list(range(8)))


def test_nested_batch_stays_serial(two_threads, monkeypatch):
    """A batch inside a worker of another batch runs its frames on that worker, in order."""
    import depthnormals.batch as batch

    pools, limits = [], []
    real_pool = batch._pool

    def spy_pool(n):
        pools.append(n)
        return real_pool(n)

    monkeypatch.setattr(batch, "_pool", spy_pool)

    def inner(i):
        limits.append(_parallel.threads_here())
        return dn.estimate_normals(np.full((2, 40, 50), 2.0 + i), ROUGH_K, method="3f2n")

    outs = map_threads(inner, [0, 1, 2])
    assert pools == [2, 2]  # the outer batch's two workers only; the inner batches ran inline
    assert limits == [1, 1, 1] and _parallel.threads_here() == 2
    assert all(o.shape == (2, 40, 50, 3) for o in outs)
    np.testing.assert_allclose(outs[1][1, 20, 25], [0.0, 0.0, -1.0], atol=1e-6)
