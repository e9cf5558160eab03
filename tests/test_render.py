"""The z-buffer renderer against closed-form geometry."""

from __future__ import annotations

import numpy as np
import pytest

from depthnormals.camera import Intrinsics
from depthnormals.render import KINECT_V2, look_at, render_mesh, render_subsamples
from depthnormals.synth.meshes import box, icosphere

K = Intrinsics(120.0, 110.0, 63.5, 47.5)
W, H = 128, 96


def _rays(cam=K, w=W, h=H):
    u = (np.arange(w) - cam.cx) / cam.fx
    v = (np.arange(h) - cam.cy) / cam.fy
    return np.stack(np.broadcast_arrays(u[None, :], v[:, None], np.ones((h, w))), axis=-1)


def _plane_quad(n, d, half=50.0):
    """A large square on the plane n . X = d (camera frame), as 2 triangles."""
    n = np.asarray(n, float) / np.linalg.norm(n)
    a = np.cross(n, [0.3, 1.0, 0.2])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    c = n * d
    V = np.array([c - half * a - half * b, c + half * a - half * b, c + half * a + half * b,
                  c - half * a + half * b])
    return V, np.array([[0, 1, 2], [0, 2, 3]])


@pytest.mark.parametrize("n", [(0.3, -0.4, -1.0), (0.8, 0.1, -0.6), (-0.2, 0.7, -0.7), (0, 0, -1)])
@pytest.mark.parametrize("d", [-0.7, -3.3])
def test_tilted_plane_depth_exact(n, d):
    V, F = _plane_quad(n, d)
    r = render_mesh(V, F, K, width=W, height=H)
    n = np.asarray(n, float) / np.linalg.norm(n)
    z = d / (_rays() @ n)
    hit = r.face >= 0
    assert hit.mean() > 0.95
    rel = np.abs(r.depth[hit] - z[hit]) / z[hit]
    assert rel.max() < 1e-9
    # the normal faces the camera (n . X = d < 0) and equals the plane normal
    assert np.allclose(r.normals[hit], n, atol=1e-12)
    assert np.all(np.isnan(r.normals[~hit]))


def test_sphere_within_tessellation_bound():
    R, c = 0.5, np.array([0.1, -0.05, 2.0])
    V, F = icosphere(c, R, level=5)
    r = render_mesh(V, F, K, width=W, height=H)
    hit = r.face >= 0
    assert hit.sum() > 1000
    X = _rays()[hit] * r.depth[hit][:, None]
    dist = np.linalg.norm(X - c, axis=1)
    # every face plane lies between the inscribed distance and R
    tri = V[F]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    inner = np.min(np.abs(np.einsum("ij,ij->i", fn, tri[:, 0] - c)))
    assert inner > R * (1 - 1e-3)  # level 5: sagitta < 0.1 % of R
    assert dist.min() >= inner - 1e-12 and dist.max() <= R + 1e-12
    # depth against the exact sphere: never nearer, and no farther than the bound allows
    rays = _rays()[hit]
    a = np.einsum("ij,ij->i", rays, rays)
    bq = -2 * rays @ c
    disc = bq ** 2 - 4 * a * (c @ c - R ** 2)
    ok = disc > 0
    z_sphere = (-bq[ok] - np.sqrt(disc[ok])) / (2 * a[ok])
    dz = r.depth[hit][ok] - z_sphere
    assert dz.min() > -1e-12
    # the GT normal is within the face's angular circumradius of the smooth sphere normal
    ns = (X[ok] - c) / R
    ns /= np.linalg.norm(ns, axis=1, keepdims=True)  # outward: toward the camera on the visible side
    ang = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", r.normals[hit][ok], ns), -1, 1)))
    assert ang.max() <= np.degrees(np.arccos(inner / R)) + 1e-9
    assert np.median(ang) < 0.6
    assert np.all(np.einsum("ij,ij->i", r.normals[hit], X) < 0)


