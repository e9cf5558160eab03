"""depthnormals.torch: inputs, outputs, dtypes, errors, the module twin and the import rule."""

from __future__ import annotations

import inspect
import subprocess
import sys

import numpy as np
import pytest
import torch  # not importorskip: CI installs the torch extra and no torch test may be skipped

import depthnormals as dn
import depthnormals.torch as dt

K4 = (131.25, 131.25, 79.5, 59.5)


def _tn(*args, **kwargs):
    """The torch implementation itself (a CPU tensor without gradients would otherwise be
    computed by the numba library: ``backend="auto"``)."""
    return dt.estimate_normals(*args, backend="torch", **kwargs)


@pytest.fixture(scope="module")
def rough(rough_sphere):
    return torch.from_numpy(rough_sphere(1, 0.003).astype(np.float32))


def test_import_depthnormals_does_not_import_torch():
    code = "import sys, depthnormals; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_methods_and_defaults_follow_the_numba_library():
    assert dt.METHODS == ("3f2n", "d2nt", "sne-roadseg", "3f2n+", "d2nt+", "sne-roadseg+")
    for base, func in (("3f2n", dn.three_filters_to_normal), ("d2nt", dn.d2nt),
                       ("sne-roadseg", dn.sne_roadseg)):
        sig = {p.name: p.default for p in inspect.signature(func).parameters.values()
               if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name != "depth_scale"}
        assert dt.method_defaults(base) == sig
        sig.update(dn.ddm.module_defaults())
        # except the margin of an explicit curvature selection (TORCH_MODULE_DEFAULTS)
        sig.update({"consistency": 0.0})
        assert dt.method_defaults(base + "+") == sig
    # the module's choices are the numba module's (its public constants)
    from depthnormals.torch._api import _CHOICES

    assert set(_CHOICES["curvature"]) == {*dn.ddm.CURVATURES, "none"}
    assert set(_CHOICES["correlation"]) == set(dn.ddm.CORRELATIONS)
    assert set(_CHOICES["neighbourhood"]) == set(dn.ddm.NEIGHBOURHOODS)
    assert set(_CHOICES["derivatives"]) == set(dn.ddm.DERIVATIVES)
    # today's defaults, pinned (if the numba ones change, the torch path follows: see above);
    # the torch default selection="auto" is the clean branch of the numba default
    # (docs/torch.md): the plane hypotheses
    assert dn.ddm.module_defaults()["selection"] == "auto"
    d = dt.method_defaults("3f2n+")
    assert (d["curvature"], d["self_weight"], d["selection"], d["consistency"], d["crf"],
            d["correlation"]) == ("mean", 0.8, "auto", 0.0, False, "none")
    from depthnormals.torch._api import TORCH_MODULE_DEFAULTS

    assert TORCH_MODULE_DEFAULTS == {"consistency": 0.0}


def test_torch_default_is_the_numba_default(rough_sphere):
    """docs/torch.md: the torch default 3f2n+ computes the numba default, on clean depth (auto's
    clean branch, the plane hypotheses) and on noisy depth (the box-fit; more in
    tests/test_torch_default_parity.py)."""
    from depthnormals.analytic import make_scene

    for scene in ("sphere-before-wall", "box-on-floor"):
        clean = make_scene(scene).render(K=K4, shape=(120, 160)).depth
        assert dn.estimate_noise(clean, K4) < 1e-3
        for method in ("3f2n+", "d2nt+"):
            n = _tn(torch.from_numpy(clean)[None], K4, method=method)
            n = n[0].permute(1, 2, 0).numpy()
            ref = dn.estimate_normals(clean, K4, method=method)
            assert np.array_equal(np.isnan(n), np.isnan(ref))
            assert np.nanmax(dn.angular_error(n, ref)) < 1e-3, (scene, method)
            n32 = _tn(torch.from_numpy(clean.astype(np.float32))[None], K4,
                                      method=method)[0].permute(1, 2, 0).numpy()
            ref32 = dn.estimate_normals(clean.astype(np.float32), K4, method=method)
            err = dn.angular_error(n32, ref32)
            assert np.nanpercentile(err, 99.9) < 0.1 and np.nanmean(err) < 0.01, (scene, method)
    noisy = rough_sphere(1, 0.003)
    assert dn.estimate_noise(noisy, K4) >= 1e-3
    n = _tn(torch.from_numpy(noisy)[None], K4)[0].permute(1, 2, 0).numpy()
    planes = dn.estimate_normals(noisy, K4, selection="planes")
    box = dn.estimate_normals(noisy, K4)
    assert np.array_equal(np.isnan(n), np.isnan(box))
    assert np.nanmax(dn.angular_error(n, box)) < 1e-3
    assert np.nanmean(dn.angular_error(n, planes)) > 1.0  # the clean branch would be far off
    # with the CRF, auto's clean branch is the curvature selection at margin 0 in both (on the
    # sphere: on box-on-floor the two curvature selections differ at ~120 edge pixels, with or
    # without the CRF, an older parity gap noted in docs/torch.md)
    clean = make_scene("sphere-before-wall").render(K=K4, shape=(120, 160)).depth
    n = _tn(torch.from_numpy(clean)[None], K4, crf=True)[0].permute(1, 2, 0)
    ref = dn.estimate_normals(clean, K4, crf=True)
    assert np.nanpercentile(dn.angular_error(n.numpy(), ref), 99.9) < 0.1


