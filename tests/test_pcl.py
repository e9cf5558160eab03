"""PCL's integral-image normals (``pcl_integral_image``, four registered modes) and the plain
cross-product normal map (``cross_product``).

The fast kernels are checked against a plain per-pixel numpy reference written here from
the definitions (brute-force chamfer distance, explicit folded index lists, numpy eigh),
on analytic scenes with exact normals, on abstention with hand-counted coverage, and (the
forward cross product) against Open3D's ``create_normal_map`` where it is installed.
"""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import Box, Plane, Scene, Sphere, make_scene, planar_interior
from depthnormals.estimators.pcl import MODES, distance_map

PCL_METHODS = ("pcl-average-3d-gradient", "pcl-covariance-matrix", "pcl-average-depth-change",
               "pcl-simple-3d-gradient")
K_SMALL = (131.25, 131.25, 39.5, 29.5)


# --- the per-pixel reference -------------------------------------------------------------

def _ref_distance(z, factor):
    """Brute force: marked pixels from every 4-neighbour pair, then the (1, 1.4) chamfer
    distance max + 0.4 min to the nearest marked pixel (h + w when none)."""
    h, w = z.shape
    valid = np.isfinite(z)
    marked = ~valid
    for (dv, du) in ((0, 1), (1, 0)):
        a = z[:h - dv, :w - du]
        b = z[dv:, du:]
        with np.errstate(invalid="ignore"):
            jump = ~(np.isfinite(a) & np.isfinite(b)
                     & (np.abs(a - b) <= 2 * factor * (np.minimum(a, b) + 1)))
        marked[:h - dv, :w - du] |= jump
        marked[dv:, du:] |= jump
    mv, mu = np.nonzero(marked)
    if mv.size == 0:
        return np.full(z.shape, float(h + w))
    v, u = np.mgrid[0:h, 0:w]
    dv = np.abs(v[..., None] - mv)
    du = np.abs(u[..., None] - mu)
    return (np.maximum(dv, du) + 0.4 * np.minimum(dv, du)).min(axis=-1)


def _fold(i, n):
    i = np.asarray(i)
    return np.where(i < 0, -i - 1, np.where(i >= n, 2 * n - 1 - i, i))


def _points(z, K):
    fx, fy, cx, cy = K
    v, u = np.mgrid[0:z.shape[0], 0:z.shape[1]].astype(np.float64)
    return np.stack([(u - cx) * z / fx, (v - cy) * z / fy, z], axis=-1)


