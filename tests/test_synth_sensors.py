"""Active-stereo (``realsense_d4xx``) and time-of-flight (``tof``) noise models, and the
statistics of every model against real frames (``kinect_v1`` plateaus and steps, spatially
correlated noise; the real values come from ``benchmarks/sensor_stats.py``).

Analytic scenes: fronto-parallel or tilted planes rendered by the rasteriser, and step
scenes built directly as arrays (a foreground slab at 1 m over a background at 3 m), where
the occlusion band, the fattened edge and the mixed pixels have exact expected columns.
"""

from __future__ import annotations

import numpy as np
import pytest

from depthnormals.camera import Intrinsics
from depthnormals.render import render_mesh, render_subsamples
from depthnormals.synth import generate
from depthnormals.synth.noise import (
    MODELS,
    _correlated_normal,
    _correlation_kernel,
    _separable_reference,
    discontinuity_mask,
    incidence_angle,
    kinect_v1_noise,
    noise_std,
    parse_noise_spec,
    realsense_d4xx_noise,
    stereo_occlusion,
    tof_noise,
)

K = Intrinsics(365.5, 365.5, 63.5, 52.5)  # Kinect v2 focal length, 128 x 106 crop
H, W = 106, 128
F_B = 365.5 * 0.05  # focal (px) x D435 baseline (m)
OFF = {"subpixel": 0.0, "quantum": 0.0, "hole_range": np.inf}  # the geometric effects alone


