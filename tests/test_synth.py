"""Synthetic benchmark: recipes, consistency of stored ground truth, determinism, resume, errors."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from depthnormals.camera import Intrinsics
from depthnormals.cli import main
from depthnormals.datasets import open as open_dataset
from depthnormals.synth import (
    PoseConstraints,
    Scene,
    export_3f2n,
    generate,
    make_scene,
    sample_poses,
    scene_names,
)
from depthnormals.synth.meshes import box

SMALL_K = Intrinsics(91.375, 91.375, 63.5, 52.5)  # Kinect v2 field of view at 128 x 106
SMALL = (106, 128)


def _tree_hashes(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def test_recipes_count_and_reproducible():
    assert len(scene_names("indoor")) >= 10 and len(scene_names("outdoor")) >= 10
    a, b, c = make_scene("street", seed=5), make_scene("street", seed=5), make_scene("street", seed=6)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert not (a.vertices.shape == c.vertices.shape and np.array_equal(a.vertices, c.vertices))
    with pytest.raises(ValueError, match="unknown scene recipe"):
        make_scene("castle")


@pytest.fixture(scope="module")
def every_recipe(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("all") / "ds"
    generate(out, indoor=10, outdoor=10, views=1, seed=11, noise=(), K=SMALL_K, size=SMALL,
             progress=False)
    return out


def _cross_product_normals(depth, K):
    z = np.where(depth > 0, depth.astype(np.float64), np.nan)
    h, w = z.shape
    u = (np.arange(w) - K[0, 2]) / K[0, 0]
    v = (np.arange(h) - K[1, 2]) / K[1, 1]
    P = np.stack([u[None, :] * z, v[:, None] * z, z], axis=-1)
    du = P[1:-1, 2:] - P[1:-1, :-2]
    dv = P[2:, 1:-1] - P[:-2, 1:-1]
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    c = P[1:-1, 1:-1]
    n *= -np.sign(np.einsum("...i,...i->...", n, c))[..., None]
    return n, P


def test_every_recipe_gt_consistent_with_depth(every_recipe):
    groups = set()
    for f in open_dataset(every_recipe):
        groups.add(f.group)
        n_est, P = _cross_product_normals(f.depth, f.K)
        g = f.normals.astype(np.float64)[1:-1, 1:-1]
        c = P[1:-1, 1:-1]
        # planar interior: the 4 neighbours lie on the centre pixel's GT plane
        off = np.abs(np.einsum("...i,...i->...", g, c))
        interior = np.all(np.isfinite(g), axis=-1)
        for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            nb = P[1 + dy:P.shape[0] - 1 + dy, 1 + dx:P.shape[1] - 1 + dx]
            with np.errstate(invalid="ignore"):
                interior &= np.abs(np.einsum("...i,...i->...", g, nb - c)) < 1e-5 * off
        assert interior.sum() > 500, f.group
        cross = np.linalg.norm(np.cross(n_est[interior], g[interior]), axis=-1)
        dot = np.einsum("ij,ij->i", n_est[interior], g[interior])
        err = np.degrees(np.arctan2(cross, dot))
        assert np.median(err) < 0.05, (f.group, np.median(err))
        assert np.all(np.einsum("...i,...i->...", g[interior], c[interior]) < 0)  # faces the camera
    assert len(groups) == 20


def test_same_command_twice_is_byte_identical(tmp_path):
    args = ["--indoor", "1", "--outdoor", "1", "--views", "2", "--seed", "3", "--width", "128",
            "--height", "106", "--noise", "kinect_v2,gaussian,kinect_v1", "--no-progress",
            "--scenes", "procedural"]
    assert main(["synth", str(tmp_path / "a"), *args]) == 0
    assert main(["synth", str(tmp_path / "b"), *args]) == 0
    ha, hb = _tree_hashes(tmp_path / "a"), _tree_hashes(tmp_path / "b")
    assert len(ha) == 1 + 2 * (1 + 2 * 6)  # sidecar + per scene (scene.json + 2 views x 6 files)
    assert ha == hb
    meta = json.loads((tmp_path / "a" / "dataset.json").read_text())
    assert meta["library_version"] and meta["settings"]["seed"] == 3
    assert [n["model"] for n in meta["settings"]["noise"]] == ["kinect_v2", "gaussian", "kinect_v1"]
    # noisy variants differ from clean, clean is exact float32 of the render
    d = tmp_path / "a" / "indoor" / "living_room-00"
    clean, noisy = np.load(d / "clean" / "0000.npy"), np.load(d / "kinect_v2" / "0000.npy")
    both = (clean > 0) & (noisy > 0)
    assert 0.0005 < np.std(noisy[both] - clean[both]) < 0.05


def test_resume_and_refuse_other_settings(tmp_path):
    kw = {"indoor": 1, "outdoor": 0, "views": 2, "seed": 1, "K": SMALL_K, "size": SMALL, "progress": False}
    s1 = generate(tmp_path, **kw)
    before = _tree_hashes(tmp_path)
    victim = tmp_path / "indoor" / "living_room-00" / "kinect_v2" / "0001.npy"
    victim.unlink()
    s2 = generate(tmp_path, **kw)
    assert (s1.written, s2.written, s2.skipped) == (2, 1, 1)
    assert _tree_hashes(tmp_path) == before
    with pytest.raises(ValueError, match="other settings"):
        generate(tmp_path, **{**kw, "seed": 2})
    assert _tree_hashes(tmp_path) == before  # nothing lost or changed


def test_export_3f2n_round_trip(tmp_path):
    generate(tmp_path / "ds", indoor=1, outdoor=0, views=1, noise=(), K=SMALL_K, size=SMALL,
             progress=False)
    dirs = export_3f2n(tmp_path / "ds", tmp_path / "x")
    params = (dirs[0] / "params.txt").read_text().split()
    assert [float(x) for x in params] == [91.375, 91.375, 64.5, 53.5, 1.0]
    ours = next(open_dataset(tmp_path / "ds"))
    theirs = next(open_dataset(tmp_path / "x"))
    assert theirs.depth.shape == SMALL and np.allclose(theirs.K, ours.K)
    ok = ours.mask & theirs.mask
    assert ok.sum() > 0.9 * ours.mask.sum()
    assert np.array_equal(theirs.depth[ok], ours.depth[ok])
    a, g = theirs.normals[ok].astype(float), ours.normals[ok].astype(float)
    ang = np.degrees(np.arctan2(np.linalg.norm(np.cross(a, g), axis=-1), np.einsum("ij,ij->i", a, g)))
    assert ang.max() < 0.01  # 16-bit quantisation only


def test_user_mesh_through_trimesh(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    mesh = trimesh.Trimesh(*box((-1.0, -1.0, 0.0), (1.0, 1.0, 1.5)))
    for ext in ("stl", "ply", "obj", "glb"):
        mesh.export(tmp_path / f"blk.{ext}")
    out = tmp_path / "ds"
    s = generate(out, indoor=0, outdoor=0, views=1, meshes=[tmp_path / "blk.ply", tmp_path / "blk.glb"],
                 noise=(), K=SMALL_K, size=SMALL, progress=False,
                 constraints=PoseConstraints(min_valid=0.05, median_depth=(1.5, 4.0)))
    assert s.written == 2
    frames = list(open_dataset(out))
    assert [f.group for f in frames] == ["mesh/blk-00/clean", "mesh/blk-01/clean"]
    assert all(f.mask.sum() > 50 for f in frames)


def test_bad_inputs_clear_errors_nothing_lost(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        generate(tmp_path / "a", indoor=0, outdoor=0, meshes=[tmp_path / "missing.obj"], progress=False)
    assert not (tmp_path / "a").exists()  # failed before writing anything
    (tmp_path / "bad.ply").write_bytes(b"ply\nformat garbage\n\x00\x01\x02")
    with pytest.raises(ValueError, match=r"bad\.ply"):
        generate(tmp_path / "a", indoor=0, outdoor=0, meshes=[tmp_path / "bad.ply"], progress=False)
    (tmp_path / "empty.obj").write_text("# no faces\nv 0 0 0\n")
    with pytest.raises(ValueError, match="no triangles"):
        generate(tmp_path / "a", indoor=0, outdoor=0, meshes=[tmp_path / "empty.obj"], progress=False)
    with pytest.raises(ValueError, match="nothing to generate"):
        generate(tmp_path / "a", indoor=0, outdoor=0, progress=False)
    # a camera that sees nothing: the only surface is far away from where cameras look
    V, F = box((1000.0, 1000.0, 0.0), (1001.0, 1001.0, 1.0))
    far = Scene("far", "mesh", V, F, np.zeros((0, 2, 3)), np.array([[0, 0, 1.0], [1, 1, 2.0]]),
                np.array([[0, 0, 0.0], [1, 1, 1.0]]))
    with pytest.raises(ValueError, match="camera sees nothing"):
        sample_poses(far, 1, rng=np.random.default_rng(0), K=SMALL_K, size=SMALL,
                     constraints=PoseConstraints(max_tries=20))
    # unwritable output: a path below a regular file
    (tmp_path / "file").write_text("x")
    with pytest.raises(OSError, match="cannot create output folder"):
        generate(tmp_path / "file" / "out", indoor=1, outdoor=0, views=1, progress=False)
    with pytest.raises(ValueError, match="not a folder"):
        generate(tmp_path / "file", indoor=1, outdoor=0, views=1, progress=False)
    assert (tmp_path / "file").read_text() == "x"
    # a non-empty foreign folder is refused and left alone
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(ValueError, match="not empty"):
        generate(tmp_path / "mine", indoor=1, outdoor=0, views=1, progress=False)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"
    assert main(["synth", str(tmp_path / "file" / "x"), "--indoor", "1", "--outdoor", "0",
                 "--views", "1", "--no-progress", "--scenes", "procedural"]) == 1


def test_progress_counter_without_tqdm(tmp_path, monkeypatch, capsys):
    import builtins

    real_import = builtins.__import__

    def no_tqdm(name, *args, **kwargs):
        if name == "tqdm":
            raise ImportError("no tqdm")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_tqdm)
    generate(tmp_path, indoor=1, outdoor=0, views=2, noise=(), K=SMALL_K, size=SMALL, progress=True)
    err = capsys.readouterr().err                    # one line per view, no carriage returns
    assert err.splitlines() == ["synth: 1/2 view", "synth: 2/2 view"]


def test_pose_constraints_validated():
    with pytest.raises(ValueError, match="min_valid"):
        PoseConstraints(min_valid=1.5)
    with pytest.raises(ValueError, match="median_depth"):
        PoseConstraints(median_depth=(3.0, 1.0))