def _reference(depth, K, mode, factor=0.02, size=10.0, dds=False, policy="mirror"):
    """PCL's estimator pixel by pixel, from the definitions (slow)."""
    fx, fy, cx, cy = K
    z = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan).astype(np.float64)
    h, w = z.shape
    P = _points(z, K)
    # central differences, NaN where undefined
    DX = np.full((h, w, 3), np.nan)
    DY = np.full((h, w, 3), np.nan)
    DX[:, 1:-1] = P[:, 2:] - P[:, :-2]
    DY[1:-1] = P[2:] - P[:-2]
    dist = _ref_distance(z, factor)
    out = np.full((h, w, 3), np.nan)
    for v in range(h):
        for u in range(w):
            if not np.isfinite(z[v, u]):
                continue
            sm = min(dist[v, u], size + z[v, u] / 10 if dds else size)
            if not sm > 2:
                continue
            r = min(int(sm) // 2, min(h, w))
            if policy == "ignore":
                b = int(size)
                if (v < b or v >= h - b or u < b or u >= w - b or v <= r or v + r >= h
                        or u <= r or u + r >= w):
                    continue

            def rows(a, b):
                return _fold(np.arange(a, b + 1), h)

            def cols(a, b):
                return _fold(np.arange(a, b + 1), w)

            def box(arr, r0, r1, c0, c1):
                return arr[np.ix_(rows(r0, r1), cols(c0, c1))].reshape(-1, arr.shape[-1])

            if mode == "average-3d-gradient":
                gx = box(DX, v - r, v + r, u - r, u + r)
                gy = box(DY, v - r, v + r, u - r, u + r)
                gx = gx[np.isfinite(gx).all(1)].sum(0)
                gy = gy[np.isfinite(gy).all(1)].sum(0)
                n = np.cross(gy, gx)
            elif mode == "covariance-matrix":
                q = box(P, v - r, v + r, u - r, u + r)
                q = q[np.isfinite(q).all(1)]
                q = q - q.mean(0)
                n = np.linalg.eigh(q.T @ q)[1][:, 0]
            elif mode == "simple-3d-gradient":
                def mean(r0, r1, c0, c1):
                    return np.nanmean(box(P, r0, r1, c0, c1), axis=0)
                gx = mean(v - r, v + r, u + r, u + r) - mean(v - r, v + r, u - r, u - r)
                gy = mean(v + r, v + r, u - r, u + r) - mean(v - r, v - r, u - r, u + r)
                n = np.cross(gy, gx)
            else:  # average depth change
                q = r // 2

                def centre(r0, r1, c0, c1):
                    zz = np.nanmean(box(z[..., None], r0, r1, c0, c1))
                    uu = cols(c0, c1).mean()
                    vv = rows(r0, r1).mean()
                    return np.array([(uu - cx) * zz / fx, (vv - cy) * zz / fy, zz])
                tx = centre(v - q, v + q, u + 1, u + r) - centre(v - q, v + q, u - r, u - 1)
                ty = centre(v + 1, v + r, u - q, u + q) - centre(v - r, v - 1, u - q, u + q)
                n = np.cross(tx, ty)
            n = n / np.linalg.norm(n)
            if n @ P[v, u] > 0:
                n = -n
            out[v, u] = n
    return out


def _rough_scene(seed=3, shape=(22, 28)):
    """A box on a floor before a wall with holes and mild noise: jumps, creases, invalid
    pixels and the border all inside a small image."""
    sc = Scene([Plane((0.0, -1.0, 0.0), -1.0), Plane((0.0, 0.0, -1.0), -4.0),
                Box((0.1, 0.5, 2.2), (0.35, 0.3, 0.3), (0.0, 30.0, 0.0))])
    r = sc.render((30.0, 30.0, (shape[1] - 1) / 2, (shape[0] - 1) / 2), shape)
    rng = np.random.default_rng(seed)
    z = r.depth * (1 + 0.002 * rng.standard_normal(r.depth.shape))
    z[rng.random(z.shape) < 0.03] = 0.0
    return z, (r.K.fx, r.K.fy, r.K.cx, r.K.cy)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("policy", ["mirror", "ignore"])
@pytest.mark.parametrize("dds, size", [(False, 10.0), (False, 5.0), (True, 4.0)])
def test_fast_kernel_equals_the_per_pixel_reference(mode, policy, dds, size):
    z, K = _rough_scene()
    if policy == "ignore" and size == 10.0:
        size = 6.0  # keep an interior in 22 x 28 pixels
    got = dn.pcl_integral_image(z, K, mode=mode, normal_smoothing_size=size,
                                depth_dependent_smoothing=dds, border_policy=policy)
    want = _reference(z, K, mode, size=size, dds=dds, policy=policy)
    assert np.array_equal(np.isnan(got[..., 0]), np.isnan(want[..., 0]))
    ok = np.isfinite(want[..., 0])
    assert ok.sum() > (40 if policy == "ignore" else 150)
    np.testing.assert_allclose(got[ok], want[ok], atol=2e-6)


def test_distance_map_equals_brute_force():
    z, _ = _rough_scene(seed=5, shape=(30, 40))
    for factor in (0.0, 0.02, 0.5):
        np.testing.assert_array_equal(distance_map(z, max_depth_change_factor=factor),
                                      _ref_distance(np.where(z > 0, z, np.nan), factor))


# --- analytic accuracy ----------------------------------------------------------------------

@pytest.mark.parametrize("normal", [(0.0, 0.0, -1.0), (0.6, 0.0, -0.8), (-0.5, 0.4, -0.77),
                                    (0.7, 0.45, -0.55)])
@pytest.mark.parametrize("mode", MODES)
def test_planes(normal, mode):
    """Every window sum of a plane is in the plane: three modes are exact (float32), the
    average depth change is exact on fronto-parallel planes and within 0.2 deg elsewhere
    (the mean depth of a box is not the depth at its mean pixel: z is not linear in u)."""
    r = Scene([Plane(normal, -2.0)]).render(K_SMALL, (60, 80))
    n = dn.pcl_integral_image(r.depth, r.K, mode=mode)
    assert n.dtype == np.float32 and np.isfinite(n).all()  # mirror: every pixel
    err = dn.angular_error(n, r.normals)
    tol = 1e-4 if mode != "average-depth-change" or normal[2] == -1.0 else 0.2
    assert err.max() < tol


@pytest.mark.parametrize("mode", MODES)
def test_box_scene_exact_on_planar_interiors_and_abstains_at_jumps(mode):
    r = make_scene("box-on-floor").render()
    n = dn.pcl_integral_image(r.depth, r.K, mode=mode)
    err = dn.angular_error(n, r.normals)
    ok = np.isfinite(err)
    inner = planar_interior(r, 6)  # the whole 11 x 11 window on one face
    assert inner.sum() > 200000 and ok[inner].all()
    assert np.percentile(err[inner], 99) < (0.05 if mode == "average-depth-change" else 0.01)
    # it abstains at the box's occluding contour: exactly where the distance map is <= 2
    d = distance_map(r.depth)
    assert np.array_equal(ok, (d > 2) & (r.depth > 0))
    cov = ok[r.depth > 0].mean()
    assert 0.97 < cov < 0.995


def test_sphere():
    """A sphere filling the view: smooth, no jumps; the 11-pixel window costs < 0.3 deg."""
    r = Scene([Sphere((0.1, -0.05, 2.5), 1.5)]).render(K_SMALL, (60, 80))
    assert (r.depth > 0).all()
    for mode in MODES:
        n = dn.pcl_integral_image(r.depth, r.K, mode=mode)
        err = dn.angular_error(n, r.normals)
        assert np.isfinite(err).all()
        assert np.median(err) < 0.3 and err.max() < 3.0


# --- abstention and coverage ----------------------------------------------------------------

def _step(h=20, w=30, near=1.0, far=2.0, at=15):
    z = np.full((h, w), near)
    z[:, at:] = far
    return z


@pytest.mark.parametrize("method", PCL_METHODS)
def test_abstains_within_two_pixels_of_a_jump(method):
    """Step between columns 14 and 15: both are marked, columns 12, 13, 16, 17 are 1 and 2
    pixels away (window <= 2): 6 NaN columns of 30, coverage 0.8 exactly (mirror)."""
    n = dn.estimate_normals(_step(), (100.0, 100.0, 14.5, 9.5), method=method)
    finite = np.isfinite(n[..., 0])
    assert finite.mean() == 0.8
    assert not finite[:, 12:18].any() and finite[:, :12].all() and finite[:, 18:].all()
    assert np.abs(n[finite] - [0, 0, -1]).max() < 1e-6


def test_ignore_border_policy_coverage():
    """BORDER_POLICY_IGNORE: NaN within int(size) = 10 pixels of the border, so on the step
    only rows 10..29 and columns 10, 11, 18, 19 remain: 20 x 4 of 40 x 30 pixels."""
    z = _step(h=40)
    n = dn.pcl_integral_image(z, (100.0, 100.0, 14.5, 19.5), border_policy="ignore")
    finite = np.isfinite(n[..., 0])
    assert finite.sum() == 80
    assert finite[10:30][:, [10, 11, 18, 19]].all()
    mirror = dn.pcl_integral_image(z, (100.0, 100.0, 14.5, 19.5))
    np.testing.assert_array_equal(n[finite], mirror[finite])  # same windows inside


def test_abstains_around_an_invalid_pixel():
    """A hole marks itself and its 4 neighbours (a pair with an invalid pixel is a jump);
    NaN wherever the chamfer distance to that plus-shape is <= 2: the 5 x 5 square without
    its corners and the 4 pixels 3 away on the axes, 25 pixels."""
    z = np.full((21, 21), 1.5)
    z[10, 10] = 0.0
    n = dn.pcl_integral_image(z, (100.0, 100.0, 10.0, 10.0), mode="covariance-matrix")
    nan = np.isnan(n[..., 0])
    v, u = np.mgrid[-10:11, -10:11]
    plus = [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)]
    d = np.min([np.maximum(abs(v - a), abs(u - b)) + 0.4 * np.minimum(abs(v - a), abs(u - b))
                for a, b in plus], axis=0)
    assert np.array_equal(nan, d <= 2) and nan.sum() == 25


