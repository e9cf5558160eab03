"""depthnormals.compat: each drop-in pinned against the original's conventions, on a plane and a box.

kornia is installed: compared directly with ``kornia.geometry.depth.depth_to_normals``. gsplat
and FFB6D's normalSpeed are not: compared with a short reimplementation of their formulas
(``_gsplat_reference``: gsplat/utils.py ``depth_to_points`` + ``depth_to_normal``;
``_normalspeed_reference``: normalSpeed/normal.cpp ``depthNormals``), written from their
sources (2DGS's ``point_utils.depth_to_normal`` too: ``_twodgs_reference``, through the mapping
that docs/torch.md gives). Each test also rejects the opposite orientation.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch  # not importorskip: CI installs the torch extra and no torch test may be skipped

import depthnormals as dn
from depthnormals.analytic import make_scene, planar_interior, tilted_plane
from depthnormals.compat import depth_normal, depth_to_normals, gsplat_depth_to_normal

torch.set_num_threads(1)

K4 = (131.25, 131.25, 79.5, 59.5)
SHAPE = (120, 160)


def _matrix(fx, fy, cx, cy, dtype=torch.float64):
    return torch.tensor([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=dtype)


def _angle(a, b):
    """Angle in degrees between (..., 3) arrays of unit vectors (NaN where either is 0)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    cos = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _rotation(rx, ry, rz):
    c, s = np.cos, np.sin
    X = np.array([[1, 0, 0], [0, c(rx), -s(rx)], [0, s(rx), c(rx)]])
    Y = np.array([[c(ry), 0, s(ry)], [0, 1, 0], [-s(ry), 0, c(ry)]])
    Z = np.array([[c(rz), -s(rz), 0], [s(rz), c(rz), 0], [0, 0, 1]])
    return Z @ Y @ X


def test_import_compat_does_not_import_torch():
    code = "import sys, depthnormals.compat; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# ----------------------------------------------------------------------------------- kornia
kornia_depth = pytest.importorskip("kornia.geometry.depth")


@pytest.fixture(scope="module")
def plane_and_box():
    plane = tilted_plane().render(K=K4, shape=SHAPE)
    box = make_scene("box-on-floor").render(K=K4, shape=SHAPE)
    return plane, box


@pytest.mark.parametrize("scene", ["plane", "box"])
def test_kornia_same_normals_on_planes(plane_and_box, scene):
    """On plane faces (3x3 neighbourhood on one face) kornia's Sobel cross product is exact
    (its chords lie in the plane), and so is 3F2N+: the two agree to 1e-4 deg, with kornia's
    orientation (away from the camera: the negated ground truth), also on the image border
    of the plane."""
    r = plane_and_box[0 if scene == "plane" else 1]
    depth = torch.from_numpy(r.depth)[None, None]
    K = _matrix(*K4)[None]
    ours = depth_to_normals(depth, K)[0].permute(1, 2, 0).numpy()
    theirs = kornia_depth.depth_to_normals(depth, K)[0].permute(1, 2, 0).numpy()
    inner = planar_interior(r, 1)
    assert inner.sum() > 0.5 * inner.size if scene == "plane" else inner.sum() > 1000
    assert np.max(_angle(ours[inner], theirs[inner])) < 1e-4  # exact, float64
    assert np.max(_angle(ours[inner], -r.normals[inner])) < 1e-4  # away from the camera
    assert np.min(_angle(ours[inner], r.normals[inner])) > 179.9  # not ours (facing)
    if scene == "plane":  # the border too: both exact on a plane
        assert np.max(_angle(ours, theirs)) < 1e-4


