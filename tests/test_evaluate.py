"""The evaluation harness: scoring protocol, results equal to normal_metrics, resume, outputs."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import depthnormals as dn
from depthnormals import analytic
from depthnormals._png import read_png
from depthnormals.evaluate import (
    FIELDS,
    HIST_BIN_DEG,
    Protocol,
    discontinuity_mask,
    group_levels_key,
    parse_method_spec,
    pooled_median,
    read_results_csv,
    resolve_methods,
    run_evaluation,
    score_frame,
    scoring_mask,
)
from depthnormals.evaluate._protocol import histogram
from depthnormals.io import write_png

# ---------------------------------------------------------------- a tiny 3F2N-format dataset

K = analytic.DEFAULT_K


def _write_3f2n_scene(folder: Path, renders: list) -> None:
    """Write analytic renders in the 3F2N layout (background depth 1.0, white normals)."""
    (folder / "depth").mkdir(parents=True)
    (folder / "normal").mkdir()
    (folder / "params.txt").write_text(f"{K.fx} {K.fy} {K.cx + 1} {K.cy + 1} {len(renders)}\n")
    for i, r in enumerate(renders, start=1):
        miss = r.depth <= 0
        depth = np.where(miss, 1.0, r.depth).astype("<f4")
        depth.tofile(folder / "depth" / f"{i:06d}.bin")
        n = np.clip(np.round((np.nan_to_num(r.normals) + 1) / 2 * 65535), 0, 65535)
        n = n.astype(np.uint16)
        n[miss] = 65535
        write_png(folder / "normal" / f"{i:06d}.png", n)


def _noisy(render, sigma: float, seed: int):
    rng = np.random.default_rng(seed)
    depth = render.depth * (1 + sigma * rng.standard_normal(render.depth.shape))
    return type(render)(**{**render.__dict__, "depth": np.where(render.depth > 0, depth, 0.0)})


@pytest.fixture(scope="module")
def tiny_3f2n(tmp_path_factory) -> Path:
    """Two 3F2N scenes (groups) with 2 and 1 frames, 480 x 640, from analytic scenes."""
    root = tmp_path_factory.mktemp("tiny3f2n")
    box = analytic.box_on_floor().render()
    sphere = analytic.sphere_before_wall().render()
    _write_3f2n_scene(root / "Easy" / "box", [box, _noisy(box, 2e-3, 1)])
    _write_3f2n_scene(root / "Easy" / "sphere", [sphere])
    return root


def _border_mask(frame, border: int = 1) -> np.ndarray:
    m = frame.mask.copy()
    m[:border] = m[-border:] = False
    m[:, :border] = m[:, -border:] = False
    return m


# ------------------------------------------------------------------------- protocol pieces


def test_score_frame_equals_normal_metrics_and_policies():
    rng = np.random.default_rng(0)
    truth = rng.normal(size=(12, 14, 3))
    truth[..., 2] = -np.abs(truth[..., 2]) - 0.5
    est = truth + 0.3 * rng.normal(size=truth.shape)
    est[2, 3] = -est[2, 3]                      # flipped: 180 - small signed, small folded
    est[5, 5] = np.nan                          # invalid estimates
    est[6, 7] = 0.0
    truth[0, 6] = np.nan                        # invalid ground truth: never scored
    mask = np.ones((12, 14), bool)
    mask[8, 8] = False
    for folded in (True, False):
        p = Protocol(folded=folded, border=1)
        s = score_frame(est, truth, mask=mask, protocol=p)
        ref = dn.normal_metrics(est, truth, mask=scoring_mask(truth, mask, border=1),
                                folded=folded)
        assert s.metrics == ref
        assert s.scored == 10 * 12 - 1 and s.covered == s.scored - 2
        assert s.metrics.count == s.covered
    signed = score_frame(est, truth, protocol=Protocol(folded=False, border=0))
    folded = score_frame(est, truth, protocol=Protocol(folded=True, border=0))
    assert signed.error[2, 3] > 150 and folded.error[2, 3] < 30
    assert signed.error[2, 3] + folded.error[2, 3] == pytest.approx(180.0)
    # score90: the two invalid estimates count as 90 degrees, coverage still reported
    drop = score_frame(est, truth, mask=mask, protocol=Protocol(border=1))
    s90 = score_frame(est, truth, mask=mask, protocol=Protocol(border=1, invalid="score90"))
    n = drop.scored
    assert s90.metrics.count == n and drop.metrics.count == n - 2
    assert s90.metrics.mean == pytest.approx((drop.metrics.mean * (n - 2) + 180.0) / n)
    assert s90.metrics.coverage == drop.metrics.coverage == pytest.approx((n - 2) / n)


def test_border_and_mask():
    truth = np.zeros((10, 9, 3))
    truth[..., 2] = -1
    assert scoring_mask(truth, None, border=0).sum() == 90
    assert scoring_mask(truth, None, border=2).sum() == 6 * 5
    with pytest.raises(ValueError, match="mask has shape"):
        scoring_mask(truth, np.ones((9, 9), bool), border=0)
    with pytest.raises(TypeError, match="boolean"):
        scoring_mask(truth, np.ones((10, 9)), border=0)


def test_discontinuity_mask_depth_crease_silhouette():
    h, w = 7, 12
    n = np.zeros((h, w, 3))
    n[..., 2] = -1
    z = np.full((h, w), 2.0)
    valid = np.ones((h, w), bool)
    kw = {"radius": 2, "edge_angle": 10.0, "depth_jump": 0.05}
    assert not discontinuity_mask(n, z, valid, **kw).any()
    # an occlusion between columns 5 and 6: edge pixels 5, 6, dilated by 2 -> 3..8
    z2 = z.copy()
    z2[:, 6:] = 2.5
    cols = np.flatnonzero(discontinuity_mask(n, z2, valid, **kw)[3])
    assert cols.tolist() == [3, 4, 5, 6, 7, 8]
    # a 4 % jump is below the 5 % threshold
    z3 = z.copy()
    z3[:, 6:] = 2.08
    assert not discontinuity_mask(n, z3, valid, **kw).any()
    # a 30-degree crease between rows 2 and 3, radius 1 -> rows 1..4
    n2 = n.copy()
    n2[3:] = [0.0, np.sin(np.radians(30)), -np.cos(np.radians(30))]
    rows = np.flatnonzero(discontinuity_mask(n2, z, valid, radius=1)[:, 4])
    assert rows.tolist() == [1, 2, 3, 4]
    # a flipped (sign-ambiguous) normal is not a crease
    n3 = n.copy()
    n3[:, 6:] *= -1
    assert not discontinuity_mask(n3, z, valid, **kw).any()
    # the silhouette against invalid pixels; invalid pixels are never "near"
    v2 = valid.copy()
    v2[:, :2] = False
    near = discontinuity_mask(n, z, v2, radius=1)
    assert np.flatnonzero(near[3]).tolist() == [2, 3]
    with pytest.raises(TypeError, match="boolean"):
        discontinuity_mask(n, z, valid.astype(int))
    with pytest.raises(ValueError, match="edge_angle"):
        discontinuity_mask(n, z, valid, edge_angle=95.0)


def test_near_and_smooth_means():
    truth = np.zeros((8, 10, 3))
    truth[..., 2] = -1
    est = truth.copy()
    est[:, 5:] = [0.0, np.sin(np.radians(4)), -np.cos(np.radians(4))]
    near = np.zeros((8, 10), bool)
    near[:, 4:7] = True
    s = score_frame(est, truth, near=near, protocol=Protocol(border=0))
    assert s.near_count == 24 and s.smooth_count == 56
    assert s.near_mean == pytest.approx(4.0 * 2 / 3)
    assert s.smooth_mean == pytest.approx(4.0 * 24 / 56)


def test_pooled_median_from_histogram():
    e = np.random.default_rng(3).gamma(2.0, 3.0, size=10001)
    assert abs(pooled_median(histogram(e)) - np.median(e)) <= HIST_BIN_DEG
    assert np.isnan(pooled_median(np.zeros(18000, np.int64)))


@pytest.mark.parametrize(("kwargs", "exc", "match"), [
    ({"invalid": "ignore"}, ValueError, "invalid policy"),
    ({"border": -1}, ValueError, "border"),
    ({"border": 1.5}, TypeError, "border"),
    ({"folded": "yes"}, TypeError, "folded"),
    ({"edge_angle": 0}, ValueError, "edge_angle"),
])
def test_protocol_rejects_bad_options(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        Protocol(**kwargs)


def test_method_specs():
    spec = parse_method_spec("3f2n[aggregate=mean, kernel_size=5]")
    assert (spec.label, spec.method, spec.options) == (
        "3f2n[aggregate=mean,kernel_size=5]", "3f2n", {"aggregate": "mean", "kernel_size": 5})
    specs = resolve_methods("3f2n,3f2n[aggregate=mean],d2nt",
                            {"3f2n": {"kernel": "sobel"}, "d2nt": {"variant": "basic"}})
    assert [s.options for s in specs] == [
        {"kernel": "sobel"}, {"kernel": "sobel", "aggregate": "mean"}, {"variant": "basic"}]
    with pytest.raises(ValueError, match=r"valid methods: .*3f2n"):
        resolve_methods("nope")
    with pytest.raises(ValueError, match="twice"):
        resolve_methods(["d2nt", "d2nt"])
    with pytest.raises(ValueError, match="unbalanced"):
        resolve_methods("3f2n[aggregate=mean")
    with pytest.raises(ValueError, match="not among the methods"):
        resolve_methods("d2nt", {"3f2n": {"kernel": "fd"}})
    with pytest.raises(TypeError, match="JSON"):
        resolve_methods("d2nt", {"d2nt": {"variant": object()}})


# ----------------------------------------------------------------------- run_evaluation


def test_run_equals_normal_metrics_on_3f2n_folder(tiny_3f2n, tmp_path):
    res = run_evaluation(tiny_3f2n, "3f2n,d2nt[variant=dag]", tmp_path / "out", figures=0)
    frames = list(dn.datasets.open(tiny_3f2n))
    assert [(f.group, f.name) for f in frames] == [
        ("Easy/box", "000001"), ("Easy/box", "000002"), ("Easy/sphere", "000001")]
    rows = read_results_csv(tmp_path / "out" / "results.csv")
    assert len(rows) == 6 and list(rows[0]) == list(FIELDS)
    by = {(r["group"], r["frame"], r["method"]): r for r in rows}
    pooled: dict[str, list] = {"3f2n": [], "d2nt[variant=dag]": []}
    for f in frames:
        for label, method, opts in (("3f2n", "3f2n", {}),
                                    ("d2nt[variant=dag]", "d2nt", {"variant": "dag"})):
            est = dn.estimate_normals(f.depth, f.K, method=method, **opts)
            ref = dn.normal_metrics(est, f.normals, mask=_border_mask(f), folded=True)
            row = by[(f.group, f.name, label)]
            for col, val in (("mean_deg", ref.mean), ("median_deg", ref.median),
                             ("rmse_deg", ref.rmse), ("a5", ref.a5), ("a11_25", ref.a11_25),
                             ("a22_5", ref.a22_5), ("a30", ref.a30),
                             ("coverage", ref.coverage), ("count", ref.count)):
                assert row[col] == val, (f.group, f.name, label, col)
            err = dn.angular_error(est, f.normals, folded=True)[_border_mask(f)]
            pooled[label].append(err[np.isfinite(err)])
    s = res.summary["groups"]
    box = [by[("Easy/box", n, "3f2n")]["mean_deg"] for n in ("000001", "000002")]
    assert s["Easy/box"]["3f2n"]["e_A"] == pytest.approx(np.mean(box), rel=1e-12)
    assert s["Easy/box"]["3f2n"]["frames"] == 2
    # the noisy box frame is worse than the clean one: the numbers are not all alike
    assert box[1] > box[0] + 1.0
    for label, errs in pooled.items():
        e = np.concatenate(errs)
        assert s["(all)"][label]["mean"] == pytest.approx(e.mean(), rel=1e-12)
        assert s["(all)"][label]["rmse"] == pytest.approx(np.sqrt(np.mean(e * e)), rel=1e-12)
        assert s["(all)"][label]["a11_25"] == pytest.approx(np.mean(e < 11.25), rel=1e-12)
        assert abs(s["(all)"][label]["median"] - np.median(e)) <= HIST_BIN_DEG
        assert s["(all)"][label]["near_mean"] > s["(all)"][label]["smooth_mean"]
    assert (tmp_path / "out" / "summary.md").read_text().count("| 3f2n |") == 4
    settings = json.loads((tmp_path / "out" / "settings.json").read_text())
    assert settings["completed"] is True and settings["version"] == dn.__version__
    assert settings["methods"][1] == {"label": "d2nt[variant=dag]", "method": "d2nt",
                                      "options": {"variant": "dag"}}
    assert settings["protocol"]["folded"] is True and settings["protocol"]["border"] == 1
    assert settings["counts"] == {"frames": 3, "rows": 6, "computed": 6, "reused": 0}


def test_torusknot_reference_values(shared_data, tmp_path):
    folder = shared_data / "3f2n-torusknot"
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent")
    res = run_evaluation(folder, ["3f2n", "d2nt"], tmp_path, figures=0)
    means = {r["method"]: r["mean_deg"] for r in res.rows}
    assert round(means["3f2n"], 4) == 2.8424
    assert round(means["d2nt"], 4) == 1.4609
    assert res.summary["groups"]["3f2n-torusknot"]["d2nt"]["e_A"] == means["d2nt"]


def test_signed_border_score90_reach_the_rows(tiny_3f2n, tmp_path):
    base = run_evaluation(tiny_3f2n, "3f2n", tmp_path / "a", figures=0, frames=1)
    other = run_evaluation(tiny_3f2n, "3f2n", tmp_path / "a", figures=0, frames=1,
                           protocol=Protocol(border=5, folded=False, invalid="score90"))
    assert other.reused == 0 and other.computed == 1   # a new protocol is not reused
    assert other.rows[0]["scored"] < base.rows[0]["scored"]
    assert other.rows[0]["count"] == other.rows[0]["scored"]
    assert other.settings["protocol"]["border"] == 5
    # the protocol options moved into Protocol: the old keywords say so
    with pytest.raises(TypeError, match=r"protocol=Protocol\(border=5, folded=False\)"):
        run_evaluation(tiny_3f2n, "3f2n", tmp_path / "b", border=5, folded=False)
    with pytest.raises(TypeError, match="unexpected keyword"):
        run_evaluation(tiny_3f2n, "3f2n", tmp_path / "b", figurs=0)
    assert not (tmp_path / "b").exists()


def test_threads_drive_the_estimators_and_are_recorded(tiny_3f2n, tmp_path, monkeypatch):
    """threads= sets the row-band pool the estimators use (not only numba's), records it in
    settings.json and restores the previous count afterwards."""
    import depthnormals.registry as registry

    before = dn.get_num_threads()
    want = 1 if before != 1 else 2
    real = registry.estimate_normals
    seen: list[int] = []

    def spy(*args, **kwargs):
        seen.append(dn.get_num_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(registry, "estimate_normals", spy)
    res = run_evaluation(tiny_3f2n, "3f2n", tmp_path, figures=0, frames=1, threads=want)
    assert seen and set(seen) == {want}
    assert res.settings["timing"]["threads"] == want
    saved = json.loads((tmp_path / "settings.json").read_text())
    assert saved["timing"]["threads"] == want
    assert dn.get_num_threads() == before          # restored after the run
    seen.clear()
    res = run_evaluation(tiny_3f2n, "3f2n", tmp_path / "default", figures=0, frames=1)
    assert set(seen) == {before} and res.settings["timing"]["threads"] == before
    with pytest.raises(ValueError, match="threads must be"):
        run_evaluation(tiny_3f2n, "3f2n", tmp_path / "c", figures=0, threads=0)


def test_resume_after_injected_interruption(tiny_3f2n, tmp_path, monkeypatch):
    methods = "3f2n,d2nt"
    clean = run_evaluation(tiny_3f2n, methods, tmp_path / "clean", figures=0)
    import depthnormals.registry as registry

    real = registry.estimate_normals
    calls = {"n": 0}

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] > 5:          # 2 warm-ups + 3 frames' worth of estimates, then "kill"
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(registry, "estimate_normals", flaky)
    with pytest.raises(KeyboardInterrupt):
        run_evaluation(tiny_3f2n, methods, tmp_path / "resumed", figures=0)
    kept = read_results_csv(tmp_path / "resumed" / "results.csv")
    assert len(kept) == 3      # what finished was kept
    monkeypatch.setattr(registry, "estimate_normals", real)
    resumed = run_evaluation(tiny_3f2n, methods, tmp_path / "resumed", figures=0)
    assert (resumed.reused, resumed.computed) == (3, 3)
    assert _without_ms(tmp_path / "resumed") == _without_ms(tmp_path / "clean")
    for g, per in clean.summary["groups"].items():
        for label, s in per.items():
            t = resumed.summary["groups"][g][label]
            assert {k: v for k, v in s.items() if not k.startswith("ms")} == \
                   {k: v for k, v in t.items() if not k.startswith("ms")}


def _without_ms(out: Path) -> list[list[str]]:
    lines = (out / "results.csv").read_text().splitlines()
    idx = lines[0].split(",").index("ms")
    return [[c for i, c in enumerate(line.split(",")) if i != idx] for line in lines]


_SLOW_RUN = """
import sys, time
import depthnormals.registry as registry
real = registry.estimate_normals
def slow(*a, **k):
    out = real(*a, **k)
    if a[0].shape[0] > 100:
        time.sleep(0.4)
    return out
registry.estimate_normals = slow
from depthnormals.evaluate import run_evaluation
run_evaluation(sys.argv[1], "3f2n,d2nt", sys.argv[2], figures=0)
"""


def test_resume_after_kill(tiny_3f2n, tmp_path):
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-c", _SLOW_RUN, str(tiny_3f2n), str(out)])
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:
            if len(list((out / "parts").glob("*/*.npz"))) >= 2:
                break
            assert proc.poll() is None, "the run ended before it could be killed"
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    done = len(list((out / "parts").glob("*/*.npz")))
    assert 2 <= done < 6
    resumed = run_evaluation(tiny_3f2n, "3f2n,d2nt", out, figures=0)
    assert resumed.reused == done and resumed.computed == 6 - done
    clean = run_evaluation(tiny_3f2n, "3f2n,d2nt", tmp_path / "clean", figures=0)
    assert clean.computed == 6
    assert _without_ms(out) == _without_ms(tmp_path / "clean")


def test_figures_written(tiny_3f2n, tmp_path):
    pytest.importorskip("matplotlib")
    res = run_evaluation(tiny_3f2n, "3f2n,d2nt", tmp_path, figures=1, frames=2)
    names = sorted(p.name for p in res.figures)
    assert names == ["fig3-Easy-box-000001.png", "threshold-curves.png"]
    img = read_png(tmp_path / "figures" / "fig3-Easy-box-000001.png")
    assert img.ndim == 3 and img.shape[1] > 3 * img.shape[0]     # one row of 5 panels
    assert img.std() > 10                                         # not a blank picture
    curves = res.summary["curves"]
    share = np.array(curves["Easy/box"]["d2nt"])
    assert share[0] == 0.0 and np.all(np.diff(share) >= 0) and share[-1] <= 1.0
    t = np.array(curves["thresholds"])
    row = res.summary["groups"]["Easy/box"]["d2nt"]
    assert share[t == 11.25][0] == pytest.approx(row["a11_25"], abs=1e-3)


def test_frames_iterable_and_bad_input(tiny_3f2n, tmp_path):
    frames = list(dn.datasets.open(tiny_3f2n))[:1]
    with pytest.raises(ValueError, match="dataset_name"):
        run_evaluation(frames, "3f2n", tmp_path, figures=0)
    res = run_evaluation(frames, "3f2n", tmp_path, figures=0, dataset_name="mine")
    assert len(res.rows) == 1
    with pytest.raises(ValueError, match="twice"):
        run_evaluation(frames * 2, "3f2n", tmp_path / "b", figures=0, dataset_name="dup")
    with pytest.raises(ValueError, match="frames must be"):
        run_evaluation(tiny_3f2n, "3f2n", tmp_path, frames=0)
    with pytest.raises(ValueError, match="figure_method"):
        run_evaluation(tiny_3f2n, "3f2n", tmp_path, figure_method="d2nt")
    with pytest.raises(TypeError, match="unknown option"):
        run_evaluation(tiny_3f2n, "3f2n[colour=red]", tmp_path / "c", figures=0)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        run_evaluation(tmp_path / "missing", "3f2n", tmp_path / "d", figures=0)
    assert not (tmp_path / "d").exists()     # nothing written for a missing dataset
    with pytest.raises(ValueError, match="error_vmax must be finite and > 0"):
        run_evaluation(tiny_3f2n, "3f2n", tmp_path / "e", error_vmax=0)
    assert not (tmp_path / "e").exists()


def test_a_border_that_leaves_no_pixel_is_refused(tiny_3f2n, tmp_path):
    """Before: every pixel left out, the run "succeeded" with a table of "-"."""
    h, w = next(iter(dn.datasets.open(tiny_3f2n))).depth.shape
    with pytest.raises(ValueError, match=f"leaves no pixel of a {w}x{h} image"):
        run_evaluation(tiny_3f2n, "3f2n", tmp_path, figures=0, protocol=Protocol(border=min(h, w) // 2))
    res = run_evaluation(tiny_3f2n, "3f2n", tmp_path / "b", figures=0,
                         protocol=Protocol(border=(min(h, w) - 1) // 2))
    assert all(r["scored"] > 0 for r in res.rows)


def test_import_stays_light():
    code = ("import sys, depthnormals, depthnormals.evaluate; "
            "bad = [m for m in ('matplotlib', 'cv2', 'torch') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_group_levels_pool_groups(tiny_3f2n, tmp_path):
    res = run_evaluation(tiny_3f2n, "d2nt", tmp_path, figures=0, group_levels=[0])
    assert list(res.summary["groups"]) == ["Easy"]
    s = res.summary["groups"]["Easy"]["d2nt"]
    assert s["frames"] == 3
    assert s["e_A"] == pytest.approx(np.mean([r["mean_deg"] for r in res.rows]), rel=1e-12)
    assert [r["group"] for r in res.rows] == ["Easy/box", "Easy/box", "Easy/sphere"]


@pytest.mark.parametrize("levels", [[2], [0, 2], [-3]])
def test_group_levels_outside_the_names_are_refused(tiny_3f2n, tmp_path, levels):
    """The group names here have two components: a third level was dropped silently, and a
    name with no level left summarised apart, so [2] gave the unpooled table."""
    with pytest.raises(ValueError, match=r"name no component of the group 'Easy/.*levels 0\.\.1"):
        run_evaluation(tiny_3f2n, "d2nt", tmp_path, figures=0, group_levels=levels)
    assert not (tmp_path / "summary.json").exists()
    assert group_levels_key([-1])("Easy/box") == "box"
    with pytest.raises(ValueError, match="name no component"):
        group_levels_key([1])("Easy")


def test_generated_benchmark_equals_normal_metrics(tmp_path):
    synth = pytest.importorskip("depthnormals.synth")
    from depthnormals import cli

    if "synth" not in cli.COMMANDS or not hasattr(synth, "generate"):
        pytest.skip("the synthetic benchmark generator is not there yet")
    root = tmp_path / "bench"
    synth.generate(root, indoor=1, outdoor=1, views=1, seed=0, size=(60, 80),
                   noise=("gaussian:sigma_px=0.1",), K=dn.Intrinsics(57.1, 57.1, 39.5, 29.5),
                   progress=False)
    try:
        frames = list(dn.datasets.open(root))
    except ValueError:
        pytest.skip("datasets.open does not read the synthetic format yet")
    assert len(frames) == 4
    res = run_evaluation(root, "3f2n,d2nt", tmp_path / "out", figures=0, group_levels=[0, 2])
    by = {(r["group"], r["frame"], r["method"]): r for r in res.rows}
    for f in frames:
        for method in ("3f2n", "d2nt"):
            est = dn.estimate_normals(f.depth, f.K, method=method)
            ref = dn.normal_metrics(est, f.normals, mask=_border_mask(f), folded=True)
            row = by[(f.group, f.name, method)]
            assert (row["mean_deg"], row["median_deg"], row["a11_25"], row["coverage"],
                    row["count"]) == (ref.mean, ref.median, ref.a11_25, ref.coverage, ref.count)
    groups = res.summary["groups"]
    assert set(groups) == {"indoor/clean", "indoor/gaussian", "outdoor/clean",
                           "outdoor/gaussian", "(all)"}
    key = next(k for k in by if k[0].startswith("outdoor") and k[0].endswith("gaussian")
               and k[2] == "d2nt")
    assert groups["outdoor/gaussian"]["d2nt"]["e_A"] == by[key]["mean_deg"]


@pytest.mark.parametrize("terminal, with_tqdm", [(True, True), (False, True), (True, False)])
def test_progress_bar_or_plain_lines(tiny_3f2n, tmp_path, monkeypatch, capsys, terminal,
                                     with_tqdm):
    """A tqdm bar on a terminal; one plain line per frame in a pipe or log (or without tqdm)."""
    if with_tqdm:
        pytest.importorskip("tqdm")
    else:
        monkeypatch.setitem(sys.modules, "tqdm", None)     # import tqdm -> ImportError
    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal, raising=False)
    run_evaluation(tiny_3f2n, "d2nt", tmp_path, figures=0, frames=2, progress=True)
    err = capsys.readouterr().err
    if terminal and with_tqdm:
        assert "evaluate" in err and "2/2" in err and "\r" in err
    else:
        assert err.splitlines() == [
            "evaluate: frame 1 Easy/box/000001 (1 computed, 0 reused)",
            "evaluate: frame 2 Easy/box/000002 (2 computed, 0 reused)"]
