"""Conventions of depthnormals.torch, pinned, with kornia's reading rejected.

OpenCV frame (x right, y down, z forward), (B, 3, H, W) layout, unit normals facing the camera
(``dot(n, X) < 0``): a fronto-parallel wall gives (0, 0, -1), not kornia's (0, 0, +1).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch  # not importorskip: CI installs the torch extra and no torch test may be skipped

import depthnormals as dn
import depthnormals.torch as dt
from depthnormals.analytic import planar_interior, tilted_plane


def _tn(*args, **kwargs):
    """The torch implementation itself (a CPU tensor without gradients would otherwise be
    computed by the numba library: ``backend="auto"``)."""
    return dt.estimate_normals(*args, backend="torch", **kwargs)

K = (60.0, 60.0, 39.5, 29.5)


@pytest.mark.parametrize("method", dt.METHODS)
def test_fronto_parallel_wall(method):
    n = _tn(torch.full((2, 1, 7, 9), 3.0), (50.0, 50.0, 4.0, 3.0), method=method)
    expected = torch.tensor([0.0, 0.0, -1.0]).reshape(1, 3, 1, 1).expand_as(n)
    torch.testing.assert_close(n, expected)
    assert (n[:, 2] < 0).all()  # kornia's depth_to_normals gives (0, 0, +1) here


@pytest.mark.parametrize("method", dt.METHODS)
def test_tilted_plane_exact(method):
    """The analytic tilted plane (normal (0.3, -0.4, -1) normalised): 3F2N and SNE-RoadSeg are
    exact on planes (inverse depth is linear), D2NT's depth differences within 0.2 deg."""
    r = tilted_plane().render(K=K, shape=(60, 80))
    n = _tn(torch.from_numpy(r.depth)[None], K, method=method)
    assert n.dtype == torch.float64
    got = n[0].permute(1, 2, 0).numpy()
    err = dn.angular_error(got, r.normals)
    tol = 0.2 if method.startswith("d2nt") else 1e-8
    assert np.nanmax(err) < tol
    want = np.array([0.3, -0.4, -1.0]) / np.linalg.norm([0.3, -0.4, -1.0])
    np.testing.assert_allclose(got[30, 40], want, atol=1e-4 if method.startswith("d2nt") else 1e-10)


@pytest.mark.parametrize("method", dt.METHODS)
def test_axes_and_facing(method, rough_sphere):
    """Depth growing to the right (u) tilts the camera-facing normal toward +x (the left wall
    of a corridor faces +x), growing downward (v) toward +y (a ceiling faces +y, down); kornia,
    whose normals point away, documents -x and -y for the same surfaces. Every finite normal
    is unit and faces the camera."""
    v, u = torch.meshgrid(torch.arange(30.0), torch.arange(40.0), indexing="ij")
    right = _tn((2.0 + 0.02 * u)[None], K, method=method)[0, :, 15, 20]
    down = _tn((2.0 + 0.02 * v)[None], K, method=method)[0, :, 15, 20]
    assert right[0] > 0.1 and abs(right[1]) < 1e-3 and right[2] < 0
    assert down[1] > 0.1 and abs(down[0]) < 1e-3 and down[2] < 0
    z = torch.from_numpy(rough_sphere(4, 0.004).astype(np.float32))[None]
    n = _tn(z, (131.25, 131.25, 79.5, 59.5), method=method)[0]
    ok = torch.isfinite(n[0])
    uu = (torch.arange(160.0) - 79.5) / 131.25
    vv = (torch.arange(120.0)[:, None] - 59.5) / 131.25
    dot = n[0] * uu + n[1] * vv + n[2]
    # (perpendicular to the ray, within float32's rounding of the tie rule, n_z < 0 decides)
    tie = dot.abs() <= 2e-6 * torch.sqrt(uu * uu + vv * vv + 1.0)
    assert ((dot < 0) | (tie & (n[2] < 0)))[ok].all()
    torch.testing.assert_close(n.norm(dim=0)[ok], torch.ones(int(ok.sum())), atol=1e-6, rtol=0)
    assert torch.equal(ok, torch.isfinite(n).all(0)) and not ok[~(z[0] > 0)].any()


def test_planar_interior_of_box_scene():
    """On the box-on-floor scene, 3F2N+ is exact wherever the 3x3 neighbourhood is one face."""
    from depthnormals.analytic import box_on_floor

    r = box_on_floor().render(K=K, shape=(60, 80))
    n = _tn(torch.from_numpy(r.depth)[None], K, method="3f2n+")[0].permute(1, 2, 0).numpy()
    m = planar_interior(r, radius=2)
    assert m.sum() > 1000
    assert dn.angular_error(n, r.normals)[m].max() < 1e-6


def test_sorting_network_sorts():
    """The 19-comparator network sorts every 0/1 input of 8 (the 0-1 principle)."""
    from depthnormals.torch._threefn import sort8

    bits = torch.tensor([[(i >> k) & 1 for k in range(8)] for i in range(256)], dtype=torch.float32)
    out = torch.stack(sort8(list(bits.T)), dim=1)
    torch.testing.assert_close(out, bits.sort(dim=1).values)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_normal_perpendicular_to_its_ray_as_numba(dtype):
    """A 3F2N normal exactly perpendicular to its ray (tests/test_conventions.py, the tie
    rule: n_z < 0) is the numba library's in torch too, not its opposite."""
    from conftest import TIE_K, tie_depth

    for v in range(2, 40):
        z = tie_depth(v)
        ref = dn.estimate_normals(z, TIE_K, method="3f2n")[v, 4]
        n = _tn(torch.from_numpy(z).to(dtype)[None], TIE_K, method="3f2n")
        np.testing.assert_allclose(n[0, :, v, 4].double().numpy(), ref, atol=1e-6)
