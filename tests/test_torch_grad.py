"""depthnormals.torch is differentiable: finite gradients at holes and jumps, gradcheck on small
float64 inputs, and whole graphs (no host synchronisation) under torch.compile."""

from __future__ import annotations

import numpy as np
import pytest
import torch  # not importorskip: CI installs the torch extra and no torch test may be skipped

import depthnormals.torch as dt

K4 = (131.25, 131.25, 79.5, 59.5)  # conftest.ROUGH_K: the rough scene's intrinsics
GRAD_CASES = [(m, {}) for m in dt.METHODS] + [
    ("3f2n", {"aggregate": "mean"}), ("3f2n", {"aggregate": "trimean"}),
    ("3f2n", {"aggregate": "trimmed-mean"}), ("3f2n", {"kernel": "sobel", "kernel_size": 5}),
    ("3f2n", {"kernel": "roberts"}), ("d2nt", {"variant": "basic"}), ("d2nt", {"variant": "dag"}),
    ("3f2n+", {"correlation": "kendall", "crf": True}), ("3f2n+", {"correlation": "pearson", "crf": True}),
    ("3f2n+", {"correlation": "kendall"}), ("3f2n+", {"curvature": "pixel-mean", "neighbourhood": "square"}),
]


def _ids(case):
    m, o = case
    return m + "".join(f"-{k}={v}" for k, v in o.items())


@pytest.mark.parametrize("case", GRAD_CASES, ids=_ids)
def test_gradients_finite_at_holes_and_jumps(rough_sphere, case):
    """The rough scene (holes, a 7x10 hole, the sphere's occlusion edge): the gradient of a
    loss over the finite normals is finite everywhere, non-zero somewhere, and zero at
    invalid depth."""
    method, options = case
    z0 = torch.from_numpy(rough_sphere(2, 0.004).astype(np.float32))[None]
    z = z0.clone().requires_grad_(True)
    n = dt.estimate_normals(z, K4, method=method, **options)
    ok = torch.isfinite(n)
    assert ok.any(dim=1).sum() > 0.8 * z.numel()
    w = torch.randn(n.shape, generator=torch.Generator().manual_seed(0))
    loss = torch.where(ok, n * w, 0.0).sum()
    loss.backward()
    g = z.grad
    assert torch.isfinite(g).all(), f"{int((~torch.isfinite(g)).sum())} non-finite gradients"
    assert (g != 0).sum() > 0.5 * z.numel()
    assert (g[~(z0 > 0)] == 0).all()


@pytest.mark.parametrize("case", GRAD_CASES, ids=_ids)
def test_gradcheck(case):
    """torch.autograd.gradcheck on a small float64 surface (a tilted, gently curved patch
    with a little noise: no ties, so every selection is locally constant)."""
    method, options = case
    gen = torch.Generator().manual_seed(3)
    v, u = torch.meshgrid(torch.arange(7.0), torch.arange(8.0), indexing="ij")
    z = 2.0 + 0.05 * u - 0.03 * v + 0.004 * (u - 3.5) ** 2 + 0.002 * torch.randn(7, 8, generator=gen)
    z = z.to(torch.float64)[None].requires_grad_(True)

    def f(depth):
        return dt.estimate_normals(depth, (60.0, 62.0, 3.5, 3.0), method=method, invalid="zero", **options)

    assert torch.isfinite(f(z)).all()
    assert torch.autograd.gradcheck(f, (z,), eps=1e-6, atol=1e-5, rtol=1e-3, fast_mode=True)


def test_gradient_flows_through_the_chosen_candidate():
    """3F2N's median picks candidates: the gradient of nz at a pixel reaches the depth of its
    neighbours only (a 3x3 stencil), and the orientation flip keeps it finite."""
    v, u = torch.meshgrid(torch.arange(9.0), torch.arange(9.0), indexing="ij")
    z = (1.0 / (0.5 + 0.01 * u + 0.02 * v)).to(torch.float64)[None].requires_grad_(True)
    n = dt.estimate_normals(z, (50.0, 50.0, 4.0, 4.0), method="3f2n")
    n[0, 2, 4, 4].backward()
    nz = (z.grad[0] != 0).nonzero()
    assert nz[:, 0].min() >= 3 and nz[:, 0].max() <= 5 and nz[:, 1].min() >= 3 and nz[:, 1].max() <= 5


@pytest.mark.slow
@pytest.mark.parametrize("method", dt.METHODS)
def test_one_graph_no_host_sync(method):
    """torch._dynamo traces every method into one graph with no break: no ``.item()``, no
    branching on tensor values, nothing that leaves the graph (slow: ~20 s each here). The
    module with an explicit selection; ``selection="auto"`` (the default) reads each frame's
    noise on the host to choose its branch: a graph break there (test_compiled_default_on_sensor_depth)."""
    K = torch.tensor([60.0, 60.0, 4.0, 3.5])
    opts = {"selection": "planes"} if method.endswith("+") else {}
    ex = torch._dynamo.explain(lambda z: dt.estimate_normals(z, K, method=method, backend="torch", **opts))(
        torch.rand(1, 8, 9) + 1)
    assert ex.graph_count == 1 and ex.graph_break_count == 0, [b.reason for b in ex.break_reasons]


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:`torch.jit.script_method` is deprecated:DeprecationWarning")
def test_torch_compile_cpu():
    """torch.compile (inductor, C++ on CPU) gives the eager result (slow: a cold compile takes
    ~100 s on the shared 2-core machine; inductor itself raises a DeprecationWarning inside
    torch.jit, ignored here)."""
    z = torch.rand(2, 1, 12, 16) + 1.0
    K = (20.0, 20.0, 7.5, 5.5)
    f = torch.compile(lambda d: dt.estimate_normals(d, K, method="3f2n", backend="torch"), fullgraph=True)
    torch.testing.assert_close(f(z), dt.estimate_normals(z, (20.0, 20.0, 7.5, 5.5), method="3f2n"),
                               equal_nan=True, atol=1e-5, rtol=1e-5)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["kinect_v1", "gaussian"])
def test_compiled_default_on_sensor_depth(model):
    """The default on sensor depth (the measured support, kinect_v1, and the box-fit,
    Gaussian: the noise and the support profile are read on the host, so the graph breaks
    there) runs under ``torch.compile`` (dynamo with its eager backend: the tracing, breaks and
    guards, without inductor's minutes of code generation) and gives the eager call's bits,
    twice (the second call reuses the guards). Before session 36 the measured support failed
    here: dynamo traced the profile's numpy choice (``depth_exponent``: TypeError)."""
    from depthnormals.analytic import make_scene
    from depthnormals.synth import noise as sensor

    K = (120.0, 120.0, 39.5, 29.5)
    r = make_scene("demo-room").render(K=K, shape=(60, 80))
    def draw(s):
        rng = np.random.default_rng(s)
        if model == "gaussian":
            return sensor.gaussian_noise(r.depth, K, rng=rng, sigma_px=0.3)
        return sensor.kinect_v1_noise(r.depth, r.normals, K, rng=rng)

    z = torch.from_numpy(np.stack([np.asarray(draw(s)) for s in range(2)]))[:, None]
    eager = dt.estimate_normals(z, K, backend="torch")
    f = torch.compile(lambda d: dt.estimate_normals(d, K, backend="torch"), backend="eager")
    for _ in range(2):
        assert torch.equal(torch.nan_to_num(f(z)), torch.nan_to_num(eager))
