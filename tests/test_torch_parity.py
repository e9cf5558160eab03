"""depthnormals.torch against the numba library: every method, every option, three kinds of data.

Acceptance (issue 14): float32, a batch of 4 frames, <= 0.01 deg mean and <= 0.1 deg at the
99.9th percentile, and the same NaN pattern. The numba side is called through the public API
only (``depthnormals.estimate_normals``) on the same float32 depth.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch  # not importorskip: CI installs the torch extra and no torch test may be skipped

import depthnormals as dn
import depthnormals.torch as dt
from depthnormals.analytic import make_scene, scene_names


def _tn(*args, **kwargs):
    """The torch implementation itself (a CPU tensor without gradients would otherwise be
    computed by the numba library: ``backend="auto"``)."""
    return dt.estimate_normals(*args, backend="torch", **kwargs)

ROUGH_K = (131.25, 131.25, 79.5, 59.5)  # conftest.ROUGH_K: the rough scene's intrinsics

DEFAULT_METHODS = ("3f2n", "d2nt", "sne-roadseg", "3f2n+", "d2nt+")


def _batch_numba(depths, Ks, method, **options):
    return np.stack([dn.estimate_normals(z, K, method=method, **options)
                     for z, K in zip(depths, Ks, strict=True)])


def _batch_torch(depths, Ks, method, **options):
    z = torch.from_numpy(np.stack(depths))[:, None]
    K = torch.from_numpy(np.stack([dn.as_intrinsics(k).matrix for k in Ks]))
    with torch.no_grad():
        n = _tn(z, K, method=method, **options)
    assert n.shape == (len(depths), 3, *depths[0].shape) and n.dtype == torch.float32
    return n.permute(0, 2, 3, 1).numpy()


#: The module options both sides are given for a "+" method unless a test overrides them: the
#: torch path has the curvature selection only (the numba default is "auto", docs/torch.md),
#: and the two defaults of `consistency` differ (0.1 numba, 0.0 torch), so the margin is explicit.
SAME_MODULE = {"selection": "curvature", "consistency": 0.1}


def assert_parity(depths, Ks, method, **options):
    """The acceptance test: same NaN pattern, mean and 99.9th percentile of the angle."""
    if method.endswith("+"):
        options = {**SAME_MODULE, **options}
    a = _batch_numba(depths, Ks, method, **options)
    b = _batch_torch(depths, Ks, method, **options)
    na, nb = np.isnan(a).any(-1), np.isnan(b).any(-1)
    assert (na == nb).all(), f"{method} {options}: NaN patterns differ at {int((na != nb).sum())} pixels"
    assert (np.isnan(a).any(-1) == np.isnan(a).all(-1)).all()
    assert (np.isnan(b).any(-1) == np.isnan(b).all(-1)).all()
    m = ~na
    # no folding: a normal perpendicular to its ray (3F2N's median beside the torus knot's
    # silhouette) takes the same side in both (kernels.orient.TIE_COS; session 34)
    err = dn.angular_error(a[m][None], b[m][None])[0]
    mean, p999 = float(err.mean()), float(np.percentile(err, 99.9))
    assert mean <= 0.01 and p999 <= 0.1, f"{method} {options}: mean {mean:.2e}, p99.9 {p999:.2e} deg"
    return mean, p999


@pytest.fixture(scope="module")
def torus_batch(torusknot):
    """Four 480x640 frames: the torus knot, mirrored left-right and up-down (intrinsics
    mirrored with it), and at twice the depth; one camera matrix per frame."""
    z = torusknot.depth.astype(np.float32)
    cam = dn.as_intrinsics(torusknot.K)
    h, w = z.shape
    depths = [z, np.ascontiguousarray(z[:, ::-1]), np.ascontiguousarray(z[::-1]), z * np.float32(2.0)]
    Ks = [cam, (cam.fx, cam.fy, w - 1 - cam.cx, cam.cy), (cam.fx, cam.fy, cam.cx, h - 1 - cam.cy), cam]
    return depths, Ks


@pytest.mark.parametrize("method", DEFAULT_METHODS)
def test_parity_torusknot(torus_batch, method):
    assert_parity(*torus_batch, method)


@pytest.fixture(scope="module")
def analytic_batch():
    """The analytic scenes at 120x160 (depth 0 where a ray misses), float32."""
    K = (105.0, 105.0, 79.5, 59.5)
    depths = [make_scene(n).render(K=K, shape=(120, 160)).depth.astype(np.float32)
              for n in scene_names()]
    return depths, [K] * len(depths)


@pytest.mark.parametrize("method", DEFAULT_METHODS)
def test_parity_analytic(analytic_batch, method):
    assert_parity(*analytic_batch, method)


@pytest.fixture(scope="module")
def noisy_batch(rough_sphere):
    """Four noisy sphere-before-wall frames (120x160) with 3 % random holes and a 7x10 hole."""
    depths = [rough_sphere(seed, 0.005).astype(np.float32) for seed in range(4)]
    return depths, [ROUGH_K] * 4


@pytest.mark.parametrize("method", DEFAULT_METHODS)
def test_parity_noisy(noisy_batch, method):
    assert_parity(*noisy_batch, method)


THREEFN_OPTIONS = (
    [{"kernel": k, "aggregate": a} for k in ("fd", "sobel", "scharr", "prewitt", "roberts")
     for a in ("median", "mean", "trimean", "trimmed-mean")]
    + [{"kernel": "roberts", "kernel_size": 5}]
    + [{"kernel": k, "kernel_size": s} for k in ("fd", "sobel", "scharr", "prewitt") for s in (5, 7, 9, 11)]
)


@pytest.mark.parametrize("options", THREEFN_OPTIONS, ids=lambda o: "-".join(map(str, o.values())))
def test_parity_3f2n_options(noisy_batch, options):
    assert_parity(noisy_batch[0][:2], noisy_batch[1][:2], "3f2n", **options)


@pytest.mark.parametrize("options", [{"kernel": "roberts"}, {"kernel": "sobel", "aggregate": "trimean"},
                                     {"kernel": "scharr", "kernel_size": 7, "aggregate": "trimmed-mean"}],
                         ids=lambda o: "-".join(map(str, o.values())))
def test_parity_torusknot_options(torusknot, options):
    """Kernels and aggregates on the torus knot (beside its silhouette, Roberts' median gives
    normals perpendicular to the viewing ray: both sides take the orientation's tie rule)."""
    assert_parity([torusknot.depth.astype(np.float32)], [torusknot.K], "3f2n", **options)


@pytest.mark.parametrize("variant", ["basic", "dag", "mnr"])
def test_parity_d2nt_variants(noisy_batch, variant):
    assert_parity(*noisy_batch, "d2nt", variant=variant)


MODULE_OPTIONS = [
    {"curvature": "max"}, {"curvature": "normal"}, {"curvature": "gauss"},
    {"curvature": "pixel-mean"}, {"curvature": "none"}, {"footprint": "neighbours"},
    {"footprint": "neighbours", "curvature": "max"}, {"slope": "central"}, {"derivatives": "depth"},
    {"neighbourhood": "square"}, {"self_weight": 1.0, "consistency": None}, {"consistency": 0.5},
    {"consistency": 0.0},
    {"correlation": "kendall"}, {"correlation": "kendall-prose"},
    {"correlation": "kendall", "neighbourhood": "square"},
    {"correlation": "kendall", "crf": True}, {"crf": True}, {"correlation": "kendall-prose", "crf": True},
    {"correlation": "pearson", "crf": True},
    {"correlation": "kendall", "crf": True, "neighbourhood": "square"},
    {"correlation": "kendall", "crf": True, "crf_iterations": 3}, {"crf": True, "lambda_": 0.5, "sigma": 0.5},
    {"aggregate": "mean"}, {"kernel": "sobel"},
]


@pytest.mark.parametrize("method", ["3f2n", "d2nt"])
def test_parity_float32_quantised_kinect_depth(shared_data, method):
    """Real Kinect v1 depth in float32 (the dtype sensors are read in), the plain estimators.
    Quantised depth makes exact ties: D2NT's copy refinement (variant ``mnr``, the default)
    takes the neighbour of least |Laplacian|, which the torch backend summed in float32 and
    broke ties otherwise (2446 of 307,200 pixels over 10 deg off the numba library's, mean
    0.77 deg); 3F2N's median of two candidates symmetric about the pixel gives normals
    perpendicular to the ray, which took opposite sides (617 pixels 180 deg apart). Session
    34: the Laplacian in float64 and the orientation's tie rule (kernels.orient.TIE_COS)."""
    frame = next(f for f in dn.datasets.open(shared_data / "real-sensors")
                 if f.group.startswith("nyu_raw"))
    assert_parity([np.asarray(frame.depth, dtype=np.float32)], [frame.K], method)


@pytest.mark.parametrize("options", MODULE_OPTIONS, ids=lambda o: "-".join(f"{k}={v}" for k, v in o.items()))
def test_parity_module_options(noisy_batch, options):
    assert_parity(noisy_batch[0][:2], noisy_batch[1][:2], "3f2n+", **options)


@pytest.mark.parametrize("method", ["d2nt+", "sne-roadseg+"])
def test_parity_other_plus(noisy_batch, method):
    assert_parity(noisy_batch[0][:2], noisy_batch[1][:2], method, correlation="kendall", crf=True)


def test_parity_padded_batch(torusknot):
    """Frames of different sizes padded with invalid depth (0) into one batch: every frame's
    normals inside its own size equal those of the frame alone (padding is just a hole)."""
    z = torusknot.depth.astype(np.float32)
    K = dn.as_intrinsics(torusknot.K)
    crops = [z[:200, :300], z[100:340, 200:520], z[50:250, 150:400], z[:240, :320]]
    offs = [(0, 0), (100, 200), (50, 150), (0, 0)]
    h = max(c.shape[0] for c in crops)
    w = max(c.shape[1] for c in crops)
    padded = np.zeros((4, h, w), np.float32)
    for i, c in enumerate(crops):
        padded[i, :c.shape[0], :c.shape[1]] = c
    Ks = torch.tensor([[K.fx, K.fy, K.cx - ou, K.cy - ov] for ov, ou in offs])
    with torch.no_grad():
        n = _tn(torch.from_numpy(padded), Ks, method="3f2n+",
                                **SAME_MODULE).permute(0, 2, 3, 1).numpy()
    for i, (c, (ov, ou)) in enumerate(zip(crops, offs, strict=False)):
        ref = dn.estimate_normals(c, (K.fx, K.fy, K.cx - ou, K.cy - ov), method="3f2n+", **SAME_MODULE)
        got = n[i, :c.shape[0], :c.shape[1]]
        # the padding is invalid depth: the last row / column sees a hole instead of the
        # image border, which both treat alike
        assert (np.isnan(ref) == np.isnan(got)).all()
        m = ~np.isnan(ref).any(-1)
        err = dn.angular_error(ref[m][None], got[m][None])[0]
        assert err.mean() <= 0.01 and np.percentile(err, 99.9) <= 0.1
        assert np.isnan(n[i, c.shape[0]:]).all() and np.isnan(n[i, :, c.shape[1]:]).all()
