"""The plane reference (``depthnormals.evaluate.plane_reference`` / ``score_planes``): planes
recovered on analytic scenes (exact, noisy, quantised like a Kinect v1), interior and rim
masks on a square, scores on a constructed case, the compiled region kernels against NumPy
references, and at least two planes on every real sensor frame of ``../shared``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from depthnormals.analytic import make_scene, tilted_plane
from depthnormals.evaluate import PlaneReference, plane_reference, score_planes
from depthnormals.evaluate._planes_kernels import (
    chessboard_inside,
    chessboard_to,
    label_8connected,
    plane_inliers,
    plane_ratio,
)
from depthnormals.metrics import angular_error

# Kinect v1 disparity: f * baseline ~ 580 px * 0.075 m, quantised to 1/8 px
KINECT_FB = 580.0 * 0.075


def _kinect(depth: np.ndarray, seed: int, sigma_z2: float = 0.0012) -> np.ndarray:
    """Gaussian noise ``sigma_z2 * z^2`` on depth, then 1/8 px disparity quantisation."""
    rng = np.random.default_rng(seed)
    z = depth + rng.normal(0.0, 1.0, depth.shape) * sigma_z2 * depth**2
    with np.errstate(divide="ignore"):
        disp = np.round(8.0 * KINECT_FB / z) / 8.0
        out = np.where(depth > 0, KINECT_FB / disp, 0.0)
    return out


def _plane_errors(ref: PlaneReference, truth: np.ndarray) -> list[float]:
    """Angle (deg) between each reference plane and the median truth normal of its interior."""
    out = []
    for k in range(ref.n_planes):
        g = truth[(ref.labels == k) & ref.interior]
        med = np.median(g, axis=0)
        out.append(float(angular_error(ref.normals[k][None, None], med[None, None])[0, 0]))
    return out


def test_exact_box_on_floor():
    r = make_scene("box-on-floor").render()
    ref = plane_reference(r.depth, r.K, consensus=1)
    assert ref.n_planes >= 4  # floor, wall, two box faces
    # the box faces keep a 1-2 px band of the unextracted top face at their crease (inside the
    # 1 cm threshold): their fits tilt by a few hundredths of a degree
    assert max(_plane_errors(ref, r.normals)) < 0.1
    s = score_planes(r.normals, ref)
    assert s["interior_mean"] < 0.05
    assert s["coverage"] == 1.0
    # normals face the camera and the offsets put the points on the planes
    for k in range(2):  # the floor and the wall: exact
        v, u = np.nonzero(ref.labels == k)
        z = r.depth[v, u]
        X = np.stack([(u - r.K.cx) * z / r.K.fx, (v - r.K.cy) * z / r.K.fy, z], 1)
        assert np.all(X @ ref.normals[k] < 0)
        assert np.median(np.abs(X @ ref.normals[k] + ref.offsets[k])) < 1e-6


def test_small_faces_take_back_their_band():
    """A low box on the floor: its front face (2812 px) and top (1334 px) are too small to be
    references, but as competitors they take back the band of the floor's threshold that
    climbs them; without them the floor's interior holds 228 px of the box face (90 deg)."""
    import depthnormals.evaluate._planes as planes
    from depthnormals.analytic import Box, Plane, Scene

    r = Scene([Plane((0.0, -1.0, 0.0), -1.0), Plane((0.0, 0.0, -1.0), -6.0),
               Box((0.0, 0.9, 3.0), (0.2, 0.1, 0.2))]).render()
    ref = plane_reference(r.depth, r.K, consensus=1)
    assert ref.n_planes == 2  # floor and wall
    err = angular_error(r.normals, ref.normal_map())
    assert not (ref.interior & (err > 1.0)).any()
    assert score_planes(r.normals, ref)["interior_mean"] < 1e-6
    old = planes.COMPETITOR_FRACTION
    try:
        planes.COMPETITOR_FRACTION = 0.01  # no competitors below the reference size
        worse = plane_reference(r.depth, r.K, consensus=1)
    finally:
        planes.COMPETITOR_FRACTION = old
    err = angular_error(r.normals, worse.normal_map())
    assert (worse.interior & (err > 1.0)).sum() > 100


