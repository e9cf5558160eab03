"""The noise estimate, the box-fit kernels and the noise-aware selection (issue 13)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import box_on_floor, make_scene, planar_interior, tilted_plane
from depthnormals.ddm.auto import box_radius, box_select
from depthnormals.ddm.boxfit import MIN_POINTS, box_fit_normals, box_fit_windows
from depthnormals.kernels.depth import prepare

K_SMALL = (160.0, 160.0, 79.5, 59.5)


def _noisy(depth: np.ndarray, fx: float, sigma: float, seed: int = 0) -> np.ndarray:
    d = depth.copy()
    m = d > 0
    d[m] += np.random.default_rng(seed).normal(size=int(m.sum())) * sigma * d[m] / fx
    return d


@pytest.mark.parametrize("sigma", [0.05, 0.1, 0.3])
def test_noise_estimate_recovers_sigma_on_a_noisy_plane(sigma):
    r = tilted_plane().render()
    est = dn.estimate_noise(_noisy(r.depth, r.K.fx, sigma), r.K)
    assert abs(est - sigma) < 0.1 * sigma


def test_noise_estimate_is_tiny_on_clean_depth_and_unit_free():
    r = box_on_floor().render()
    assert dn.estimate_noise(r.depth.astype(np.float32), r.K) < 1e-3  # float32 rounding only
    d = _noisy(r.depth, r.K.fx, 0.1)
    assert dn.estimate_noise(d, r.K) == pytest.approx(dn.estimate_noise(d * 1000.0, r.K), rel=1e-9)
    assert abs(dn.estimate_noise(d, r.K) - 0.1) < 0.01  # edges do not move the median


def test_noise_estimate_without_triples_is_nan():
    z = np.zeros((5, 6))
    z[2, 2] = 1.0
    assert np.isnan(dn.estimate_noise(z, K_SMALL))


def test_box_fit_is_exact_on_planes():
    r = tilted_plane().render(shape=(120, 160), K=K_SMALL)
    for radius in (1, 2, 5):
        n = box_fit_normals(r.depth, r.K, radius=radius)
        assert np.abs(n - r.normals).max() < 2e-5
    # every face interior of the box scene, with shifted windows choosing at the edges
    r = box_on_floor().render(shape=(120, 160), K=K_SMALL)
    n = box_fit_normals(r.depth, r.K, radius=2)
    inner = planar_interior(r, radius=2)
    err = dn.angular_error(n, r.normals)[inner]
    assert np.nanmax(err) < 1e-3


def _reference_fit(z: np.ndarray, fx, fy, cx, cy, r):
    """Per-pixel numpy least squares of w = a du + b dv + c (the slow, readable path)."""
    h, w = z.shape
    nrm = np.full((3, h, w), np.nan)
    score = np.full((h, w), np.inf)
    for v in range(h):
        for u in range(w):
            rows = []
            for dv in range(-r, r + 1):
                for du in range(-r, r + 1):
                    a, b = v + dv, u + du
                    if 0 <= a < h and 0 <= b < w and np.isfinite(z[a, b]):
                        rows.append((du, dv, 1.0, 1.0 / z[a, b]))
            if len(rows) < MIN_POINTS:
                continue
            m = np.array(rows)
            X, y = m[:, :3], m[:, 3]
            if np.linalg.matrix_rank(X) < 3:
                continue
            (ca, cb, cc), *_ = np.linalg.lstsq(X, y, rcond=None)
            rss = float(np.sum((X @ np.array([ca, cb, cc]) - y) ** 2))
            n = np.array([fx * ca, fy * cb, cc - ca * (u - cx) - cb * (v - cy)])
            n /= np.linalg.norm(n)
            if n @ np.array([(u - cx) / fx, (v - cy) / fy, 1.0]) > 0:
                n = -n
            nrm[:, v, u] = n
            score[v, u] = rss / (len(rows) - 3) * (fx / cc) ** 2
    return nrm, score


@pytest.mark.parametrize("radius", [1, 2, 4])
def test_fast_box_fit_equals_the_numpy_reference(radius):
    r = make_scene("sphere-before-wall").render(shape=(36, 44), K=(40.0, 40.0, 21.5, 17.5))
    d = _noisy(r.depth, 40.0, 0.3, seed=1)
    d[5:9, 10:13] = 0.0  # a hole
    d[20, 30] = np.nan
    z, cam = prepare(d, r.K, None)
    fast_n, fast_s = box_fit_windows(z, cam.fx, cam.fy, cam.cx, cam.cy, radius)
    ref_n, ref_s = _reference_fit(z, cam.fx, cam.fy, cam.cx, cam.cy, radius)
    assert np.array_equal(np.isnan(fast_n), np.isnan(ref_n))
    ok = np.isfinite(ref_s)
    assert np.nanmax(np.abs(fast_n - ref_n)) < 1e-5
    assert np.allclose(fast_s[ok], ref_s[ok], rtol=1e-3, atol=1e-6)
    assert np.all(np.isinf(fast_s[~ok]))


def test_box_radius_follows_the_noise():
    assert box_radius(float("nan")) == 1
    assert box_radius(0.1) == 2
    assert box_radius(0.43) == 3
    assert box_radius(100.0) == 6


def test_big_radius_follows_the_noise():
    """The large centred window: 17x17 up to 0.29 footprints (predicted 0.2 deg), growing to
    33x33 from about 1 footprint, never below the small windows; 17x17 without a level."""
    from depthnormals.ddm.auto import BIG_RADIUS, MAX_BIG_RADIUS, big_radius

    assert big_radius(float("nan")) == big_radius(0.0) == big_radius(0.29) == BIG_RADIUS == 8
    assert big_radius(0.3) == 9 and big_radius(0.5) == 11
    assert big_radius(1.0) == big_radius(100.0) == MAX_BIG_RADIUS == 16
    sig = np.geomspace(0.01, 50.0, 200)
    radii = [big_radius(s) for s in sig]
    assert radii == sorted(radii) and all(b >= box_radius(s) for b, s in zip(radii, sig, strict=True))


@pytest.mark.parametrize(("scene", "noise", "before", "bound"), [
    ("tilted-plane", "gaussian", 0.76, 0.25), ("tilted-plane", "tof", 1.60, 0.55),
    ("box-on-floor", "tof", 1.91, 1.1), ("sphere-before-wall", "gaussian", 0.88, 0.65)])
def test_the_large_window_on_noisier_depth(scene, noise, before, bound):
    """Where one plane holds a 33x33 window within the noise, the default takes it on depth
    of ~1 footprint of noise: the mean error (640x480, 1 footprint Gaussian or the tof model)
    drops from ``before`` (a 17x17 large window, git e0e0173) below ``bound``; the map follows
    (within 40 %)."""
    from depthnormals.synth.noise import tof_noise

    r = make_scene(scene).render(K=(525.0, 525.0, 319.5, 239.5), shape=(480, 640))
    if noise == "tof":
        d = np.asarray(tof_noise(r.depth, r.normals, r.K, rng=np.random.default_rng(1)))
    else:
        d = _noisy(r.depth, r.K.fx, 1.0, seed=2)
    assert dn.noise_profile(d, r.K).branch == "box-fit"
    n, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
    e = float(np.nanmean(dn.angular_error(n, r.normals)))
    assert e < bound < before
    assert 0.6 < float(np.nanmean(u)) / e < 1.6


def test_auto_on_clean_depth_is_the_plane_selection():
    r = box_on_floor().render(shape=(120, 160), K=K_SMALL)
    d = r.depth.astype(np.float32)
    auto = dn.estimate_normals(d, r.K, method="3f2n+", selection="auto")
    ref = dn.estimate_normals(d, r.K, method="3f2n+", selection="planes")
    assert np.array_equal(auto, ref, equal_nan=True)
    assert np.array_equal(auto, dn.ddm.plane_normals(d, r.K), equal_nan=True)
    # the generic path (any estimator's normals) agrees with the fused one
    gen = dn.discontinuity_discrimination(dn.estimate_normals(d, r.K, method="3f2n"), d, r.K,
                                          selection="auto")
    assert np.array_equal(auto, gen, equal_nan=True)
    # the paper's CRF keeps its curvature selection (margin 0) on clean depth
    crf = dn.estimate_normals(d, r.K, method="3f2n+", crf=True, lambda_=0.0)
    cur = dn.estimate_normals(d, r.K, method="3f2n+", selection="curvature", consistency=0.0)
    assert np.array_equal(crf, cur, equal_nan=True)


def test_auto_on_slightly_noisy_depth_is_the_box_fit():
    """Between the plane hypotheses' limit (0.001 footprints) and sensor noise the box-fit
    runs: the curvature selection (auto's clean branch until session 6) was 5-20x worse
    there."""
    r = box_on_floor().render(shape=(120, 160), K=K_SMALL)
    d = _noisy(r.depth, K_SMALL[0], 0.005)
    assert 1e-3 < dn.estimate_noise(d, r.K) < 0.03
    auto = dn.estimate_normals(d, r.K)
    assert np.array_equal(auto, dn.estimate_normals(d, r.K, selection="box-fit"), equal_nan=True)
    e = dn.normal_metrics(auto, r.normals).mean
    e_cur = dn.normal_metrics(dn.estimate_normals(d, r.K, selection="curvature",
                                                  consistency=0.0), r.normals).mean
    e_planes = dn.normal_metrics(dn.estimate_normals(d, r.K, selection="planes"),
                                 r.normals).mean
    assert e < 0.5 * e_cur and e < 0.5 * e_planes, (e, e_cur, e_planes)


def test_auto_on_noisy_depth_beats_the_curvature_selection():
    r = box_on_floor().render(shape=(240, 320), K=(262.5, 262.5, 159.5, 119.5))
    d = _noisy(r.depth, r.K.fx, 0.1)
    e_today = dn.normal_metrics(dn.estimate_normals(d, r.K, selection="curvature", consistency=0.1),
                                r.normals).mean
    e_auto = dn.normal_metrics(dn.estimate_normals(d, r.K, selection="auto"), r.normals).mean
    e_box = dn.normal_metrics(dn.estimate_normals(d, r.K, selection="box-fit"), r.normals).mean
    assert e_auto < 0.1 * e_today  # measured 0.63 vs 11.1 deg (curvature selection, the old default)
    assert e_box == e_auto  # noisy depth: "auto" is the box-fit


def test_auto_keeps_the_abstentions_of_the_base():
    r = box_on_floor().render(shape=(120, 160), K=K_SMALL)
    for d in (r.depth, _noisy(r.depth, K_SMALL[0], 0.1)):
        base = dn.estimate_normals(d, r.K, method="line-mod")
        plus = dn.estimate_normals(d, r.K, method="line-mod+", selection="auto")
        assert np.isnan(base).any()
        assert np.array_equal(np.isnan(plus).any(-1), np.isnan(base).any(-1) | ~(d > 0))


def test_box_fit_rejects_bad_options():
    z = np.ones((8, 8))
    with pytest.raises(ValueError, match="radius"):
        box_fit_normals(z, K_SMALL, radius=0)
    with pytest.raises(TypeError, match="radius"):
        box_fit_normals(z, K_SMALL, radius=2.5)
    with pytest.raises(ValueError, match="shift"):
        box_fit_normals(z, K_SMALL, radius=2, shift=3)
    with pytest.raises(ValueError, match="gate"):
        box_fit_normals(z, K_SMALL, gate=-1.0)


def _reference_local_choice(z, K, r, big, gate, sigma):
    """Per-pixel numpy version of the box-fit's choice with a noise level (module doc)."""
    fx, fy, cx, cy = K
    nrm_s, s_s = _reference_fit(z, fx, fy, cx, cy, r)
    nrm_b, s_b = _reference_fit(z, fx, fy, cx, cy, big)
    h, w = z.shape
    out = np.full((h, w, 3), np.nan)
    for v in range(h):
        for u in range(w):
            if not np.isfinite(z[v, u]):
                continue
            if s_b[v, u] <= gate:
                out[v, u] = nrm_b[:, v, u]
                continue
            best, pick = np.inf, (v, u)
            if not s_s[v, u] <= gate:
                for dv, du in ((0, 0), (-1, 0), (0, -1), (0, 1), (1, 0), (-1, -1), (-1, 1),
                               (1, -1), (1, 1)):
                    a, b = v + r * dv, u + r * du
                    if not (0 <= a < h and 0 <= b < w and np.isfinite(s_s[a, b])):
                        continue
                    n = nrm_s[:, a, b]
                    total = 0.0
                    for p in range(max(v - 1, 0), min(v + 2, h)):
                        for q in range(max(u - 1, 0), min(u + 2, w)):
                            if np.isfinite(z[p, q]):
                                ray_p = np.array([(q - cx) / fx, (p - cy) / fy, 1.0])
                                ray_c = np.array([(b - cx) / fx, (a - cy) / fy, 1.0])
                                # the window's plane, through its fitted point at its centre
                                pred = (n @ ray_p) / (n @ ray_c) * _centre_w(z, a, b, r)
                                res = (1.0 / z[p, q] - pred) * fx * z[p, q] / sigma
                                total += min(res * res, 25.0)
                    if total < best:
                        best, pick = total, (a, b)
            out[v, u] = nrm_s[:, pick[0], pick[1]]
    return out


def _centre_w(z, a, b, r):
    """The fitted inverse depth at a window's centre (its intercept c)."""
    h, w = z.shape
    rows = [(du, dv, 1.0, 1.0 / z[a + dv, b + du]) for dv in range(-r, r + 1)
            for du in range(-r, r + 1)
            if 0 <= a + dv < h and 0 <= b + du < w and np.isfinite(z[a + dv, b + du])]
    m = np.array(rows)
    return np.linalg.lstsq(m[:, :3], m[:, 3], rcond=None)[0][2]


def test_local_window_choice_equals_the_numpy_reference():
    K = (40.0, 40.0, 21.5, 17.5)
    r = box_on_floor().render(shape=(30, 40), K=K)
    d = _noisy(r.depth, 40.0, 0.1, seed=2)
    z, _ = prepare(d, K, None)
    fast = box_fit_normals(d, K, radius=1, big_radius=3, gate=0.03, sigma=0.1)
    ref = _reference_local_choice(z, K, 1, 3, 0.03, 0.1)
    assert np.array_equal(np.isnan(fast), np.isnan(ref))
    assert np.nanmax(np.abs(fast - ref)) < 1e-4


# --- "auto" is the module's default (issue 13) -------------------------------------------

def test_the_module_default_is_auto():
    assert dn.ddm.module_defaults()["selection"] == "auto"
    assert dn.ddm.ModuleOptions().selection == "auto"
    # the margin of an explicit selection="curvature" is unchanged (0.1); auto's clean branch
    # takes min(consistency, 0)
    assert dn.ddm.module_defaults()["consistency"] == 0.1


@pytest.mark.parametrize("scene", ["tilted-plane", "box-on-floor", "stairs", "sphere-before-wall"])
def test_default_on_clean_analytic_depth_is_the_plane_selection(scene):
    r = make_scene(scene).render(shape=(120, 160), K=K_SMALL)
    assert dn.estimate_noise(r.depth, r.K) < 1e-3
    for method in ("3f2n+", "d2nt+"):  # the fused path and the generic one
        default = dn.estimate_normals(r.depth, r.K, method=method)
        clean = dn.estimate_normals(r.depth, r.K, method=method, selection="planes")
        assert np.array_equal(default, clean, equal_nan=True), method
        n0 = dn.estimate_normals(r.depth, r.K, method=method[:-1])
        assert np.array_equal(dn.discontinuity_discrimination(n0, r.depth, r.K),
                              dn.discontinuity_discrimination(n0, r.depth, r.K, selection="planes"),
                              equal_nan=True)
    # never worse than the curvature selection (auto's clean branch until session 6)
    old = dn.estimate_normals(r.depth, r.K, method="3f2n+", selection="curvature", consistency=0.0)
    new = dn.estimate_normals(r.depth, r.K, method="3f2n+")
    e_old, e_new = (dn.normal_metrics(n, r.normals).mean for n in (old, new))
    assert e_new <= e_old + 1e-4, (e_new, e_old)


@pytest.mark.parametrize("scene", ["box-on-floor", "sphere-before-wall"])
def test_default_on_noisy_analytic_depth_is_the_box_fit(scene):
    r = make_scene(scene).render(shape=(120, 160), K=K_SMALL)
    d = _noisy(r.depth, K_SMALL[0], 0.1)
    assert dn.estimate_noise(d, r.K) >= 0.03
    for method in ("3f2n+", "d2nt+", "line-mod+"):
        default = dn.estimate_normals(d, r.K, method=method)
        box = dn.estimate_normals(d, r.K, method=method, selection="box-fit")
        assert np.array_equal(default, box, equal_nan=True), method
    # the fused 3f2n+ under noise is the box-fit branch alone (3F2N's normals are not used)
    z, cam = prepare(d, r.K, None)
    branch = box_select(z, None, cam.fx, cam.fy, cam.cx, cam.cy, dn.estimate_noise(d, r.K))
    default = dn.estimate_normals(d, r.K)
    assert np.array_equal(default, branch, equal_nan=True)
    old = dn.estimate_normals(d, r.K, selection="curvature", consistency=0.1)
    e, e_old = (dn.normal_metrics(n, r.normals).mean for n in (default, old))
    assert e < 0.25 * e_old, (e, e_old)


def test_estimate_noise_is_public_and_documented():
    import depthnormals.ddm.noise as noise

    assert "estimate_noise" in dn.__all__
    assert dn.estimate_noise is noise.estimate_noise
    doc = dn.estimate_noise.__doc__
    assert "Parameters" in doc and "Returns" in doc and "footprint" in doc
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    assert "estimate_noise" in readme
    assert "estimate_noise" in (Path(__file__).resolve().parents[1] / "docs" / "3f2n-plus.md").read_text()


# --- per-region noise (issue 13: "per image or per region") -------------------------------

def _two_level_plane(left: float, right: float, seed: int = 0):
    r = tilted_plane().render()
    s = np.where(np.arange(r.depth.shape[1]) < 320, left, right)[None, :]
    d = r.depth + np.random.default_rng(seed).normal(size=r.depth.shape) * s * r.depth / r.K.fx
    return r, d


def test_noise_map_reads_each_region_level():
    r, d = _two_level_plane(0.1, 0.4)
    m = dn.estimate_noise_map(d, r.K)
    assert m.shape == d.shape and m.dtype == np.float32
    # tiles wholly left of column 320 read 0.1, wholly right 0.4: each a median of ~340
    # samples (~8 % standard error), so every tile within 35 % and their median within 5 %
    left, right = m[::64, :256:64], m[::64, 384::64]
    assert np.allclose(left, 0.1, rtol=0.35) and np.allclose(right, 0.4, rtol=0.35)
    assert abs(np.median(left) - 0.1) < 0.005 and abs(np.median(right) - 0.4) < 0.02
    # the image's level lies between the two
    assert 0.1 * 1.15 < dn.estimate_noise(d, r.K) < 0.4 * 0.85


def test_noise_map_falls_back_to_the_image_level_and_rejects_bad_tiles():
    r, d = _two_level_plane(0.2, 0.2)
    d[:, :64] = 0.0  # a column of tiles with no valid triple
    m = dn.estimate_noise_map(d, r.K, tile=32)
    from depthnormals.ddm.noise import noise_levels

    z, cam = prepare(d, r.K, None)
    sigma32, _ = noise_levels(z, cam.fx, cam.fy, tile=32)  # the median of the map's own samples
    assert np.all(m[:, :64] == np.float32(sigma32))
    assert abs(sigma32 - dn.estimate_noise(d, r.K)) < 0.05 * sigma32
    rest = m[:, 96:]  # ~100 samples a 32x32 tile: ~13 % standard error
    assert 0.1 < rest.min() and rest.max() < 0.4 and abs(np.median(rest) - 0.2) < 0.02
    for bad in (4, 7.5, True, "64"):
        with pytest.raises(ValueError, match="tile"):
            dn.estimate_noise_map(d, r.K, tile=bad)


def test_box_fit_with_one_tile_level_equals_the_global_level():
    from depthnormals.ddm.boxfit import box_fit_from_prepared

    r = box_on_floor().render(shape=(120, 160), K=K_SMALL)
    d = _noisy(r.depth, K_SMALL[0], 0.2, seed=3)
    z, cam = prepare(d, r.K, None)
    args = (z, cam.fx, cam.fy, cam.cx, cam.cy)
    kw = {"radius": 2, "shift": 2, "gate": 0.12, "self_weight": 1.0, "big_radius": 6, "sigma": 0.2}
    plain = box_fit_from_prepared(*args, **kw)
    same = box_fit_from_prepared(*args, **kw, sigma_tiles=(np.full((2, 3), 0.2), 64))
    assert np.array_equal(plain, same, equal_nan=True)
    # NaN tiles read as the global level too; another level changes the answer
    nan_tiles = box_fit_from_prepared(*args, **kw, sigma_tiles=(np.full((2, 3), np.nan), 64))
    assert np.array_equal(plain, nan_tiles, equal_nan=True)
    other = box_fit_from_prepared(*args, **kw, sigma_tiles=(np.full((2, 3), 0.05), 64))
    assert not np.array_equal(plain, other, equal_nan=True)


def test_local_noise_beats_one_level_where_the_noise_changes_across_the_image():
    # a step whose near half is noisier (as a Kinect's near range): the per-tile level keeps the
    # noisy half's large windows and the quiet half's edges
    r = make_scene("stairs").render()
    s = np.where(np.arange(r.depth.shape[1]) < 320, 0.05, 0.4)[None, :]
    d = r.depth + np.random.default_rng(1).normal(size=r.depth.shape) * s * r.depth / r.K.fx
    z, cam = prepare(d, r.K, None)
    sigma = dn.estimate_noise(d, r.K)
    local = box_select(z, None, cam.fx, cam.fy, cam.cx, cam.cy, sigma)
    one = box_select(z, None, cam.fx, cam.fy, cam.cx, cam.cy, sigma, local=False)
    e_local, e_one = (dn.normal_metrics(n, r.normals).mean for n in (local, one))
    assert e_local < 0.97 * e_one, (e_local, e_one)
    assert np.array_equal(dn.estimate_normals(d, r.K), local, equal_nan=True)