def test_kornia_wall_sign_and_hole():
    """A fronto-parallel wall gives (0, 0, +1) in both; a zero-depth hole gives the zero
    vector here (kornia: finite, wrong normals over the hole's 3x3 neighbourhood), and its
    neighbours keep the wall's normal."""
    depth = torch.full((1, 1, 7, 9), 2.0)
    K = _matrix(50.0, 50.0, 4.0, 3.0, torch.float32)[None]
    want = torch.tensor([0.0, 0.0, 1.0]).reshape(1, 3, 1, 1).expand(1, 3, 7, 9)
    torch.testing.assert_close(depth_to_normals(depth, K), want)
    torch.testing.assert_close(kornia_depth.depth_to_normals(depth, K), want)
    depth[0, 0, 3, 4] = 0.0
    n = depth_to_normals(depth, K)
    assert torch.isfinite(n).all()
    assert n[0, :, 3, 4].tolist() == [0.0, 0.0, 0.0]
    keep = torch.ones(7, 9, dtype=torch.bool)
    keep[3, 4] = False
    torch.testing.assert_close(n[0][:, keep], want[0][:, keep])
    k = kornia_depth.depth_to_normals(depth, K)
    assert torch.isfinite(k).all() and (k[0, 2, 3, 3] < 0.5)  # kornia's neighbour is wrong


def test_kornia_normalize_points_reads_ray_length(plane_and_box):
    """``normalize_points=True``: depth is the Euclidean distance along the ray, as in kornia."""
    r = plane_and_box[0]
    fx, fy, cx, cy = K4
    h, w = SHAPE
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    ray = np.sqrt(((u - cx) / fx) ** 2 + ((v - cy) / fy) ** 2 + 1.0)
    dist = torch.from_numpy(r.depth * ray)[None, None]
    K = _matrix(*K4)[None]
    ours = depth_to_normals(dist, K, normalize_points=True)
    theirs = kornia_depth.depth_to_normals(dist, K, normalize_points=True)
    planar = depth_to_normals(torch.from_numpy(r.depth)[None, None], K)
    torch.testing.assert_close(ours, planar, atol=1e-9, rtol=0)
    assert np.max(_angle(ours[0].permute(1, 2, 0).numpy(), theirs[0].permute(1, 2, 0).numpy())) < 1e-4
    wrong = depth_to_normals(dist, K)  # the ray length read as z: a curved surface
    assert np.max(_angle(wrong[0].permute(1, 2, 0).numpy(), theirs[0].permute(1, 2, 0).numpy())) > 1.0


@pytest.mark.parametrize(("dd", "kd"), [(torch.float32, torch.float32), (torch.float32, torch.float64),
                                        (torch.float16, torch.float32), (torch.float64, torch.float64)])
def test_kornia_dtype_is_kornias(dd, kd):
    depth = torch.full((2, 1, 6, 8), 2.0, dtype=dd)
    K = _matrix(50.0, 50.0, 3.5, 2.5, kd)[None].expand(2, 3, 3)
    assert depth_to_normals(depth, K).dtype == kornia_depth.depth_to_normals(depth, K).dtype


def test_kornia_bad_input():
    K = _matrix(50.0, 50.0, 3.5, 2.5)
    with pytest.raises(ValueError, match=r"\(B, 1, H, W\)"):
        depth_to_normals(torch.ones(1, 6, 8), K[None])
    with pytest.raises(ValueError, match=r"\(B, 3, 3\)"):
        depth_to_normals(torch.ones(1, 1, 6, 8), K)
    with pytest.raises(ValueError, match=r"\(B, 3, 3\) with B = 2"):
        depth_to_normals(torch.ones(2, 1, 6, 8), K[None])
    with pytest.raises(ValueError, match="H >= 2"):
        depth_to_normals(torch.ones(1, 1, 1, 8), K[None])
    with pytest.raises(TypeError, match=r"torch\.Tensor"):
        depth_to_normals(np.ones((1, 1, 6, 8)), K[None])
    with pytest.raises(TypeError, match="normalize_points"):
        depth_to_normals(torch.ones(1, 1, 6, 8), K[None], normalize_points="yes")


