"""benchmarks/icp.py: the point-to-plane ICP recovers known motions, and on one real Kinect v1
pair it lands within the errors measured for docs/benchmarks.md section 18.

The solver parts run here with fixed correspondences; everything that needs Open3D (its
nearest neighbours, its ``registration_icp``) runs in a subprocess, as tests/test_ply.py does:
Open3D bundles an old TBB which, once loaded, can make numba warn (an error under this suite)."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import depthnormals as dn

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "icp.py"


@pytest.fixture(scope="module")
def icp(load_benchmark):
    return load_benchmark("icp")


def test_quaternion_pose_and_errors(icp):
    s = np.sqrt(0.5)
    T = icp.quat_pose(1.0, 2.0, 3.0, 0.0, 0.0, s, s)  # 90 deg about z
    np.testing.assert_allclose(T[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_array_equal(T[:3, 3], [1.0, 2.0, 3.0])
    P = icp.perturbation(np.random.default_rng(3), 3.0, 50.0)
    rot, trans = icp.pose_error(P @ T, T)
    assert rot == pytest.approx(3.0, abs=1e-9)
    assert icp.pose_error(T @ P, T)[0] == pytest.approx(3.0, abs=1e-9)
    assert np.linalg.norm(P[:3, 3]) * 1e3 == pytest.approx(50.0)
    assert trans > 0.0 and icp.pose_error(T, T) == (0.0, 0.0)


def test_pairs(icp):
    assert icp.pairs(5) == [(0, 1), (1, 2), (2, 3), (3, 4), (0, 2), (1, 3), (2, 4)]


def test_solver_with_fixed_correspondences_is_exact(icp):
    """Points with normals of three orientations moved by 5 deg / 100 mm: with the true
    correspondences the Gauss-Newton loop lands on the motion to 1e-7 deg / 1e-6 mm (weights
    change the path, not the answer)."""
    rng = np.random.default_rng(0)
    normals = np.repeat(np.array([[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [-0.8, 0.0, -0.6]]), 200, axis=0)
    target = rng.uniform(-1.0, 1.0, (600, 3)) + np.array([0.0, 0.0, 3.0])
    T_true = icp.perturbation(rng, 5.0, 100.0)
    source = icp.transform(np.linalg.inv(T_true), target)

    def same_index(q):  # the true pairs, with their distances (the convergence test reads them)
        return np.arange(len(q)), np.linalg.norm(q - target, axis=1)

    for w in (None, rng.uniform(0.1, 10.0, 600)):
        r = icp.point_to_plane_icp(source, target, normals, np.eye(4), max_dist=1.0,
                                   iterations=20, nearest=same_index, target_weights=w)
        rot, trans = icp.pose_error(r["transformation"], T_true)
        assert rot < 1e-7 and trans < 1e-6, (rot, trans)
        assert r["iterations"] < 20 and r["fitness"] == 1.0
    # one step from the start already removes most of the error (the linearisation is right)
    one = icp.point_to_plane_icp(source, target, normals, np.eye(4), max_dist=1.0, iterations=1,
                                 nearest=same_index)
    assert icp.pose_error(one["transformation"], T_true)[0] < 0.2


def test_weights(icp):
    w = icp.weights_from_uncertainty(np.array([0.1, 1.0, 2.0, 10.0]), 1.0)
    np.testing.assert_allclose(w, [1.0, 1.0, 0.25, 0.01])


def test_residual_weights(icp):
    """The inverse of a pair's residual variance ``2 s_z^2 + |p - q|^2 s_n^2``, ``s_n`` the
    per-axis spread of a Rayleigh angle of mean ``u`` (u / sqrt(pi / 2), radians); without the
    map the depth's term alone. Read per pair through ``idx`` (the target points paired)."""
    noise = np.array([0.001, 0.002, 0.004])
    u = np.array([0.0, 10.0, 40.0])
    p = np.array([[0.01, 0.0, 1.0], [0.0, 0.02, 1.0]])
    q = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    idx = np.array([2, 1])
    s_n = np.radians([40.0, 10.0]) / np.sqrt(np.pi / 2.0)
    want = 1.0 / (2.0 * np.array([0.004, 0.002]) ** 2 + np.array([1e-4, 4e-4]) * s_n ** 2)
    np.testing.assert_allclose(icp.residual_weights(noise, u)(p, q, idx), want, rtol=1e-12)
    np.testing.assert_allclose(icp.residual_weights(noise, None)(p, q, idx),
                               [1.0 / 3.2e-5, 1.0 / 8e-6], rtol=1e-12)