@pytest.mark.parametrize("step, marked", [(0.079, False), (0.081, True)])
def test_depth_change_threshold(step, marked):
    """At z = 1 m the threshold is 2 * 0.02 * (1 + 1) = 0.08 m."""
    z = _step(near=1.0, far=1.0 + step)
    d = distance_map(z)
    assert (d.min() == 0) == marked
    finite = np.isfinite(dn.pcl_integral_image(z, (100.0, 100.0, 14.5, 9.5))[..., 0])
    assert finite.all() != marked


def test_depth_dependent_smoothing_grows_the_window():
    """normal_smoothing_size + z / 10: at z = 40 m a size of 3 becomes 7 pixels, so the
    pixels 3 pixels from the jump keep their window of 3 only without it."""
    z = _step(near=40.0, far=60.0)
    K = (100.0, 100.0, 14.5, 9.5)
    plain = dn.pcl_integral_image(z, K, normal_smoothing_size=3.0)
    grown = dn.pcl_integral_image(z, K, normal_smoothing_size=3.0, depth_dependent_smoothing=True)
    # the distance map caps both windows near the jump: the same abstention
    np.testing.assert_array_equal(np.isnan(plain), np.isnan(grown))
    # and the grown window is visible on a curved surface
    r = Scene([Sphere((0.0, 0.0, 40.0), 30.0)]).render(K, (20, 30))
    a = dn.pcl_integral_image(r.depth, K, normal_smoothing_size=3.0, mode="covariance-matrix")
    b = dn.pcl_integral_image(r.depth, K, normal_smoothing_size=3.0, mode="covariance-matrix",
                              depth_dependent_smoothing=True)
    assert np.nanmax(np.abs(a - b)) > 1e-4


