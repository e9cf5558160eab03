"""The expected-error map of ``estimate_normals(..., return_uncertainty=True)`` and the vMF
conversions (:mod:`depthnormals.ddm.uncertainty`)."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import tilted_plane
from depthnormals.ddm.uncertainty import UNCERTAINTY_METHODS


def _no_bend(w: int) -> tuple:
    """No bend term in the measured support's product (``_support_rows``) on ``w`` columns
    (:func:`depthnormals.ddm.bend.bend_term` of a grid of zeros)."""
    from depthnormals.ddm.bend import bend_term

    return bend_term(np.zeros((1, 1)), 8, 0.0, w)


def _plane(noise: float, seed: int = 0, shape=(120, 160)):
    r = tilted_plane((0.0, -0.6, -0.8), 2.0).render(shape=shape)
    fx = dn.as_intrinsics(r.K).fx
    rng = np.random.default_rng(seed)
    return r, r.depth * (1.0 + noise * rng.standard_normal(r.depth.shape) / fx)


def _kinect_like_plane(seed, shape=(240, 320)):
    """A tilted plane 2 m away seen as Kinect-like depth: disparity noise correlated over a
    9x9 box, quantised to 1/8 px."""
    r = tilted_plane((0.0, -0.6, -0.8), 2.0).render(shape=shape)
    return r, _kinect_like_depth(r.depth, seed)


def _kinect_like_depth(z, seed):
    """Clean depth ``z`` seen as by a Kinect v1: disparity noise correlated over a 9x9 box,
    quantised to 1/8 px."""
    rng = np.random.default_rng(seed)
    e = rng.standard_normal((z.shape[0] + 8, z.shape[1] + 8))
    k = np.ones(9) / 3.0
    e = np.apply_along_axis(lambda x: np.convolve(x, k, "valid"), 0, e)
    e = np.apply_along_axis(lambda x: np.convolve(x, k, "valid"), 1, e)
    disp = 580 * 0.075 / z + 0.05 * e
    return 580 * 0.075 / (np.round(disp * 8) / 8)


@pytest.mark.parametrize("method", UNCERTAINTY_METHODS)
def test_nan_pattern_matches_normals_with_holes(method):
    r, d = _plane(0.1)
    d = d.copy()
    d[30:50, 40:70] = 0.0
    d[::7, ::11] = np.nan
    n, u = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True)
    assert u.dtype == np.float32 and u.shape == d.shape
    np.testing.assert_array_equal(np.isnan(u), np.isnan(n[..., 0]))
    assert np.all(u[np.isfinite(u)] >= 0.0)


@pytest.mark.parametrize("method", UNCERTAINTY_METHODS)
@pytest.mark.parametrize("shape", [(1, 48), (48, 1), (30, 40), (40, 30)])
def test_small_images_get_a_map(method, shape):
    """Images one row or column across, or smaller than the plain maps' pair span
    (PLAIN_SPAN, 41 px), on noisy depth. Before session 28 the plain maps raised numpy's
    broadcast error on the 30 x 40 and 40 x 30 ones (a pair slice whose stop fell below 0
    wrapped to the image's end) and the one-row image raised a slice error: the plane-fit
    kernel took its one-row placeholders for "no large window" and "no spreads" for arrays
    of the image's one row (and read the first past its end)."""
    rng = np.random.default_rng(0)
    K = np.array([[300.0, 0.0, 20.0], [0.0, 300.0, 15.0], [0.0, 0.0, 1.0]])
    d = 1.0 + 0.001 * rng.random(shape)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", dn.NoValidNormalWarning)
        n, u = dn.estimate_normals(d, K, method=method, return_uncertainty=True)
    assert u.dtype == np.float32 and u.shape == shape
    np.testing.assert_array_equal(np.isnan(u), np.isnan(n[..., 0]))
    fin = u[np.isfinite(u)]
    assert np.all((fin >= 0.0) & (fin <= 90.0))
    if min(shape) > 1:
        assert fin.size > shape[0] * shape[1] // 2


@pytest.mark.parametrize("method", UNCERTAINTY_METHODS)
def test_map_never_exceeds_the_error_of_no_information(method):
    """A camera-facing normal that carries no information errs 57.3-90 deg on average
    (MAX_ERROR): no map reads more. Before the ceiling (00b3423), on these inputs, the 3f2n+
    map of uniform random depth read 204 deg on average (95 % of it above 90, up to 445) and
    the plain maps of 5 cm noise at 2 m up to 103-124 (0.3-0.7 % above 90); each method has
    pixels at the ceiling, so a lower one fails too."""
    rng = np.random.default_rng(0)
    K = np.array([[500.0, 0.0, 80.0], [0.0, 500.0, 60.0], [0.0, 0.0, 1.0]])
    if method == "3f2n+":
        d = rng.uniform(1.0, 3.0, (120, 160))
    else:
        d = 2.0 + 0.05 * rng.standard_normal((120, 160))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", dn.NoValidNormalWarning)
        n, u = dn.estimate_normals(d, K, method=method, return_uncertainty=True)
    np.testing.assert_array_equal(np.isnan(u), np.isnan(n[..., 0]))
    fin = u[np.isfinite(u)]
    assert fin.size > 1000
    assert float(fin.max()) == 90.0
    assert np.count_nonzero(fin == np.float32(90.0)) >= 20


@pytest.mark.parametrize("method, options", [("3f2n+", {}), ("fals", {}), ("pcl-covariance-matrix", {}),
                                             ("plane-svd", {}), ("plane-pca", {"window": 7})])
def test_iid_plane_mean_prediction_within_20_percent(method, options):
    """On i.i.d. noise the closed form holds for every window (the plane fits' 3x3 default and
    a 7x7 window, whose error is 5.6x less: read at the default's radius it would be 5.6x high;
    measured 3.33 / 3.38 deg and 0.59 / 0.61)."""
    r, d = _plane(0.2, shape=(240, 320))
    n, u = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True, **options)
    e = dn.angular_error(n, r.normals)
    ok = np.isfinite(e)
    pred, obs = float(np.mean(u[ok])), float(np.mean(e[ok]))
    assert abs(pred - obs) <= 0.2 * obs, (pred, obs)


def test_monotonic_in_noise_level():
    means = []
    for s in (0.02, 0.1, 0.4):
        r, d = _plane(s)
        _, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
        means.append(float(np.nanmean(u)))
    assert means[0] < means[1] < means[2]


def test_measured_support_branch_on_quantised_depth():
    r = tilted_plane((0.0, -0.6, -0.8), 2.0).render(shape=(240, 320))
    disparity = np.round(580 * 0.075 / r.depth * 8) / 8
    d = 580 * 0.075 / disparity
    assert dn.noise_profile(d, r.K).branch == "measured-support"
    n, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
    np.testing.assert_array_equal(np.isnan(u), np.isnan(n[..., 0]))
    assert np.nanmean(u) > 0.0


def test_normals_unchanged_by_the_flag():
    r, d = _plane(0.1)
    for m in UNCERTAINTY_METHODS:
        n, _ = dn.estimate_normals(d, r.K, method=m, return_uncertainty=True)
        np.testing.assert_array_equal(n, dn.estimate_normals(d, r.K, method=m))


def test_unsupported_methods_raise():
    r, d = _plane(0.1)
    with pytest.raises(ValueError, match="supported for methods 3f2n\\+, fals"):
        dn.estimate_normals(d, r.K, method="d2nt", return_uncertainty=True)
    with pytest.raises(ValueError, match="default options"):
        dn.estimate_normals(d, r.K, method="3f2n+", crf=True, return_uncertainty=True)
    with pytest.raises(ValueError, match="unknown method"):
        dn.estimate_normals(d, r.K, method="nope", return_uncertainty=True)
    with pytest.raises(TypeError, match="return_uncertainty"):
        dn.estimate_normals(d, r.K, return_uncertainty="yes")
    # a stack is no refusal: one map per frame (estimate_normals_batch)
    _, u = dn.estimate_normals(np.stack([d, d]), r.K, return_uncertainty=True)
    assert u.shape == (2, *d.shape) and u.dtype == np.float32


def test_kappa_round_trip():
    e = np.array([0.1, 1.0, 5.0, 20.0])
    np.testing.assert_allclose(dn.kappa_to_uncertainty(dn.uncertainty_to_kappa(e)), e, rtol=1e-12)
    assert float(dn.uncertainty_to_kappa(1.0)) == pytest.approx(math.pi / 2 / math.radians(1.0) ** 2)
    with pytest.raises(ValueError):
        dn.kappa_to_uncertainty(0.0)
    with pytest.raises(ValueError):
        dn.uncertainty_to_kappa(-1.0)


@pytest.mark.parametrize("err", [1.0, 5.0, 15.0])
def test_kappa_matches_sampled_vmf(err):
    kappa = float(dn.uncertainty_to_kappa(err))
    rng = np.random.default_rng(1)
    # vMF on S^2 around +z: cos(theta) = 1 + log(u + (1 - u) exp(-2 kappa)) / kappa
    u = rng.random(200_000)
    w = 1.0 + np.log(u + (1.0 - u) * np.exp(-2.0 * kappa)) / kappa
    mean = float(np.degrees(np.arccos(np.clip(w, -1.0, 1.0))).mean())
    assert mean == pytest.approx(err, rel=0.02)