def test_sphere_is_not_a_plane():
    r = make_scene("demo-room").render()
    ref = plane_reference(r.depth, r.K, consensus=1)
    sphere = ~r.planar & (r.depth > 0)
    assert ((ref.labels >= 0) & sphere).sum() < 0.01 * sphere.sum()


@pytest.mark.parametrize("scene", ["box-on-floor", "demo-room"])
def test_noisy_quantised_planes(scene):
    r = make_scene(scene).render()
    z = _kinect(r.depth, seed=3)
    # the staircase is there: steps of >= 1 cm at 2 m and beyond
    ref = plane_reference(z, r.K, seed=1, consensus=1)
    assert ref.n_planes >= 3
    errs = _plane_errors(ref, r.normals)
    big = [e for e, p in zip(errs, ref.planes, strict=True) if p.n_interior > 20000]
    assert len(big) >= 2 and max(big) < 0.5, errs
    assert max(errs) < 2.0, errs


def test_tilted_plane_staircase():
    n = np.array([0.3, -0.4, -1.0]) / np.linalg.norm([0.3, -0.4, -1.0])
    r = tilted_plane(tuple(n), 3.0).render()
    z = _kinect(r.depth, seed=0, sigma_z2=0.0)
    steps = np.unique(np.round(z[240, 300:340], 6))
    assert np.diff(steps).min() > 0.01  # the disparity steps exceed 1 cm here
    ref = plane_reference(z, r.K, consensus=1)
    assert ref.n_planes == 1
    assert _plane_errors(ref, r.normals)[0] < 0.05
    assert ref.planes[0].n_pixels > 0.95 * 480 * 640


def test_consensus_keeps_what_the_runs_agree_on(shared_data):
    root = shared_data / "real-sensors" / "tum_kinect1_open3d"
    if not root.is_dir():
        pytest.skip(f"{root} is absent")
    from depthnormals.datasets import open as open_dataset

    f = next(open_dataset(root))
    one = plane_reference(f.depth, f.K, seed=4, consensus=1)
    three = plane_reference(f.depth, f.K, seed=4)  # default: three runs, seeds 4, 5, 6
    assert three.settings["consensus"] == 3
    on = three.labels >= 0
    assert on.sum() > 0.05 * f.depth.size and on.sum() <= (one.labels >= 0).sum()
    # the planes are the first run's (those that keep enough agreed pixels)
    for n in three.normals:
        assert np.min(np.degrees(np.arccos(np.clip(one.normals @ n, -1, 1)))) < 1e-3


def test_deterministic_for_a_seed():
    r = make_scene("box-on-floor").render()
    z = _kinect(r.depth, seed=5)
    a = plane_reference(z, r.K, seed=7)
    b = plane_reference(z, r.K, seed=7)
    assert np.array_equal(a.labels, b.labels)
    assert np.array_equal(a.normals, b.normals)


def _square():
    depth = np.zeros((60, 80))
    depth[10:40, 20:50] = 2.0  # a fronto-parallel square, nothing around it
    return depth, (100.0, 100.0, 39.5, 29.5)


def test_square_interior_and_rim():
    depth, K = _square()
    ref = plane_reference(depth, K, min_fraction=0.05, consensus=1)
    assert ref.n_planes == 1
    assert np.allclose(ref.normals[0], [0, 0, -1]) and np.isclose(ref.offsets[0], 2.0)
    square = depth > 0
    assert np.array_equal(ref.labels >= 0, square)
    interior = np.zeros_like(square)
    interior[14:36, 24:46] = True  # >= 5 px inside: 4 px rim on each side
    assert np.array_equal(ref.interior, interior)
    assert np.array_equal(ref.rim, square & ~interior)
    assert ref.distance[10, 20] == 1 and ref.distance[14, 30] == 5 and ref.distance[0, 0] == 0
    assert ref.planes[0].n_interior == 22 * 22 and ref.planes[0].n_rim == 900 - 484


