"""benchmarks/completion.py (issue 25): the clouds, the Chamfer / F1 scores, and a tiny end-to-end run."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("pybullet_data", reason="the object meshes ship in pybullet (the assets extra)")
pytest.importorskip("trimesh")



@pytest.fixture(scope="module")
def bench(load_benchmark):
    return load_benchmark("completion")


def test_chamfer_matches_cdist_and_scores(bench):
    g = torch.Generator().manual_seed(0)
    p, q = torch.randn(3, 40, 3, generator=g), torch.randn(3, 70, 3, generator=g)
    d = torch.cdist(p, q)
    ref = (d.min(2).values.mean(1) + d.min(1).values.mean(1)) / 2
    assert torch.allclose(bench.chamfer_l1(p, q), ref, atol=1e-5)
    gt = np.random.default_rng(0).normal(size=(2, 300, 3)).astype(np.float32)
    s = bench.completion_scores(gt.copy(), gt, np.ones(2, bool))
    assert s["cd_l1_mm"] == pytest.approx(0, abs=1e-3) and s["f1_5mm"] == 1.0
    shifted = bench.completion_scores(gt + np.float32(10.0), gt, np.ones(2, bool))  # 1 m in x, y, z
    assert shifted["f1_10mm"] < 0.2 and shifted["cd_l1_mm"] > 10


def test_partial_clouds_lie_on_the_truth(bench, tmp_path):
    objs = bench.objs
    v = objs.object_views(4, seed=7, size=48, cache_dir=tmp_path)
    x, gt, ok = bench.clouds(v, {}, ("xyz",), objs.intrinsics(48), n_gt=4000, seed=0)
    assert x["xyz"].shape == (4, 3, bench.N_IN) and gt.shape == (4, 4000, 3) and ok.all()
    # the noisy partial points lie within a few mm of the full surface (units: decimetres)
    d = torch.cdist(torch.from_numpy(x["xyz"].transpose(0, 2, 1)), torch.from_numpy(gt)).min(2).values
    assert float(d.median()) * 100 < 6.0


def test_tiny_run_writes_table_sidecar_and_figure(bench, tmp_path, capsys):
    out, fig = tmp_path / "c.md", tmp_path / "fig" / "c.png"
    argv = ["--train", "16", "--test", "8", "--size", "32", "--epochs", "1", "--seeds", "2",
            "--cache", str(tmp_path / "cache"), "--out", str(out), "--figure", str(fig)]
    assert bench.main(argv) == 0
    assert "| xyz+3f2n+ |" in capsys.readouterr().out
    meta = json.loads(out.with_suffix(".json").read_text())
    assert set(meta["results"]) == {"xyz", "xyz+3f2n+", "xyz+fals"}
    assert set(meta["p_vs_xyz"]) == {"xyz+3f2n+", "xyz+fals"}
    assert fig.stat().st_size > 1000