# ----------------------------------------------------------------------------------- gsplat
def _gsplat_reference(depths, c2w, Ks, z_depth=True):
    """gsplat.utils.depth_to_normal (gsplat 1.x), for (..., H, W, 1) float64 numpy input:
    rays ((u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy, 1) rotated by c2w, points o + d * ray
    (the ray normalised when not z_depth); dx along the rows, dy along the columns;
    normalize(cross(dx, dy)); a one-pixel zero border."""
    h, w = depths.shape[-3:-1]
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    fx, fy = Ks[..., 0, 0, None, None], Ks[..., 1, 1, None, None]
    cx, cy = Ks[..., 0, 2, None, None], Ks[..., 1, 2, None, None]
    a, b = (u - cx + 0.5) / fx, (v - cy + 0.5) / fy
    dirs = np.stack(np.broadcast_arrays(a, b, np.ones_like(a)), axis=-1)
    dirs = np.einsum("...ij,...hwj->...hwi", c2w[..., :3, :3], dirs)
    if not z_depth:
        dirs = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    P = c2w[..., None, None, :3, 3] + depths * dirs
    dx = P[..., 2:, 1:-1, :] - P[..., :-2, 1:-1, :]
    dy = P[..., 1:-1, 2:, :] - P[..., 1:-1, :-2, :]
    n = np.cross(dx, dy)
    n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    pad = [(0, 0)] * (n.ndim - 3) + [(1, 1), (1, 1), (0, 0)]
    return np.pad(n, pad)


def _gsplat_inputs(r_list, rotations):
    """Depth (C, H, W, 1), camtoworlds (C, 4, 4) and Ks (C, 3, 3) for renders made with K4
    (integer pixel centres): gsplat's K has cx + 0.5, cy + 0.5 for the same rays."""
    fx, fy, cx, cy = K4
    depths = np.stack([r.depth for r in r_list])[..., None]
    c2w = np.stack([np.eye(4) for _ in r_list])
    for i, R in enumerate(rotations):
        c2w[i, :3, :3] = R
        c2w[i, :3, 3] = (1.0 + i, -2.0, 0.5)
    Ks = np.stack([_matrix(fx, fy, cx + 0.5, cy + 0.5).numpy() for _ in r_list])
    return depths, c2w, Ks


@pytest.mark.parametrize("scene", ["plane", "box"])
def test_gsplat_same_normals_as_its_formula(plane_and_box, scene):
    """Two cameras (leading dimension 2) with their own rotations: the world-frame normals of
    gsplat's formula (exact on plane faces: central chords in the plane), facing the camera
    (R @ the camera-facing ground truth), zero on the one-pixel border."""
    r = plane_and_box[0 if scene == "plane" else 1]
    Rs = [_rotation(0.3, -0.5, 0.2), _rotation(-1.0, 0.4, 2.5)]
    depths, c2w, Ks = _gsplat_inputs([r, r], Rs)
    ref = _gsplat_reference(depths, c2w, Ks)
    ours = gsplat_depth_to_normal(*(torch.from_numpy(x) for x in (depths, c2w, Ks))).numpy()
    assert ours.shape == (2, *SHAPE, 3) and ours.dtype == np.float64
    inner = planar_interior(r, 1)
    inner[0, :] = inner[-1, :] = inner[:, 0] = inner[:, -1] = False
    for i, R in enumerate(Rs):
        assert np.max(_angle(ours[i][inner], ref[i][inner])) < 1e-4  # half a pixel off: ~0.01 deg
        truth = r.normals[inner] @ R.T  # camera-facing, rotated to the world
        assert np.max(_angle(ours[i][inner], truth)) < 1e-4
        assert np.min(_angle(ours[i][inner], -truth)) > 179.9  # kornia's orientation rejected
        border = np.ones(SHAPE, bool)
        border[1:-1, 1:-1] = False
        assert not ours[i][border].any() and not ref[i][border].any()