def test_score_exact_numbers():
    depth, K = _square()
    ref = plane_reference(depth, K, min_fraction=0.05, consensus=1)
    est = np.zeros((60, 80, 3))
    est[..., 2] = -1.0
    t = np.radians(10.0)
    est[14:25, 24:46] = [np.sin(t), 0.0, -np.cos(t)]  # half the interior (11 of 22 rows) off by 10 deg
    est[10, 21:50] = np.nan  # the top rim row but its first pixel (29 px) missing
    est[10:40, 20] = [0.0, 0.0, 1.0]  # the left rim column (30 px) facing away: 180 deg
    s = score_planes(est, ref)
    assert s["n_interior"] == 484 and s["n_rim"] == 416
    assert s["interior_mean"] == pytest.approx(5.0, abs=1e-9)
    assert s["interior_median"] == pytest.approx(5.0, abs=1e-9)  # 242 zeros and 242 tens
    assert s["scored_rim"] == 416 - 29
    assert s["rim_mean"] == pytest.approx(30 * 180.0 / 387, abs=1e-9)
    assert s["rim_median"] == 0.0
    assert s["coverage"] == pytest.approx((484 + 387) / 900)
    assert s["rim_coverage"] == pytest.approx(387 / 416)
    assert s["interior_coverage"] == 1.0
    folded = score_planes(est, ref, folded=True)
    assert folded["rim_mean"] == 0.0
    assert len(s["planes"]) == 1 and s["planes"][0]["interior_mean"] == s["interior_mean"]


def test_no_plane_and_bad_input():
    ref = plane_reference(np.zeros((30, 40)), (30.0, 30.0, 19.5, 14.5), consensus=1)
    assert ref.n_planes == 0 and (ref.labels == -1).all()
    s = score_planes(np.zeros((30, 40, 3)), ref)
    assert np.isnan(s["interior_mean"]) and np.isnan(s["coverage"]) and s["n_interior"] == 0
    with pytest.raises(TypeError, match="threshold"):
        plane_reference(np.ones((30, 40)), (30.0, 30.0, 19.5, 14.5), threshold=0.01, consensus=1)
    with pytest.raises(TypeError, match="depth_scale"):
        plane_reference(np.ones((30, 40), np.uint16), (30.0, 30.0, 19.5, 14.5), consensus=1)
    with pytest.raises(TypeError, match="PlaneReference"):
        score_planes(np.zeros((30, 40, 3)), {"labels": None})
    with pytest.raises(ValueError):
        score_planes(np.zeros((31, 40, 3)), ref)


# --- the compiled kernels against short NumPy / Python references -------------------------

def _components_reference(mask: np.ndarray) -> list[set]:
    """8-connected components as sets of pixels (plain Python flood fill)."""
    seen = np.zeros_like(mask)
    comps = []
    h, w = mask.shape
    for v0, u0 in zip(*np.nonzero(mask), strict=False):
        if seen[v0, u0]:
            continue
        stack, comp = [(v0, u0)], set()
        seen[v0, u0] = True
        while stack:
            v, u = stack.pop()
            comp.add((v, u))
            for dv in (-1, 0, 1):
                for du in (-1, 0, 1):
                    vv, uu = v + dv, u + du
                    if 0 <= vv < h and 0 <= uu < w and mask[vv, uu] and not seen[vv, uu]:
                        seen[vv, uu] = True
                        stack.append((vv, uu))
        comps.append(comp)
    return comps