def test_import_stays_light():
    code = ("import sys, depthnormals; "
            "print(any(m in sys.modules for m in ('torch', 'matplotlib')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def _cli_inputs(tmp_path):
    import json

    r, d = _plane(0.1, shape=(48, 64))
    K = dn.as_intrinsics(r.K)
    (tmp_path / "k.json").write_text(json.dumps({"fx": K.fx, "fy": K.fy, "cx": K.cx, "cy": K.cy}))
    (tmp_path / "in").mkdir()
    np.save(tmp_path / "in" / "a.npy", d.astype(np.float32))
    np.save(tmp_path / "in" / "b.npy", d.astype(np.float32))
    return r, d


def test_cli_single_file_writes_uncertainty(tmp_path):
    from depthnormals.cli import main

    r, d = _cli_inputs(tmp_path)
    out = tmp_path / "out" / "a.vis.png"
    assert main(["estimate", str(tmp_path / "in" / "a.npy"), "-K", str(tmp_path / "k.json"),
                 "-o", str(out), "--uncertainty"]) == 0
    u = np.load(tmp_path / "out" / "a.uncertainty.npy")
    _, want = dn.estimate_normals(d.astype(np.float32), r.K, return_uncertainty=True)
    np.testing.assert_array_equal(u, want)


def test_cli_many_records_the_flag(tmp_path):
    import json

    from depthnormals.cli import main
    from depthnormals.jobs import MANIFEST

    _cli_inputs(tmp_path)
    out = tmp_path / "many"
    assert main(["estimate", str(tmp_path / "in"), "-K", str(tmp_path / "k.json"), "-o", str(out),
                 "--uncertainty", "-q"]) == 0
    assert sorted(p.name for p in out.rglob("*.uncertainty.npy")) == ["a.uncertainty.npy",
                                                                      "b.uncertainty.npy"]
    settings = json.loads((out / MANIFEST).read_text())["settings"]
    assert settings["uncertainty"] is True
    # without the flag the manifest differs: a resumed run is refused
    assert main(["estimate", str(tmp_path / "in"), "-K", str(tmp_path / "k.json"), "-o", str(out),
                 "-q"]) != 0


def test_cli_unsupported_method(tmp_path):
    from depthnormals.cli import main

    _cli_inputs(tmp_path)
    assert main(["estimate", str(tmp_path / "in"), "-K", str(tmp_path / "k.json"), "-o",
                 str(tmp_path / "x"), "--uncertainty", "-m", "d2nt", "-q"]) != 0


def test_covariance_in_the_tangent_plane():
    r, d = _plane(0.1, shape=(24, 32))
    n, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
    c = dn.uncertainty_to_covariance(n, u).astype(np.float64)
    assert c.shape == (24, 32, 3, 3)
    ok = np.isfinite(u)
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", c, n)[ok], 0.0, atol=1e-9)
    s2 = np.radians(u[ok].astype(np.float64)) ** 2 / (math.pi / 2)
    np.testing.assert_allclose(np.trace(c, axis1=-2, axis2=-1)[ok], 2 * s2, rtol=1e-4)
    with pytest.raises(ValueError, match="shape"):
        dn.uncertainty_to_covariance(n, u[:2])


def _kinect_like_corner(seed, shape=(240, 320)):
    """Two planes meeting at a horizontal 90 deg crease through the image centre (``Z + Y =
    2`` above, ``Z - Y = 2`` below: mirror images), seen by :func:`_kinect_like_depth`; depth,
    K and the exact normals."""
    h, w = shape
    K = np.array([[300.0, 0.0, (w - 1) / 2], [0.0, 300.0, (h - 1) / 2], [0.0, 0.0, 1.0]])
    y = (np.arange(h)[:, None] - K[1, 2]) / K[1, 1] + np.zeros((1, w))
    z = np.where(y < 0, 2.0 / (1 + y), 2.0 / (1 - y))
    g = np.zeros((h, w, 3), np.float32)
    g[y < 0] = (0.0, -math.sqrt(0.5), -math.sqrt(0.5))
    g[y > 0] = (0.0, math.sqrt(0.5), -math.sqrt(0.5))
    return _kinect_like_depth(z, seed).astype(np.float32), K, g


def test_measured_support_map_is_symmetric_about_a_crease():
    """A corner whose two faces are mirror images about a horizontal crease: the observed
    error 4.5-11.5 px above and below it is alike (0.72 / 0.77 deg, seeds 0-2), and so must
    the map be, within a factor 2 (measured 5.4 / 8.1 deg: both far above the error, which
    the estimator keeps low on this clean corner; docs/benchmarks.md 17). The map of the
    one-sided spread ``R`` to the right and below (4282cd1, before session 13) read 4.3 / 0.9
    deg: it flagged the pixels whose crease lies below them, not those whose crease lies
    above."""
    above, below, e_above, e_below = [], [], [], []
    for seed in range(3):
        d, K, g = _kinect_like_corner(seed)
        assert dn.noise_profile(d, K).branch == "measured-support"
        n, u = dn.estimate_normals(d, K, return_uncertainty=True)
        err = dn.angular_error(n, g)
        c = (d.shape[0] - 1) // 2  # the crease lies between rows c and c + 1 (240 rows)
        for x, a, b in ((u, above, below), (err, e_above, e_below)):
            a.append(np.nanmean(x[c - 11:c - 3]))  # 4.5-11.5 px above
            b.append(np.nanmean(x[c + 5:c + 13]))  # 4.5-11.5 px below
    assert 0.7 < np.mean(e_above) / np.mean(e_below) < 1.4, (e_above, e_below)
    assert 0.5 < np.mean(above) / np.mean(below) < 2.0, (above, below)


@pytest.mark.parametrize("seed", [0, 1])
def test_correlated_quantised_plane_mean_prediction(seed):
    """Kinect-like depth (disparity noise correlated over a 9x9 box, 1/8 px steps) on one
    isolated plane: the measured-support map reads 0.81x / 0.79x the observed mean (0.52 /
    0.64 and 0.53 / 0.67 deg, predicted / observed; 0.74x / 0.73x before session 15's depth
    ramp, which adds where the depth straddles the pixel's plane). It was within 25 % before
    the map became a product of the spreads (docs/benchmarks.md 17): the fitted exponents give
    the frame's interior level 1/8, and on a plane alone the spreads are small; the floor
    ``LEVEL_FLOOR lev`` keeps it above half the level. The top decile of the prediction holds
    its observed mean within 25 % (1.07 / 0.98 and 1.15 / 1.20 deg; session 14's ramp of the
    lesser side's magnitude read 0.76 / 1.08, and the same form against the frame's tail 1.91
    / 0.74: a pixel's own noise leaves its plane the same way on both sides). Since session
    37's bend term (:mod:`depthnormals.ddm.bend`: the mean normals 48 px apart, whose residual
    noise on the correlated depth is what the level missed) 0.99x / 0.98x (0.63 / 0.64 and
    0.66 / 0.67 deg), the top decile 1.18 / 1.02 and 1.32 / 1.28."""
    r, d = _kinect_like_plane(seed)
    assert dn.noise_profile(d, r.K).branch == "measured-support"
    n, u = dn.estimate_normals(d, r.K, return_uncertainty=True)
    err = dn.angular_error(n, r.normals)
    ok = np.isfinite(err)
    pred, obs = float(np.mean(u[ok])), float(np.mean(err[ok]))
    assert 0.9 * obs <= pred <= 1.1 * obs, (pred, obs)
    top = ok & (u >= np.quantile(u[ok], 0.9))
    assert 0.75 <= np.mean(err[top]) / np.mean(u[top]) <= 1.25, (np.mean(u[top]), np.mean(err[top]))


@pytest.mark.parametrize("method", ["fals", "pcl-covariance-matrix", "pcl-average-3d-gradient"])
def test_plain_map_self_calibrates_on_correlated_quantised_depth(method, monkeypatch):
    """On Kinect-like depth the plain fits' i.i.d. closed form reads 0.46x (FALS), 0.18x
    (PCL's covariance) and 0.27x (3-D gradients) the observed mean; the map (the normals'
    spread one window away, ``_far_spread``, raised by the frame's measured excess
    ``_pair_excess``) reads 1.00-1.03x, 0.96-0.97x and 1.06-1.08x (seeds 0-2)."""
    from depthnormals.ddm import uncertainty as U

    r, d = _kinect_like_plane(0)
    n, u = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True)
    err = dn.angular_error(n, r.normals)
    ok = np.isfinite(err)
    pred, obs = float(np.mean(u[ok])), float(np.mean(err[ok]))
    assert 0.85 * obs <= pred <= 1.15 * obs, (pred, obs)
    monkeypatch.setattr(U, "_pair_excess", lambda *a: 1.0)
    monkeypatch.setattr(U, "_far_spread", lambda n, d: np.full(n.shape[:2], np.nan, np.float32))
    _, u0 = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True)
    assert float(np.mean(u0[ok])) < 0.5 * obs  # the i.i.d. form alone: far too low


def test_far_spread_exact_on_a_crease_and_nan_without_neighbours():
    """Two half-planes at 90 deg: a pixel whose right neighbour ``d`` away lies across the
    crease (its other three on its side) reads 90 / 4 / sqrt 2 deg; one with no neighbour
    ``d`` away inside the image reads NaN (the map then takes the closed form)."""
    from depthnormals.ddm.uncertainty import _far_spread

    n = np.zeros((20, 20, 3), np.float32)
    n[:, :8] = (0.0, 0.0, -1.0)
    n[:, 8:] = (-1.0, 0.0, 0.0)
    s = _far_spread(n, 5)
    assert s[10, 7] == pytest.approx(90.0 / 4.0 / math.sqrt(2.0), rel=1e-6)
    assert s[10, 3] == pytest.approx(90.0 / 3.0 / math.sqrt(2.0), rel=1e-6)  # no left one
    assert s[10, 2] == 0.0 and s[10, 12] == pytest.approx(90.0 / 4.0 / math.sqrt(2.0))
    assert np.isnan(_far_spread(n[:4, :4], 5)).all()
    n[10, 12] = np.nan  # an invalid neighbour does not count
    assert s[10, 7] != _far_spread(n, 5)[10, 7] and _far_spread(n, 5)[10, 7] == 0.0


@pytest.mark.parametrize(("shape", "d"), [((37, 53), 1), ((37, 53), 5), ((37, 53), 41), ((1, 48), 3),
                                         ((48, 1), 3), ((6, 6), 7)])
def test_far_spread_equals_its_numpy_form(shape, d):
    """The compiled spread (session 38: 89 -> 20 ms a 640x480 frame, equal to the bit; session
    39: vectorised, 3 ms) equals the numpy form it replaced to float32's last place:
    :func:`depthnormals.angular_error` to the right and below, each pair's angle counted for
    both pixels (right, left, below, above), over ``sqrt 2``; NaN at the same pixels; on
    random normals of any length with NaN and zero ones, and spans past the image."""
    from depthnormals.ddm.uncertainty import _far_spread

    rng = np.random.default_rng(d)
    n = (rng.standard_normal((*shape, 3)) * rng.uniform(0.1, 10.0, (*shape, 1))).astype(np.float32)
    n[rng.random(shape) < 0.2] = np.nan
    n[rng.random(shape) < 0.05] = 0.0
    h, w = shape
    acc, cnt = np.zeros(shape), np.zeros(shape)
    for dv, du in ((0, d), (d, 0)):
        if dv >= h or du >= w:
            continue
        ang = dn.angular_error(n[: h - dv, : w - du], n[dv:, du:])
        ok = np.isfinite(ang)
        for part in ((slice(0, h - dv), slice(0, w - du)), (slice(dv, h), slice(du, w))):
            acc[part] += np.where(ok, ang, 0.0)
            cnt[part] += ok
    with np.errstate(invalid="ignore", divide="ignore"):
        want = (acc / cnt / math.sqrt(2.0)).astype(np.float32)
    got = _far_spread(n, d)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_allclose(got, want, rtol=2.5e-7, atol=0.0)  # ~2 units in float32's last place


@pytest.mark.parametrize(("method", "gain"), [("fals", 0.15), ("pcl-covariance-matrix", 0.08)])
def test_plain_map_ranks_edges_above_the_closed_form(method, gain, monkeypatch, load_benchmark):
    """The box on the floor with 0.3 footprints of noise: the spread map ranks the error with
    Spearman 0.752 (FALS) / 0.688 (PCL's covariance) against 0.575 / 0.581 for the closed
    form, which sees the windows across the box's edges only through their residual."""
    from depthnormals.analytic import make_scene
    from depthnormals.ddm import uncertainty as U

    r = make_scene("box-on-floor").render()
    fx = dn.as_intrinsics(r.K).fx
    d = r.depth * (1 + 0.3 * np.random.default_rng(0).standard_normal(r.depth.shape) / fx)
    n, u = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True)
    e = dn.angular_error(n, r.normals)
    ok = np.isfinite(e) & np.isfinite(u)
    monkeypatch.setattr(U, "_far_spread", lambda n, d: np.full(n.shape[:2], np.nan, np.float32))
    _, u0 = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True)
    spearman = load_benchmark("uncertainty_calibration").spearman
    assert spearman(u[ok], e[ok]) > spearman(u0[ok], e[ok]) + gain


def test_pair_excess_is_one_on_iid_noise_and_reads_a_scaled_map():
    """On a plane with independent noise the pairs agree with the i.i.d. map (the factor
    stays 1: only correlated noise raises it); a map made 3x too low reads about 3."""
    from depthnormals.ddm import uncertainty as U
    from depthnormals.ddm.boxfit import box_fit_windows
    from depthnormals.kernels.depth import prepare

    r, d = _plane(0.3, shape=(240, 320))
    n, u = dn.estimate_normals(d, r.K, method="fals", return_uncertainty=True)
    z, cam = prepare(d, r.K, None)
    _, score = box_fit_windows(z, float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy), 2,
                               normals=False)
    assert U._pair_excess(n, u, score) < 1.1
    assert 2.6 < U._pair_excess(n, u / 3.0, score) < 3.4


def test_plain_map_takes_no_excess_on_clean_depth(monkeypatch):
    """On clean depth the interior pairs' angles are the scene's curvature, not noise (the
    factor read 37-355 on the clean synthetic renders): the plain map stays the i.i.d. one."""
    from depthnormals.analytic import make_scene
    from depthnormals.ddm import uncertainty as U

    r = make_scene("sphere-before-wall").render()
    _, u = dn.estimate_normals(r.depth, r.K, method="fals", return_uncertainty=True)
    monkeypatch.setattr(U, "_pair_excess", lambda *a: 100.0)
    _, u100 = dn.estimate_normals(r.depth, r.K, method="fals", return_uncertainty=True)
    np.testing.assert_array_equal(u, u100)
    rp, d = _kinect_like_plane(0)  # while on noisy depth the factor is applied, capped
    monkeypatch.setattr(U, "PLAIN_FLOOR", 0.0)  # (the floor reads the factor too: below)
    _, un = dn.estimate_normals(d, rp.K, method="fals", return_uncertainty=True)
    monkeypatch.setattr(U, "_pair_excess", lambda *a: 1.0)
    _, u1 = dn.estimate_normals(d, rp.K, method="fals", return_uncertainty=True)
    np.testing.assert_array_equal(un, np.minimum(u1 * np.float32(100.0),
                                                 np.maximum(u1, np.float32(U.PLAIN_CAP))))
    assert (un > u1).mean() > 0.9


@pytest.mark.parametrize("seed", [0, 1])
def test_plain_map_floor_lifts_the_chance_low_spreads(seed, monkeypatch):
    """PlaneSVD's 3x3 fits on Kinect-like depth: the spread of four normals one window away
    reads low by chance where the error is not low. Without the floor (``PLAIN_FLOOR = 0``)
    the tenth of the pixels mapped lowest erred 2.37x / 2.55x their map (seeds 0 / 1), with
    it 1.59x / 1.67x, the mean map 35.2 -> 36.4 deg (seed 0) against an observed 37.1."""
    from depthnormals.ddm import uncertainty as U

    r, d = _kinect_like_plane(seed)

    def lowest_tenth_ratio():
        n, u = dn.estimate_normals(d, r.K, method="plane-svd", return_uncertainty=True)
        e = dn.angular_error(n, r.normals)
        ok = np.isfinite(e)
        low = u[ok] <= np.quantile(u[ok], 0.1)
        return float(e[ok][low].mean() / u[ok][low].mean()), float(u[ok].mean()), float(e[ok].mean())

    ratio, pred, obs = lowest_tenth_ratio()
    assert ratio < 1.8 and 0.9 * obs <= pred <= 1.1 * obs, (ratio, pred, obs)
    monkeypatch.setattr(U, "PLAIN_FLOOR", 0.0)
    ratio0, pred0, _ = lowest_tenth_ratio()
    assert ratio0 > 2.2 and pred0 < pred, (ratio0, pred0)


def test_box_plane_fits_share_one_map():
    """PlanePCA and PlaneSVD fit the same centred plane: one map, read at their window."""
    r, d = _kinect_like_plane(0, shape=(120, 160))
    n1, u1 = dn.estimate_normals(d, r.K, method="plane-pca", window=5, return_uncertainty=True)
    n2, u2 = dn.estimate_normals(d, r.K, method="plane-svd", window=5, return_uncertainty=True)
    np.testing.assert_array_equal(n1, n2)
    np.testing.assert_array_equal(u1, u2)
    _, u3 = dn.estimate_normals(d, r.K, method="plane-svd", return_uncertainty=True)
    assert float(np.nanmean(u3)) > 1.5 * float(np.nanmean(u2))  # the 3x3 default errs more