def test_gsplat_ray_depth_shapes_and_border(plane_and_box):
    """``z_depth=False`` reads the distance along gsplat's ray; no leading dimension works
    (one camera); ``keep_border`` keeps our border estimates."""
    r = plane_and_box[0]
    depths, c2w, Ks = _gsplat_inputs([r], [_rotation(0.1, 0.2, 0.3)])
    d, c, k = (torch.from_numpy(x[0]) for x in (depths, c2w, Ks))
    fx, fy, cx, cy = K4
    u, v = np.meshgrid(np.arange(SHAPE[1]), np.arange(SHAPE[0]))
    ray = np.sqrt(((u - cx) / fx) ** 2 + ((v - cy) / fy) ** 2 + 1.0)[..., None]
    planar = gsplat_depth_to_normal(d, c, k)
    assert planar.shape == (*SHAPE, 3)
    dist = gsplat_depth_to_normal(d * torch.from_numpy(ray), c, k, False)
    torch.testing.assert_close(dist, planar, atol=1e-9, rtol=0)
    ref = _gsplat_reference(depths[0] * ray, c2w[0], Ks[0], z_depth=False)
    assert np.max(_angle(dist.numpy()[1:-1, 1:-1], ref[1:-1, 1:-1])) < 1e-4
    full = gsplat_depth_to_normal(d, c, k, keep_border=True).numpy()
    truth = r.normals @ c2w[0, :3, :3].T
    assert np.max(_angle(full, truth)) < 1e-4


def _twodgs_reference(depth, c2w, fx, fy):
    """2DGS ``utils.point_utils.depth_to_normal(view, depth)`` for (1, H, W) float64 numpy
    depth: intrinsics with the principal point at (W/2, H/2) and integer pixel centres,
    points ``depth * ([u, v, 1] @ inv(K).T @ R.T) + o``, ``cross(P[v+1] - P[v-1], P[u+1] -
    P[u-1])`` normalised, zeros on the one-pixel border; (H, W, 3)."""
    h, w = depth.shape[1:]
    Ki = np.linalg.inv(np.array([[fx, 0.0, w / 2.0], [0.0, fy, h / 2.0], [0.0, 0.0, 1.0]]))
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pix = np.stack([u, v, np.ones_like(u)], axis=-1).reshape(-1, 3)
    P = (depth.reshape(-1, 1) * (pix @ Ki.T @ c2w[:3, :3].T) + c2w[:3, 3]).reshape(h, w, 3)
    n = np.cross(P[2:, 1:-1] - P[:-2, 1:-1], P[1:-1, 2:] - P[1:-1, :-2])
    out = np.zeros((h, w, 3))
    out[1:-1, 1:-1] = n / np.linalg.norm(n, axis=-1, keepdims=True)
    return out


@pytest.mark.parametrize("scene", ["plane", "box"])
def test_twodgs_through_the_documented_mapping(scene):
    """2DGS's depth_to_normal is ours with depth[..., None], c2w[None] and Ks[None] whose
    principal point is (W/2 + 0.5, H/2 + 0.5) (docs/torch.md): same world normals on the
    faces, facing the camera, the same zero border."""
    h, w = SHAPE
    fx = fy = 131.25
    sc = tilted_plane() if scene == "plane" else make_scene("box-on-floor")
    r = sc.render(K=(fx, fy, w / 2.0, h / 2.0), shape=SHAPE)
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = _rotation(0.4, 0.2, -0.7), (0.5, 1.0, -3.0)
    ref = _twodgs_reference(r.depth[None], c2w, fx, fy)
    Ks = _matrix(fx, fy, w / 2.0 + 0.5, h / 2.0 + 0.5)[None]
    ours = gsplat_depth_to_normal(torch.from_numpy(r.depth)[None, ..., None],
                                  torch.from_numpy(c2w)[None], Ks)[0].numpy()
    inner = planar_interior(r, 1)
    inner[0, :] = inner[-1, :] = inner[:, 0] = inner[:, -1] = False
    assert np.max(_angle(ours[inner], ref[inner])) < 1e-4  # half a pixel off: 0.009 deg
    assert np.max(_angle(ours[inner], r.normals[inner] @ c2w[:3, :3].T)) < 1e-4
    border = np.ones(SHAPE, bool)
    border[1:-1, 1:-1] = False
    assert not ours[border].any() and not ref[border].any()