def _chessboard_reference(labels: np.ndarray) -> np.ndarray:
    """Brute force: the smallest max(|dv|, |du|) to a pixel of another label, the ring of
    pixels around the image counting as outside."""
    pad = np.pad(labels, 1, constant_values=-2)
    v, u = np.mgrid[-1:labels.shape[0] + 1, -1:labels.shape[1] + 1]
    out = np.zeros(labels.shape, np.int32)
    for (pv, pu), lab in np.ndenumerate(labels):
        if lab >= 0:
            other = pad != lab
            out[pv, pu] = np.maximum(np.abs(v[other] - pv), np.abs(u[other] - pu)).min()
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_label_kernel_matches_reference(seed):
    rng = np.random.default_rng(seed)
    mask = rng.random((23, 31)) < 0.45
    labels = np.empty(mask.shape, np.int32)
    sizes = label_8connected(mask, labels)
    ref = _components_reference(mask)
    assert len(sizes) == len(ref)
    got = [set(zip(*np.nonzero(labels == k), strict=False)) for k in range(len(sizes))]
    assert sorted(map(sorted, got)) == sorted(map(sorted, ref))
    assert [len(g) for g in got] == sizes.tolist()
    assert (labels[~mask] == -1).all()


@pytest.mark.parametrize("seed", [0, 1])
def test_chessboard_kernel_matches_reference(seed):
    rng = np.random.default_rng(seed)
    labels = np.full((40, 50), -1, np.int32)
    for k in range(4):
        v, u = rng.integers(0, 30, 2)
        labels[v:v + rng.integers(5, 20), u:u + rng.integers(5, 25)] = k
    labels[rng.random(labels.shape) < 0.02] = -1
    dist = np.empty(labels.shape, np.int32)
    chessboard_inside(labels, dist)
    assert np.array_equal(dist, _chessboard_reference(labels))


@pytest.mark.parametrize("seed", [0, 1])
def test_chessboard_to_matches_reference(seed):
    rng = np.random.default_rng(seed)
    mask = rng.random((30, 41)) < 0.01
    dist = np.empty(mask.shape, np.int32)
    chessboard_to(mask, dist)
    v, u = np.nonzero(mask)
    gv, gu = np.mgrid[0:30, 0:41]
    ref = np.maximum(np.abs(gv[..., None] - v), np.abs(gu[..., None] - u)).min(axis=-1)
    assert np.array_equal(dist, ref)
    for r in (0, 3):  # the dilation of _planes
        assert np.array_equal(dist <= r, ref <= r)


def test_plane_kernels_match_numpy():
    rng = np.random.default_rng(0)
    pts = rng.normal(0.0, 1.0, (20, 30, 3))
    pts[3, 4] = np.nan
    thr = rng.uniform(0.1, 1.0, (20, 30))
    allowed = rng.random((20, 30)) < 0.7
    plane = np.array([0.6, 0.0, -0.8, 0.3])
    ratio = np.empty((20, 30))
    plane_ratio(pts, thr, plane, ratio)
    with np.errstate(invalid="ignore"):
        ref = np.abs(pts @ plane[:3] + plane[3]) / thr
    assert np.allclose(ratio[np.isfinite(ref)], ref[np.isfinite(ref)], rtol=1e-12)
    assert ratio[3, 4] == np.inf
    mask = np.empty((20, 30), bool)
    plane_inliers(pts, thr, allowed, plane, mask)
    assert np.array_equal(mask, allowed & (np.nan_to_num(ref, nan=np.inf) <= 1.0))


# --- the real sensor frames ---------------------------------------------------------------

def test_real_frames_have_planes(shared_data):
    root = shared_data / "real-sensors"
    if not root.is_dir():
        pytest.skip(f"{root} is absent")
    from depthnormals.datasets import open as open_dataset
    from depthnormals.evaluate import sensor_threshold

    n = 0
    for f in open_dataset(root):
        ref = plane_reference(f.depth, f.K, threshold=sensor_threshold(f.meta), consensus=1)
        assert ref.n_planes >= 2, (f.group, f.name)
        assert ref.interior.sum() > 0.05 * f.depth.size, (f.group, f.name)
        assert all(p.rms_ratio <= 0.45 * 1.2 for p in ref.planes)  # MAX_RMS_RATIO, KEEP_SLACK
        n += 1
    assert n == 11


# --- the front end: run_plane_evaluation and `depthnormals evaluate --reference planes` ----