@pytest.mark.parametrize("method", [m for m in UNCERTAINTY_METHODS if m != "3f2n+"])
def test_plain_maps_read_the_estimators_own_default_window(method):
    """A plain fit's map without a window option reads the window the estimator itself
    defaults to (its signature's, not a copy of it): the same map as that window passed
    explicitly, and another than the next larger window's."""
    import inspect

    from depthnormals.registry import get_estimator

    r, d = _kinect_like_plane(1, shape=(60, 80))
    params = inspect.signature(get_estimator(method).func).parameters
    option = "window" if "window" in params else "normal_smoothing_size"
    default = params[option].default
    _, u = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True)
    _, u_same = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True,
                                    **{option: default})
    _, u_wider = dn.estimate_normals(d, r.K, method=method, return_uncertainty=True,
                                     **{option: type(default)(default + 4)})
    np.testing.assert_array_equal(u, u_same)
    assert not np.array_equal(u, u_wider, equal_nan=True)


def _neighbour(a, dv, du):
    """``a`` (H, W, ...) read ``(dv, du)`` away: ``out[v, u] = a[v + dv, u + du]``, NaN
    outside."""
    h, w = a.shape[:2]
    o = np.full_like(a, np.nan)
    ys, yd = slice(max(0, dv), h + min(0, dv)), slice(max(0, -dv), h + min(0, -dv))
    xs, xd = slice(max(0, du), w + min(0, du)), slice(max(0, -du), w + min(0, -du))
    o[yd, xd] = a[ys, xs]
    return o


def _angle_ref(n, dv, du):
    """The chord angle (degrees, as the kernels) of ``n`` to its neighbour ``(dv, du)`` away,
    NaN outside or where either is NaN."""
    c2 = 2.0 - 2.0 * (n * _neighbour(n, dv, du)).sum(-1)
    k = np.sqrt(np.maximum(c2, 0.0))
    return np.degrees(k + k * c2 / 24.0)


def _mean_finite(angles):
    a = np.stack(angles)
    c = np.isfinite(a).sum(0)
    return np.where(c > 0, np.nansum(a, 0) / np.maximum(c, 1), 0.0)