def test_gsplat_hole_float32_and_bad_input():
    depth = torch.full((6, 8, 1), 2.0)
    depth[3, 4] = 0.0
    K = _matrix(50.0, 50.0, 4.0, 3.0, torch.float32)
    n = gsplat_depth_to_normal(depth, torch.eye(4), K)
    assert n.dtype == torch.float32 and n[3, 4].tolist() == [0.0, 0.0, 0.0]
    assert n[2, 3].tolist() == [0.0, 0.0, -1.0]
    with pytest.raises(ValueError, match=r"\(\.\.\., H, W, 1\)"):
        gsplat_depth_to_normal(depth[..., 0], torch.eye(4), K)
    with pytest.raises(ValueError, match=r"camtoworlds must be \(\.\.\., 4, 4\)"):
        gsplat_depth_to_normal(depth, torch.eye(3), K)
    with pytest.raises(ValueError, match="leading dimensions differ"):
        gsplat_depth_to_normal(depth[None], torch.eye(4), K)
    with pytest.raises(TypeError, match="z_depth"):
        gsplat_depth_to_normal(depth, torch.eye(4), K, "z")


# ------------------------------------------------------------------------------ normalSpeed
def _normalspeed_reference(depth_mm, fx, fy, k, far, diff, into):
    """normalSpeed's ``depthNormals`` (LINE-MOD): per pixel of depth d < far, the least-squares
    gradient of the 8 neighbours at distance k whose |delta| < diff; n = (fx ddx, fy ddy,
    -det d), flipped when ``into`` and n_z < 0, normalised; 0 elsewhere and on the border
    (rows/columns k .. size - k - 2 computed). Its final 3x3 median filter is left out (it
    does not change a plane's normal)."""
    d = np.asarray(depth_mm, np.float64)
    h, w = d.shape
    out = np.zeros((h, w, 3))
    A0 = np.zeros((h, w))
    A1 = np.zeros((h, w))
    A3 = np.zeros((h, w))
    b0 = np.zeros((h, w))
    b1 = np.zeros((h, w))
    ys, xs = slice(k, h - k - 1), slice(k, w - k - 1)
    c = d[ys, xs]
    for i in (-k, 0, k):
        for j in (-k, 0, k):
            if i == j == 0:
                continue
            nb = d[k + j:h - k - 1 + j, k + i:w - k - 1 + i]  # i along x (columns), j along y
            f = (np.abs(nb - c) < diff).astype(np.float64)
            A0[ys, xs] += f * i * i
            A1[ys, xs] += f * i * j
            A3[ys, xs] += f * j * j
            b0[ys, xs] += f * i * (nb - c)
            b1[ys, xs] += f * j * (nb - c)
    det = A0 * A3 - A1 * A1
    n = np.stack([fx * (A3 * b0 - A1 * b1), fy * (-A1 * b0 + A0 * b1), -det * d], axis=-1)
    if into:
        n = np.where(n[..., 2:] < 0, -n, n)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    ok = (norm[..., 0] > 0) & (d < far)
    ok[:k] = ok[h - k - 1:] = False
    ok[:, :k] = ok[:, w - k - 1:] = False
    out[ok] = n[ok] / norm[ok]
    return out


FFB6D_K = (262.5, 262.5, 159.5, 119.5)  # principal point at the image centre of (240, 320)