def _sensor_folder(tmp_path):
    """A real-sensor-style folder: box-on-floor at 320 x 240 with Kinect v1 quantisation,
    stored as a millimetre PNG beside an intrinsics.json, plus a colour image to skip."""
    from depthnormals._png import encode_png

    K = (262.5, 262.5, 159.5, 119.5)
    r = make_scene("box-on-floor").render(K=K, shape=(240, 320))
    mm = np.round(_kinect(r.depth, seed=2) * 1000.0).astype(np.uint16)
    (tmp_path / "cam").mkdir()
    (tmp_path / "cam" / "depth.png").write_bytes(encode_png(mm))
    (tmp_path / "cam" / "rgb.png").write_bytes(encode_png(np.zeros((240, 320, 3), np.uint8)))
    (tmp_path / "cam" / "intrinsics.json").write_text(json.dumps(
        {"fx": K[0], "fy": K[1], "cx": K[2], "cy": K[3], "depth_scale": 0.001,
         "invalid_value": 0, "sensor": "simulated Kinect v1"}))
    return tmp_path / "cam", r


def test_run_plane_evaluation(tmp_path):
    from depthnormals.evaluate import run_plane_evaluation

    folder, _ = _sensor_folder(tmp_path)
    res = run_plane_evaluation(folder, "3f2n+,fals[window=11]", tmp_path / "out", figures=True)
    assert len(res.frames) == 1 and res.frames[0]["group"] == "cam"
    f = res.frames[0]
    assert len(f["planes"]) >= 3 and set(f["scores"]) == {"3f2n+", "fals[window=11]"}
    for label in ("3f2n+", "fals[window=11]"):
        s = f["scores"][label]
        assert 0.0 < s["interior_mean"] < 20.0 and s["coverage"] > 0.95 and s["ms"] > 0
        assert res.summary["(all)"][label]["interior_mean"] == s["interior_mean"]
    saved = json.loads((tmp_path / "out" / "planes.json").read_text())
    assert saved["settings"]["reference"] == "planes" and saved["settings"]["seed"] == 0
    assert saved["frames"][0]["planes"][0]["n_pixels"] == f["planes"][0]["n_pixels"]
    assert "| cam | 3f2n+ |" in (tmp_path / "out" / "planes.md").read_text()
    # the crease bands: the box's foot on the floor (concave) and its top edge (convex), every
    # band pixel scored; the default places them closer than FALS-11 (7.0 against 17.3 deg)
    pairs = f["creases"]["pairs"]
    assert {p["convex"] for p in pairs} == {True, False} and f["creases"]["pixels"] > 1000
    ours, fals = f["scores"]["3f2n+"], f["scores"]["fals[window=11]"]
    assert ours["n_crease"] == ours["scored_crease"] == f["creases"]["pixels"]
    assert ours["crease_mean"] < fals["crease_mean"]
    assert res.summary["(all)"]["3f2n+"]["pooled_crease_mean"] == pytest.approx(ours["crease_mean"])
    assert "crease (deg)" in (tmp_path / "out" / "planes.md").read_text()
    (png,) = res.figures
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_reference_planes(tmp_path, capsys):
    from depthnormals import cli

    folder, _ = _sensor_folder(tmp_path)
    rc = cli.main(["evaluate", str(folder), "-m", "3f2n", "-o", str(tmp_path / "o"),
                   "--reference", "planes", "--figures", "0", "-q"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "| cam | 3f2n |" in text and "interior (deg)" in text
    assert (tmp_path / "o" / "planes.json").is_file()
    assert not (tmp_path / "o" / "figures").exists()


def test_cli_without_truth_points_to_planes(tmp_path, capsys):
    from depthnormals import cli

    folder, _ = _sensor_folder(tmp_path)
    rc = cli.main(["evaluate", str(folder), "-m", "3f2n", "-o", str(tmp_path / "o"), "-q"])
    assert rc != 0
    assert "--reference planes" in capsys.readouterr().err