def test_planes_selection_with_the_crf_is_refused():
    z = torch.full((1, 1, 8, 8), 2.0)
    with pytest.raises(ValueError, match="curvature selection"):
        _tn(z, K4, selection="planes", crf=True)
    with pytest.raises(ValueError, match="curvature selection"):
        dn.estimate_normals(z[0, 0].numpy(), K4, selection="planes", correlation="kendall")


@pytest.mark.parametrize("layout", ["B1HW", "BHW"])
def test_layouts_give_b3hw(rough, layout):
    z = rough[None, None] if layout == "B1HW" else rough[None]
    n = _tn(z, K4, method="3f2n")
    assert n.shape == (1, 3, *rough.shape) and n.dtype == torch.float32
    ref = dn.estimate_normals(rough.numpy(), K4, method="3f2n")
    np.testing.assert_allclose(n[0].permute(1, 2, 0).numpy(), ref, atol=2e-5)


def test_intrinsics_forms_agree(rough):
    cam = dn.Intrinsics(*K4)
    z = rough[None]
    ref = _tn(z, K4, method="d2nt")
    for K in (cam, cam.matrix, torch.tensor(cam.matrix), torch.tensor(cam.matrix)[None],
              torch.tensor(K4), torch.tensor(K4)[None], list(K4)):
        torch.testing.assert_close(_tn(z, K, method="d2nt"), ref, equal_nan=True)


def test_per_frame_intrinsics(rough):
    """(B, 3, 3): each frame uses its own camera (a different one changes that frame only)."""
    z = torch.stack([rough, rough])
    K = torch.tensor([K4, (2 * K4[0], 2 * K4[1], K4[2], K4[3])])
    n = _tn(z, K, method="3f2n")
    torch.testing.assert_close(n[0], _tn(rough[None], K4, method="3f2n")[0], equal_nan=True)
    torch.testing.assert_close(n[1], _tn(rough[None], K[1], method="3f2n")[0],
                               equal_nan=True)
    assert not torch.allclose(n[0].nan_to_num(), n[1].nan_to_num())


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float64])
def test_dtypes(rough, dtype):
    """float16/bfloat16 computed in float32 and returned in their dtype; float64 in float64."""
    z = rough[None].to(dtype)
    n = _tn(z, K4, method="3f2n+")
    assert n.dtype == dtype
    ref = _tn(z.to(torch.float32 if dtype != torch.float64 else dtype), K4, method="3f2n+")
    tol = {torch.float16: 1e-3, torch.bfloat16: 8e-3, torch.float64: 0.0}[dtype]
    torch.testing.assert_close(n, ref.to(dtype), atol=tol, rtol=0, equal_nan=True)


def test_integer_depth_needs_scale(rough):
    mm = (rough * 1000).round().to(torch.int32)[None]
    with pytest.raises(TypeError, match="depth_scale"):
        _tn(mm, K4, method="3f2n")
    n = _tn(mm, K4, method="3f2n", depth_scale=0.001)
    assert n.dtype == torch.float32
    ref = dn.estimate_normals(mm[0].numpy(), K4, method="3f2n", depth_scale=0.001)
    got = n[0].permute(1, 2, 0).numpy()
    assert (np.isnan(got) == np.isnan(ref)).all()
    err = dn.angular_error(got, ref)
    # millimetre steps make grazing normals (dot(n, X) ~ 0) whose orientation is decided by
    # rounding: compare the lines, not the signs, there
    err = np.minimum(err, 180.0 - err)
    assert np.nanmean(err) < 0.01 and np.nanpercentile(err, 99.9) < 0.1


def test_non_contiguous_input(rough):
    wide = torch.zeros(1, rough.shape[0], 2 * rough.shape[1])
    wide[0, :, ::2] = rough
    z = wide[:, :, ::2]
    assert not z.is_contiguous()
    torch.testing.assert_close(_tn(z, K4, method="3f2n+"),
                               _tn(z.contiguous(), K4, method="3f2n+"), equal_nan=True)


def test_invalid_zero_and_mask(rough):
    z = rough[None]
    n_nan = _tn(z, K4, method="3f2n+")
    n_zero = _tn(z, K4, method="3f2n+", invalid="zero")
    mask = dt.normals_mask(n_nan)
    assert mask.shape == (1, 1, *rough.shape) and mask.dtype == torch.bool
    assert torch.equal(mask, dt.normals_mask(n_zero))
    assert torch.equal(mask[0, 0], ~torch.isnan(n_nan[0, 0]))
    assert (n_zero[~mask.expand_as(n_zero)] == 0).all()
    torch.testing.assert_close(n_zero[mask.expand_as(n_zero)], n_nan[mask.expand_as(n_nan)])
    invalid = ~(rough > 0)
    assert invalid.any() and not mask[0, 0][invalid].any()