@pytest.mark.parametrize("kernel", ["fit-error", "box-fit", "support", "support-bands"])
def test_spreads_match_numpy_in_any_bands(kernel):
    """The spreads of the noisy maps equal a numpy reference, in one band of rows or two: the
    plane-fit error kernel's (:func:`_fit_error_rows` with ``near_d`` 0: the four neighbours,
    ``R`` to the right and below), the box-fit map's (``near_d`` :data:`NEAR_SPAN`: the four
    pixels that far, ``R`` to the right and below) and the measured support's
    (:func:`_spreads_rows`: the four pixels :data:`NEAR_SPAN` away and the four ``R`` away,
    right, left, below and above). A one-sided spread or a neighbour distance of 1 where 3 is
    meant fails it."""
    from depthnormals.ddm import uncertainty as U

    rng = np.random.default_rng(3)
    n = rng.standard_normal((41, 53, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    n[rng.random((41, 53)) < 0.1] = np.nan
    big = 6

    def cross(d):
        return _mean_finite([_angle_ref(n, dv, du) for dv, du in ((-d, 0), (d, 0), (0, -d), (0, d))])

    assert U.NEAR_SPAN == 3
    out = np.empty((2, 41, 53), dtype=np.float32)
    # each band computes the vertical pairs above its first row (session 40): bands from the
    # bottom up, one starting within the near span of the top, so that no freed ring of the
    # band before holds them by chance
    bands = ((17, 41), (2, 17), (0, 2)) if kernel != "support" else ((0, 41),)
    if kernel in ("fit-error", "box-fit"):
        s1 = cross(1 if kernel == "fit-error" else U.NEAR_SPAN)
        sr = _mean_finite([_angle_ref(n, big, 0), _angle_ref(n, 0, big)])
        z = np.ones((41, 53), dtype=np.float32)
        tiles = (np.ones((1, 1)), np.ones((1, 1)), 64)
        box = ((np.zeros((2, 41, 53), np.float32), 0, np.empty((41, 53), np.float32), U.NEAR_SPAN,
                0.0) if kernel == "box-fit" else
               (np.empty((2, 1, 1), np.float32), 0, np.empty((1, 1), np.float32), 0, 0.0))
        for v0, v1 in bands:
            U._fit_error_rows(v0, v1, z, n, np.ones((41, 53), np.float32), 0, tiles,
                              (1.0, 0, 1.0, False), (np.full((1, 1), np.inf, np.float32),
                                                          0.0, 1.0), (40.0, 40.0, 26.0, 20.0),
                              np.empty((41, 53), np.float32), out, big, box)
    else:
        s1, sr = cross(U.NEAR_SPAN), cross(big)
        planar = np.ascontiguousarray(n.transpose(0, 2, 1))  # (H, 3, W)
        for v0, v1 in bands:
            U._spreads_rows(v0, v1, planar, U.NEAR_SPAN, big, out)
    ok = np.isfinite(n[..., 0])
    np.testing.assert_allclose(out[0][ok], s1[ok], atol=2e-4)
    np.testing.assert_allclose(out[1][ok], sr[ok], atol=2e-4)


def _offsets_ref(z, n, d, cam):
    """numpy reference of :func:`_offsets_rows`: per axis, where ``n . (Q - P) / (z / fx) / d``
    has opposite signs on the two sides, the lesser magnitude, else 0 (also where a side is
    invalid); the larger axis."""
    fx, fy, cx, cy = cam
    h, w = z.shape
    v, u = np.mgrid[0:h, 0:w]
    x = np.stack([(u - cx) / fx * z, (v - cy) / fy * z, z], -1).astype(np.float64)

    def side(dv, du):
        return (n * (_neighbour(x, dv, du) - x)).sum(-1) / (z / fx) / d

    def axis(a, b):
        return np.where(a * b < 0, np.fmin(np.abs(a), np.abs(b)), 0.0)

    with np.errstate(invalid="ignore"):
        return np.fmax(axis(side(0, d), side(0, -d)), axis(side(d, 0), side(-d, 0)))


@pytest.mark.parametrize("span", [3, 6])
def test_offsets_match_numpy_and_read_the_tilt(span):
    """How far each pixel's plane misses its depth ``d`` cells away (each of
    :data:`DEPTH_SPANS`): equal to a numpy reference with invalid depth and normals (one band
    of rows or two). With ``d = 3``: on a fronto-parallel plane whose normals are tilted by 30
    deg about the y axis it reads sin 30 deg = 0.5 (the slope across the tilt), with the true
    normals 0; beside a crease (a fronto-parallel face, one receding 1:1) with the true normals
    0 (one side of each axis fits), and where the receding face's first pixels took the other
    face's normal, k / 3 at k pixels past the crease (the depth rises on one side and falls on
    the other; the larger side would read 1 at every k); a pixel whose own depth is off its
    plane, and a pixel beside a one-sided step, read 0 (both sides leave the plane the same
    way, or one side fits: the lesser magnitude alone would read the spike's height)."""
    from depthnormals.ddm import uncertainty as U

    assert U.DEPTH_SPANS == (3, 6)
    cam = (40.0, 40.0, 26.0, 20.0)
    rng = np.random.default_rng(5)
    z = (2.0 + 0.05 * rng.standard_normal((41, 53))).astype(np.float32)
    z[rng.random(z.shape) < 0.1] = np.nan
    n = rng.standard_normal((41, 53, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    n[rng.random((41, 53)) < 0.1] = np.nan
    planar = np.ascontiguousarray(n.transpose(0, 2, 1))
    want = _offsets_ref(z, n, span, cam)
    assert np.count_nonzero(want) > 100
    for bands in (((0, 41),), ((0, 17), (17, 41))):
        out = np.full((2, *z.shape), -1.0, np.float32)
        for v0, v1 in bands:
            U._offsets_rows(v0, v1, z, planar, (span, 3), cam, out)
        np.testing.assert_allclose(out[0], want, rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(out[1], _offsets_ref(z, n, 3, cam), rtol=1e-4, atol=1e-5)
    if span != 3:
        return

    def offsets(z, n):
        out = np.empty((1, *z.shape), np.float32)
        U._offsets_rows(0, z.shape[0], z, np.ascontiguousarray(n.transpose(0, 2, 1)),
                        (3,), cam, out)
        return out[0]

    flat = np.full((41, 53), 2.0, np.float32)
    t = math.radians(30.0)
    tilted = np.broadcast_to(np.float32([math.sin(t), 0.0, -math.cos(t)]), (41, 53, 3))
    o = offsets(flat, tilted)
    np.testing.assert_allclose(o[:, 3:-3], 0.5, atol=1e-5)
    assert np.all(o[:, :3] == 0.0) and np.all(o[:, -3:] == 0.0)  # one side only: no reading
    assert np.abs(offsets(flat, np.broadcast_to(np.float32([0, 0, -1]), (41, 53, 3)))).max() < 1e-6
    u = np.arange(53, dtype=np.float32)
    # a crease at column 26: left face fronto-parallel, right face receding 1:1
    xr = (u - cam[2]) / cam[0]
    zc = np.where(u <= 26, 2.0, 2.0 / (1.0 - xr + xr[26])).astype(np.float32)
    zz = np.broadcast_to(zc, (41, 53)).copy()
    nl = np.float32([0.0, 0.0, -1.0])
    nr = np.float32([1.0, 0.0, -1.0]) / np.float32(math.sqrt(2.0))
    true = np.where((u <= 26)[None, :, None], nl, nr).astype(np.float32) * np.ones((41, 1, 1), np.float32)
    o = offsets(zz, true)
    assert o[5:-5, 20:33].max() < 1e-3  # beside the crease, one side of each axis fits
    wrong = true.copy()
    wrong[:, 27:30] = nl  # three pixels of the receding face took the other face's normal
    o = offsets(zz, wrong)
    for k in (1, 2, 3):  # k pixels into it: no side fits, the nearer misses by k of 3 cells
        np.testing.assert_allclose(o[5:-5, 26 + k], k / 3.0, rtol=0.05)
    front = np.broadcast_to(nl, (41, 53, 3))
    spike = flat.copy()
    spike[20, 30] = 2.1  # the pixel's own depth 0.1 m behind its plane: 1 footprint per cell
    o = offsets(spike, front)
    assert o[20, 30] == 0.0
    assert np.abs(_offsets_ref(spike, front, 3, cam)[20, 30]) == 0.0
    step = flat.copy()
    step[:, 30:] = 2.05  # a step: the pixels beside it see it on one side only
    assert offsets(step, front)[5:-5].max() < 1e-6


def _support_row(w):
    """One row of ``w`` pixels for ``_support_rows``: depth 2 m, normals facing the camera but
    the last (NaN), by row ((1, 3, W), as the branch hands them), no jumps or steps."""
    z = np.full((1, w), 2.0, np.float32)
    n = np.zeros((1, 3, w), np.float32)
    n[0, 2] = -1.0
    n[0, :, w - 1] = np.nan
    return z, n, np.zeros((2, 1, w), np.float32)


def test_support_map_adds_the_depth_ramp():
    """The measured support's map, last: plus ``A t^2 min(m / DEPTH_FULL, 1)`` with ``t`` the
    ramp of the offsets over their frame scales (:data:`DEPTH_RAMP`), the lesser of the two
    spans, over ``sqrt(growth)``: nothing up to ``r0``, a quarter at the middle, all from
    ``r1``; the scale and the growth divide; NaN where the normal is NaN."""
    from depthnormals.ddm import uncertainty as U

    a, r0, r1 = U.DEPTH_RAMP
    assert (a, r0, r1, U.DEPTH_FULL) == (55.0, 0.7, 2.5, 0.5)
    w = 8
    z, n, sub = _support_row(w)

    def run(o3, o6, inv_q=(1.0, 1.0), model=(1.0, 2.0, 0), spreads=(2.0, 3.0)):
        out = np.empty((1, w), np.float32)
        offs = np.stack([np.float32([o3]), np.float32([o6])])
        s1 = np.full((1, w), spreads[0], np.float32)
        far = np.full((1, 1, w), spreads[1], np.float32)
        zero = np.zeros((1, w), np.float32)
        U._support_rows(0, 1, z, n, model, (s1, far, sub, 0, offs, inv_q, zero, 5.0), _no_bend(w),
                        out)
        return out[0]

    m = run([0.0] * w, [0.0] * w)
    assert np.all(m[:7] > U.DEPTH_FULL) and np.isnan(m[7])
    mid = (r0 + r1) / 2
    got = run([0.0, r0, mid, r1, 5.0, 5.0, 5.0, 5.0], [0.0, r0, mid, r1, 5.0, r0, 5.0, 5.0])
    want = m + a * np.float32([0.0, 0.0, 0.25, 1.0, 1.0, 0.0, 1.0, 1.0])
    np.testing.assert_allclose(got[:7], want[:7], rtol=1e-5)
    assert np.isnan(got[7])
    # the frame's scale: at inverse scale 1/2 offsets of 2 r1 read r1 (all), of 2 r0 nothing
    got = run([2 * r1, 2 * r0] + [0.0] * 6, [2 * r1, 2 * r0] + [0.0] * 6, inv_q=(0.5, 0.5))
    np.testing.assert_allclose(got[:2], m[:2] + a * np.float32([1.0, 0.0]), rtol=1e-5)
    # the growth: at twice zref with half = 4 (sqrt(growth) = 2) an offset of 2 r1 reads r1
    zg = run([2 * r1] * w, [2 * r1] * w, model=(1.0, 1.0, 4))
    mg = run([0.0] * w, [0.0] * w, model=(1.0, 1.0, 4))
    np.testing.assert_allclose(zg[:7], mg[:7] + a, rtol=1e-5)
    # a map under DEPTH_FULL gains in proportion
    lo = run([r1] * w, [r1] * w, model=(0.2, 2.0, 0), spreads=(0.1, 0.1))
    m_lo = run([0.0] * w, [0.0] * w, model=(0.2, 2.0, 0), spreads=(0.1, 0.1))
    assert np.all(m_lo[:7] < U.DEPTH_FULL)
    np.testing.assert_allclose(lo[:7], m_lo[:7] + a * m_lo[:7] / U.DEPTH_FULL, rtol=1e-5)


def test_support_map_reads_the_fallback():
    """A pixel that fell back to small windows (deviation > DEVIATION) reads FALLBACK_SCALE
    times the map of the choice before the fallback; the others as before; NaN stays NaN."""
    from depthnormals.ddm import uncertainty as U
    from depthnormals.ddm.support import DEVIATION

    assert U.FALLBACK_SCALE == 0.8
    w = 8
    z, n, sub = _support_row(w)

    def run(dev):
        out = np.empty((1, w), np.float32)
        offs = np.zeros((2, 1, w), np.float32)
        s1 = np.full((1, w), 2.0, np.float32)
        far = np.full((1, 1, w), 3.0, np.float32)
        U._support_rows(0, 1, z, n, (1.0, 2.0, 0), (s1, far, sub, 0, offs, (1.0, 1.0),
                                                     np.float32([dev]), DEVIATION), _no_bend(w), out)
        return out[0]

    m = run([0.0] * w)
    assert np.all(m[:7] > U.DEPTH_FULL) and np.isnan(m[7])
    got = run([0.0, DEVIATION, DEVIATION + 0.01, 9.0, 0.0, 1.0, 50.0, 9.0])
    scale = np.float32([1, 1, U.FALLBACK_SCALE, U.FALLBACK_SCALE, 1, 1, U.FALLBACK_SCALE])
    np.testing.assert_allclose(got[:7], m[:7] * scale, rtol=1e-6)
    assert np.isnan(got[7])


def _kinect_like_kerb(seed, shape=(240, 320), kerb=2.0, road=1.2, top=1.05):
    """A road ``road`` m below the camera, a kerb whose vertical riser stands ``kerb`` m ahead
    and whose top lies ``top`` m below (a face about 22 rows tall), seen by
    :func:`_kinect_like_depth` (rows above the horizon invalid); depth, K, the exact normals
    and the riser's mask."""
    h, w = shape
    K = np.array([[300.0, 0.0, (w - 1) / 2], [0.0, 300.0, 20.0], [0.0, 0.0, 1.0]])
    y = (np.arange(h)[:, None] - K[1, 2]) / K[1, 1] + np.zeros((1, w))
    ok = y > 0.05
    yy = np.where(ok, y, 1.0)
    zr, zt = road / yy, top / yy
    riser = ok & (zt <= kerb) & (zr > kerb)
    z = np.where(zt > kerb, zt, np.where(zr > kerb, kerb, zr))
    g = np.zeros((h, w, 3), np.float32)
    g[:] = (0.0, -1.0, 0.0)
    g[riser] = (0.0, 0.0, -1.0)
    d = _kinect_like_depth(z, seed).astype(np.float32)
    d[~ok] = np.nan
    return d, K, g, riser


def test_support_map_misses_a_risers_margins():
    """A known weakness, pinned (session 20; update it when the map or the normals improve
    there): on a Kinect-like kerb the riser (22 rows at 2 m) falls back to small windows in
    its middle, but its outer rows by each crease keep the road's or the kerb top's normal
    and err 73 / 75 / 88 / 79 deg over the outer four (seeds 0-3) while the map read 3.3 /
    3.1 / 6.1 / 3.5 deg: the choice is one face there and no spread sees it (the synthetic
    kinect_v1 column's misses, docs/benchmarks.md 17, "Session 20"; reading the near spread
    on the normals returned as well lifted these rows only to 4.3-6.1 deg). The crease floor
    (session 24, :data:`CREASE_FLOOR`) does not reach them: it reads the creases between two
    cells that both fell back, and these rows kept their windows; nor the third and fourth rows
    from the lower crease (33-55 deg, read 6), which fell back beside them. The middle rows,
    which fell back, err 9-16 deg and read 15-21.

    Session 31: the face switch (ddm/faceswitch.py) puts the lower crease's two outer rows on
    the riser on three seeds of four (err 5.6 / 5.7 / 67.5 / 7.1 deg), the upper crease's stay
    on the kerb top (77-88), and the map reads the switch's decisions there: the outer four rows
    err 44.3 / 43.5 / 77.6 / 42.0 and read 31.0 / 30.3 / 19.9 / 30.7 (no longer 3-6); the
    middle rows err 9-12 and read 13-14."""
    lower = []
    for seed in range(4):
        d, K, g, riser = _kinect_like_kerb(seed)
        assert dn.noise_profile(d, K).branch == "measured-support"
        n, u = dn.estimate_normals(d, K, return_uncertainty=True)
        err = dn.angular_error(n, g)
        rows = np.nonzero(riser[:, 0])[0]
        assert 20 <= rows.size <= 24
        margins = np.zeros(riser.shape, bool)
        margins[rows[:2]] = margins[rows[-2:]] = True
        middle = np.zeros(riser.shape, bool)
        middle[rows[6]:rows[-6]] = True
        assert np.nanmean(err[rows[:2]]) > 60.0  # the upper crease: still the top's face
        assert np.nanmean(err[margins]) > 40.0
        assert np.nanmean(u[margins]) > 15.0  # read: the switch's decisions
        assert np.nanmean(err[middle]) < 25.0
        assert np.nanmean(u[middle]) > 10.0
        lower.append(np.nanmean(err[rows[-2:]]))
    assert sum(e < 10.0 for e in lower) >= 3, lower  # the lower crease: on the riser


def test_crease_floor_raises_the_pixels_by_a_crease_between_fallen_back_cells(monkeypatch):
    """The crease floor end to end (:data:`CREASE_FLOOR`), on the Kinect-like sawtooth
    (:func:`_kinect_like_sawtooth`, seeds 0-2): the map with it is the map without it or above,
    the same NaN; it raises a few pixels (0.01-0.04 %), which err 46-49 deg where the map read
    1-2 without it and 14-17 with it."""
    from depthnormals.ddm import uncertainty as U

    raised_err, before, after = [], [], []
    for seed in range(3):
        d, K, g = _kinect_like_sawtooth(seed)[:3]
        monkeypatch.setattr(U, "CREASE_FLOOR", (0.0, 0.6, 20.0))
        n, u0 = dn.estimate_normals(d, K, return_uncertainty=True)
        monkeypatch.setattr(U, "CREASE_FLOOR", (0.8, 0.6, 20.0))
        _, u1 = dn.estimate_normals(d, K, return_uncertainty=True)
        assert np.array_equal(np.isnan(u0), np.isnan(u1))
        ok = np.isfinite(u0)
        assert np.all(u1[ok] >= u0[ok])
        r = ok & (u1 > u0)
        assert 0 < r.sum() < 0.001 * r.size
        raised_err.append(dn.angular_error(n, g)[r])
        before.append(u0[r])
        after.append(u1[r])
    e, b, a = (np.concatenate(x) for x in (raised_err, before, after))
    assert np.nanmean(e) > 30.0 and np.mean(b) < 3.0 and np.mean(a) > 10.0, (
        np.nanmean(e), np.mean(b), np.mean(a))


def _kinect_like_sawtooth(seed, period=8, shape=(240, 320), wall=1.5):
    """A wall ``wall`` m ahead whose middle (rows 60-179, columns 60-259) is a sawtooth of
    45 deg faces ``period`` px apart (``period / 2`` footprints peak to peak: 2 cm at 8 px), seen by
    :func:`_kinect_like_depth`: depth, K, the exact normals and the sawtooth's mask."""
    h, w = shape
    f = 300.0
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    rx = (np.arange(w)[None, :] - K[0, 2]) / f + np.zeros((h, 1))
    saw = np.zeros((h, w), bool)
    saw[60:180, 60:260] = True
    p = period * wall / f  # the period in metres at the wall
    z = np.full((h, w), wall)
    for _ in range(50):  # the ray's depth on z = wall - tri(x): a contraction (slope 1 / 2)
        ph = np.mod(rx * z, p) / p
        z = np.where(saw, wall - np.where(ph < 0.5, ph, 1.0 - ph) * p, wall)
    ph = np.mod(rx * z, p) / p
    g = np.zeros((h, w, 3), np.float32)
    g[..., 2] = -1.0
    dzdx = np.where(ph < 0.5, -1.0, 1.0)  # the teeth's faces; n ~ (dz/dx, 0, -1) faces the camera
    g[saw, 0] = (dzdx / np.sqrt(2.0))[saw]
    g[saw, 2] = -1.0 / np.sqrt(2.0)
    return _kinect_like_depth(z, seed).astype(np.float32), K, g, saw


def test_support_map_misses_a_sawtooth_narrower_than_its_windows():
    """A known weakness, pinned (session 22; update it when the map improves there): a
    sawtooth of 45 deg faces 8 px apart on a wall 1.5 m away under Kinect-like noise is
    plainly in the depth (its windows' residual is 4-6x the wall's), but the measured support
    (radius 16) fits it as the wall and errs 45 deg while the map reads under 3: the map reads
    no per-pixel residual, its spreads see a smooth output and its offsets look for a tilt.
    The clutter of the benchmark's own scenes (`--preset ssn`: shelves of books and tins),
    where kinect_v1, realsense_d4xx and tof under-predict by 1.3-1.8x (docs/benchmarks.md 17,
    "Session 22"). The wall beside it stays calibrated: 0.78-0.81x its observed error
    before session 37's bend term (:mod:`depthnormals.ddm.bend`), 1.12-1.29x with it (the
    residual noise of the wall's mean normals 48 px apart, which the term adds)."""
    from depthnormals.ddm import uncertainty as U
    from depthnormals.ddm.support import support_profile, support_select

    for seed in range(3):
        d, K, g, saw = _kinect_like_sawtooth(seed)
        prof = dn.noise_profile(d, K)
        assert prof.branch == "measured-support" and prof.radius == 16
        n, u = dn.estimate_normals(d, K, return_uncertainty=True)
        err = dn.angular_error(n, g)
        inner = np.zeros(saw.shape, bool)
        inner[80:160, 80:240] = True  # the sawtooth, 20 px in from its rim
        wall = np.zeros(saw.shape, bool)
        wall[200:] = True
        assert 44.0 < np.nanmean(err[inner]) < 48.0
        assert np.nanmean(u[inner]) < 3.0
        assert np.nanmean(err[wall]) < 0.6
        assert 0.5 < np.nanmean(u[wall]) / np.nanmean(err[wall]) < 1.35
        z, cam = U.prepare(d, K, None)
        c = (float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy))
        scores: list = []
        support_select(z, *c, prof.sigma, profile=support_profile(z, *c, prof.sigma),
                       out_scores=scores)
        score, halved = scores[0], scores[5]
        assert halved  # the windows' residuals on every second row and column
        assert np.median(score[40:80, 40:120]) > 4.0 * np.median(score[100:])


def test_offset_scales_read_the_percentile_over_the_growth():
    """The frame scale of each span's offsets: the :data:`DEPTH_QUANTILE` th percentile of
    ``o / sqrt(growth)`` on every :data:`MEDIAN_STEP`-th row and column, where the normal is
    valid and the offset positive; 0 with none."""
    from depthnormals.ddm import uncertainty as U

    rng = np.random.default_rng(2)
    h, w = 60, 70
    z = np.full((h, w), 4.0, np.float32)
    z[: h // 2] = 1.0
    n = np.zeros((h, w, 3), np.float32)
    n[..., 2] = -1.0
    n[::3, ::5] = np.nan
    offs = rng.random((2, h, w)).astype(np.float32)
    offs[1] *= 3.0
    offs[:, ::4] = 0.0
    got = U._offset_scales(z, n[..., 0], offs, 1.0, 4)  # sqrt(growth) = z / zref
    st = U.MEDIAN_STEP
    for i in range(2):
        s = (offs[i] / z)[::st, ::st]
        s = s[np.isfinite(n[::st, ::st, 0]) & (s > 0)]
        assert got[i] == pytest.approx(np.percentile(s, U.DEPTH_QUANTILE), rel=1e-5)
    assert got[1] > 2.0 * got[0]
    flat = U._offset_scales(z, n[..., 0], offs, 1.0, 0)  # no growth
    assert flat[0] > got[0]
    assert np.all(U._offset_scales(z, n[..., 0], np.zeros_like(offs), 1.0, 4) == 0.0)


def test_edge_integrals_match_numpy():
    """Depth jumps (over 3 % of the nearer depth, or invalid) and quantisation steps per
    pixel, summed into integral images, and their window means."""
    from depthnormals.ddm import uncertainty as U

    rng = np.random.default_rng(4)
    z = (2.0 + np.round(rng.standard_normal((30, 37)) * 4) / 100).astype(np.float32)
    z[5:9, 10:20] = 3.0
    z[20, 3] = np.nan
    jump = ~np.isfinite(z)
    steps = np.zeros(z.shape)
    for ax in (0, 1):
        a, b = (z[:-1], z[1:]) if ax == 0 else (z[:, :-1], z[:, 1:])
        d = np.abs(a - b)
        j = ~(d <= 0.03 * np.fmin(a, b))
        s = (d > 0) & np.isfinite(d)
        for arr, x in ((jump, j), (steps, s)):
            if ax == 0:
                arr[:-1] += x
                arr[1:] += x
            else:
                arr[:, :-1] += x
                arr[:, 1:] += x
    ij = np.empty((31, 38), np.float32)
    ist = np.empty((31, 38), np.float32)
    U._edge_integrals(z, U.JUMP_REL, ij, ist)
    np.testing.assert_array_equal(ij[1:, 1:], np.cumsum(np.cumsum(jump, 0), 1))
    np.testing.assert_array_equal(ist[1:, 1:], np.cumsum(np.cumsum(steps, 0), 1))
    mj = np.empty(z.shape, np.float32)
    ms = np.empty(z.shape, np.float32)
    U._box_planes(ij, ist, 2, mj, ms)
    v, u = 12, 0  # a window clipped at the left edge: rows 10..14, columns 0..2
    assert mj[v, u] == pytest.approx(jump[10:15, 0:3].mean())
    assert ms[v, u] == pytest.approx(steps[10:15, 0:3].mean())
    for v in range(z.shape[0]):  # every window, clipped at any border or not
        for u in range(z.shape[1]):
            rows, cols = slice(max(0, v - 2), v + 3), slice(max(0, u - 2), u + 3)
            assert mj[v, u] == pytest.approx(jump[rows, cols].mean(), rel=1e-6)
            assert ms[v, u] == pytest.approx(steps[rows, cols].mean(), rel=1e-6)


def test_box_fit_ramp_and_high_factor():
    """The box-fit branch's last pass: times ``BOX_HIGH[1]`` where the noise error exceeds
    its bound, then the monotone ramp ``BOX_RAMP``: unchanged up to 8 deg, x1.125 at 10 deg,
    x1.25 from 12 deg; NaN stays NaN."""
    from depthnormals.ddm import uncertainty as U

    a, m0, m1 = U.BOX_RAMP
    assert (a, m0, m1) == (0.25, 8.0, 12.0)
    m = np.array([[1.0, 8.0, 10.0, 12.0, 40.0, np.nan, 20.0]], np.float32)
    e = np.array([[0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 5.0]], np.float32)  # the last one high
    out = m.copy()
    U._box_final_rows(0, 1, e, 1.0, 1.0, out)
    hi = 20.0 * U.BOX_HIGH[1]
    want = [1.0, 8.0, 10.0 * 1.125, 15.0, 50.0, np.nan,
            hi * (1.0 + a * min(1.0, max(0.0, (hi - m0) / (m1 - m0))))]
    np.testing.assert_allclose(out[0], want, rtol=1e-6)
    ramp = np.linspace(0.0, 60.0, 601, dtype=np.float32)[None]
    r = ramp.copy()
    U._box_final_rows(0, 1, np.zeros_like(ramp), 1.0, 1.0, r)
    assert np.all(np.diff(r[0]) > 0)  # monotone: the ranking is unchanged
    scaled = m.copy()  # the excess's scale multiplies after the ramp, then the cap
    U._box_final_rows(0, 1, e, 1.0, 1.5, scaled)
    np.testing.assert_allclose(scaled[0], np.minimum(1.5 * np.array(want), U.MAX_ERROR),
                               rtol=1e-6)


def test_box_map_grows_with_the_measured_excess(monkeypatch):
    """The box-fit branch's map is linear in the excess of the measured fit error over the
    i.i.d. prediction: ``e`` carries it at the power 3/8 (the product), the last factor at
    :data:`BOX_EXCESS` (session 32: the tof model's frames, excess 1.1-1.8, under-read 1.13-1.24x
    everywhere without it), so where no ramp applies the map at an excess ``x`` is
    ``x^(3/8 + BOX_EXCESS)`` times the map at 1; the normals do not change."""
    from depthnormals.analytic import make_scene
    from depthnormals.ddm import uncertainty as U

    assert U.BOX_EXCESS == 0.5
    K = (300.0, 300.0, 159.5, 119.5)
    r = make_scene("box-on-floor").render(K=K, shape=(240, 320))
    rng = np.random.default_rng(4)
    d = (r.depth * (1.0 + 0.002 * rng.standard_normal(r.depth.shape))).astype(np.float32)
    maps = {}
    monkeypatch.setattr(U, "_clean", lambda z: 0.0)  # the jump term linear in the product
    for x in (1.0, 1.69):
        monkeypatch.setattr(U, "_excess_at", lambda prof, radius, x=x: x)
        n, u = dn.estimate_normals(d, K, return_uncertainty=True)
        maps[x] = (n, u)
    np.testing.assert_array_equal(maps[1.0][0], maps[1.69][0])
    u1, u2 = maps[1.0][1], maps[1.69][1]
    low = np.isfinite(u1) & (u1 < 0.5 * U.BOX_RAMP[1])  # below the ramp, also once scaled
    assert low.mean() > 0.5
    np.testing.assert_allclose(u2[low] / u1[low], 1.69 ** (3 / 8 + U.BOX_EXCESS), rtol=1e-4)


def test_box_product_weighs_clean_jumps_only_where_the_windows_cross_an_edge():
    """On a frame of clean jumps (``clean`` 1, :data:`BOX_CLEAN`) the jump term counts only as
    far as the product without it reads a window across an edge: none below ``t0`` deg, all
    of it from ``t1``, linear between; on a frame of mixed pixels (``clean`` 0) all of it, as
    before session 33; half clean, halfway."""
    from depthnormals.ddm import uncertainty as U

    s0, s1, t0, t1 = U.BOX_CLEAN
    assert 0.0 < s0 < s1 < 1.0 and 0.0 < t0 < t1
    k = U.BOX_POW
    n = 7
    e = np.geomspace(0.01, 1e4, n).astype(np.float32)  # products from below t0 to above t1
    s = np.full(n, 2.0, np.float32)
    j = np.full(n, 0.2, np.float32)
    st = np.zeros(n, np.float32)
    p = U.BOX_MAP[0] * (e ** k[0] * s ** k[1] * s ** k[2] * U.STEP_OFFSET ** k[3]) ** 0.125
    assert p.min() < t0 and p.max() > t1
    t = np.clip((p - t0) / (t1 - t0), 0.0, 1.0)
    for clean, w in ((0.0, np.ones(n)), (1.0, t), (0.5, 1.0 - 0.5 * (1.0 - t))):
        out = np.empty(n, np.float32)
        U._box_product(e, s, s, j, st, clean, out)
        np.testing.assert_allclose(out, p * (1.0 + U.BOX_MAP[1] * j * w), rtol=1e-5)
    out = np.empty(n, np.float32)
    U._box_product(e, s, s, j, st, 1.0, out)
    np.testing.assert_allclose(out[p < t0], p[p < t0], rtol=1e-5)  # no jump term at all


def test_clean_jumps_lower_the_box_map_only_beside_a_jump(monkeypatch):
    """The box on the floor with Gaussian noise (one-pixel steps: ``_clean`` reads 1) against
    the same frame read as mixed (``_clean`` 0): the normals do not change; the map does not
    change where no jump lies in the large window, and beside the box's jumps, where the map
    is low, it falls by the jump term (session 33: on Gaussian noise those pixels read
    0.35-0.76 of their map)."""
    from depthnormals.analytic import make_scene
    from depthnormals.ddm import uncertainty as U
    from depthnormals.ddm.auto import MAX_BIG_RADIUS

    K = (300.0, 300.0, 159.5, 119.5)
    r = make_scene("box-on-floor").render(K=K, shape=(240, 320))
    rng = np.random.default_rng(4)
    d = (r.depth * (1.0 + 0.1 * rng.standard_normal(r.depth.shape) / 300.0)).astype(np.float32)
    z = np.where(d > 0, d, np.nan).astype(np.float32)
    assert U._clean(z) == 1.0
    n1, u1 = dn.estimate_normals(d, K, return_uncertainty=True)
    monkeypatch.setattr(U, "_clean", lambda z: 0.0)
    n0, u0 = dn.estimate_normals(d, K, return_uncertainty=True)
    np.testing.assert_array_equal(n0, n1)
    np.testing.assert_array_equal(np.isnan(u0), np.isnan(u1))
    ok = np.isfinite(u0)
    assert (u1[ok] <= u0[ok]).all()
    # no jump within the largest window (MAX_BIG_RADIUS) on the map's grid (every
    # 2^BOX_SUB-th row and column, where a steep floor can pass the relative test): no jump
    # term, the map as it was
    st = 1 << U.BOX_SUB
    sub = U._densities(z, MAX_BIG_RADIUS, U.BOX_SUB)[0]
    jr = np.repeat(np.repeat(sub, st, 0), st, 1)[:z.shape[0], :z.shape[1]]
    far = ok & (jr == 0.0)
    assert far.mean() > 0.2
    np.testing.assert_array_equal(u1[far], u0[far])
    low = ok & (u0 < 0.5 * U.BOX_CLEAN[2])
    moved = low & (u1 < 0.9 * u0)
    assert moved.sum() > 500  # the pixels beside the box's jumps


def test_box_product_is_linear_in_the_noise_and_weights_the_far_spread():
    """The box-fit map's product of powers (session 21: exponents (3, 3, 2) eighths of the
    noise error, the near spread and the spread one large radius away): on a plane, where
    both spreads are proportional to the noise, the map is proportional to it (the three
    exponents sum to 8: twice the noise, twice the map); a near spread 4x reads 4^(3/8) = 1.68x,
    a far one 4x 4^(2/8) = 1.41x (1.19x before session 21: the window one radius away shares
    no pixel with the pixel's own, so its angle is the realised error, and it ranks the error
    better). Jumps and steps enter as before."""
    from depthnormals.ddm import uncertainty as U

    k = U.BOX_POW
    assert k[0] + k[1] + k[2] == 8 and k[2] > 1
    e = np.array([0.2, 0.4, 0.2, 0.2, 0.2], np.float32)
    s1 = np.array([0.3, 0.6, 1.2, 0.3, 0.3], np.float32)
    s3 = np.array([0.25, 0.5, 0.25, 1.0, 0.25], np.float32)
    j = np.array([0.0, 0.0, 0.0, 0.0, 0.1], np.float32)
    st = np.zeros(5, np.float32)
    out = np.empty(5, np.float32)
    U._box_product(e, s1, s3, j, st, 0.0, out)
    want = (U.BOX_MAP[0] * (1.0 + U.BOX_MAP[1] * j)
            * (e ** k[0] * s1 ** k[1] * s3 ** k[2] * (U.STEP_OFFSET + st) ** k[3]) ** 0.125)
    np.testing.assert_allclose(out, want, rtol=1e-5)
    assert out[1] == pytest.approx(2.0 * out[0], rel=1e-5)  # twice the noise on a plane
    assert out[2] / out[0] == pytest.approx(4.0 ** (k[1] / 8), rel=1e-5)
    assert out[3] / out[0] == pytest.approx(4.0 ** (k[2] / 8), rel=1e-5)
    assert out[3] / out[0] > 1.4  # the far spread at twice its former weight


def test_real_frame_held_out(shared_data):
    """A held-out real frame (the first of ``tum_fr2_kinect1_slambook``; not in the training
    split of the map's constants) on its plane references: Spearman 0.565, mean predicted
    4.74 against 5.25 deg observed (the former map: Spearman 0.39 over the folder's two
    frames, docs/benchmarks.md 17); since session 16's fallback of narrow faces 0.553, 4.96
    against 4.47 (the normals err less, the map reads the choice before the fallback); since
    session 31's face switch 0.549, 4.82 against 4.03 (the normals err less again; the map reads
    the switch's decisions); since session 37's bend term (:mod:`depthnormals.ddm.bend`)
    0.548, 5.12 against 4.03 (its lowest quartile, 0.72 against 1.36 deg before, rises with the
    rest: the frame's map was high above its median already)."""
    from depthnormals.evaluate import plane_reference, sensor_threshold

    f = next(iter(dn.datasets.open(shared_data / "real-sensors" / "tum_fr2_kinect1_slambook")))
    ref = plane_reference(f.depth, f.K, seed=0, threshold=sensor_threshold(f.meta))
    n, u = dn.estimate_normals(f.depth, f.K, return_uncertainty=True)
    err = dn.angular_error(n, ref.normal_map().astype(np.float32))
    m = (ref.interior | ref.rim) & np.isfinite(err) & np.isfinite(u)
    p, o = u[m].astype(np.float64), err[m].astype(np.float64)
    rank = np.corrcoef(np.argsort(np.argsort(p)), np.argsort(np.argsort(o)))[0, 1]
    assert rank >= 0.545, rank
    assert abs(p.mean() - o.mean()) <= 0.3 * o.mean(), (p.mean(), o.mean())


def test_calibration_bench_reference_agreement_counts_each_case(load_benchmark):
    """``ReferenceAgreement`` (``--planes``): six pixels, one per case, the angles chosen on
    each side of ``WRONG_DEG`` (30) and ``SAME_DEG`` (10): a reference over 30 deg off with the
    estimate on it (off the same way), one with the estimate off both, the estimate alone off,
    all right, a pixel outside both parts and one with a NaN; interiors and rims apart."""
    bench = load_benchmark("uncertainty_calibration")
    #                  same  both  est   right outside nan
    err_exact = np.array([40.0, 50.0, 35.0, 2.0, 90.0, 1.0])
    err_ref = np.array([5.0, 45.0, 33.0, 2.0, 90.0, np.nan])
    ref_exact = np.array([41.0, 31.0, 3.0, 0.5, 90.0, 0.0])
    interior = np.array([True, False, True, True, False, True])
    rim = np.array([False, True, False, False, False, False])
    a = bench.ReferenceAgreement()
    a.add(err_exact, err_ref, ref_exact, (interior, rim))
    a.add(err_exact, err_ref, ref_exact, (interior, rim))  # counts add up
    rows = a.rows()
    assert rows["interior"] == {"pixels": 6, "reference_off": 2 / 6, "estimate_off_exact": 4 / 6,
                                "estimate_off_reference": 2 / 6, "off_the_same_way": 2 / 6}
    assert rows["rim"] == {"pixels": 2, "reference_off": 1.0, "estimate_off_exact": 1.0,
                           "estimate_off_reference": 1.0, "off_the_same_way": 0.0}
    empty = bench.ReferenceAgreement().rows()["rim"]
    assert empty["pixels"] == 0 and math.isnan(empty["off_the_same_way"])


def test_calibration_bench_splits_synthetic_on_and_off_planes(tmp_path, load_benchmark):
    """``benchmarks/uncertainty_calibration.py --planes``: each noisy synthetic column is
    split into the pixels of the plane reference found on its noisy depth and the rest, so the
    two together are exactly the column (no pixel lost or counted twice), the clean column is
    not split, and both parts of a room scene have pixels; ``synth-asreal`` holds the plane
    pixels scored as the real frames are, against the reference's own normals (its mean
    observed error that of the estimate against ``PlaneReference.normal_map``, not the exact
    normals')."""
    from depthnormals.camera import Intrinsics
    from depthnormals.synth import generate

    generate(tmp_path, indoor=1, outdoor=0, views=1, seed=3, K=Intrinsics(91.375, 91.375, 63.5, 52.5),
             size=(106, 128), progress=False, noise=("kinect_v1",))
    bench = load_benchmark("uncertainty_calibration")
    agreement: dict = {}
    cols = {k: c.summary() for k, c in bench.synth_columns(tmp_path, "3f2n+", planes=True,
                                                           agreement=agreement).items()}
    assert set(cols) == {"synth/clean", "synth/kinect_v1", "synth-planes/kinect_v1",
                         "synth-off/kinect_v1", "synth-asreal/kinect_v1"}
    on, off = cols["synth-planes/kinect_v1"]["pixels"], cols["synth-off/kinect_v1"]["pixels"]
    assert on > 0 and off > 0
    assert on + off == cols["synth/kinect_v1"]["pixels"]
    assert [bench._order(k) < bench._order(j) for k, j in
            (("analytic", "synth/kinect_v1"), ("synth/kinect_v1", "synth-planes/kinect_v1"),
             ("synth-planes/kinect_v1", "synth-off/kinect_v1"),
             ("synth-off/kinect_v1", "synth-asreal/kinect_v1"))] == [True] * 4
    # the same pixels and predictions, scored against the reference (recomputed here)
    from depthnormals.datasets.synthetic import read_synthetic
    from depthnormals.evaluate import plane_reference, sensor_threshold

    f = next(f for f in read_synthetic(tmp_path) if f.group.endswith("kinect_v1"))
    ref = plane_reference(f.depth, f.K, seed=0, threshold=sensor_threshold({}))
    n, u = dn.estimate_normals(f.depth, f.K, return_uncertainty=True)
    g = ref.normal_map()
    assert g.shape == n.shape and np.isnan(g[ref.labels < 0]).all()
    assert np.array_equal(g[ref.labels == 0], np.broadcast_to(ref.normals[0], g[ref.labels == 0].shape))
    g = g.astype(np.float32)
    err = dn.angular_error(n, g)
    keep = (ref.interior | ref.rim) & np.isfinite(u) & np.isfinite(err)
    real_like = cols["synth-asreal/kinect_v1"]
    assert real_like["pixels"] == keep.sum() == on
    assert real_like["mean_observed"] == pytest.approx(float(err[keep].astype(np.float64).mean()),
                                                       rel=1e-12)
    assert real_like["mean_predicted"] == cols["synth-planes/kinect_v1"]["mean_predicted"]
    exact = cols["synth-planes/kinect_v1"]["mean_observed"]
    assert abs(real_like["mean_observed"] - exact) > 1e-3 * exact  # not the exact normals
    # the reference against the exact normals, per part, counted as recomputed here
    rows = agreement["synth/kinect_v1"].rows()
    assert set(agreement) == {"synth/kinect_v1"} and list(rows) == ["interior", "rim"]
    e_exact = dn.angular_error(n, f.normals)
    r_exact = dn.angular_error(g, f.normals)
    ok = np.isfinite(e_exact) & np.isfinite(err) & np.isfinite(r_exact)
    for part, m in (("interior", ref.interior), ("rim", ref.rim)):
        m = m & ok
        r = rows[part]
        off = m & (r_exact > bench.WRONG_DEG)
        assert r["pixels"] == m.sum() > 0
        assert r["reference_off"] == off.sum() / m.sum()
        assert r["estimate_off_exact"] == (m & (e_exact > bench.WRONG_DEG)).sum() / m.sum()
        assert r["estimate_off_reference"] == (m & (err > bench.WRONG_DEG)).sum() / m.sum()
        assert r["off_the_same_way"] == (off & (err <= bench.SAME_DEG)).sum() / m.sum()
    assert rows["interior"]["pixels"] + rows["rim"]["pixels"] == on


def test_calibration_bench_geometry_labels_a_crease_and_a_jump(load_benchmark):
    """``geometry_labels`` (``--by-crease``): a floor 2 m away whose columns 20.. bend up by
    60 deg (a crease at column 20, the depth continuous across it) and whose rows 30.. stand
    on a step 0.5 m farther (a jump at row 30): pixels within 4 px of the jump read 1, within
    8 px of the crease 2 (the jump wins where both), the rest 0; a bend of 10 deg is no
    crease, a relative step of 2 % no jump."""
    bench = load_benchmark("uncertainty_calibration")
    assert (bench.CREASE_DEG, bench.CREASE_PX, bench.JUMP_REL, bench.JUMP_PX) == (15.0, 8, 0.03, 4)
    h, w = 48, 40

    def scene(bend_deg, step):
        z = np.full((h, w), 2.0)
        z[30:] += step
        n = np.zeros((h, w, 3))
        n[..., 2] = -1.0
        t = np.radians(bend_deg)
        n[:, 20:] = (np.sin(t), 0.0, -np.cos(t))
        return z.astype(np.float32), n.astype(np.float32)

    lab = bench.geometry_labels(*scene(60.0, 0.5))
    col = np.arange(w)
    near_crease = (col >= 19 - 8) & (col <= 20 + 8)
    for v in (0, 10, 24, 40, 47):  # rows farther than 4 px from the jump (rows 29 | 30)
        np.testing.assert_array_equal(lab[v], np.where(near_crease, 2, 0))
    np.testing.assert_array_equal(lab[25:35], 1)  # rows 29 and 30 and 4 px either side
    assert lab[24, 0] == 0 and lab[35, 0] == 0
    # a 10 deg bend and a 2 % step: neither
    np.testing.assert_array_equal(bench.geometry_labels(*scene(10.0, 0.04)), 0)
    # an invalid depth is a jump
    z, n = scene(0.0, 0.0)
    z[5, 5] = 0.0
    lab = bench.geometry_labels(z, n)
    assert lab[1, 1] == 1 and lab[9, 9] == 1 and lab[10, 10] == 0 and lab[0, 10] == 0


def test_calibration_bench_splits_synthetic_by_crease(tmp_path, load_benchmark, monkeypatch):
    """``--by-crease``: each noisy column's pixels by a crease, by a jump and the rest are
    exactly the column (none lost or counted twice; the frames named as the column's), each
    part of a room scene has pixels, and the clean column is not split; a set without the
    clean variant raises."""
    from depthnormals.camera import Intrinsics
    from depthnormals.synth import generate

    generate(tmp_path, indoor=1, outdoor=0, views=2, seed=3, K=Intrinsics(91.375, 91.375, 63.5, 52.5),
             size=(106, 128), progress=False, noise=("kinect_v1",))
    bench = load_benchmark("uncertainty_calibration")
    cols = bench.synth_columns(tmp_path, "3f2n+", by_crease=True)
    parts = ("synth-crease/kinect_v1", "synth-jump/kinect_v1", "synth-rest/kinect_v1")
    assert set(cols) == {"synth/clean", "synth/kinect_v1", *parts}
    whole = cols["synth/kinect_v1"]
    assert all(cols[k].summary()["pixels"] > 0 for k in parts)
    for j in range(2):  # per frame, the three parts are the frame's pixels
        assert all(cols[k].names[j] == whole.names[j] for k in parts)
        np.testing.assert_array_equal(np.sort(np.concatenate([cols[k].pred[j] for k in parts])),
                                      np.sort(whole.pred[j]))
    assert bench._order("synth/kinect_v1") < bench._order("synth-crease/kinect_v1") < \
        bench._order("synth-rest/kinect_v1")
    # a set without the clean variant (the exact geometry's depth) is refused, not mislabelled
    import depthnormals.datasets.synthetic as synthetic

    read = synthetic.read_synthetic
    monkeypatch.setattr(synthetic, "read_synthetic",
                        lambda root: (f for f in read(root) if f.meta.get("variant") != "clean"))
    with pytest.raises(ValueError, match="no clean variant"):
        bench.synth_columns(tmp_path, "3f2n+", by_crease=True)
    assert "synth/kinect_v1" in bench.synth_columns(tmp_path, "3f2n+")  # without the split: fine


def test_calibration_bench_thin_labels_a_riser_and_a_post(load_benchmark):
    """``thin_labels`` (``--thin``): on a face of one normal, a riser 3 rows tall (80 deg off)
    and a post 2 columns wide (60 deg off, rows 42..47) are faces narrower than 5 px: they and
    the pixels within 3 px of them read True; a band 10 rows tall (80 deg off, its two creases
    with the face) and the rest read False; without the post (its columns the face's) and with
    a 20 deg riser, nothing is thin."""
    bench = load_benchmark("uncertainty_calibration")
    assert (bench.THIN_DEG, bench.THIN_SPANS, bench.THIN_PX) == (30.0, (2, 3), 3)
    h, w = 48, 40

    def tilt(deg):
        t = np.radians(deg)
        return (0.0, -np.sin(t), -np.cos(t))

    def scene(riser_deg, post):
        n = np.zeros((h, w, 3))
        n[..., 2] = -1.0
        n[10:13] = tilt(riser_deg)
        n[24:34] = tilt(80.0)
        if post:
            n[42:, 30:32] = (np.sin(np.radians(60.0)), 0.0, -np.cos(np.radians(60.0)))
        return n.astype(np.float32)

    lab = bench.thin_labels(scene(80.0, True))
    want = np.zeros((h, w), dtype=bool)
    want[7:16] = True  # the riser's rows 10-12 and 3 either side
    want[39:, 27:35] = True  # the post's columns 30-31, rows 42-47, and 3 px around
    np.testing.assert_array_equal(lab, want)
    np.testing.assert_array_equal(bench.thin_labels(scene(20.0, False)), False)
    # no surface beside a pixel is another face: one valid column between two empty ones
    n = np.full((h, w, 3), np.nan, dtype=np.float32)
    n[:, 20] = (0.0, 0.0, -1.0)
    lab = bench.thin_labels(n)
    assert lab[:, 17:24].all() and not lab[:, :17].any() and not lab[:, 24:].any()


def test_calibration_bench_splits_synthetic_by_thin_faces(tmp_path, load_benchmark):
    """``--thin``: each noisy column's pixels by a thin face and the others are exactly the
    column (none lost or counted twice, the frames named as the column's); the clean column
    is not split."""
    from depthnormals.camera import Intrinsics
    from depthnormals.synth import generate

    generate(tmp_path, indoor=1, outdoor=0, views=2, seed=3, K=Intrinsics(91.375, 91.375, 63.5, 52.5),
             size=(106, 128), progress=False, noise=("kinect_v1",))
    bench = load_benchmark("uncertainty_calibration")
    cols = bench.synth_columns(tmp_path, "3f2n+", thin=True)
    parts = ("synth-thin/kinect_v1", "synth-resolved/kinect_v1")
    assert set(cols) == {"synth/clean", "synth/kinect_v1", *parts}
    whole = cols["synth/kinect_v1"]
    assert cols["synth-resolved/kinect_v1"].summary()["pixels"] > 0
    for j in range(2):
        assert all(cols[k].names[j] == whole.names[j] for k in parts)
        np.testing.assert_array_equal(np.sort(np.concatenate([cols[k].pred[j] for k in parts])),
                                      np.sort(whole.pred[j]))
    assert bench._order("synth-rest/kinect_v1") < bench._order("synth-thin/kinect_v1") < \
        bench._order("synth-resolved/kinect_v1")


def test_calibration_bench_pools_several_synthetic_folders(tmp_path, load_benchmark):
    """``--synth A B``: each sensor column holds the frames of both folders, its pixels
    exactly the sum of the two folders' (none lost or counted twice), the frames named by
    their folder (leave-one-out must say which set's frame a bin hangs on)."""
    from depthnormals.camera import Intrinsics
    from depthnormals.synth import generate

    roots = [tmp_path / "a", tmp_path / "b"]
    for seed, root in enumerate(roots):
        generate(root, indoor=1, outdoor=0, views=1, seed=seed, K=Intrinsics(91.375, 91.375, 63.5, 52.5),
                 size=(106, 128), progress=False, noise=("kinect_v1",))
    bench = load_benchmark("uncertainty_calibration")
    alone = [bench.synth_columns(r, "3f2n+")["synth/kinect_v1"] for r in roots]
    both = bench.synth_columns(roots, "3f2n+")["synth/kinect_v1"]
    assert both.summary()["frames"] == 2
    assert both.summary()["pixels"] == sum(c.summary()["pixels"] for c in alone) > 0
    assert [n.split("/")[0] for n in both.names] == ["a", "b"]
    assert alone[0].names[0] == both.names[0].split("/", 1)[1]
    np.testing.assert_array_equal(np.concatenate(both.pred),
                                  np.concatenate([alone[0].pred[0], alone[1].pred[0]]))


@pytest.mark.parametrize("argv", [["--real", "no-such-folder"],
                                  ["--real", "", "--synth", "no-such-folder"],
                                  ["--real", "", "--synth", ".", "no-such-folder"]])
def test_calibration_bench_refuses_a_missing_folder(tmp_path, monkeypatch, load_benchmark, capsys,
                                                     argv):
    """A mistyped ``--real`` or ``--synth`` is an error naming the folder, not a table with
    those columns silently left out (the script exits before computing anything)."""
    monkeypatch.chdir(tmp_path)
    bench = load_benchmark("uncertainty_calibration")
    with pytest.raises(SystemExit) as exc:
        bench.main(argv)
    assert exc.value.code == 2
    assert "no-such-folder: no such folder" in capsys.readouterr().err


def _undecided(shape):
    """Face switch decisions of cells that saw no other face (all NaN): with an infinite
    saturation the map's last pass leaves every value as it was."""
    return np.full((2, *shape), np.nan, dtype=np.float32)


@pytest.mark.parametrize("w", [8, 9])
def test_upsample_reads_the_cell_and_keeps_invalid_depth(w):
    """The half grid's map upsampled: each pixel its 2x2 cell's value, NaN exactly where the
    depth is invalid (odd widths and heights included), for bands of rows (no crease: the
    cells' edges all 0)."""
    from depthnormals.ddm import uncertainty as U

    rng = np.random.default_rng(3)
    h = 7
    coarse = rng.random(((h + 1) // 2, (w + 1) // 2)).astype(np.float32)
    z = np.full((h, w), 2.0, np.float32)
    z[rng.random((h, w)) < 0.2] = np.nan
    out = np.full((h, w), -1.0, np.float32)
    edges = np.zeros((2, *coarse.shape), np.float32)
    for v0, v1 in ((0, 3), (3, h)):
        U._upsample_rows(v0, v1, coarse, edges, 0.6, z, _undecided(coarse.shape),
                         U.DECIDED_MAP, np.inf, out)
    want = np.repeat(np.repeat(coarse, 2, 0), 2, 1)[:h, :w]
    want[np.isnan(z)] = np.nan
    np.testing.assert_array_equal(out, want)


def _floor_ref(coarse, edges, far, z, cap):
    """The crease floor of :func:`_upsample_rows` pixel by pixel: the edges of its cell that it
    lies on (left for an even column, right for an odd one; above for an even row, below for an
    odd one) whole, all four times ``far``."""
    h, w = z.shape
    out = np.empty((h, w), np.float32)
    for v in range(h):
        for u in range(w):
            i, j = v // 2, u // 2
            right = edges[0, i, j]
            left = edges[0, i, j - 1] if j > 0 else 0.0
            below = edges[1, i, j]
            above = edges[1, i - 1, j] if i > 0 else 0.0
            near = max(right if u % 2 else left, below if v % 2 else above)
            f = min(max(near, far * max(right, left, below, above)), cap)
            c = coarse[i, j]
            out[v, u] = np.nan if np.isnan(c) or np.isnan(z[v, u]) else max(c, f)
    return out


@pytest.mark.parametrize("w", [8, 9])
def test_upsample_floors_the_cell_by_its_edges(w):
    """The crease floor (:data:`CREASE_FLOOR`) in the upsampled map against the definition
    pixel by pixel: each pixel takes the edges of its cell that it lies on whole and the cell's
    other two times ``far``, at most MAX_ERROR; a NaN cell or depth stays NaN; for bands of rows
    that start on an odd row too."""
    from depthnormals.ddm import uncertainty as U

    rng = np.random.default_rng(4)
    h = 9
    shape = ((h + 1) // 2, (w + 1) // 2)
    coarse = (3.0 * rng.random(shape)).astype(np.float32)
    coarse[1, 1] = np.nan
    edges = np.where(rng.random((2, *shape)) < 0.5, 0.0, 100.0 * rng.random((2, *shape)))
    edges = edges.astype(np.float32)
    edges[0, :, -1] = 0.0  # as _cell_edges_rows writes them: no cell right of the last
    edges[1, -1] = 0.0
    z = np.full((h, w), 2.0, np.float32)
    z[rng.random((h, w)) < 0.1] = np.nan
    out = np.full((h, w), -1.0, np.float32)
    for v0, v1 in ((0, 3), (3, 4), (4, h)):
        U._upsample_rows(v0, v1, coarse, edges, 0.6, z, _undecided(coarse.shape),
                         U.DECIDED_MAP, np.inf, out)
    want = _floor_ref(coarse, edges, 0.6, z, U.MAX_ERROR)
    np.testing.assert_allclose(out, want, rtol=1e-6)
    assert np.array_equal(np.isnan(out), np.isnan(want))
    up = np.repeat(np.repeat(coarse, 2, 0), 2, 1)[:h, :w]
    ok = np.isfinite(out)
    assert (out[ok] > up[ok]).mean() > 0.3  # the floor is not idle here


def test_cell_edges_read_the_angle_past_the_threshold():
    """:func:`_cell_edges_rows`: ``scale`` times the angle to the right and lower neighbour
    (atan2 of the renormalised pair) where it exceeds the threshold and both cells fell back
    (deviation past the limit), 0 below it, where either cell kept its window, on the last
    column and row and beside a NaN normal; within 1 % up to 90 deg (the chord series), for
    bands of rows."""
    from depthnormals.ddm import uncertainty as U

    rng = np.random.default_rng(5)
    h, w = 6, 7
    tilt = np.radians(45.0) * np.sqrt(rng.random((h, w)))  # within 45 deg of -z: pairs <= 90
    phi = 2 * np.pi * rng.random((h, w))
    n = np.stack([np.sin(tilt) * np.cos(phi), np.sin(tilt) * np.sin(phi), -np.cos(tilt)], -1)
    n = n.astype(np.float32)
    n[2, 3] = np.nan
    theta = 20.0
    fell = rng.random((h, w)) < 0.7
    dev = np.where(fell, 3.0, 1.0).astype(np.float32)
    out = np.full((2, h, w), -1.0, np.float32)
    for v0, v1 in ((0, 2), (2, h)):
        U._cell_edges_rows(v0, v1, n, 0.5 * 180 / np.pi, np.cos(np.radians(theta)), dev, 2.0,
                           out)
    right = dn.angular_error(n[:, :-1], n[:, 1:])
    below = dn.angular_error(n[:-1], n[1:])
    both = (fell[:, :-1] & fell[:, 1:], fell[:-1] & fell[1:])
    for got, ang, b in ((out[0, :, :-1], right, both[0]), (out[1, :-1], below, both[1])):
        want = np.where((ang > theta) & b, 0.5 * ang, 0.0)
        want = np.nan_to_num(want, nan=0.0)
        np.testing.assert_allclose(got, want, rtol=0.01, atol=1e-3)
        assert 0 < (want > 0).mean() < 1  # both sides of the threshold are read
    assert np.all(out[0, :, -1] == 0) and np.all(out[1, -1] == 0)
    assert out[0, 2, 2] == out[0, 2, 3] == out[1, 1, 3] == out[1, 2, 3] == 0
    assert ((right > theta) & ~both[0]).any()  # a crease beside a cell that kept its window


def test_floor_rows_take_the_largest_of_the_four_edges():
    """On the pixel grid (a choice made on every pixel) a pixel lies on all four edges of its
    cell: the map is at least the largest, at most MAX_ERROR; NaN stays NaN."""
    from depthnormals.ddm import uncertainty as U

    rng = np.random.default_rng(6)
    h, w = 5, 6
    edges = (120.0 * rng.random((2, h, w))).astype(np.float32)
    edges[rng.random((2, h, w)) < 0.5] = 0.0
    edges[0, :, -1] = 0.0
    edges[1, -1] = 0.0
    m = (10.0 * rng.random((h, w))).astype(np.float32)
    m[0, 0] = np.nan
    out = m.copy()
    for v0, v1 in ((0, 2), (2, h)):
        U._floor_rows(v0, v1, edges, _undecided((h, w)), U.DECIDED_MAP, np.inf, out)
    left = np.pad(edges[0], ((0, 0), (1, 0)))[:, :w]
    above = np.pad(edges[1], ((1, 0), (0, 0)))[:h]
    f = np.minimum(np.maximum.reduce([edges[0], left, edges[1], above]), U.MAX_ERROR)
    want = np.where(np.isnan(m), np.nan, np.maximum(m, f))
    np.testing.assert_array_equal(out, want)
    assert (out > m).any() and (out[np.isfinite(m)] <= m[np.isfinite(m)]).any()


def test_calibration_bench_reads_smaller_planes_on_request(shared_data, load_benchmark):
    """``--min-fraction``: the real references keep smaller planes, so the real columns score
    more pixels (the NYU raw frame: 124,647 -> about 138,000, its furniture's smaller faces);
    without it the references are ``plane_reference``'s default (the 124,647 of
    docs/benchmarks.md section 17)."""
    bench = load_benchmark("uncertainty_calibration")
    root = shared_data / "real-sensors" / "nyu_raw_kinect1_open3d"
    px = {mf: bench.real_columns(root, "3f2n+", 0, mf)["real"].summary()["pixels"]
          for mf in (None, 0.0025)}
    assert abs(px[None] - 124647) <= 100
    assert px[0.0025] > 1.05 * px[None]


@pytest.mark.parametrize("value", ["0", "-0.01", "1.5", "nan"])
def test_calibration_bench_refuses_a_bad_min_fraction(tmp_path, monkeypatch, load_benchmark,
                                                     capsys, value):
    """A ``--min-fraction`` outside [1e-06, 1] is an error before any column is computed."""
    monkeypatch.chdir(tmp_path)
    bench = load_benchmark("uncertainty_calibration")
    with pytest.raises(SystemExit) as exc:
        bench.main(["--real", "", "--min-fraction", value])
    assert exc.value.code == 2
    assert f"--min-fraction {float(value)}: must be in" in capsys.readouterr().err


def test_calibration_bench_targets_the_pooled_real_frames_and_each_folder(load_benchmark):
    """The issue's targets: Spearman 0.6 and every bin on the synthetic column of each of the
    five noise models (of any set; Gaussian since session 33), 0.5 on the real frames pooled
    and, the stricter reading, on each folder; clean depth, the analytic scenes, the diagnostic
    splits and the crease bands hold none."""
    bench = load_benchmark("uncertainty_calibration")
    assert bench.target("real") == 0.5
    assert bench.target("real/tum_fr2_kinect1_slambook") == 0.5
    for name in ("synth/gaussian", "synth/kinect_v1", "synth/kinect_v2", "synth/tof",
                 "synth/realsense_d4xx"):
        assert bench.target(name) == 0.6, name
    for name in ("real+creases", "real+creases/sunrgbd_open3d", "synth/clean",
                 "synth-thin/kinect_v1", "synth-planes/tof", "synth-planes/gaussian", "analytic"):
        assert bench.target(name) is None, name


def test_calibration_bench_bootstrap_bins_as_the_table(load_benchmark):
    """``--bootstrap``: frames resampled with replacement, each resample binned like the
    table. Two identical frames give every resample the table's own ratios (so the binning is
    the table's); a frame calibrated beside one observing 3x its prediction spreads the ratios
    (1 to 3) and passes only in the resamples drawing the calibrated frame twice (1/4)."""
    bench = load_benchmark("uncertainty_calibration")
    rng = np.random.default_rng(1)
    p = rng.gamma(1.5, 2.0, 5000)
    o = p * rng.uniform(0.8, 1.25, p.size)
    table = bench.reliability(np.concatenate([p, p]), np.concatenate([o, o]))
    want = [b["observed"] / b["predicted"] for b in table]
    bs = bench.bootstrap_bins([p, p], [o, o], 50, seed=0)
    np.testing.assert_allclose(bs["ratio_p5"], want, rtol=2e-3)
    np.testing.assert_allclose(bs["ratio_p95"], want, rtol=2e-3)
    assert bs["bin_pass_share"] == [1.0] * 10 and bs["all_pass_share"] == 1.0
    bs = bench.bootstrap_bins([p, p], [p, 3.0 * p], 400, seed=0)
    assert min(bs["ratio_p5"]) >= 0.999 and max(bs["ratio_p95"]) <= 3.001
    assert max(bs["ratio_p95"]) > 2.9 and min(bs["ratio_p5"]) < 1.01
    assert 0.17 <= bs["all_pass_share"] <= 0.33, bs["all_pass_share"]


def test_calibration_bench_leave_one_out_names_the_frame_a_bin_hangs_on(load_benchmark):
    """``--leave-one-out``: the table without each frame in turn, binned as the table bins.
    Three calibrated frames beside one whose error is 3x its prediction: only the table
    without that frame passes every bin, and its ratios are the three frames' own (1.0 where
    they observe exactly their prediction); with it, every decile reads between 1 and 3."""
    bench = load_benchmark("uncertainty_calibration")
    rng = np.random.default_rng(2)
    p = [rng.gamma(1.5, 2.0, 4000) for _ in range(4)]
    o = [p[0], p[1], 3.0 * p[2], p[3]]
    got = bench.leave_one_out(p, o, ["a", "b", "c", "d"])
    assert got["every_bin_passes_without"] == ["c"]
    rows = {r["left_out"]: r for r in got["frames"]}
    assert rows["c"]["bins_passed"] == 10
    np.testing.assert_allclose(rows["c"]["ratios"], 1.0, rtol=1e-12)
    for k in "abd":
        assert rows[k]["bins_passed"] < 10
        assert all(1.0 < r < 3.0 for r in rows[k]["ratios"])
    # the same binning as the table: the frames but "c" pooled
    table = bench.reliability(np.concatenate([p[0], p[1], p[3]]), np.concatenate([o[0], o[1], o[3]]))
    np.testing.assert_allclose(rows["c"]["ratios"], [b["observed"] / b["predicted"] for b in table])


def test_calibration_bench_excess_frames_carry_the_failing_bins(load_benchmark):
    """``--frames N``: the frames ranked by the excess they add to a column's failing bins.
    Six calibrated frames beside two that observe twice their prediction, one with twice the
    other's pixels: those two lead, with two thirds and one third of the excess (the others'
    is exactly 0) and their own ratio 2; a column whose every bin passes lists none."""
    bench = load_benchmark("uncertainty_calibration")
    rng = np.random.default_rng(4)
    p = [rng.gamma(1.5, 2.0, 3000) for _ in range(6)] + [rng.gamma(1.5, 2.0, n) for n in (4000, 2000)]
    o = [x.copy() for x in p[:6]] + [2.0 * p[6], 2.0 * p[7]]
    names = [f"f{i}" for i in range(8)]
    got = bench.excess_frames(p, o, names, top=3)
    assert got["bins"]  # some decile fails: the two frames' pixels are 6000 of 24000
    table = bench.reliability(np.concatenate(p), np.concatenate(o))
    assert got["bins"] == [i + 1 for i, b in enumerate(table) if not b["pass"]]
    top = got["frames"]
    assert [r["frame"] for r in top[:2]] == ["f6", "f7"]
    assert top[0]["share"] + top[1]["share"] == pytest.approx(1.0)
    assert top[0]["share"] == pytest.approx(2.0 * top[1]["share"], rel=0.15)
    assert top[0]["ratio"] == pytest.approx(2.0) and top[1]["ratio"] == pytest.approx(2.0)
    assert top[2]["excess"] == 0.0 and top[2]["ratio"] == pytest.approx(1.0)
    assert bench.excess_frames(p[:6], o[:6], names[:6], top=3) == {"bins": [], "frames": []}


def test_calibration_bench_scores_the_crease_bands_on_request(shared_data, load_benchmark):
    """``--creases``: the real columns ``real+creases/<folder>`` hold the plane pixels and the
    crease band (crease_band) that the plane reference leaves out: on TUM fr2 the desk's front
    edge, 4,272 pixels of the first frame by seed 0's reference, which the default's normals
    miss by far more than the planes (its top's normal on most of the edge's face)."""
    bench = load_benchmark("uncertainty_calibration")
    root = shared_data / "real-sensors" / "tum_fr2_kinect1_slambook"
    cols = {k: c.summary() for k, c in bench.real_columns(root, "3f2n+", 0, creases=True).items()}
    assert set(cols) == {"real", "real+creases", "real/tum_fr2_kinect1_slambook",
                         "real+creases/tum_fr2_kinect1_slambook"}
    plain, more = cols["real"], cols["real+creases"]
    assert abs(more["pixels"] - plain["pixels"] - 4272) <= 200
    added = ((more["mean_observed"] * more["pixels"] - plain["mean_observed"] * plain["pixels"])
             / (more["pixels"] - plain["pixels"]))
    assert added > 5 * plain["mean_observed"]


def test_calibration_bench_band_profile_bins_by_distance(load_benchmark):
    """``--creases``' profile: each band pixel counted once in the bin of its distance from the
    crease line (0-1, 1-2, 2-3, 3-4, 4-6, 6-8, 8-10 px; 10 itself in the last), with the mean
    observed and predicted error and the share observed over 45 deg; NaN distance (off the
    band) or a NaN map left out."""
    bench = load_benchmark("uncertainty_calibration")
    prof = bench.BandProfile()
    d = np.array([0.0, 0.5, 1.0, 3.9, 5.0, 10.0, np.nan, 2.0])
    err = np.array([90.0, 10.0, 50.0, 20.0, 30.0, 1.0, 5.0, 7.0])
    unc = np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, np.nan])
    prof.add(unc, err, d)
    rows = prof.rows()
    assert [r["pixels"] for r in rows] == [2, 1, 0, 1, 1, 0, 1]
    assert rows[0]["observed"] == 50.0 and rows[0]["predicted"] == 15.0 and rows[0]["over_45"] == 0.5
    assert rows[1]["over_45"] == 1.0 and np.isnan(rows[2]["observed"])
    assert rows[6]["to_px"] == 10.0 and rows[6]["predicted"] == 60.0


@pytest.mark.parametrize("shift", [0, 1])
def test_decided_cells_read_the_face_switch(shift):
    """The measured support's map where the face switch examined the pixel's cell: at least
    ``P theta + (1 - P) e_r`` (``P = a / (1 + (L / s)^2)``, ``s`` by the sign of L) and at
    least ``keep`` times before, then every pixel ``x / (1 + x / sat)``; NaN stays NaN; a
    pixel reads its cell (``v >> shift``, ``u >> shift``): on the pixel grid (``_floor_rows``,
    no crease edges) and upsampled from the half grid (``_upsample_rows``)."""
    from depthnormals.ddm import uncertainty as U
    from depthnormals.ddm.uncertainty import DECIDED_MAP, SATURATION

    a, s_neg, s_pos, e_r, keep = DECIDED_MAP
    h, w = 6, 8
    cells = (h >> shift, w >> shift)
    dec = np.full((2, *cells), np.nan, dtype=np.float32)
    dec[:, 0, 0] = (0.0, 60.0)      # a tie: P = a, the map at least a 60 + (1 - a) e_r
    dec[:, 1, 1] = (-2.4, 40.0)     # a clear switch
    dec[:, 2, 1] = (5.0, 30.0)      # a clear stay
    coarse = np.full(cells, 3.0, dtype=np.float32)
    coarse[0, 1 >> shift] = 100.0   # above the floor: halved at most
    z = np.full((h, w), 2.0, dtype=np.float32)
    z[5, 7] = np.nan
    edges = np.zeros((2, *cells), dtype=np.float32)
    before = np.repeat(np.repeat(coarse, 1 << shift, 0), 1 << shift, 1)
    before[np.isnan(z)] = np.nan
    if shift:
        out = np.empty((h, w), dtype=np.float32)
        for v0, v1 in ((0, 3), (3, h)):
            U._upsample_rows(v0, v1, coarse, edges, 0.6, z, dec, DECIDED_MAP, SATURATION, out)
    else:
        out = before.copy()
        for v0, v1 in ((0, 3), (3, h)):
            U._floor_rows(v0, v1, edges, dec, DECIDED_MAP, SATURATION, out)

    def sat(x):
        return x / (1.0 + x / SATURATION)

    def floor(L, theta):
        p = a / (1.0 + (L / (s_neg if L < 0 else s_pos)) ** 2)
        return p * theta + (1.0 - p) * e_r

    expect = sat(before.astype(np.float64))
    for (i, j), (L, theta) in (((0, 0), (0.0, 60.0)), ((1, 1), (-2.4, 40.0)),
                               ((2, 1), (5.0, 30.0))):
        for v in range(h):
            for u in range(w):
                if (v >> shift, u >> shift) == (i, j) and np.isfinite(before[v, u]):
                    expect[v, u] = sat(max(floor(L, theta), keep * before[v, u]))
    assert np.allclose(out, expect, rtol=1e-5, equal_nan=True)
    assert np.isnan(out[5, 7]) and np.isfinite(np.delete(out.ravel(), 5 * w + 7)).all()
    assert out[0, 0] == pytest.approx(sat(a * 60.0 + (1.0 - a) * e_r), rel=1e-5)
    # 100 deg: on the half grid in the tie's cell (at least keep times it, and the floor),
    # on the pixel grid in a cell that saw no other face (only saturated)
    want = max(floor(0.0, 60.0), keep * 100.0) if shift else 100.0
    assert out[0, 1] == pytest.approx(sat(want), rel=1e-5)


def test_measured_support_map_follows_the_switch(monkeypatch):
    """On a Kinect-like box the map reads the face switch's decisions: without them (the
    decisions all NaN) it differs exactly on the examined cells' pixels (and by the
    saturation nowhere else)."""
    from depthnormals.analytic import make_scene
    from depthnormals.ddm import support
    from depthnormals.synth.noise import kinect_v1_noise

    K = (262.5, 262.5, 159.5, 119.5)
    r = make_scene("box-on-floor").render(K=K, shape=(240, 320))
    d = np.asarray(kinect_v1_noise(r.depth, r.normals, K, rng=np.random.default_rng(2)),
                   np.float32)
    assert dn.noise_profile(d, K).branch == "measured-support"
    seen = {}
    orig = support.switch_faces

    def spy(z, n, *a, **k):
        out = orig(z, n, *a, **k)
        seen["dec"] = out[2]
        return out

    monkeypatch.setattr(support, "switch_faces", spy)
    n1, u1 = dn.estimate_normals(d, K, return_uncertainty=True)
    dec = seen["dec"]

    def blind(z, n, *a, **k):
        out = orig(z, n, *a, **k)
        return out[0], out[1], np.full_like(out[2], np.nan)

    monkeypatch.setattr(support, "switch_faces", blind)
    n2, u2 = dn.estimate_normals(d, K, return_uncertainty=True)
    assert np.array_equal(n1, n2, equal_nan=True)
    ex = np.isfinite(dec[0])
    if dec.shape[1:] != d.shape:
        ex = np.repeat(np.repeat(ex, 2, 0), 2, 1)[:d.shape[0], :d.shape[1]]
    assert ex.any()
    differ = ~np.isclose(u1, u2, equal_nan=True)
    assert differ.any() and not (differ & ~ex).any()


def test_calibration_bench_surface_floor_reads_the_depths_own_bend(load_benchmark):
    """``--surface`` (``surface_floor``): a wall facing the camera 2 m away, one reference
    plane whose normal is (0, 0, -1). Flat, the plane of each pixel's own points within R px is
    the reference's (0 deg); bowed by ``c x^2`` (x metres from the middle) it tilts with the
    local slope, atan(2 c x), while the reference keeps the mean plane; pixels whose window is
    mostly another plane's, and the rims, get NaN."""
    pytest.importorskip("cv2")
    import types

    bench = load_benchmark("uncertainty_calibration")
    h, w, f = 120, 160, 80.0
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
    x = (np.arange(w) - (w - 1) / 2) / f * 2.0  # metres across at z = 2
    labels = np.zeros((h, w), np.int64)
    labels[:, :20] = 1  # another plane at the left
    interior = np.zeros((h, w), bool)
    interior[5:-5, 25:-5] = True
    ref = types.SimpleNamespace(labels=labels, interior=interior,
                                normal_map=lambda: np.broadcast_to(np.array([0.0, 0.0, -1.0]),
                                                                   (h, w, 3)))
    flat = bench.surface_floor(np.full((h, w), 2.0), K, ref, 10)
    assert np.isfinite(flat[interior]).mean() > 0.9 and np.nanmax(flat) < 1e-4
    assert np.isnan(flat[~interior]).all()
    c = 0.01
    bowed = bench.surface_floor(2.0 + c * x[None, :] ** 2 * np.ones((h, 1)), K, ref, 10)
    v = 60
    for u in (60, 80, 120, 150):  # the fit's tilt follows the slope 2 c x (the window's mean)
        want = np.degrees(np.arctan(2 * c * abs(x[u])))
        assert bowed[v, u] == pytest.approx(want, abs=0.05 + 0.1 * want), (u, bowed[v, u], want)


def test_calibration_bench_speed_reads_every_frame_and_the_640x480_ones(load_benchmark, shared_data,
                                                                          capsys):
    """``--speed``: one line per real frame with both times and their ratio, the ratio over all
    frames, and the 640x480 frames' range with how many are at or under the issue's 1.3x (the
    ten Kinect v1 frames of ``real-sensors``; KITTI's 1242x375 is not among them). Times are
    not asserted (a shared machine); the counts and the lines are."""
    import re

    bench = load_benchmark("uncertainty_calibration")
    bench.speed("3f2n+", None, str(shared_data / "real-sensors"), repeats=1)
    out = capsys.readouterr().out.splitlines()
    frames = [s for s in out if s.startswith("real/")]
    assert len(frames) == 11 and sum("640x480" in s for s in frames) == 10
    ratios = [float(re.search(r" x(\d+\.\d+) \(medians", s).group(1)) for s in frames if "640x480" in s]
    m = re.fullmatch(r"640x480 frames: x(\d\.\d\d)-x(\d\.\d\d) \(median x\d\.\d\d, (\d+) of 10 at or under "
                     r"x1\.30\)", out[-1])
    assert m is not None, out[-1]
    assert float(m.group(1)) == min(ratios) and float(m.group(2)) == max(ratios)
    assert int(m.group(3)) == sum(r <= 1.3 for r in ratios)
    assert out[-2].startswith("all frames: x")