@pytest.mark.parametrize("scene", ["plane", "box"])
@pytest.mark.parametrize("into", [False, True])
def test_normalspeed_same_orientation_and_units(scene, into):
    """Depth in mm in, (H, W, 3) float32 out; camera-facing by default (n_z < 0), into the
    surface with ``point_into_surface=True``. normalSpeed ignores the principal point
    (n ~ (fx z_u, fy z_v, -z)), so its normals are right only near it: we agree within 2 deg
    on the faces within 20 px of it, and everywhere on the faces within 25 deg (normalSpeed's
    own error there; ours is exact), facing the same way. The box needs a larger
    ``difference_threshold`` for normalSpeed to give its faces and the floor a normal."""
    h, w = 240, 320
    sc = tilted_plane(distance=1.0) if scene == "plane" else make_scene("box-on-floor")
    r = sc.render(K=FFB6D_K, shape=(h, w))
    depth_mm = r.depth * 1000.0
    far, diff = (2000, 20) if scene == "plane" else (10000, 500)
    ours = depth_normal(depth_mm, FFB6D_K[0], FFB6D_K[1], 5, far, diff, into)
    ref = _normalspeed_reference(depth_mm, FFB6D_K[0], FFB6D_K[1], 5, far, diff, into)
    assert ours.shape == (h, w, 3) and ours.dtype == np.float32
    inner = planar_interior(r, 6) & ref.any(axis=-1)
    assert len(np.unique(r.face[inner])) == (1 if scene == "plane" else 4)  # floor, wall, 2 box faces
    near = np.zeros((h, w), bool)
    near[120 - 20:120 + 20, 160 - 20:160 + 20] = True
    assert (inner & near).sum() > 800
    assert np.max(_angle(ours[inner & near], ref[inner & near])) < 2.0
    assert np.max(_angle(ours[inner], ref[inner])) < 25.0
    sign = 1.0 if into else -1.0  # facing: dot(n, X) < 0 (n_z < 0 off the floor, 0 on it)
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    ray = np.stack([(u - FFB6D_K[2]) / FFB6D_K[0], (v - FFB6D_K[3]) / FFB6D_K[1], np.ones((h, w))], -1)
    for n in (ours, ref):
        assert np.all(sign * np.sum(n[inner] * ray[inner], axis=-1) > 0)
    assert np.max(_angle(ours[inner], -sign * r.normals[inner])) < 0.01  # exact (3F2N+)
    assert np.min(_angle(ours[inner], sign * r.normals[inner])) > 179.9  # the other sign rejected


def test_normalspeed_uint16_far_cut_and_zeros():
    """uint16 millimetres as normalSpeed takes them; zeros at invalid depth and at and beyond
    ``distance_threshold``; the unused arguments are still checked; numpy only."""
    r = tilted_plane(distance=1.5).render(K=FFB6D_K, shape=(60, 80))
    depth_mm = np.round(r.depth * 1000.0).astype(np.uint16)
    depth_mm[30, 40] = 0
    n = depth_normal(depth_mm, 262.5, 262.5, 5, 2000, 20, False)
    assert n[30, 40].tolist() == [0.0, 0.0, 0.0]
    ok = np.ones((60, 80), bool)
    ok[30, 40] = False
    assert np.all(np.linalg.norm(n[ok], axis=-1) > 0.999) and np.all(n[ok][:, 2] < 0)
    cut = depth_normal(depth_mm, 262.5, 262.5, 5, 1600, 20, False)
    beyond = depth_mm >= 1600
    assert beyond.any() and (~beyond).any()
    assert not cut[beyond].any() and np.all(np.linalg.norm(cut[~beyond & ok], axis=-1) > 0.999)
    want = dn.estimate_normals(depth_mm, dn.Intrinsics(262.5, 262.5, 39.5, 29.5), depth_scale=0.001)
    np.testing.assert_array_equal(n[ok], want[ok])
    with pytest.raises(TypeError, match="k_size"):
        depth_normal(depth_mm, 262.5, 262.5, 2.5, 2000, 20, False)
    with pytest.raises(ValueError, match="fx"):
        depth_normal(depth_mm, -1.0, 262.5, 5, 2000, 20, False)
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        depth_normal(depth_mm[None], 262.5, 262.5, 5, 2000, 20, False)
    with pytest.raises(TypeError, match="point_into_surface"):
        depth_normal(depth_mm, 262.5, 262.5, 5, 2000, 20, 1)