def _plane(z0, tilt_deg=0.0):
    """Render the plane through (0, 0, z0) rotated about the camera y axis by tilt_deg."""
    a = np.radians(tilt_deg)
    n = np.array([np.sin(a), 0.0, -np.cos(a)])
    e1 = np.cross(n, [0, 1, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    c = np.array([0, 0, z0])
    V = np.array([c - 50 * e1 - 50 * e2, c + 50 * e1 - 50 * e2, c + 50 * e1 + 50 * e2, c - 50 * e1 + 50 * e2])
    r = render_mesh(V, [[0, 1, 2], [0, 2, 3]], K, width=W, height=H)
    assert np.all(r.face >= 0)
    return r


def _step(fg_cols):
    """Depth 3 m with a 1 m foreground on the columns ``fg_cols``; normals face the camera."""
    z = np.full((H, W), 3.0)
    z[:, fg_cols] = 1.0
    n = np.zeros((H, W, 3))
    n[..., 2] = -1.0
    return z, n


def _rng(seed=0):
    return np.random.default_rng(seed)


# ---------------------------------------------------------------- realsense_d4xx: noise ----

def test_stereo_std_grows_as_z_squared():
    zs = np.array([0.6, 1.0, 1.6, 2.5, 4.0])
    stds = []
    for i, z0 in enumerate(zs):
        r = _plane(z0)
        noisy = realsense_d4xx_noise(r.depth, r.normals, K, rng=_rng(i), hole_range=np.inf)
        ok = noisy > 0
        res = noisy[ok] - r.depth[ok]
        stds.append(np.sqrt(np.mean(res ** 2)))
        # and the level is the published one: z^2 sqrt(0.08^2 + (1/32)^2 / 12) / (f b)
        assert stds[-1] / noise_std("realsense_d4xx", z0, K=K) == pytest.approx(1.0, abs=0.04)
    slope = np.polyfit(np.log(zs), np.log(stds), 1)[0]
    assert abs(slope - 2.0) < 0.15, slope
    # a gaussian model's std grows as z (sigma_px): the fit tells the two apart
    assert abs(slope - 1.0) > 0.8


def test_stereo_baseline_scales_noise():
    r = _plane(2.0)
    rms = []
    for b in (0.05, 0.1):
        noisy = realsense_d4xx_noise(r.depth, r.normals, K, rng=_rng(3), baseline=b, hole_range=np.inf)
        ok = noisy > 0
        rms.append(np.sqrt(np.mean((noisy[ok] - r.depth[ok]) ** 2)))
    assert rms[0] / rms[1] == pytest.approx(2.0, rel=0.05)


def test_stereo_disparity_quantised_to_32nds():
    r = _plane(2.0)
    noisy = realsense_d4xx_noise(r.depth, r.normals, K, rng=_rng(1))
    disp = F_B / noisy[noisy > 0]
    assert np.allclose(disp * 32, np.rint(disp * 32), atol=1e-6)
    levels = np.unique(np.rint(disp * 32))
    assert len(levels) >= 10  # noise 0.08 px spans several 1/32 steps
    assert np.min(np.diff(levels)) == 1  # consecutive steps present: the grid is 1/32, not coarser
    # without quantisation the values leave the grid
    free = realsense_d4xx_noise(r.depth, r.normals, K, rng=_rng(1), quantum=0.0)
    d2 = F_B / free[free > 0] * 32
    assert np.mean(np.abs(d2 - np.rint(d2)) > 0.01) > 0.9


# ---------------------------------------------------------- realsense_d4xx: geometry ----

def test_occlusion_band_left_of_foreground_for_right_imager():
    z, n = _step(slice(64, None))  # foreground on the right half
    noisy = realsense_d4xx_noise(z, n, K, rng=_rng(), fatten_px=0, **OFF)
    # background column u is hidden iff 64 - d_fg < u - d_bg: u >= 64 - (d_fg - d_bg) = 51.8
    d_fg, d_bg = F_B / 1.0, F_B / 3.0
    first = int(np.ceil(64 - (d_fg - d_bg)))
    assert first == 52
    assert np.all(noisy[:, first:64] == 0)
    # left image border: u - d_bg < -0.5 is outside the second image
    border = int(np.ceil(d_bg - 0.5))
    assert np.all(noisy[:, :border] == 0) and np.all(noisy[:, border:first] > 0)
    assert np.all(noisy[:, 64:] > 0)
    np.testing.assert_allclose(noisy[:, border:first], 3.0, rtol=1e-12)


def test_occlusion_band_follows_the_baseline_sign():
    z, n = _step(slice(None, 64))  # foreground on the left half
    right = realsense_d4xx_noise(z, n, K, rng=_rng(), fatten_px=0, **OFF)
    left = realsense_d4xx_noise(z, n, K, rng=_rng(), baseline=-0.05, fatten_px=0, **OFF)
    # second imager at +x: the background right of the foreground is seen by both
    assert np.all(right[:, 64:W - 1] > 0)
    # second imager at -x: it is hidden for d_fg - d_bg = 12.2 columns
    assert np.all(left[:, 64:76] == 0) and np.all(left[:, 76:W - 7] > 0)
    # the function itself, mirrored
    disp = F_B / z
    assert np.array_equal(stereo_occlusion(disp, right=False), stereo_occlusion(disp[:, ::-1])[:, ::-1])


def test_edge_fattening_moves_the_foreground_boundary_outward():
    z, n = _step(slice(None, 64))  # right edge of the foreground is visible to both imagers
    widths = {}
    for px in (0, 2, 4):
        noisy = realsense_d4xx_noise(z, n, K, rng=_rng(), fatten_px=px, **OFF)
        fg = np.isclose(noisy, 1.0)  # (the left 18 columns are the border band, d_fg = 18.3 px)
        widths[px] = np.flatnonzero(fg[H // 2])[-1] + 1  # the foreground's right boundary
        assert np.all(np.isclose(noisy[:, 64 + px:W - 1], 3.0))  # beyond the fattened band: background
    assert widths == {0: 64, 2: 66, 4: 68}


def test_fattening_leaves_smooth_slopes_alone():
    r = _plane(2.0, tilt_deg=60.0)
    a = realsense_d4xx_noise(r.depth, r.normals, K, rng=_rng(), fatten_px=3, **OFF)
    b = realsense_d4xx_noise(r.depth, r.normals, K, rng=_rng(), fatten_px=0, **OFF)
    assert np.array_equal(a, b)


def test_stereo_range_limits_and_far_holes():
    # nearer than MinZ = f b / 126 = 0.145 m: nothing; farther than 10 m (13 m: 5 sigma): nothing
    for z0 in (0.12, 13.0):
        z = np.full((H, W), z0)
        n = np.zeros((H, W, 3))
        n[..., 2] = -1
        out = realsense_d4xx_noise(z, n, K, rng=_rng(), hole_range=np.inf)
        assert np.all(out == 0)
    # just inside: returned (right of the border band of width d)
    for z0, cols, share in ((0.3, slice(70, None), 1.0), (9.0, slice(10, None), 0.98)):
        z = np.full((H, W), z0)
        n = np.zeros((H, W, 3))
        n[..., 2] = -1
        out = realsense_d4xx_noise(z, n, K, rng=_rng(), hole_range=np.inf)
        assert np.mean(out[:, cols] > 0) >= share
    # fill rate falls with distance as the logistic says (blocks of 4 px: 27 x 32 draws)
    rates = []
    for z0 in (2.0, 6.0, 8.0):
        r = _plane(z0)
        out = realsense_d4xx_noise(r.depth, r.normals, K, rng=_rng(5))
        rates.append(np.mean(out[:, 40:] > 0))  # right of the 40 px border band
    theta = incidence_angle(_plane(6.0).normals, K)[:, 40:]
    expect6 = 1 - np.mean(1 / (1 + np.exp(-(6.0 / np.sqrt(np.cos(theta)) - 6.0) / 0.6)))
    assert rates[0] > 0.99 and rates[2] < 0.1
    assert abs(rates[1] - expect6) < 0.06


# ------------------------------------------------------------------------- tof ----

def _tof_pixels(z0, tilt, seed):
    r = _plane(z0, tilt)
    noisy = tof_noise(r.depth, r.normals, K, rng=_rng(seed), rounding=0.0)
    ok = noisy > 0
    theta = incidence_angle(r.normals, K)[ok]
    amp = 0.5 * np.cos(theta) / r.depth[ok] ** 2
    return noisy[ok] - r.depth[ok], amp, noise_std("tof", r.depth[ok], theta, rounding=0.0)


def test_tof_std_scales_with_inverse_sqrt_amplitude():
    rms_res, rms_amp = [], []
    for i, (z0, tilt) in enumerate([(0.8, 0), (1.5, 0), (3.0, 0), (2.0, 30), (2.0, 60), (1.5, 75)]):
        res, amp, pred = _tof_pixels(z0, tilt, i)
        assert np.sqrt(np.mean(res ** 2)) / np.sqrt(np.mean(pred ** 2)) == pytest.approx(1.0, abs=0.04)
        rms_res.append(np.sqrt(np.mean(res ** 2)))
        rms_amp.append(np.sqrt(np.mean(1.0 / amp)))  # the RMS of amplitude^-1/2
    slope = np.polyfit(np.log(rms_amp), np.log(rms_res), 1)[0]
    assert abs(slope - 1.0) < 0.05, slope  # sigma ~ amplitude^-1/2 (1/amplitude would give 2)


def test_tof_spec_level_and_low_amplitude_cutoff():
    # 15 % reflectivity at 3.86 m: the Azure Kinect random error, 17 mm
    assert float(noise_std("tof", 3.86, albedo=0.15, rounding=0.0)) == pytest.approx(0.017, rel=1e-12)
    # default albedo 0.5: amplitude falls below the reference beyond 3.86 sqrt(0.5 / 0.15) = 7.05 m
    z = np.full((4, 4), 7.0)
    n = np.zeros((4, 4, 3))
    n[..., 2] = -1
    cam = Intrinsics(365.5, 365.5, 1.5, 1.5)
    assert np.all(tof_noise(z, n, cam, rng=_rng()) > 0)
    assert np.all(tof_noise(np.full((4, 4), 7.1), n, cam, rng=_rng()) == 0)
    assert np.all(tof_noise(np.full((4, 4), 0.45), n, cam, rng=_rng()) == 0)  # min range 0.5 m


def test_tof_flying_pixels_lie_between_the_surfaces():
    z, n = _step(slice(None, 64))
    out = tof_noise(z, n, K, rng=_rng(), sigma_ref=0.0, rounding=0.0)
    edge = out[:, 63:65]
    assert np.all((edge > 1.0) & (edge < 3.0))  # every pixel beside the jump is mixed
    assert np.array_equal(out[:, :63], z[:, :63]) and np.array_equal(out[:, 65:], z[:, 65:])
    # the centre keeps at least half the footprint; with 1/z^2 weights a half-half pixel reads
    # (1/1 + 3/9) / (1/1 + 1/9) = 1.2 m: the fg pixels stay below, the bg pixels above
    assert np.all(out[:, 63] <= 1.2 + 1e-12) and np.all(out[:, 64] >= 1.2 - 1e-12)
    assert np.ptp(out[:, 64]) > 1.0  # the share is drawn per pixel: a spread, not one value


def test_tof_flying_pixels_from_subsamples():
    # a 0.6 m square at 1 m in front of a wall at 3 m, rendered with 3 x 3 sub-samples
    wall = [[-9, -9, 3.0], [9, -9, 3.0], [9, 9, 3.0], [-9, 9, 3.0]]
    sq = [[-0.3, -0.3, 1.0], [0.3, -0.3, 1.0], [0.3, 0.3, 1.0], [-0.3, 0.3, 1.0]]
    V = np.array(wall + sq, dtype=float)
    Fc = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]
    cam = Intrinsics(91.375, 91.375, 63.3, 52.7)  # off-centre: edges cut pixels
    r = render_mesh(V, Fc, cam, width=W, height=H)
    sub = render_subsamples(V, Fc, cam, width=W, height=H, factor=3, mask=discontinuity_mask(r.depth))
    out = tof_noise(r.depth, r.normals, cam, rng=_rng(), subsamples=sub, sigma_ref=0.0, rounding=0.0)
    ok = out > 0
    assert np.all((out[ok] >= 1.0 - 1e-9) & (out[ok] <= 3.0 + 1e-9))
    flying = ok & (out > 1.0 + 1e-6) & (out < 3.0 - 1e-6)
    assert 20 < flying.sum() < 400  # a ring one pixel wide around the square
    assert np.all(discontinuity_mask(r.depth)[flying])


# ------------------------------------------------------------- both: determinism, spec ----

@pytest.mark.parametrize("fn", [realsense_d4xx_noise, tof_noise])
def test_deterministic_for_a_seed(fn):
    z, n = _step(slice(40, 90))
    a = fn(z, n, K, rng=_rng(7))
    b = fn(z, n, K, rng=_rng(7))
    c = fn(z, n, K, rng=_rng(8))
    assert a.dtype == np.float64 and a.shape == (H, W)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_models_appended_after_existing_ones():
    # seeds derive from the index: the older models keep theirs
    assert MODELS[:3] == ("gaussian", "kinect_v1", "kinect_v2")
    assert MODELS[3:] == ("realsense_d4xx", "tof")


def test_spec_parsing_defaults_and_overrides():
    name, st = parse_noise_spec("realsense_d4xx:baseline=0.055:fatten_px=3")
    assert name == "realsense_d4xx"
    assert st["baseline"] == 0.055 and st["fatten_px"] == 3 and isinstance(st["fatten_px"], int)
    assert st["subpixel"] == 0.08 and st["quantum"] == 1 / 32 and st["focal"] is None
    _, st = parse_noise_spec("tof:albedo=0.2:supersample=1")
    assert st["albedo"] == 0.2 and st["supersample"] == 1 and st["sigma_ref"] == 0.017


@pytest.mark.parametrize("spec, match", [
    ("realsense_d4xx:baseline=0", "baseline must be non-zero"),
    ("realsense_d4xx:fatten_px=1.5", "fatten_px must be a whole number"),
    ("realsense_d4xx:subpixel=-0.1", "subpixel must be"),
    ("realsense_d4xx:subpixel=abc", "subpixel must be a number"),
    ("realsense_d4xx:hole_blob=0", "hole_blob must be in 1..256"),
    ("realsense_d4xx:focal=0", "focal must be"),
    ("realsense_d4xx:width=3", "has no setting 'width'"),
    ("tof:albedo=2", "albedo must be"),
    ("tof:supersample=2", "supersample must be 1"),
    ("tof:sigma_ref=nan", "sigma_ref must be finite"),
    ("tofu", "unknown noise model 'tofu'"),
])
def test_spec_errors_are_clear(spec, match):
    with pytest.raises(ValueError, match=match):
        parse_noise_spec(spec)


def test_function_options_checked():
    z, n = _step(slice(40, 90))
    with pytest.raises(ValueError, match="baseline must be non-zero"):
        realsense_d4xx_noise(z, n, K, rng=_rng(), baseline=0.0)
    with pytest.raises(ValueError, match="cutoff must be"):
        tof_noise(z, n, K, rng=_rng(), cutoff=-1.0)
    with pytest.raises(ValueError, match="needs K"):
        noise_std("realsense_d4xx", 2.0)


def test_generate_writes_both_models(tmp_path):
    small_k = Intrinsics(91.375, 91.375, 63.5, 52.5)
    generate(tmp_path, indoor=1, outdoor=0, views=1, seed=3, K=small_k, size=(H, W), progress=False,
             noise=("realsense_d4xx:baseline=0.055", "tof"))
    d = tmp_path / "indoor" / "living_room-00"
    clean = np.load(d / "clean" / "0000.npy")
    for model in ("realsense_d4xx", "tof"):
        noisy = np.load(d / model / "0000.npy")
        assert noisy.dtype == np.float32 and noisy.shape == clean.shape
        both = (clean > 0) & (noisy > 0)
        assert both.mean() > 0.5
        assert 1e-4 < np.median(np.abs(noisy[both] - clean[both])) < 0.05


# ------------------------------------------- statistics against real frames (all models) ----
# Measured on the real frames of ../shared/data/real-sensors with benchmarks/sensor_stats.py
# (docs/synthetic.md, "Sensor models against real frames"): Kinect v1 / Xtion frames (TUM,
# NYU raw disparity, SUN RGB-D) have 51-55 % exactly-zero second differences on smooth
# surfaces, steps of 2.84-2.93 mm x z^2 (11.5 mm at 2 m, 46 mm at 4 m for 1/8 px at f b =
# 580 x 0.075) and a lag-1 autocorrelation of 0.66-0.67 of the residual of 31 x 31 plane fits.

REAL_KINECT_ZERO_D2 = 0.51  # the lowest of TUM 50.9 %, NYU raw 55.2 %, SUN 51.3 %
REAL_KINECT_AC1 = 0.66  # the lowest of TUM 0.66, NYU raw 0.67, SUN 0.66


def _zero_d2_share(z):
    """Share of exactly-zero second differences along rows and columns, valid triples."""
    zero = total = 0
    for a in (z, z.T):
        left, mid, right = a[:, :-2], a[:, 1:-1], a[:, 2:]
        ok = (left > 0) & (mid > 0) & (right > 0)
        zero += np.count_nonzero(ok & (left - mid == mid - right))
        total += np.count_nonzero(ok)
    return zero / total


def _plateau_steps(z):
    """Non-zero jumps between adjacent row pixels that both sit on plateaus (runs >= 2 px)."""
    left, a, b, right = z[:, :-3], z[:, 1:-2], z[:, 2:-1], z[:, 3:]
    sel = (left == a) & (b == right) & (a != b) & (left > 0) & (right > 0)
    return np.abs(b - a)[sel]


def _residual_ac(z, lags=(1,), tile=31):
    """Mean autocorrelation (rows and columns) of the residual of planes fitted to ``1/z`` on
    the fully valid ``tile x tile`` windows."""
    v, u = np.mgrid[0:tile, 0:tile].astype(np.float64)
    A = np.stack([u.ravel(), v.ravel(), np.ones(tile * tile)], axis=1)
    out = []
    for v0 in range(0, z.shape[0] - tile + 1, tile):
        for u0 in range(0, z.shape[1] - tile + 1, tile):
            p = z[v0:v0 + tile, u0:u0 + tile]
            if not np.all(p > 0):
                continue
            coef = np.linalg.lstsq(A, 1.0 / p.ravel(), rcond=None)[0]
            r = p - 1.0 / (A @ coef).reshape(tile, tile)
            r -= r.mean()
            out.append([0.5 * (np.sum(r[:, :-k] * r[:, k:]) + np.sum(r[:-k] * r[k:])) / np.sum(r * r)
                        for k in lags])
    assert len(out) >= 6
    return np.mean(out, axis=0)


def test_kinect_v1_plateaus_like_real_frames():
    r = _plane(2.0, tilt_deg=30.0)  # disparity changes by 0.27 of a 1/8 px step per column
    share = [_zero_d2_share(kinect_v1_noise(r.depth, r.normals, K, rng=_rng(s))) for s in range(3)]
    # measured 0.542-0.546: the real frames' 51-55 % (a naive second-difference noise estimate
    # reads 0 on half the pixels); independent noise (window 1) breaks the plateaus up: 0.22
    assert min(share) > REAL_KINECT_ZERO_D2 - 0.06, share
    white = _zero_d2_share(kinect_v1_noise(r.depth, r.normals, K, rng=_rng(0), window=1))
    assert white < 0.3 < min(share)
    # and the values are exactly on the 1/8-px disparity grid (quantised after the noise)
    out = kinect_v1_noise(r.depth, r.normals, K, rng=_rng(0))
    disp8 = 580.0 * 0.075 / out[out > 0] * 8
    assert np.allclose(disp8, np.rint(disp8), rtol=0, atol=1e-9)


def test_kinect_v1_steps_grow_as_z_squared():
    steps = {}
    for z0 in (2.0, 4.0):
        r = _plane(z0, tilt_deg=30.0)
        st = np.concatenate([_plateau_steps(kinect_v1_noise(r.depth, r.normals, K, rng=_rng(s)))
                             for s in range(2)])
        assert st.size > 200
        steps[z0] = np.median(st)
    # one 1/8-px disparity step: z^2 / (8 x 580 x 0.075) = 11.5 mm at 2 m, 46 mm at 4 m
    # (measured 11.4-11.6 / 46.5 mm; the real frames: 11.8-13.9 / 40-45 mm)
    assert steps[2.0] == pytest.approx(2.0 ** 2 / (8 * 43.5), rel=0.1)
    assert steps[4.0] / steps[2.0] == pytest.approx(4.0, abs=0.5)


def test_kinect_v1_residual_correlated_like_real_frames():
    r = _plane(2.0, tilt_deg=30.0)
    ac = [_residual_ac(kinect_v1_noise(r.depth, r.normals, K, rng=_rng(s)))[0] for s in range(3)]
    # measured 0.60-0.62 (real 0.66-0.67; independent noise -0.01)
    assert min(ac) > REAL_KINECT_AC1 - 0.16, ac
    white = _residual_ac(kinect_v1_noise(r.depth, r.normals, K, rng=_rng(0), window=1))[0]
    assert abs(white) < 0.1


def test_kinect_v1_lateral_jitter_only_across_edges():
    z, n = _step(slice(40, 90))
    out = kinect_v1_noise(z, n, K, rng=_rng(0), window=1)
    fg = kinect_v1_noise(np.full((H, W), 1.0), n, K, rng=_rng(0), window=1)
    # away from the edges the fronto-parallel foreground is untouched by the jitter
    assert np.array_equal(out[:, 45:85], fg[:, 45:85])
    # at the edges pixels read the other surface: jagged, not straight
    edge_cols = out[:, 38:42] < 2.0
    assert 0 < edge_cols.sum(axis=1).std()


@pytest.mark.parametrize(("fn", "off"), [(tof_noise, {"blur": 0.0}),
                                         (realsense_d4xx_noise, {"window": 1})])
def test_tof_and_stereo_noise_spatially_correlated(fn, off):
    r = _plane(2.0, tilt_deg=30.0)
    kw = {"hole_range": np.inf} if fn is realsense_d4xx_noise else {}
    ac = _residual_ac(fn(r.depth, r.normals, K, rng=_rng(0), **kw))[0]
    white = _residual_ac(fn(r.depth, r.normals, K, rng=_rng(0), **kw, **off))[0]
    # measured: tof 0.23 (0.5 px blur, 1 mm rounding), realsense 0.75 (5 x 5 window); off: ~0
    assert ac > 0.15 and abs(white) < 0.05, (ac, white)


def test_correlation_settings_parsed_and_checked():
    _, st = parse_noise_spec("kinect_v1:window=1")
    assert st["window"] == 1 and isinstance(st["window"], int)
    assert parse_noise_spec("kinect_v1")[1]["window"] == 9
    assert parse_noise_spec("realsense_d4xx")[1]["window"] == 5
    assert parse_noise_spec("tof:blur=1.5")[1]["blur"] == 1.5
    for spec, match in (("kinect_v1:window=2.5", "window must be a whole number"),
                        ("kinect_v1:window=0", "window must be"),
                        ("realsense_d4xx:window=0", "window must be"),
                        ("tof:blur=-1", "blur must be")):
        with pytest.raises(ValueError, match=match):
            parse_noise_spec(spec)


@pytest.mark.parametrize(("window", "blur"), [(9, 0.0), (5, 0.0), (1, 0.5), (3, 1.2), (1, 0.0)])
def test_correlated_noise_compiled_equals_reference(window, blur):
    kern = _correlation_kernel(window, blur)
    x = _rng(4).standard_normal((H + kern.size - 1, W + kern.size - 1))
    got = _correlated_normal(_rng(4), (H, W), window=window, blur=blur)
    want = x if kern.size == 1 else _separable_reference(x, kern)
    assert np.array_equal(got, want)


def test_correlated_noise_unit_variance_and_box_correlation():
    e = _correlated_normal(_rng(5), (400, 400), window=9)
    assert e.std() == pytest.approx(1.0, abs=0.05)
    for k in (1, 4, 8, 9):  # a 9-px box: correlation 1 - k / 9 along rows and columns
        ac = 0.5 * (np.mean(e[:, :-k] * e[:, k:]) + np.mean(e[:-k] * e[k:])) / e.var()
        assert ac == pytest.approx(max(0.0, 1 - k / 9), abs=0.05), (k, ac)
    g = _correlated_normal(_rng(5), (400, 400), blur=0.5)
    ac = np.mean(g[:, :-1] * g[:, 1:]) / g.var()
    kern = _correlation_kernel(1, 0.5)  # the sampled Gaussian: lag 1 = sum k_i k_i+1 = 0.26
    assert g.std() == pytest.approx(1.0, abs=0.03)
    assert ac == pytest.approx(np.sum(kern[:-1] * kern[1:]), abs=0.03) and ac > 0.2
