"""The bend of a surface at the scale of tens of pixels (:mod:`depthnormals.ddm.bend`), which
the measured support's expected-error map adds in quadrature."""

from __future__ import annotations

import math

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.ddm import bend

H, W, F = 160, 240, 200.0
CAM = (F, F, (W - 1) / 2, (H - 1) / 2)


def _bowed_wall(c: float, z0: float = 2.0):
    """A wall facing the camera ``z0`` away, bowed as ``z = z0 + c X^2``: the planar depth of
    every pixel's ray (the quadratic's root) and the exact normals, facing the camera."""
    a = (np.arange(W) - CAM[2]) / F  # X / z along each column
    if c == 0.0:
        z1 = np.full(W, z0)
    else:  # c a^2 z^2 - z + z0 = 0, the root near z0
        z1 = (1.0 - np.sqrt(1.0 - 4.0 * c * a * a * z0)) / (2.0 * c * a * a + 1e-300)
        z1 = np.where(np.abs(a) < 1e-12, z0, z1)
    z = np.repeat(z1[None, :], H, 0)
    X = a[None, :] * z
    n = np.stack([2.0 * c * X, np.zeros_like(X), -np.ones_like(X)], -1)
    return z, n / np.linalg.norm(n, axis=-1, keepdims=True)


def _angle(a, b):
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(np.dot(a, b))))