def test_not_scale_invariant_and_registered():
    for m in PCL_METHODS:
        info = dn.get_estimator(m)
        assert not info.scale_invariant
        assert set(info.options) == {"max_depth_change_factor", "normal_smoothing_size",
                                     "depth_dependent_smoothing", "border_policy"}
    assert dn.get_estimator("cross-product").scale_invariant


# --- conventions and validation -----------------------------------------------------------

@pytest.mark.parametrize("method", [*PCL_METHODS, "cross-product"])
def test_conventions(method):
    r = Scene([Plane((0.3, -0.2, -1.0), -2.0)]).render(K_SMALL, (30, 40))
    z = r.depth.astype(np.float32)
    z[5, 7] = np.nan
    z[20, 30] = -1.0
    n = dn.estimate_normals(z, r.K, method=method)
    assert n.dtype == np.float32 and n.shape == (30, 40, 3)
    assert np.isnan(n[5, 7]).all() and np.isnan(n[20, 30]).all()
    ok = np.isfinite(n).all(-1)
    np.testing.assert_allclose(np.linalg.norm(n[ok], axis=-1), 1.0, atol=1e-6)
    pts = dn.backproject(z, r.K)
    assert (np.einsum("...i,...i->...", n.astype(np.float64), pts)[ok] < 0).all()


@pytest.mark.parametrize("opts, exc, match", [
    ({"mode": "covariance"}, ValueError, "mode"),
    ({"border_policy": "BORDER_POLICY_MIRROR"}, ValueError, "border_policy"),
    ({"normal_smoothing_size": 1.5}, ValueError, "normal_smoothing_size"),
    # 2 leaves every normal NaN unless the window grows with depth
    ({"normal_smoothing_size": 2.0}, ValueError, "depth_dependent_smoothing is True"),
    ({"normal_smoothing_size": "10"}, TypeError, "normal_smoothing_size"),
    ({"max_depth_change_factor": -0.1}, ValueError, "max_depth_change_factor"),
    ({"max_depth_change_factor": np.nan}, ValueError, "max_depth_change_factor"),
    ({"depth_dependent_smoothing": 1}, TypeError, "depth_dependent_smoothing"),
])
def test_bad_options(opts, exc, match):
    with pytest.raises(exc, match=match):
        dn.pcl_integral_image(np.ones((8, 8)), K_SMALL, **opts)


