"""The comparison family on exact analytic scenes: accuracy, agreement and formula checks."""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import make_scene, planar_interior

FAMILY = ("sda-sne", "sne-roadseg", "fals", "sri", "line-mod", "plane-svd", "plane-pca",
          "vector-svd", "area-weighted", "angle-weighted")
SCENES = ("tilted-plane", "box-on-floor", "stairs", "sphere-before-wall")
SHAPE = (480, 640)  # the scenes' own camera: depth curvature per pixel as in real use
K = (525.0, 525.0, 319.5, 239.5)


@pytest.fixture(scope="module")
def renders():
    return {name: make_scene(name).render(K=K, shape=SHAPE) for name in SCENES}


@pytest.mark.parametrize("method", FAMILY)
@pytest.mark.parametrize("scene", SCENES)
def test_planar_interiors_under_005_deg(renders, method, scene):
    r = renders[scene]
    opts = {"threshold": 100.0} if method == "line-mod" else {}
    n = dn.estimate_normals(r.depth, r.K, method=method, **opts)
    assert n.dtype == np.float32 and n.shape == (*SHAPE, 3)
    m = planar_interior(r, 5 if method == "line-mod" else 3)
    assert m.sum() > 500
    err = dn.angular_error(n, r.normals)[m]  # not folded: orientation must be right too
    assert not np.isnan(err).any()
    assert err.mean() < 0.05
    assert np.isnan(n[r.depth == 0]).all()


def test_plane_svd_equals_plane_pca(renders):
    r = renders["sphere-before-wall"]
    a = dn.plane_svd(r.depth, r.K)
    b = dn.plane_pca(r.depth, r.K)
    ok = np.isfinite(a[..., 0])
    assert ok.sum() > 10000
    assert np.nanmax(dn.angular_error(a, b)[ok]) < 1e-3


def test_window_changes_the_fit_on_curved_surfaces(renders):
    r = renders["sphere-before-wall"]
    sphere = (~r.planar) & (r.depth > 0)
    e3 = dn.angular_error(dn.plane_pca(r.depth, r.K, window=3), r.normals)[sphere]
    e7 = dn.angular_error(dn.plane_pca(r.depth, r.K, window=7), r.normals)[sphere]
    assert np.nanmean(e7) > np.nanmean(e3)


def test_sne_roadseg_closed_form_matches_the_angle_formulas(renders):
    """theta = -atan((sum nx_i cos phi + sum ny_i sin phi) / sum nz_i), phi = atan(ny / nx)."""
    r = renders["sphere-before-wall"]
    ours = dn.sne_roadseg(r.depth, r.K)
    fx, fy, cx, cy = K
    z = r.depth
    checked = 0
    for v, u in [(160, 380), (220, 400), (250, 350), (190, 420)]:
        assert not r.planar[v, u]  # on the sphere: the nz_i differ
        D = 1.0 / z
        nx = fx * (D[v, u + 1] - D[v, u - 1]) / 2
        ny = fy * (D[v + 1, u] - D[v - 1, u]) / 2
        phi = np.arctan(ny / nx)
        q = np.array([(u - cx) * z[v, u] / fx, (v - cy) * z[v, u] / fy, z[v, u]])
        s = np.zeros(3)
        for dv in (-1, 0, 1):
            for du in (-1, 0, 1):
                if dv == du == 0:
                    continue
                zz = z[v + dv, u + du]
                p = np.array([(u + du - cx) * zz / fx, (v + dv - cy) * zz / fy, zz])
                d = q - p  # the public code's differences and sign of nz_i
                nz = (nx * d[0] + ny * d[1]) / d[2]
                c = np.array([nx, ny, nz])
                s += c / np.linalg.norm(c)
        theta = -np.arctan((s[0] * np.cos(phi) + s[1] * np.sin(phi)) / s[2])
        ref = np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
        err = dn.angular_error(ours[v, u][None, None], ref[None, None], folded=True)[0, 0]
        assert err < 1e-3
        checked += 1
    assert checked == 4


def test_line_mod_threshold_is_in_depth_units():
    # a step of 0.1 between two fronto-parallel planes: with threshold 0.05 the far plane's
    # samples are ignored and the near plane stays fronto-parallel; with 1.0 they are used
    z = np.full((40, 40), 2.0)
    z[:, 20:] = 2.1
    k = (100.0, 100.0, 19.5, 19.5)
    strict = dn.line_mod(z, k, threshold=0.05)
    loose = dn.line_mod(z, k, threshold=1.0)
    front = np.float32([[[0, 0, -1]]])
    assert dn.angular_error(strict[20:21, 17:18], front)[0, 0] < 1e-4
    assert dn.angular_error(loose[20:21, 17:18], front)[0, 0] > 1.0