def test_a_flat_plane_does_not_bend():
    from depthnormals.analytic import tilted_plane

    r = tilted_plane((0.2, -0.5, -0.8), 2.0).render(K=CAM, shape=(H, W))
    z = np.where(r.depth > 0, r.depth, np.nan)
    g = bend.bend_grid(r.normals, z, CAM)
    assert g.shape == (-(-H // bend.STEP), -(-W // bend.STEP))
    assert np.nanmax(g) < 1e-4


def test_a_bowed_wall_reads_its_bend_and_twice_the_bow_twice_the_bend():
    """Along a row of a wall bowed by ``c X^2`` the mean normal of a box is the centre's (the
    normal turns linearly), so a cell reads the angle to its neighbours ``SPAN`` cells to the
    left and right, and 0 to those above and below: a quarter of the sum of the two."""
    out = []
    for c in (0.02, 0.04):
        z, n = _bowed_wall(c)
        g = bend.bend_grid(n, z, CAM)
        i, j = 10, 15  # pixel (80, 120), the middle; neighbours 48 px each way, all inside
        s = bend.SPAN * bend.STEP
        u = j * bend.STEP
        want = (_angle(n[80, u], n[80, u + s]) + _angle(n[80, u], n[80, u - s])) / 4.0
        assert want > 0.5
        assert g[i, j] == pytest.approx(want, rel=0.05), (c, g[i, j], want)
        out.append(g[i, j])
    assert out[1] / out[0] == pytest.approx(2.0, rel=0.05)


def test_no_bend_is_read_across_a_crease():
    """Two faces meeting at a vertical crease 50 deg apart: a cell and its neighbour across
    the crease do not lie on one near-plane (the chord leaves both mean tangent planes), so
    the cells whose boxes hold one face only read no bend at all."""
    u = np.arange(W) - CAM[2]
    a = u / F
    # left face z = 2 (normal (0, 0, -1)); right face through the crease at u = 0, turned
    t = math.tan(math.radians(50.0))
    z = np.where(a <= 0, 2.0, 2.0 / (1.0 + t * a))
    z = np.repeat(z[None, :], H, 0).astype(np.float64)
    nr = np.array([-math.sin(math.radians(50.0)), 0.0, -math.cos(math.radians(50.0))])
    n = np.where((a <= 0)[None, :, None], np.array([0.0, 0.0, -1.0]), nr) * np.ones((H, 1, 1))
    # (the right face: X = a z, z (1 + t a) = 2, so its points satisfy z + t X = 2)
    X = np.stack([a[None, :] * z, np.zeros_like(z), z], -1)
    assert np.allclose((X[:, a > 0] * nr).sum(-1), -2.0 * math.cos(math.radians(50.0)))
    g = bend.bend_grid(n, z, CAM)
    crease_cell = int(CAM[2]) // bend.STEP
    far = np.r_[0:crease_cell - bend.BOX - 1, crease_cell + bend.BOX + 2:g.shape[1]]
    assert np.abs(g[:, far]).max() < 1e-4


def test_invalid_depth_reads_no_bend_and_a_small_image_works():
    z, n = _bowed_wall(0.03)
    z = z.copy()
    z[:, 100:140] = np.nan
    n = n.copy()
    n[:, 100:140] = np.nan
    g = bend.bend_grid(n, z, CAM)
    assert np.isfinite(g).all()
    assert (g[:, 13:18] == 0).all() and (g[1:-1, 1:5] > 0).all()  # cells 13-17: pixels 104-136
    tiny = bend.bend_grid(n[:3, :10], z[:3, :10], CAM)
    assert tiny.shape == (1, 2) and (tiny == 0).all()


@pytest.mark.parametrize("step", [4, 8])
def test_bend_row_reads_the_nearest_cell(step):
    """``bend_term`` / ``bend_row``: each point of a row of a map's grid reads the bend cell
    nearest to it (cells every ``step`` points), scaled and squared; the rows and columns past
    the grid read its last."""
    grid = np.arange(4 * 5, dtype=np.float64).reshape(4, 5)
    w = 45
    b = bend.bend_term(grid, step, 0.5, w)
    out = np.empty(w, np.float32)
    sq = np.empty(5, np.float32)
    for v in range(40):
        bend.bend_row(b, v, sq, out)
        for u in range(w):
            want = grid[min((v + step // 2) // step, 3), min((u + step // 2) // step, 4)]
            assert out[u] == np.float32(0.5 * want) ** 2, (v, u)


def test_the_support_rows_add_the_bend_in_quadrature_keep_nan_and_cap():
    """The measured support's product (``_support_rows``): the map it would write without the
    term, then ``sqrt(x^2 + (share b)^2)`` at most ``MAX_ERROR``; NaN stays NaN."""
    from depthnormals.ddm import uncertainty as U

    rng = np.random.default_rng(0)
    h, w = 6, 40
    z = np.full((h, w), 2.0, np.float32)
    n = np.zeros((h, w, 3), np.float32)
    n[..., 2] = -1.0
    n[2, 5] = np.nan
    s1 = (3.0 * rng.random((h, w))).astype(np.float32)
    far = (3.0 * rng.random((1, h, w))).astype(np.float32)
    sub = np.zeros((2, (h + 1) // 2, (w + 1) // 2), np.float32)
    offs = np.zeros((2, h, w), np.float32)
    ctx = (s1, far, sub, 0, offs, (1.0, 1.0), np.zeros((h, w), np.float32), 5.0)
    grid = 10.0 * rng.random((2, 5))
    grid[0, 0] = 500.0

    by_row = np.ascontiguousarray(n.transpose(0, 2, 1))  # (H, 3, W), as the branch hands it

    def run(b):
        out = np.empty((h, w), np.float32)
        for v0, v1 in ((0, 4), (4, h)):
            U._support_rows(v0, v1, z, by_row, (1.0, 2.0, 0), ctx, b, out)
        return out

    without = run(bend.bend_term(np.zeros((1, 1)), 8, 0.0, w))
    with_ = run(bend.bend_term(grid, 8, 0.6, w))
    b = grid[np.minimum((np.arange(h) + 4) // 8, 1)][:, np.minimum((np.arange(w) + 4) // 8, 4)]
    want = np.minimum(np.sqrt(without.astype(np.float64) ** 2 + (0.6 * b) ** 2), U.MAX_ERROR)
    np.testing.assert_allclose(with_, want, rtol=2e-6)
    assert np.isnan(with_[2, 5]) and np.isnan(without[2, 5])
    assert with_[0, 0] == np.float32(U.MAX_ERROR) and without[0, 0] < 10.0
    ok = np.isfinite(without)
    ok[0, 0] = False
    assert (with_[ok] > without[ok]).all()


def test_the_measured_support_map_adds_the_bend(monkeypatch):
    """On Kinect-like depth of a bowed wall (the measured-support branch) the map reads the
    wall's bend (over 0.5 deg at the median) and rises with it over the map without the term
    (the bend grid all 0), the normals and the NaN pattern unchanged."""
    from depthnormals.ddm import uncertainty
    from depthnormals.synth.noise import kinect_v1_noise

    z, n = _bowed_wall(0.04)
    d = np.asarray(kinect_v1_noise(z, n, CAM, rng=np.random.default_rng(0)), np.float32)
    assert dn.noise_profile(d, CAM).branch == "measured-support"
    seen = {}
    orig = uncertainty.bend_grid_by_rows

    def spy(*a, **k):
        seen["grid"] = orig(*a, **k)
        return seen["grid"]

    monkeypatch.setattr(uncertainty, "bend_grid_by_rows", spy)
    n1, u1 = dn.estimate_normals(d, CAM, return_uncertainty=True)
    monkeypatch.setattr(uncertainty, "bend_grid_by_rows", lambda *a, **k: np.zeros((1, 1)))
    n0, u0 = dn.estimate_normals(d, CAM, return_uncertainty=True)
    assert np.array_equal(n0, n1, equal_nan=True)
    g = seen["grid"]
    assert g.shape == (-(-H // bend.STEP), -(-W // bend.STEP))
    b = g[np.minimum((np.arange(H) + 4) // 8, g.shape[0] - 1)][:, np.minimum((np.arange(W) + 4) // 8,
                                                                             g.shape[1] - 1)]
    assert np.median(b[np.isfinite(u1)]) > 0.5
    ok = np.isfinite(u1)
    assert (u1[ok] >= u0[ok]).all() and np.median(u1[ok] - u0[ok]) > 0.05
    assert np.array_equal(np.isnan(u1), np.isnan(u0))
