"""write_ply / to_open3d: what plyfile and Open3D read back equals backproject and estimate_normals."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import box_on_floor
from depthnormals.camera import Intrinsics
from depthnormals.io import write_ply

plyfile = pytest.importorskip("plyfile")

K = Intrinsics(120.0, 121.0, 63.5, 47.25)


@pytest.fixture(scope="module")
def scene():
    r = box_on_floor().render(K, (96, 128))
    depth = r.depth.astype(np.float32)
    depth[5, 7] = np.nan  # invalid depth of every kind
    depth[6, 7] = -1.0
    depth[7, 7] = np.inf
    depth[:3, :4] = 0.0
    normals = dn.estimate_normals(depth, K, method="3f2n")
    valid = np.isfinite(depth) & (depth > 0) & np.all(np.isfinite(normals), axis=-1)
    rgb = np.random.default_rng(1).integers(0, 256, (96, 128, 3), dtype=np.uint8)
    return depth, normals, valid, rgb


def test_plyfile_reads_back_backproject_and_normals_exactly(scene, tmp_path):
    depth, normals, valid, rgb = scene
    path = tmp_path / "cloud.ply"
    count = write_ply(path, depth, K, normals, colors=rgb)
    assert count == valid.sum() and 0 < count < depth.size
    assert (depth == 0).sum() > 0 and not valid[depth == 0].any()
    head = path.read_bytes()[:400]
    assert head.startswith(b"ply\nformat binary_little_endian 1.0\n")
    v = plyfile.PlyData.read(str(path))["vertex"]
    assert [p.name for p in v.properties] == ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"]
    assert v["x"].dtype == np.float32 and v["red"].dtype == np.uint8
    points = dn.backproject(depth, K)[valid].astype(np.float32)
    assert np.array_equal(np.stack([v["x"], v["y"], v["z"]], -1), points)
    assert np.array_equal(np.stack([v["nx"], v["ny"], v["nz"]], -1), normals[valid])
    assert np.array_equal(np.stack([v["red"], v["green"], v["blue"]], -1), rgb[valid])


def _needs_open3d() -> None:
    if importlib.util.find_spec("open3d") is None:  # not imported here, see _in_subprocess
        pytest.skip("open3d is not installed")


def _in_subprocess(code: str, tmp_path: Path) -> None:
    """Run ``code`` in a fresh interpreter: Open3D bundles an old TBB which, once loaded, makes
    numba warn when it later picks its threading layer (an error under this suite's filters)."""
    subprocess.run([sys.executable, "-c", code], check=True, cwd=tmp_path,
                   env={**os.environ, "PYTHONPATH": str(Path(dn.__file__).parents[1])})


def test_open3d_reads_back_the_same(scene, tmp_path):
    _needs_open3d()
    depth, normals, valid, _ = scene
    write_ply(tmp_path / "cloud.ply", depth, K, normals)
    _in_subprocess(
        "import numpy as np, open3d as o3d\n"
        "c = o3d.io.read_point_cloud('cloud.ply', format='ply')\n"
        "np.save('points.npy', np.asarray(c.points)); np.save('normals.npy', np.asarray(c.normals))\n"
        "np.save('colors.npy', np.asarray(c.has_colors()))\n", tmp_path)
    assert not np.load(tmp_path / "colors.npy")
    points = dn.backproject(depth, K)[valid].astype(np.float32)
    assert np.array_equal(np.load(tmp_path / "points.npy").astype(np.float32), points)
    assert np.array_equal(np.load(tmp_path / "normals.npy").astype(np.float32), normals[valid])


def test_to_open3d(scene, tmp_path):
    _needs_open3d()
    depth, normals, valid, rgb = scene
    np.savez(tmp_path / "in.npz", depth=depth, normals=normals, rgb=rgb, K=K.matrix)
    _in_subprocess(
        "import numpy as np, depthnormals as dn\n"
        "a = np.load('in.npz')\n"
        "c = dn.to_open3d(a['depth'], a['K'], a['normals'], colors=a['rgb'])\n"
        "np.savez('out.npz', p=np.asarray(c.points), n=np.asarray(c.normals), c=np.asarray(c.colors))\n",
        tmp_path)
    out = np.load(tmp_path / "out.npz")
    assert np.array_equal(out["p"], dn.backproject(depth, K)[valid])
    assert np.array_equal(out["n"], normals[valid].astype(np.float64))
    assert np.allclose(out["c"] * 255.0, rgb[valid], atol=1e-9)


def test_open3d_is_imported_lazily():
    code = "import sys, depthnormals; print('open3d' in sys.modules, 'h5py' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(Path(dn.__file__).parents[1])})
    assert out.stdout.split() == ["False", "False"]


def test_bad_input(scene, tmp_path):
    depth, normals, _, rgb = scene
    with pytest.raises(ValueError, match="must match"):
        write_ply(tmp_path / "a.ply", depth, K, normals[:-1])
    with pytest.raises(TypeError, match="uint8"):
        write_ply(tmp_path / "a.ply", depth, K, normals, colors=rgb.astype(np.float32))
    with pytest.raises(ValueError, match="shape"):
        write_ply(tmp_path / "a.ply", depth, K, normals, colors=rgb[:, :, :2])
    with pytest.raises(TypeError, match="depth_scale"):
        write_ply(tmp_path / "a.ply", np.nan_to_num(depth, posinf=0).astype(np.uint16), K, normals)
    assert not list(tmp_path.iterdir())


def test_crash_mid_write_leaves_no_complete_looking_file(scene, tmp_path, monkeypatch):
    depth, normals, _, _ = scene
    path = tmp_path / "cloud.ply"
    path.write_bytes(b"old")

    def disk_full(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", disk_full)  # fails after header and body are written
    with pytest.raises(OSError, match="No space"):
        write_ply(path, depth, K, normals)
    assert path.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["cloud.ply"]
    path.unlink()
    with pytest.raises(OSError, match="No space"):
        write_ply(path, depth, K, normals)
    assert list(Path(tmp_path).iterdir()) == []


def test_uncertainty_channel_reads_back(scene, tmp_path):
    """``uncertainty=``: one more float property, the map's values at the written points; the
    points are the same as without it (the map does not choose them)."""
    clean, _, _, rgb = scene
    depth = clean + np.random.default_rng(2).normal(0.0, 0.004, clean.shape).astype(np.float32)
    n, u = dn.estimate_normals(depth, K, return_uncertainty=True)
    ok = np.isfinite(depth) & (depth > 0) & np.all(np.isfinite(n), axis=-1)
    assert np.array_equal(np.isnan(u), np.isnan(n[..., 0])) and ok.sum() > 0.9 * (depth > 0).sum()
    path = tmp_path / "u.ply"
    assert write_ply(path, depth, K, n, colors=rgb, uncertainty=u) == ok.sum()
    v = plyfile.PlyData.read(str(path))["vertex"]
    assert [p.name for p in v.properties] == ["x", "y", "z", "nx", "ny", "nz", "red", "green",
                                              "blue", "uncertainty"]
    assert v["uncertainty"].dtype == np.float32
    assert np.array_equal(v["uncertainty"], u[ok]) and np.isfinite(v["uncertainty"]).all()
    # degrees: 4 mm noise, box-fit planes (~0.08) and the edges of the box (> 1)
    assert 0.02 < float(np.median(v["uncertainty"])) < 1.0
    assert float(np.percentile(v["uncertainty"], 99)) > 1.0
    assert np.array_equal(np.stack([v["nx"], v["ny"], v["nz"]], -1), n[ok])
    # a NaN in the map where the normal is valid is written as NaN, the point is kept
    u2 = u.copy()
    u2[50, 60] = np.nan
    assert ok[50, 60]
    assert write_ply(tmp_path / "u2.ply", depth, K, n, uncertainty=u2) == ok.sum()
    w = plyfile.PlyData.read(str(tmp_path / "u2.ply"))["vertex"]
    assert [p.name for p in w.properties][-1] == "uncertainty"
    assert np.isnan(w["uncertainty"]).sum() == 1
    with pytest.raises(ValueError, match="uncertainty must have shape"):
        write_ply(tmp_path / "bad.ply", depth, K, n, uncertainty=u[:-1])
    with pytest.raises(TypeError, match="uncertainty must be a real"):
        write_ply(tmp_path / "bad.ply", depth, K, n, uncertainty=u > 1)
    assert not (tmp_path / "bad.ply").exists()


@pytest.mark.parametrize("many", [False, True])
def test_cli_ply_carries_uncertainty(tmp_path, many):
    """``depthnormals estimate ... -o x.ply --uncertainty``: the PLY's uncertainty channel is
    the .npy map beside it at the written points (one file and a folder run)."""
    import json

    from depthnormals.cli import main

    r = box_on_floor().render(K, (96, 128))
    depth = r.depth.astype(np.float32)
    (tmp_path / "in").mkdir()
    np.save(tmp_path / "in" / "a.npy", depth)
    (tmp_path / "k.json").write_text(json.dumps({"fx": K.fx, "fy": K.fy, "cx": K.cx, "cy": K.cy}))
    if many:
        args = [str(tmp_path / "in"), "-o", str(tmp_path / "out"), "--format", "ply", "-q"]
    else:
        args = [str(tmp_path / "in" / "a.npy"), "-o", str(tmp_path / "out" / "a.ply")]
    assert main(["estimate", *args, "-K", str(tmp_path / "k.json"), "--uncertainty"]) == 0
    [ply] = list((tmp_path / "out").rglob("a.ply"))
    u = np.load(ply.with_name("a.uncertainty.npy"))
    n, want = dn.estimate_normals(depth, K, return_uncertainty=True)
    np.testing.assert_array_equal(u, want)
    v = plyfile.PlyData.read(str(ply))["vertex"]
    ok = np.all(np.isfinite(n), axis=-1)
    assert np.array_equal(v["uncertainty"], u[ok]) and len(v["uncertainty"]) == ok.sum()
    # without the flag: no channel
    assert main(["estimate", str(tmp_path / "in" / "a.npy"), "-K", str(tmp_path / "k.json"),
                 "-o", str(tmp_path / "plain.ply")]) == 0
    names = [p.name for p in plyfile.PlyData.read(str(tmp_path / "plain.ply"))["vertex"].properties]
    assert names == ["x", "y", "z", "nx", "ny", "nz"]
