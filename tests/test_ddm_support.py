"""The noise model of real sensors and the measured support of the noisy branch
(ddm/noise.py's plateau search, ddm/support.py, auto's choice between the two noisy branches).

Synthetic inputs with a known answer (a quantised plane, correlated noise), the kinect_v1
sensor model of the synthetic benchmark, and the real frames of ``shared/data/real-sensors``
(skipped when that folder is absent)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import make_scene, tilted_plane
from depthnormals.ddm import auto, faceswitch, noise, support
from depthnormals.ddm.noise import QUANT_SHARE, noise_pass, quantisation_step
from depthnormals.kernels.depth import prepare
from faceswitch_reference import reference_switch

K = (525.0, 525.0, 319.5, 239.5)


def _plane(normal=(0.0, -0.6, -0.8), distance=2.0, shape=(480, 640)):
    return tilted_plane(normal, distance).render(shape=shape, K=K)


def _kinect_quantised(depth, f=580.0, baseline=0.075, step=0.125):
    """Kinect v1 style: disparity ``f b / z`` rounded to ``step`` px, back to depth."""
    disp = np.round(f * baseline / depth / step) * step
    return (f * baseline / disp).astype(np.float32)


def _correlated(shape, sigma_px, window, seed):
    """Unit-variance noise averaged over a ``window`` x ``window`` box (correlated over
    ``window`` pixels), times ``sigma_px``."""
    rng = np.random.default_rng(seed)
    pad = window
    n = rng.normal(size=(shape[0] + 2 * pad, shape[1] + 2 * pad))
    c = np.cumsum(np.cumsum(np.pad(n, ((1, 0), (1, 0))), 0), 1)
    box = (c[window:, window:] - c[:-window, window:] - c[window:, :-window] + c[:-window, :-window])
    box = box[pad:pad + shape[0], pad:pad + shape[1]] / window
    return sigma_px * box / box.std()


def test_quantised_plane_reads_its_rounding_noise():
    r = _plane()
    q = _kinect_quantised(r.depth)
    # the wrong reading: every second difference inside a plateau is 0, so the median is 0
    z, cam = prepare(q, r.K, None)
    p = noise_pass(z, cam.fx, cam.fy)
    assert p.iid == 0.0
    share, step, _ = quantisation_step(z, cam.fx, cam.fy)
    assert share >= QUANT_SHARE
    # the step at the plane's depth: dz = z^2 q / (f b) -> footprints dz f / z = z q f / (f b) * f
    zm = float(np.median(r.depth))
    expected = zm * 0.125 / (580.0 * 0.075) * K[0]
    assert step == pytest.approx(expected, rel=0.25)
    sigma = dn.estimate_noise(q, r.K)
    assert sigma == pytest.approx(step / math.sqrt(12.0), rel=1e-6)
    assert sigma > 0.3


def test_clean_and_iid_depth_are_not_quantised():
    r = make_scene("demo-room").render()
    assert dn.estimate_noise(r.depth, r.K) < auto.PLANES_NOISE
    rng = np.random.default_rng(1)
    noisy = r.depth + rng.normal(size=r.depth.shape) * 0.2 * r.depth / r.K.fx
    z, cam = prepare(noisy, r.K, None)
    p = noise_pass(z, cam.fx, cam.fy)
    assert p.quant == 0.0
    assert p.sigma == pytest.approx(0.2, rel=0.1)


def test_quantised_plane_takes_the_measured_support_not_the_clean_branch():
    r = _plane()
    q = _kinect_quantised(r.depth)
    n = dn.estimate_normals(q, r.K)
    e = dn.angular_error(n, r.normals)[20:-20, 20:-20]
    # the plane hypotheses fit the staircase: most normals face the camera (tens of degrees)
    planes = dn.estimate_normals(q, r.K, selection="planes")
    e_planes = dn.angular_error(planes, r.normals)[20:-20, 20:-20]
    assert np.nanmean(e_planes) > 10.0
    assert np.nanmean(e) < 1.5
    fals = dn.estimate_normals(q, r.K, method="fals", window=11)
    assert np.nanmean(e) < np.nanmean(dn.angular_error(fals, r.normals)[20:-20, 20:-20])


def _room(shape=(240, 320)):
    K2 = dn.as_intrinsics((262.5, 262.5, 159.5, 119.5))
    return make_scene("demo-room").render(K=K2, shape=shape)


def _on_grid(depth, q_m):
    return np.where(depth > 0, np.round(depth / q_m) * q_m, 0).astype(np.float32)


def test_depth_on_a_millimetre_grid_reads_its_rounding_noise():
    """A clean render rounded to millimetres (a 16-bit PNG's units): on its fronto-parallel and
    gently sloped surfaces most second differences are exactly 0 and too few neighbours are
    equal on the slopes for plateaus (share < QUANT_SHARE), so the level read 0 and the frame
    took the clean branch. The grid's quantum (1 mm over ``z / f`` footprints) now enters as
    rounding noise: the level is about ``median(q f / z) / sqrt(12)``."""
    r = _room()
    z, cam = prepare(_on_grid(r.depth, 1e-3), r.K, None)
    p = noise_pass(z, cam.fx, cam.fy)
    assert p.iid < 1e-3 and p.quant_share < QUANT_SHARE and not p.plateaus
    valid = r.depth > 0
    # the samples are sloped surfaces (near ones count more than in the image's median)
    assert 0.5 < p.grid / np.median(1e-3 * cam.fx / r.depth[valid]) < 2.0
    assert p.quant_step == p.grid and p.sigma == pytest.approx(p.grid / math.sqrt(12.0), rel=0.05)
    for depth in (r.depth, r.depth * (1 + np.random.default_rng(0).normal(size=r.depth.shape) * 1e-3)):
        z, cam = prepare(depth, r.K, None)  # float depth: no grid
        assert noise_pass(z, cam.fx, cam.fy).grid == 0.0
    # float32's own spacing is a grid too (a nearly fronto-parallel plane: values a few ulps
    # apart, every difference a multiple of one ulp), far too fine to be a depth unit
    v, u = np.mgrid[0:120, 0:160]
    ulp = 2.0 ** -22  # float32's spacing at 2 m
    wall = (2.0 + 1.1 * ulp * u + 1.3 * ulp * v).astype(np.float32)
    assert set(np.unique(np.diff(wall.astype(np.float64), axis=1) / ulp)) == {1.0, 2.0}
    z, cam = prepare(wall, r.K, None)
    assert noise.quantisation_step(z, cam.fx, cam.fy) == (0.0, 0.0, 0.0)


def test_a_grid_under_stronger_noise_is_left_out():
    """Sensor depth stored in millimetres (the synthetic kinect_v2 and tof models, real ToF):
    the second-difference level is many times the grid's rounding noise, which is then left
    out (quant_step_of), so those frames keep their level to the bit."""
    r = _room()
    rng = np.random.default_rng(2)
    noisy = r.depth + rng.normal(size=r.depth.shape) * 0.004
    z, cam = prepare(_on_grid(noisy, 1e-3), r.K, None)
    p = noise_pass(z, cam.fx, cam.fy)
    assert p.grid > 0.0 and p.quant_step == 0.0 and p.sigma == p.iid
    # counted where its rounding noise grid / sqrt(12) is at least a third of the level
    assert noise.quant_step_of(0.2, 0.0, 0.3) == 0.3 and noise.quant_step_of(0.5, 0.0, 0.3) == 0.0
    assert noise.quant_step_of(0.0, 0.7, 0.3) == 0.7  # plateaus first


@pytest.mark.parametrize("q_mm", [1.0, 2.0])
def test_the_default_on_millimetre_depth_takes_the_box_fit_and_maps_its_error(q_mm):
    """Measured on demo-room (session 29): rounded to 1 and 2 mm the default took the plane
    hypotheses, mean error 0.19 / 0.36 deg at 320 x 240 (0.42 / 0.75 at 640 x 480), and its
    map read 0.01-0.02 deg, 10-57x too confident; now the box-fit over the rounding noise,
    0.11 / 0.23 deg, and a map that is not below the error (it over-reads the edges here, as
    on this scene's i.i.d. noise)."""
    r = _room()
    d = _on_grid(r.depth, q_mm * 1e-3)
    profile = dn.noise_profile(d, r.K)
    assert profile.branch == "box-fit" and profile.grid == profile.quant_step > 0.0
    assert dn.noise_profile(r.depth, r.K).grid == 0.0
    n, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
    e = dn.angular_error(n, r.normals)
    planes = dn.estimate_normals(d, r.K, selection="planes")
    e_planes = dn.angular_error(planes, r.normals)
    assert np.nanmean(e) < 0.7 * np.nanmean(e_planes)
    assert 0.5 < np.nanmean(u) / np.nanmean(e) < 12.0


@pytest.mark.parametrize("window", [1, 7])
def test_excess_tells_independent_from_correlated_noise(window):
    r = _plane(normal=(0.2, -0.5, -0.84))
    noise = _correlated(r.depth.shape, 0.5, window, seed=3)
    d = (r.depth * (1.0 + noise / r.K.fx)).astype(np.float32)
    z, cam = prepare(d, r.K, None)
    p = noise_pass(z, cam.fx, cam.fy)
    prof = support.support_profile(z, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma)
    if window == 1:
        assert prof.excess() <= auto.EXCESS
        # independent noise: the tuned box-fit, bit for bit
        old = auto.box_select(z, None, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma, levels=p.tiles())
        assert np.array_equal(dn.estimate_normals(d, r.K), old, equal_nan=True)
    else:
        # correlated noise: second differences see little of it, the fits a lot
        assert prof.excess() > auto.EXCESS
        assert prof.radius >= 8
        n = dn.estimate_normals(d, r.K)
        old = auto.box_select(z, None, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma)
        e_new = np.nanmean(dn.angular_error(n, r.normals))
        e_old = np.nanmean(dn.angular_error(old, r.normals))
        assert e_new < 0.5 * e_old


def _local_tables(levels, share_far, far_factor, n=60, edges=0):
    """Pair tables for :func:`support.local_excess`: ``n`` pairs per radius, a share
    ``share_far`` of them in tile 1 and the rest in tile 0, each with the angle whose
    Rayleigh error is its tile's prediction (``far_factor`` times it in tile 1) and a residual
    of its tile's level squared; ``edges`` pairs more in tile 0 with a residual 50 times it
    and an angle of 60 deg (pairs across an edge)."""
    tables = []
    for r in support.RADII:
        rows = []
        for i in range(n + edges):
            t = 1 if i < share_far * n else 0
            lev = levels.ravel()[t]
            pred = support.predicted_error(lev, r, support.sample_every(r))
            ang = pred / support.PAIR_TO_ERROR * (far_factor if t == 1 else 1.0)
            res = lev * lev
            if i >= n:
                ang, res, t = 60.0, 50.0 * levels.ravel()[0] ** 2, 0
            rows.append((ang, res, 2.0, float(t)))
        rows = np.array(rows)
        tables.append((rows, np.ones(len(rows), dtype=bool)))
    return tables


def test_local_excess_reads_each_pair_against_its_own_tile():
    """Noise that the fits read 3x its second-difference level in the far tiles: each pair
    against its own tile reads 3 where the far pairs are the majority and 1 where they are
    not (the median), whatever the tiles' levels; a pair across an edge (residual 50x) is not
    read; a NaN tile reads as the frame's level; too few pairs give NaN."""
    levels = np.array([[0.5, 2.0]])
    assert support.local_excess(_local_tables(levels, 0.7, 3.0), levels, 1.0) == pytest.approx(3.0)
    assert support.local_excess(_local_tables(levels, 0.3, 3.0), levels, 1.0) == pytest.approx(1.0)
    assert support.local_excess(_local_tables(levels, 0.7, 3.0, edges=8), levels, 1.0) == pytest.approx(3.0)
    # the far tile's level unknown: the frame's (2.0) takes its place
    nan_far = np.array([[0.5, np.nan]])
    assert support.local_excess(_local_tables(levels, 0.7, 3.0), nan_far, 2.0) == pytest.approx(3.0)
    assert math.isnan(support.local_excess(_local_tables(levels, 0.7, 3.0, n=11), levels, 1.0))


def test_active_stereo_noise_growing_with_depth_takes_the_measured_support():
    """A room seen by the realsense_d4xx model at 0.4-1.8 m: its noise, correlated over the
    matching window, grows as z^2; second differences read the far tiles 4x low and the
    image-wide excess (the median pair against the median tile) stays under 2, so the box-fit
    ran and erred 15 deg (git e0e0173). Read pair by pair against each pair's own tile the
    excess is 5: the measured support, 3.4 deg. Independent noise growing with depth as much
    stays on the box-fit."""
    from depthnormals.synth.noise import realsense_d4xx_noise

    r = make_scene("demo-room").render(K=K, shape=(480, 640))
    d0 = np.where(r.depth > 0, 0.3 * r.depth, 0.0)
    d = realsense_d4xx_noise(d0, r.normals, r.K, rng=np.random.default_rng(1))
    p = dn.noise_profile(d, r.K)
    assert p.excess <= auto.EXCESS < p.local_excess
    assert p.branch == "measured-support"
    z, cam = prepare(d, r.K, None)
    box = auto.box_select(z, None, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma, levels=p.tiles)
    e = np.nanmean(dn.angular_error(dn.estimate_normals(d, r.K), r.normals))
    assert e < 0.3 * np.nanmean(dn.angular_error(box, r.normals))
    zmed = np.median(r.depth[r.depth > 0])
    rng = np.random.default_rng(2)
    level = 3.0 * r.depth / zmed  # footprints, growing with depth
    iid = np.where(r.depth > 0, r.depth * (1 + level * rng.normal(size=r.depth.shape) / r.K.fx), 0)
    q = dn.noise_profile(iid, r.K)
    assert q.local_excess < 1.5 and q.branch == "box-fit"


def test_predicted_error_matches_independent_noise():
    # a plane with i.i.d. noise of 0.5 footprints: the pairs' measured error is the prediction
    r = _plane(normal=(0.0, 0.0, -1.0))
    rng = np.random.default_rng(7)
    d = r.depth * (1.0 + 0.5 * rng.normal(size=r.depth.shape) / r.K.fx)
    z, cam = prepare(d, r.K, None)
    prof = support.support_profile(z, cam.fx, cam.fy, cam.cx, cam.cy, 0.5, target=0.0)
    for rad, m, pr in zip(prof.radii, prof.measured, prof.predicted, strict=True):
        if rad >= 2:
            assert m == pytest.approx(pr, rel=0.3), rad
    assert support.predicted_error(0.5, 4) == pytest.approx(
        math.degrees(math.sqrt(math.pi / 2) * 0.5 / math.sqrt(81 * 4 * 5 / 3)))
    # a window read on every second row and column has a quarter of the points: 2x the error
    assert support.predicted_error(1.0, 8, 2) == pytest.approx(
        2.0 * support.predicted_error(1.0, 8), rel=0.15)


def test_depth_exponent_reads_the_growth_of_the_residual():
    rng = np.random.default_rng(0)
    z = rng.uniform(1.0, 4.0, 4000)
    res = (z / 2.0) ** 2 * rng.uniform(0.9, 1.1, z.size)
    zref, gamma = support.depth_exponent(res, z)
    assert gamma == pytest.approx(2.0, abs=0.15)
    assert zref == pytest.approx(np.median(z))
    assert support.depth_exponent(np.ones(100), np.full(100, 2.0))[1] == 0.0


def _reference_choice(z, args):
    out = np.empty((*z.shape, 3), dtype=np.float32)
    dev = np.empty(z.shape, dtype=np.float32)
    for v in range(z.shape[0]):
        for u in range(z.shape[1]):
            *out[v, u], dev[v, u] = support.choose_pixel(z, *args, v, u)
    return out, dev


def _reference_fallback(z, cam, dev, out):
    """Where ``dev`` exceeds DEVIATION: the least residual of the nine radius-2 windows, turned
    toward the pixel's ray."""
    from depthnormals.ddm.boxfit import box_fit_windows

    fx, fy, cx, cy = cam
    out = out.copy()
    rs = support.FALLBACK_RADIUS
    n, score = box_fit_windows(z, fx, fy, cx, cy, rs)
    h, w = z.shape
    for v, u in zip(*np.nonzero(dev > support.DEVIATION), strict=False):
        cand = [(score[v + rs * dv, u + rs * du], v + rs * dv, u + rs * du)
                for dv, du in support.SHIFTS
                if 0 <= v + rs * dv < h and 0 <= u + rs * du < w]
        s, r, c = min(cand, key=lambda x: x[0])  # the first of equal ones
        if s < np.inf:
            m = n[:, r, c]
            out[v, u] = -m if m @ [(u - cx) / fx, (v - cy) / fy, 1.0] > 0 else m
    return out


@pytest.mark.parametrize("radius", [3, 8])
def test_fast_choice_agrees_with_the_per_pixel_reference(radius):
    import dataclasses

    from depthnormals._parallel import run_rows

    r = make_scene("box-on-floor").render(shape=(120, 160), K=(130.0, 130.0, 79.5, 59.5))
    noise = _correlated(r.depth.shape, 0.8, 5, seed=11)
    d = (r.depth * (1.0 + noise / 130.0)).astype(np.float32)
    d[40:50, 60:90] = 0.0  # a hole
    z, cam = prepare(d, r.K, None)
    p = noise_pass(z, cam.fx, cam.fy)
    prof = dataclasses.replace(support.support_profile(z, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma),
                               radius=radius)
    # the rows against the per-pixel reference, at full resolution
    args = support.choice_inputs(z, cam.fx, cam.fy, cam.cx, cam.cy, prof)
    fast = np.empty((*z.shape, 3), dtype=np.float32)
    fast_dev = np.empty(z.shape, dtype=np.float32)
    rows = np.empty((z.shape[0], 3, z.shape[1]), dtype=np.float32)
    run_rows(support._choose_least_rows, z.shape[0], z, *args, fast, fast_dev, rows, min_rows=16)
    ref, ref_dev = _reference_choice(z, args)
    assert np.array_equal(fast, ref, equal_nan=True)
    assert np.array_equal(rows, fast.transpose(0, 2, 1), equal_nan=True)  # the same, by row
    assert np.allclose(fast_dev, ref_dev, rtol=1e-5, atol=1e-5)
    # some pixels of the box's faces deviate, most do not
    assert 0.0 < np.mean(fast_dev > support.DEVIATION) < 0.05
    # the branch: below HALF_RADIUS those rows; from it on the choice of every 2x2 cell; then
    # the fallback of the deviating pixels, then the face switch (tests/faceswitch_reference.py)
    out = support.support_select(z, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma, profile=prof)
    if radius < support.HALF_RADIUS:
        ref = _reference_fallback(z, args[4], fast_dev, fast)
        ref, switched = reference_switch(z, ref, args[4], faceswitch.SPAN)
        assert switched.any()
        assert np.array_equal(out, ref, equal_nan=True)
    else:
        zd = np.ascontiguousarray(z[::2, ::2])
        hargs = support.choice_inputs(zd, cam.fx / 2, cam.fy / 2, cam.cx / 2, cam.cy / 2, prof,
                                      radius=radius // 2, score_scale=4.0)
        zfill = np.where(np.isnan(zd), np.float32(prof.depth), zd)
        half, hdev = _reference_choice(zfill, hargs)
        hdev[np.isnan(zd)] = 0.0
        half = _reference_fallback(zd, hargs[4], hdev, half)
        half, _ = reference_switch(zd, half, hargs[4], faceswitch.SPAN // 2)
        up = np.repeat(np.repeat(half, 2, axis=0), 2, axis=1)[:z.shape[0], :z.shape[1]]
        ok = np.isfinite(out[..., 0])
        # the same window's normal, turned toward each pixel's own ray
        assert np.array_equal(ok, np.isfinite(z) & np.isfinite(up[..., 0]))
        assert np.allclose(np.abs(out[ok]), np.abs(up[ok]), atol=0.0)
    assert np.isnan(out[45, 70]).all()
    ok = np.isfinite(out[..., 0])
    assert np.allclose(np.linalg.norm(out[ok], axis=-1), 1.0, atol=1e-5)


def test_default_on_the_kinect_v1_model():
    from depthnormals.synth.noise import kinect_v1_noise

    r = make_scene("demo-room").render()
    d = kinect_v1_noise(r.depth, r.normals, r.K, rng=np.random.default_rng(0))
    assert dn.estimate_noise(d, r.K) > 0.3  # quantised: plateaus, never clean
    ok = np.isfinite(d) & (d > 0)

    def err(n):
        e = dn.angular_error(n, r.normals)
        e = np.minimum(e, 180.0 - e)[ok]
        return float(np.nanmean(e))

    ours = err(dn.estimate_normals(d, r.K))
    assert ours < 0.7 * err(dn.estimate_normals(d, r.K, method="fals", window=11))
    assert ours < 0.8 * err(dn.estimate_normals(d, r.K, method="pcl-average-3d-gradient"))


def test_batched_profile_statistics_equal_the_per_frame_ones():
    """profiles_from_pair_tables (the torch port's batched statistics) gives, bit for bit, the
    profiles of profile_from_pairs frame by frame: random pair tables with ties (rounded
    values), odd and even counts, a frame with too few pairs at some radius and an empty one."""
    from depthnormals.ddm.support import RADII, profile_from_pairs, profiles_from_pair_tables

    rng = np.random.default_rng(7)
    b, p = 6, 40
    tables = []
    for k, _ in enumerate(RADII):
        rows = np.stack([np.round(rng.gamma(2.0, 3.0 / (k + 1), (b, p)), 2),
                         np.round(rng.gamma(2.0, 0.5 * (k + 1), (b, p)), 3),
                         rng.uniform(1.0, 4.0, (b, p)),
                         rng.integers(0, 4, (b, p)).astype(np.float64)], axis=-1)
        ok = rng.random((b, p)) < 0.7
        ok[1, : p - 9 - k] = False  # frame 1: fewer than 12 pairs from some radius on
        ok[2] = False  # frame 2: none at all
        tables.append((rows, ok))
    sigmas = [0.3, 1.2, float("nan"), 0.0, 2.0, 0.05]
    # tile levels (2 x 2 tiles) per frame, a NaN tile among them (read as the frame's level)
    tiles = rng.uniform(0.02, 1.5, (b, 2, 2))
    tiles[4, 0, 1] = np.nan
    for lev in (None, tiles):
        batch = profiles_from_pair_tables(tables, sigmas, tiles=lev)
        for f, sigma in enumerate(sigmas):
            by_radius = {r: rows[f][ok[f]] for r, (rows, ok) in zip(RADII, tables, strict=True)}
            single = profile_from_pairs(by_radius.__getitem__, sigma,
                                        tiles=None if lev is None else lev[f])
            assert repr(batch[f]) == repr(single), f
    assert batch[2].radii == (1,) and len(batch[1].radii) < len(RADII)
    assert sum(np.isfinite(q.local) for q in batch) >= 2  # the local excess was read
    empty = [(np.zeros((2, 0, 4)), np.zeros((2, 0), dtype=bool)) for _ in RADII]  # no pair
    pairs = [(0.1, tiles[0]), (0.2, tiles[1])]
    assert [repr(q) for q in profiles_from_pair_tables(empty, [0.1, 0.2], tiles=tiles[:2])] == \
        [repr(profile_from_pairs(lambda r: np.zeros((0, 4)), s, tiles=t)) for s, t in pairs]


def _medians_ref(x, ok):
    """numpy reference of the profile's row medians (the implementation before session 20's
    compiled one): per row the median of the entries where ``ok``, NaN where there is none;
    the others read as infinite, so that a NaN entry sorts after them."""
    if x.shape[1] == 0:
        return np.full(x.shape[0], np.nan)
    srt = np.sort(np.where(ok, x, np.inf), axis=1)
    n = ok.sum(axis=1)
    i = np.arange(x.shape[0])
    lo = srt[i, np.clip((n - 1) // 2, 0, None)]
    hi = srt[i, np.clip(n // 2, 0, x.shape[1] - 1)]
    return np.where(n > 0, np.where(n % 2 == 1, hi, np.mean(np.stack([lo, hi]), axis=0)), np.nan)


def test_profile_statistics_equal_numpys_medians():
    """The support profile's per-radius statistics (compiled in session 20: numpy's per-call
    cost on tables of a few hundred pairs was 1.1 of the profile's 1.3 ms at 640x480) equal,
    bit for bit, the numpy reference on random tables: ties, odd and even counts, rows with
    no pair, NaN entries, no column at all, float32 and float64. Plain finite rows also
    agree with ``np.median`` itself."""
    from depthnormals.ddm.support import PAIR_TO_ERROR, _radius_stats

    rng = np.random.default_rng(11)
    for trial in range(400):
        b, m = int(rng.integers(1, 4)), int(rng.integers(0 if trial % 7 == 0 else 1, 40))
        dtype = np.float32 if trial % 3 == 0 else np.float64
        rows = rng.standard_normal((b, m, 3)).round(int(rng.integers(0, 3))).astype(dtype)
        if trial % 5 == 0 and m:
            rows[rng.random((b, m)) < 0.2, int(rng.integers(0, 2))] = np.nan
        ok = rng.random((b, m)) < rng.random()
        ang, res = rows[..., 0], rows[..., 1]
        keep = ok & (res <= _medians_ref(res, ok)[:, None])
        want = (ok.sum(axis=1), PAIR_TO_ERROR * _medians_ref(ang, keep), _medians_ref(res, keep),
                keep)
        for got, ref in zip(_radius_stats(rows, ok), want, strict=True):
            np.testing.assert_array_equal(got, ref)
            if m:
                assert np.asarray(got).dtype == np.asarray(ref).dtype
    x = rng.gamma(2.0, 1.0, (3, 25))
    ok = rng.random((3, 25)) < 0.6
    got = _radius_stats(np.stack([x, x, x], -1), ok)[2]
    keep = ok & (x <= np.array([np.median(r[o]) for r, o in zip(x, ok, strict=True)])[:, None])
    np.testing.assert_array_equal(got, [np.median(r[k]) for r, k in zip(x, keep, strict=True)])


def _table_edge(shape=(240, 320), f=290.0):
    """A table top 0.30 m below the camera from 1.5 m on, its front face 5 cm thick (a strip
    of 10 rows at 1.5 m) and a wall at 3 m below it: depth (H, W), normals, K, the strip."""
    h, w = shape
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    K = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    v = np.mgrid[0:h, 0:w][0].astype(float)
    ry = (v - cy) / f
    z = np.full(shape, 3.0)
    n = np.zeros((h, w, 3))
    n[..., 2] = -1.0
    with np.errstate(divide="ignore"):
        zt = 0.30 / ry
    top = (ry > 0) & (zt >= 1.5)
    z[top] = zt[top]
    n[top] = (0.0, -1.0, 0.0)
    front = (ry * 1.5 >= 0.30) & (ry * 1.5 <= 0.35)
    z[front] = 1.5
    n[front] = (0.0, 0.0, -1.0)
    return z.astype(np.float32), n.astype(np.float32), K, front


def test_a_face_narrower_than_the_windows_falls_back_to_small_windows(monkeypatch):
    """The front face of a table (10 rows) under Kinect v1 noise: the measured support's
    windows (radius >= 6) hold more of the top than of the face, so the face took the top's
    normal (89 deg off). Its depth lies many standard deviations off that plane: it takes a
    small window instead (35-40 deg off: quantised depth over 5x5 cells), and the frame's mean
    error drops."""
    from depthnormals.synth.noise import kinect_v1_noise

    z, normals, K, front = _table_edge()
    rows = np.nonzero(front.any(axis=1))[0]
    inner = np.zeros_like(front)
    inner[rows[0] + 1:rows[-1], 20:-20] = True  # the face's rows but its first and last
    inner &= front
    d = kinect_v1_noise(z, normals, K, rng=np.random.default_rng(0))
    assert dn.noise_profile(d, K).branch == "measured-support"
    assert dn.noise_profile(d, K).radius >= support.HALF_RADIUS

    def errors():
        e = dn.angular_error(dn.estimate_normals(d, K), normals)
        return float(np.nanmean(e[inner])), float(np.nanmean(e))

    face, frame = errors()
    monkeypatch.setattr(support, "DEVIATION", np.inf)
    face_before, frame_before = errors()
    assert face_before > 85.0  # the top's normal
    assert face < 45.0
    assert frame < frame_before - 0.1


def test_few_pixels_of_a_plane_deviate():
    """On one plane under correlated Kinect-like noise the deviation from the chosen window's
    plane is a residual in units of its own measured spread: about half-normal (median near
    0.67), and beyond DEVIATION on almost no pixel."""
    from depthnormals.synth.noise import kinect_v1_noise

    r = make_scene("tilted-plane").render(shape=(240, 320), K=(290.0, 290.0, 159.5, 119.5))
    d = kinect_v1_noise(r.depth, r.normals, r.K, rng=np.random.default_rng(2))
    zp, cam = prepare(d, r.K, None)
    p = noise_pass(zp, cam.fx, cam.fy)
    scores: list = []
    support.support_select(zp, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma, out_scores=scores)
    dev = scores[3]
    ok = dev > 0
    assert ok.mean() > 0.9
    assert 0.4 < float(np.median(dev[ok])) < 1.0
    assert float(np.mean(dev[ok] > support.DEVIATION)) < 1e-3


def test_no_fallback_below_its_radius():
    """A choice of radius FALLBACK_RADIUS or less has no smaller window to fall back to: the
    branch hands the map an infinite limit (no pixel fell back, whatever it deviates), and its
    normals are the choice's after the face switch; from radius 3 on the limit is DEVIATION.
    The map's copy of the choice is taken before the switch either way (until session 39,
    where none fell back it was the output itself, which the switch changes in place); since
    session 40 the choice writes it by row, (H, 3, W)."""
    import dataclasses

    from depthnormals.ddm.faceswitch import switch_faces
    from depthnormals.synth.noise import kinect_v1_noise

    z, normals, K, _ = _table_edge((120, 160), f=145.0)
    d = kinect_v1_noise(z, normals, K, rng=np.random.default_rng(1))
    zp, cam = prepare(d, K, None)
    p = noise_pass(zp, cam.fx, cam.fy)
    base = support.support_profile(zp, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma)
    for radius, limit in ((support.FALLBACK_RADIUS, np.inf), (3, support.DEVIATION)):
        prof = dataclasses.replace(base, radius=radius)
        scores: list = []
        out = support.support_select(zp, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma, profile=prof,
                                     out_scores=scores)
        rows, dev, got = scores[2], scores[3], scores[4]
        assert got == limit
        assert (dev > support.DEVIATION).any()  # deviating pixels either way
        assert rows.shape == (zp.shape[0], 3, zp.shape[1])  # by row, for the map
        assert not np.shares_memory(rows, out)
        before = np.ascontiguousarray(rows.transpose(0, 2, 1))
        if limit == np.inf:
            switched, _, _ = switch_faces(zp, before.copy(), cam.fx, cam.fy, cam.cx, cam.cy,
                                          span=support.SWITCH_SPAN)
            assert np.array_equal(out, switched, equal_nan=True)
            assert not np.array_equal(out, before, equal_nan=True)  # the switch moved cells
        else:
            assert not np.array_equal(out, before, equal_nan=True)