def test_camera_inside_room_near_clipping():
    room = box((-3, -3, -1.5), (3, 3, 1.5))  # camera at the origin, inside
    r = render_mesh(*room, K, width=W, height=H, near=0.05)
    assert np.all(r.face >= 0)
    assert r.depth.min() >= 0.05
    # the facing wall at z = 1.5: exact everywhere it is seen
    front = np.isin(r.face, (2, 3))  # faces 2, 3 of box(): the z = hi side
    assert front.sum() > 100 and np.all(r.depth[front] == 1.5)
    # a floor that passes under and behind the camera is clipped, not dropped
    V = np.array([[-5, 1.0, -5], [5, 1.0, -5], [5, 1.0, 10], [-5, 1.0, 10]])
    r2 = render_mesh(V, [[0, 1, 2], [0, 2, 3]], K, width=W, height=H)
    rows = np.arange(H)
    below = rows > K.cy + 1
    z_exact = 1.0 * K.fy / (rows[below] - K.cy)
    col = r2.depth[below, W // 2]
    seen = col > 0
    assert seen.sum() > 20
    assert np.allclose(col[seen], z_exact[seen], rtol=1e-12)


def test_pose_equals_pretransformed_vertices():
    V, F = box((-0.5, 2.0, -0.3), (0.4, 2.8, 0.6))
    T = look_at((0.3, -0.2, 0.1), (0.0, 2.4, 0.1))
    r_world = render_mesh(V, F, K, pose=T, width=W, height=H)
    Vc = (V - T[:3, 3]) @ T[:3, :3]
    r_cam = render_mesh(Vc, F, K, width=W, height=H)
    assert np.array_equal(r_world.face, r_cam.face)
    assert np.allclose(r_world.depth, r_cam.depth, rtol=1e-12, atol=0)


def test_subsamples_centre_is_the_pixel():
    V, F = icosphere((0, 0, 2.5), 0.6, level=3)
    r = render_mesh(V, F, K, width=W, height=H)
    ss = render_subsamples(V, F, K, width=W, height=H, factor=3)
    assert ss.shape == (H, W, 9)
    assert np.array_equal(ss[..., 4], r.depth)
    # off-centre sub-samples differ somewhere (the silhouette moves)
    assert np.count_nonzero((ss[..., 0] > 0) != (r.depth > 0)) > 5
    mask = np.zeros((H, W), bool)
    mask[10:20, 30:40] = True
    part = render_subsamples(V, F, K, width=W, height=H, mask=mask)
    assert np.all(np.isnan(part[~mask]))
    assert np.array_equal(part[mask], ss[mask])


def test_default_camera_is_kinect_v2():
    V, F = _plane_quad((0, 0, -1), -2.0)
    r = render_mesh(V, F)
    assert r.depth.shape == (424, 512) and r.K == KINECT_V2
    assert np.allclose(r.depth, 2.0, rtol=1e-15)


def test_nearest_surface_wins_and_ties_are_deterministic():
    front = _plane_quad((0, 0, -1), -1.0, half=0.2)
    back = _plane_quad((0, 0, -1), -2.0)
    V = np.concatenate([back[0], front[0]])
    F = np.concatenate([back[1], front[1] + 4])
    r = render_mesh(V, F, K, width=W, height=H)
    assert r.depth[H // 2, W // 2] == 1.0 and r.face[H // 2, W // 2] in (2, 3)
    assert r.depth[0, 0] == 2.0 and r.face[0, 0] in (0, 1)


@pytest.mark.parametrize(("V", "F", "err"), [
    (np.zeros((3, 3)), np.zeros((0, 3), int), "empty"),
    (np.zeros((3, 3)), np.array([[0, 1, 5]]), "index"),
    (np.zeros((3, 2)), np.array([[0, 1, 2]]), "vertices"),
    (np.zeros((3, 3)), np.array([[0.0, 1, 2]]), "integer"),
])
def test_bad_mesh(V, F, err):
    with pytest.raises(ValueError, match=err):
        render_mesh(V, F, K)


def test_bad_pose_and_size():
    V, F = box((0, 0, 1), (1, 1, 2))
    with pytest.raises(ValueError, match="rotation"):
        render_mesh(V, F, K, pose=np.diag([2.0, 1, 1, 1]))
    with pytest.raises(ValueError, match="width"):
        render_mesh(V, F, K, width=0)
    with pytest.raises(ValueError, match="near"):
        render_mesh(V, F, K, near=-1.0)