def test_module_twin(rough):
    net = dt.EstimateNormals("d2nt", K=torch.tensor(K4), variant="dag", invalid="zero")
    assert "K" in dict(net.named_buffers())
    assert "variant='dag'" in repr(net)
    out = net(rough[None, None])
    torch.testing.assert_close(out, _tn(rough[None], K4, method="d2nt", variant="dag",
                                                        invalid="zero"))
    torch.testing.assert_close(net(rough[None], K4), out)
    with pytest.raises(ValueError, match="no intrinsics"):
        dt.EstimateNormals("3f2n")(rough[None])
    with pytest.raises(TypeError, match="unknown option"):
        dt.EstimateNormals("3f2n", kernal="fd")


@pytest.mark.parametrize("bad, exc, match", [
    ({"method": "3f2nn"}, ValueError, "valid methods"),
    ({"method": 3}, TypeError, "method must be a string"),
    ({"method": "3f2n", "kernal": "fd"}, TypeError, "unknown option"),
    ({"method": "3f2n", "kernel": "canny"}, ValueError, "valid choices"),
    ({"method": "3f2n", "kernel_size": 4}, ValueError, "kernel_size"),
    ({"method": "3f2n", "kernel_size": 3.0}, TypeError, "kernel_size"),
    ({"method": "d2nt", "variant": "v3"}, ValueError, "valid choices"),
    ({"method": "3f2n+", "selection": "plane-fit"}, ValueError, "plane-fit"),
    ({"method": "3f2n+", "crf": True, "curvature": "none"}, ValueError, "curvature"),
    ({"method": "3f2n+", "self_weight": 0.0}, ValueError, "self_weight"),
    ({"method": "3f2n+", "crf": 1}, TypeError, "crf"),
    ({"method": "3f2n+", "crf_iterations": 0}, ValueError, "crf_iterations"),
    ({"method": "3f2n+", "iterations": 2}, TypeError, "crf_iterations"),
    ({"method": "3f2n", "invalid": "none"}, ValueError, "invalid"),
    ({"method": "3f2n", "depth_scale": -1.0}, ValueError, "depth_scale"),
])
def test_bad_options(rough, bad, exc, match):
    with pytest.raises(exc, match=match):
        _tn(rough[None], K4, **bad)


@pytest.mark.parametrize("depth, K, exc, match", [
    (np.ones((1, 4, 4), np.float32), K4, TypeError, "torch.Tensor"),
    (torch.ones(4, 4), K4, ValueError, "batch dimension"),
    (torch.ones(1, 2, 4, 4), K4, ValueError, r"\(B, 1, H, W\)"),
    (torch.ones(1, 0, 4), K4, ValueError, "empty"),
    (torch.ones(1, 4, 4, dtype=torch.bool), K4, TypeError, "real numbers"),
    (torch.ones(1, 4, 4), torch.ones(2, 3), ValueError, "K must be"),
    (torch.ones(2, 4, 4), torch.ones(3, 3, 3), ValueError, "batch of 3"),
    (torch.ones(1, 4, 4), (1.0, 2.0), ValueError, "fx, fy, cx, cy"),
    (torch.ones(1, 4, 4), "K", TypeError, "K must be"),
])
def test_bad_inputs(depth, K, exc, match):
    with pytest.raises(exc, match=match):
        _tn(depth, K, method="3f2n")


@pytest.mark.filterwarnings("ignore::depthnormals.NoValidNormalWarning")  # all-NaN shapes: warned, by design
@pytest.mark.parametrize("method", dt.METHODS)
def test_tiny_images(method):
    """1x1, 1xW and Hx1 images: no crash; a lone pixel has no normal (no gradient)."""
    for shape in ((1, 1), (1, 5), (5, 1), (2, 2)):
        z = torch.full((1, *shape), 2.0)
        n = _tn(z, (100.0, 100.0, 0.0, 0.0), method=method)
        ref = dn.estimate_normals(z[0].numpy(), (100.0, 100.0, 0.0, 0.0), method=method)
        np.testing.assert_allclose(n[0].permute(1, 2, 0).numpy(), ref, atol=1e-6)


def test_docs_examples_run():
    """The code blocks of docs/torch.md run as written."""
    import pathlib
    import re

    text = (pathlib.Path(__file__).resolve().parents[1] / "docs" / "torch.md").read_text()
    ns: dict = {}
    for block in re.findall(r"```python\n(.*?)```", text, re.S):
        exec(block, ns)
    assert ns["batch"].shape == (4, 4, 48, 64)
    assert ns["n"].shape == (2, 3, 480, 640) and ns["mask"].shape == (2, 1, 480, 640)
    net = ns["WithNormals"](torch.nn.Conv2d(4, 2, 3, padding=1), (60.0, 60.0, 31.5, 23.5))
    assert net(torch.rand(2, 1, 48, 64) + 1).shape == (2, 2, 48, 64)