def test_cross_product_bad_difference():
    with pytest.raises(ValueError, match="difference"):
        dn.cross_product(np.ones((4, 4)), K_SMALL, difference="backward")


# --- the cross product ----------------------------------------------------------------------

@pytest.mark.parametrize("difference", ["central", "forward"])
@pytest.mark.parametrize("normal", [(0.0, 0.0, -1.0), (0.6, 0.0, -0.8), (0.7, 0.45, -0.55)])
def test_cross_product_exact_on_planes(difference, normal):
    """Any two chords of a plane span it: exact up to float32 rounding."""
    r = Scene([Plane(normal, -2.0)]).render(K_SMALL, (60, 80))
    n = dn.cross_product(r.depth, r.K, difference=difference)
    finite = np.isfinite(n[..., 0])
    frame = np.zeros(finite.shape, bool)
    if difference == "central":
        frame[[0, -1], :] = frame[:, [0, -1]] = True
    else:
        frame[-1, :] = frame[:, -1] = True
    assert np.array_equal(finite, ~frame)
    assert dn.angular_error(n, r.normals)[finite].max() < 1e-4


def test_cross_product_forward_is_half_a_pixel_off_on_a_sphere():
    """The forward normal belongs to the cell (u + 1/2, v + 1/2): on a sphere it matches the
    exact normal there, not at the pixel (the central form does)."""
    K = K_SMALL
    sph = Scene([Sphere((0.1, -0.05, 2.5), 1.5)])
    r = sph.render(K, (60, 80))
    shifted = sph.render((K[0], K[1], K[2] - 0.5, K[3] - 0.5), (60, 80))
    fwd = dn.cross_product(r.depth, K, difference="forward")
    cen = dn.cross_product(r.depth, K, difference="central")
    e_pix = np.nanmedian(dn.angular_error(fwd, r.normals))
    e_cell = np.nanmedian(dn.angular_error(fwd, shifted.normals))
    assert e_cell < 0.05 < e_pix
    assert np.nanmedian(dn.angular_error(cen, r.normals)) < 0.05


@pytest.mark.parametrize("scene", ["plane", "sphere", "box"])
def test_cross_product_forward_matches_open3d(scene):
    """Open3D's t.geometry create_vertex_map + create_normal_map (float32, no orientation)
    equals ours with difference="forward" where both are defined: same pixels, components
    within 1e-5 (float32 rounding of Open3D's differences: 2.5e-6 at most here)."""
    o3d = pytest.importorskip("open3d")
    K = (110.0, 110.0, 31.5, 23.5)
    sc = {"plane": Scene([Plane((0.3, -0.2, -1.0), -2.0)]),
          "sphere": Scene([Sphere((0.1, -0.05, 2.5), 1.5)]),
          "box": Scene([Box((0.0, 0.0, 2.0), (0.4, 0.3, 0.3), (20.0, 30.0, 0.0)),
                        Plane((0.0, 0.0, -1.0), -3.0)])}[scene]
    z = sc.render(K, (48, 64)).depth.astype(np.float32)
    image = o3d.t.geometry.Image(o3d.core.Tensor(z))
    Km = o3d.core.Tensor(np.array([[K[0], 0, K[2]], [0, K[1], K[3]], [0, 0, 1]]))
    theirs = image.create_vertex_map(Km, invalid_fill=0.0).create_normal_map(
        invalid_fill=0.0).as_tensor().numpy()
    ours = dn.cross_product(z, K, difference="forward")
    ok = np.isfinite(ours).all(-1)
    assert np.array_equal(ok, ~(theirs == 0).all(-1))
    # Open3D does not orient: on a surface seen from the front its normal already faces the
    # camera; across the box's occluding contour it may not, so compare up to sign there
    same = np.abs(ours[ok] - theirs[ok]).max(-1) < 1e-5
    flipped = np.abs(ours[ok] + theirs[ok]).max(-1) < 1e-5
    assert (same | flipped).all()
    assert same.mean() > (0.98 if scene == "box" else 0.9999)
