"""Freespace labels of the road scenes, segmentation scores, the freespace benchmark's training loop."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys

import numpy as np
import pytest

from depthnormals.render import look_at, render_mesh
from depthnormals.synth.freespace import (
    ROAD_RECIPES,
    freespace_label,
    road_camera,
    road_frames,
    segmentation_scores,
)
from depthnormals.synth.scenes import PART_NAMES, Scene, make_scene, scene_names


def _world_points(depth: np.ndarray, K, pose: np.ndarray) -> np.ndarray:
    h, w = depth.shape
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    X = np.stack([(u - K.cx) / K.fx * depth, (v - K.cy) / K.fy * depth, depth], axis=-1)
    return X @ pose[:3, :3].T + pose[:3, 3]


# ---------------------------------------------------------------- part labels of the scenes

def test_part_labels_leave_the_scene_bytes_unchanged():
    # sha1 of vertices + faces + solids of make_scene(name, seed=3), computed on the main line at
    # 61ecbd9 (before Scene.parts existed): tagging faces must not move a vertex
    golden = {"street": "efc95bced6be", "parking_lot": "73be2bede39f", "office": "7a555ddb5309"}
    for name, digest in golden.items():
        s = make_scene(name, seed=3)
        h = hashlib.sha1(s.vertices.tobytes() + s.faces.tobytes() + s.solids.tobytes()).hexdigest()
        assert h[:12] == digest, name


def test_every_recipe_labels_every_face():
    for name in scene_names():
        s = make_scene(name, seed=0)
        assert s.parts is not None and s.parts.shape == (s.faces.shape[0],) and s.parts.dtype == np.uint8
        assert int(s.parts.max()) < len(PART_NAMES)
    street = make_scene("street", seed=0)
    counts = np.bincount(street.parts, minlength=len(PART_NAMES))
    assert counts[PART_NAMES.index("ground")] == 12  # one box
    assert counts[PART_NAMES.index("kerb")] == 24    # two boxes
    assert counts[PART_NAMES.index("vehicle")] > 0 and counts[PART_NAMES.index("other")] == 0


# ---------------------------------------------------------------- labels

def test_label_is_the_visible_road_top_and_not_the_pavement():
    scene = make_scene("street", seed=0)
    K = road_camera((48, 96))
    eye = np.array([-3.0, 0.0, 1.5])
    pose = look_at(eye, eye + np.array([1.0, 0.0, -0.08]))
    r = render_mesh(scene.vertices, scene.faces, K, pose=pose, width=96, height=48)
    label = freespace_label(scene, r, pose)
    parts = np.where(r.face >= 0, scene.parts[np.maximum(r.face, 0)], 255)
    kerb = parts == PART_NAMES.index("kerb")
    assert label.mean() > 0.1 and kerb.sum() > 20
    assert np.all(parts[label] == PART_NAMES.index("ground"))
    assert not np.any(label & kerb)
    X = _world_points(r.depth, K, pose)
    assert np.abs(X[label, 2]).max() < 1e-9                 # on the road plane z = 0
    kerb_y = scene.vertices[scene.faces[scene.parts == PART_NAMES.index("kerb")].ravel(), 1]
    half = np.abs(kerb_y).min()                               # the kerbs' inner edges at y = +-half
    assert np.abs(X[label, 1]).max() <= half + 1e-9          # between the kerbs
    n_world = r.normals[label] @ pose[:3, :3].T
    np.testing.assert_allclose(n_world, np.tile([0.0, 0.0, 1.0], (label.sum(), 1)), atol=1e-12)
    assert np.all(X[kerb & (np.abs((r.normals @ pose[:3, :3].T)[..., 2] - 1) < 1e-9), 2] > 0.149)


def test_label_needs_part_labels():
    s = make_scene("street", seed=0)
    bare = Scene(s.name, "mesh", s.vertices, s.faces, s.solids, s.eye_box, s.target_box)
    K = road_camera((16, 32))
    pose = look_at((-3.0, 0.0, 1.5), (10.0, 0.0, 0.0))
    r = render_mesh(s.vertices, s.faces, K, pose=pose, width=32, height=16)
    with pytest.raises(ValueError, match="no part labels"):
        freespace_label(bare, r, pose)


def test_road_frames_are_car_views_with_exact_labels_and_seeded():
    frames = road_frames(6, seed=0, size=(24, 48), noise=None, views_per_scene=2)
    assert [f.scene.split("/")[0] for f in frames] == ["street", "street", "alley", "alley", "boulevard",
                                                      "boulevard"]
    for f in frames:
        assert 1.2 <= f.pose[2, 3] <= 1.7                       # camera height
        assert f.pose[2, 2] <= 1e-12 and f.pose[2, 2] > -np.sin(np.radians(7))  # pitch 0..6 deg down
        assert f.label[-1, 24] and f.label.mean() >= 0.1
        X = _world_points(f.clean.astype(np.float64), f.K, f.pose)
        assert np.abs(X[f.label, 2]).max() < 1e-4               # float32 depth
        assert np.all(f.depth == f.clean)
    again = road_frames(6, seed=0, size=(24, 48), noise="gaussian:sigma_px=0.5", views_per_scene=2)
    for a, b in zip(frames, again, strict=True):
        np.testing.assert_array_equal(a.pose, b.pose)          # the noise model does not move the camera
        np.testing.assert_array_equal(a.label, b.label)
        ok = b.clean > 0
        assert np.all(b.depth[ok] != b.clean[ok]) and np.all(b.depth[~ok] == 0)
    repeat = road_frames(2, seed=0, size=(24, 48), noise="gaussian:sigma_px=0.5", views_per_scene=2)
    np.testing.assert_array_equal(repeat[1].depth, again[1].depth)
    other = road_frames(1, seed=1, size=(24, 48), noise=None)
    assert other[0].scene != frames[0].scene                    # held-out scene instances


def test_road_frames_reject_bad_options():
    with pytest.raises(ValueError, match="unknown road recipe"):
        road_frames(1, recipes=("office",))
    with pytest.raises(ValueError, match="unknown noise model"):
        road_frames(1, noise="lidar")
    with pytest.raises(ValueError, match="size"):
        road_frames(1, size=(16,))
    assert set(ROAD_RECIPES) <= set(scene_names("outdoor"))


# ---------------------------------------------------------------- scores

def test_scores_on_hand_made_masks():
    pred = np.zeros((4, 4), bool)
    label = np.zeros((4, 4), bool)
    pred[:2] = True            # 8 pixels
    label[:, :2] = True        # 8 pixels, 4 shared
    s = segmentation_scores(pred, label)
    assert (s["tp"], s["fp"], s["fn"], s["tn"]) == (4, 4, 4, 4)
    assert s["iou"] == pytest.approx(1 / 3, abs=0) and s["f1"] == 0.5
    s = segmentation_scores([1, 1, 1, 1, 0, 0, 0], [1, 1, 1, 0, 1, 1, 0])  # TP 3, FP 1, FN 2, TN 1
    assert (s["tp"], s["fp"], s["fn"], s["tn"]) == (3, 1, 2, 1)
    assert s["iou"] == 0.5 and s["f1"] == pytest.approx(2 / 3, abs=1e-15)
    assert s["precision"] == 0.75 and s["recall"] == 0.6
    perfect = segmentation_scores(label, label)
    assert perfect["iou"] == perfect["f1"] == 1.0
    empty = segmentation_scores(np.zeros(3, bool), np.zeros(3, bool))
    assert np.isnan(empty["iou"]) and np.isnan(empty["f1"]) and empty["tn"] == 3


def test_scores_reject_bad_input():
    with pytest.raises(ValueError, match="same shape"):
        segmentation_scores(np.zeros((2, 2), bool), np.zeros((2, 3), bool))
    with pytest.raises(TypeError, match="boolean"):
        segmentation_scores(np.zeros(2), np.zeros(2, bool))


def test_freespace_module_does_not_import_torch():
    code = "import sys, depthnormals.synth.freespace; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# ---------------------------------------------------------------- the benchmark's training loop

@pytest.fixture(scope="module")
def bench(load_benchmark):
    pytest.importorskip("torch")
    return load_benchmark("freespace")


def test_one_training_step_moves_the_weights(bench):
    import torch

    rng = np.random.default_rng(0)
    x = rng.random((4, 4, 16, 32), dtype=np.float32)
    y = rng.random((4, 16, 32)) > 0.5
    torch.manual_seed(0)
    start = {k: v.clone() for k, v in bench.make_unet(4, width=4).state_dict().items()}
    model = bench.train(x, y, seed=0, epochs=1, batch=2, width=4, max_steps=1)
    after = model.state_dict()
    assert all(torch.isfinite(v.float()).all() for v in after.values())
    moved = [k for k in start if not torch.equal(start[k], after[k])]
    assert "head.weight" in moved and "e1.0.weight" in moved
    again = bench.train(x, y, seed=0, epochs=1, batch=2, width=4, max_steps=1)
    assert all(torch.equal(after[k], v) for k, v in again.state_dict().items())  # seeded
    pred = bench.predict(model, x)
    assert pred.shape == (4, 16, 32) and pred.dtype == bool


def test_benchmark_main_writes_table_sidecar_and_figure(bench, tmp_path, capsys):
    out, fig = tmp_path / "fs.md", tmp_path / "fs.png"
    args = ["--size", "16x32", "--train", "4", "--test", "2", "--epochs", "1", "--seeds", "2",
            "--width", "4", "--threads", "1", "--inputs", "disparity,disparity+3f2n+",
            "--out", str(out), "--figure", str(fig)]
    assert bench.main(args) == 0
    table = out.read_text().splitlines()
    assert table[0].startswith("| input |") and len(table) == 4
    assert table[2].startswith("| disparity | 1 |") and table[3].startswith("| disparity+3f2n+ | 4 |")
    meta = json.loads(out.with_suffix(".json").read_text())
    runs = meta["results"]["disparity+3f2n+"]
    assert [r["seed"] for r in runs] == [0, 1]
    assert all(r["tp"] + r["fp"] + r["fn"] + r["tn"] == 2 * 16 * 32 for r in runs)
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*tmp"))
    assert "wall time" in capsys.readouterr().out
