"""benchmarks/thin_faces.py: each method's error on the faces narrower than about 5 px and on
the rest, over the pixels every method covers (docs/benchmarks.md section 30)."""

from __future__ import annotations

import json
import types

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import make_scene


@pytest.fixture(scope="module")
def stairs():
    r = make_scene("stairs").render()  # five risers a few pixels tall
    return types.SimpleNamespace(depth=r.depth.astype(np.float32), K=r.K, normals=r.normals,
                                 mask=None, meta={}, group="indoor/stairs/clean", name="0000")


def test_thin_table_scores_the_thin_part_on_the_pixels_every_method_covers(load_benchmark, stairs):
    """On the exact stairs the default's normals are exact on the risers as elsewhere (0.010
    deg on the thin part, 0.0005 on the rest), FALS's 7x7 window 36.0 and 1.5 deg off; with
    PCL's covariance estimator added both parts shrink to the pixels PCL covers (it abstains by
    the jumps, most of the thin part: 2,195 of 4,626 pixels), where FALS reads 26.5 and PCL
    20.9 deg on the thin part."""
    bench = load_benchmark("thin_faces")
    calib = load_benchmark("uncertainty_calibration")
    thin = calib.thin_labels(stairs.normals)
    two = bench.thin_table([stairs], ["3f2n+", "fals"])["clean"]
    t, r = two["thin"].means(), two["resolved"].means()
    assert t["pixels"] == int(thin.sum()) > 4000
    assert t["pixels"] + r["pixels"] == int(np.isfinite(stairs.depth).sum())
    assert t["error"]["3f2n+"] < 0.05 and r["error"]["3f2n+"] < 0.01
    assert 30.0 < t["error"]["fals"] < 42.0 and 1.0 < r["error"]["fals"] < 2.0
    assert 0.0 < t["predicted"] < 0.05  # the default's map on exact depth: float rounding
    three = bench.thin_table([stairs], ["3f2n+", "fals", "pcl-covariance-matrix"])["clean"]
    pcl = np.isfinite(dn.estimate_normals(stairs.depth, stairs.K, method="pcl-covariance-matrix")).all(-1)
    assert three["thin"].pixels == int((thin & pcl).sum()) < t["pixels"] // 2 + 500
    assert three["resolved"].pixels == int((~thin & pcl).sum())
    e = three["thin"].means()["error"]
    assert e["3f2n+"] < 0.01 and 20.0 < e["fals"] < 32.0 and 15.0 < e["pcl-covariance-matrix"] < 26.0


def test_every_must_be_positive(load_benchmark, tmp_path):
    with pytest.raises(SystemExit):
        load_benchmark("thin_faces").main([str(tmp_path), "--every", "0"])


def test_main_scores_every_kth_view_and_writes_the_table(tmp_path, load_benchmark, capsys):
    """The script on a small generated set (one room, two views, clean and kinect_v1):
    ``--every 2`` scores the first view's variants only, the JSON holds the table
    :func:`thin_table` gives on those frames, and both columns are printed."""
    from depthnormals.camera import Intrinsics
    from depthnormals.datasets.synthetic import read_synthetic
    from depthnormals.synth import generate

    data = tmp_path / "set"
    generate(data, indoor=1, outdoor=0, views=2, seed=3, K=Intrinsics(91.375, 91.375, 63.5, 52.5),
             size=(106, 128), progress=False, noise=("kinect_v1",))
    bench = load_benchmark("thin_faces")
    out = tmp_path / "thin.json"
    assert bench.main([str(data), "--methods", "fals", "--every", "2", "--json", str(out)]) == 0
    got = json.loads(out.read_text())
    assert got["methods"] == ["3f2n+", "fals"] and got["every"] == 2
    first = [f for f in read_synthetic(data) if f.name == "0000"]
    assert {f.group.rsplit("/", 1)[-1] for f in first} == {"clean", "kinect_v1"}
    want = bench.thin_table(first, ["3f2n+", "fals"])
    for v in ("clean", "kinect_v1"):
        for part in ("thin", "resolved"):
            assert got["columns"][v][part] == want[v][part].means()  # JSON keeps floats exact
    assert got["columns"]["kinect_v1"]["resolved"]["pixels"] > 5000
    printed = capsys.readouterr().out
    assert "clean: thin part" in printed and "kinect_v1: thin part" in printed