_SCRIPT = r"""
import importlib.util, json, sys
import numpy as np
spec = importlib.util.spec_from_file_location("icp_bench", sys.argv[1])
icp = importlib.util.module_from_spec(spec); spec.loader.exec_module(icp)
import depthnormals as dn
from depthnormals.analytic import box_on_floor
out = {}
# analytic: box on a floor before a wall, the camera turned 3 deg and moved 9 cm
K = dn.Intrinsics(131.25, 131.25, 79.5, 59.5)
moved, M = icp.moved_scene(box_on_floor(), 3.0, (0.04, -0.02, 0.08))
target, source = icp.rendered_frame(box_on_floor(), K, (120, 160)), icp.rendered_frame(moved, K, (120, 160))
T_true = np.linalg.inv(M)
init = icp.perturbation(np.random.default_rng(0), 2.0, 30.0) @ T_true
res = icp.register_pair(icp.subsample(source, 2), icp.subsample(target, 1), init, max_dist=0.05,
                        iterations=50, floor=1.0)
out["synthetic"] = {v: list(icp.pose_error(r["transformation"], T_true)) + [r["fitness"]]
                    for v, r in res.items()}
root = icp.ROOT
if root.is_dir():
    frames = [f for f in icp.load_frames(root) if f.name in ("2", "3")]
    ref = icp.relative_reference(frames[0], frames[1])
    init = icp.perturbation(np.random.default_rng([0, 1, 2]), 3.0, 50.0) @ ref
    res = icp.register_pair(icp.subsample(frames[0], 8), icp.subsample(frames[1], 8), init,
                            max_dist=0.05, iterations=50, floor=1.0)
    out["real"] = {v: list(icp.pose_error(r["transformation"], ref)) + [r["fitness"]]
                   for v, r in res.items()}
    out["solvers"] = list(icp.pose_error(res["ours"]["transformation"],
                                         res["o3d-icp-ours"]["transformation"]))
print("RESULT" + json.dumps(out))
"""


@pytest.fixture(scope="module")
def with_open3d(tmp_path_factory):
    """The analytic pair and (with ../shared) the real pair 2 -> 3, every variant, run in a
    fresh interpreter (about 3 s)."""
    if importlib.util.find_spec("open3d") is None:
        pytest.skip("open3d is not installed")
    cwd = tmp_path_factory.mktemp("icp")
    proc = subprocess.run([sys.executable, "-c", _SCRIPT, str(BENCH)], cwd=cwd, text=True,
                          capture_output=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(Path(dn.__file__).parents[1])})
    assert proc.returncode == 0, proc.stderr[-2000:]
    line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT")][-1]
    return json.loads(line[len("RESULT"):])


def test_analytic_motion_recovered(with_open3d):
    """Exact depth of two views 3 deg / 9 cm apart, started 2 deg / 30 mm off: every variant
    lands within 0.1 deg and 1 mm (measured: ~0.001 deg, 0.11 mm with our normals)."""
    for variant, (rot, trans, fitness) in with_open3d["synthetic"].items():
        assert rot < 0.1 and trans < 1.0, (variant, rot, trans)
        assert fitness > 0.8, (variant, fitness)


def test_real_pair_within_measured_bounds(with_open3d, shared_data):
    """Kinect v1 frames 2 -> 3 (every 8th pixel), started 3 deg / 50 mm off pose.txt's pose.
    Measured when written: 0.65 deg / 39.6 mm (ours, o3d-icp-ours, o3d-default), 0.39 deg /
    33.7 mm (ours-weighted), fitness 0.31; pose.txt itself is only good to a few cm here
    (docs/benchmarks.md section 18), so the bounds are 1 deg / 60 mm, fitness > 0.25."""
    if "real" not in with_open3d:
        pytest.skip("the nyu_registered_kinect1_slambook folder is absent")
    for variant, (rot, trans, fitness) in with_open3d["real"].items():
        assert rot < 1.0 and trans < 60.0, (variant, rot, trans)
        assert fitness > 0.25, (variant, fitness)
    # the same normals through our solver and Open3D's give the same pose
    rot, trans = with_open3d["solvers"]
    assert rot < 0.05 and trans < 1.0, (rot, trans)
