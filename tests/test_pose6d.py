"""benchmarks/pose6d.py (issue 25): the object views, the pose scores, and a tiny end-to-end run."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("pybullet_data", reason="the object meshes ship in pybullet (the assets extra)")
pytest.importorskip("trimesh")



@pytest.fixture(scope="module")
def bench(load_benchmark):
    return load_benchmark("pose6d")


def test_views_are_consistent_and_cached(bench, tmp_path):
    objs = bench.objs
    v = objs.object_views(3, seed=4, size=32, cache_dir=tmp_path)
    assert v["rgb"].shape == (3, 3, 32, 32) and v["depth"].shape == (3, 32, 32)
    assert [objs.SENSORS[s] for s in v["sensor"]] == ["kinect_v1", "tof", "realsense_d4xx"]
    assert all(v["mask"][i].sum() > 20 for i in range(3))
    for i in range(3):  # the pose maps the model onto the rendered object
        R, t = v["R"][i].astype(np.float64), v["t"][i].astype(np.float64)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-5)
        P = objs.surface_points(objs.OBJECTS[v["obj"][i]], 200) @ R.T + t
        K = objs.intrinsics(32)
        u, w = K.fx * P[:, 0] / P[:, 2] + K.cx, K.fy * P[:, 1] / P[:, 2] + K.cy
        row, col = np.clip(np.round(w).astype(int), 0, 31), np.clip(np.round(u).astype(int), 0, 31)
        inside = v["mask"][i][row, col]
        assert inside.mean() > 0.5   # points on the hidden side still project onto the silhouette
    again = objs.object_views(3, seed=4, size=32, cache_dir=tmp_path)   # from the cache
    assert all(np.array_equal(v[k], again[k], equal_nan=k == "normals") for k in v)
    assert len(list(tmp_path.glob("views-*.npz"))) == 1
    clean = objs.object_views(3, seed=4, size=32, noise=False)  # same poses, exact depth
    assert np.array_equal(clean["R"], v["R"]) and np.array_equal(clean["mask"], v["mask"])
    assert (clean["depth"][clean["mask"]] > 0).all() and not np.array_equal(clean["depth"], v["depth"])


def test_scores_of_the_true_pose_and_welch(bench):
    objs = bench.objs
    pts = np.stack([objs.surface_points(o, 50, seed=2) for o in objs.OBJECTS[:2]])
    views = {"R": np.stack([np.eye(3)] * 2), "t": np.array([[0, 0, 0.8], [0, 0, 0.9]]),
             "obj": np.array([0, 1])}
    diam = np.array([0.12, 0.12])
    s = bench.pose_scores(views["R"], views["t"], views, pts, diam)
    assert s["add_acc"] == 1.0 and s["add_mm"] == 0.0 and s["rot_deg"] == 0.0
    s = bench.pose_scores(views["R"], views["t"] + [0.02, 0, 0], views, pts, diam)
    assert s["add_acc"] == 0.0 and s["add_mm"] == pytest.approx(20.0) and s["trans_mm"] == pytest.approx(20.0)
    assert objs.welch_p([95.09, 96.5, 93.89], [97.36, 97.21, 97.39]) == pytest.approx(0.10, abs=0.01)
    assert objs.welch_p([1.0, 2.0, 3.0], [4.0, 5.0, 6.5]) == pytest.approx(0.0291, abs=1e-3)


def test_tiny_run_writes_table_sidecar_and_figure(bench, tmp_path, capsys):
    out, fig = tmp_path / "r" / "pose.md", tmp_path / "pose.png"
    argv = ["--train", "16", "--test", "8", "--size", "32", "--epochs", "1", "--point-epochs", "1",
            "--seeds", "2", "--cache", str(tmp_path / "cache"), "--out", str(out), "--figure", str(fig)]
    assert bench.main(argv) == 0
    text = capsys.readouterr().out
    assert "| image | rgb+3f2n+ |" in text and "| points | xyz+rgb+fals |" in text
    meta = json.loads(out.with_suffix(".json").read_text())
    assert set(meta["results"]) == {"image", "points"}
    assert len(meta["results"]["image"]["rgb+depth"]) == 2
    assert set(meta["normal_error_on_object_deg"]) == {"3f2n+", "fals"}
    assert fig.stat().st_size > 1000
