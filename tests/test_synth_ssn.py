"""``synth --preset ssn`` and the compact storage (format version 2): the preset's plan, the
codec's error bounds, both layouts read alike, resume after an interruption, Dask = serial."""

from __future__ import annotations

import hashlib
import json
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

from depthnormals._compact import decode_normals, encode_normals, read_view, view_bytes
from depthnormals.camera import Intrinsics
from depthnormals.cli import main
from depthnormals.datasets import read_synthetic
from depthnormals.evaluate import read_results_csv
from depthnormals.synth import MODELS, SSN_NOISE_MODELS, export_3f2n, generate, preset, scene_plan
from depthnormals.synth import views as _views

SMALL_K = Intrinsics(27.0, 27.0, 23.5, 17.5)
SMALL = (36, 48)
KW = {"indoor": 1, "outdoor": 1, "views": 3, "seed": 5, "K": SMALL_K, "size": SMALL,
      "noise": ("kinect_v2", "gaussian"), "progress": False}


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a, b = a.astype(np.float64), b.astype(np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("...i,...i->...", a, b)))


def _tree(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


# -- the preset ---------------------------------------------------------------------------


def test_preset_ssn_expands_to_10000_views(capsys):
    p = preset("ssn")
    assert (p["indoor"], p["outdoor"], p["views"], p["size"], p["storage"]) == (10, 10, 500, (424, 512),
                                                                                 "compact")
    assert p["noise"] == SSN_NOISE_MODELS and set(SSN_NOISE_MODELS) <= set(MODELS)
    plan = scene_plan(p["indoor"], p["outdoor"])
    assert len(plan) * p["views"] == 10_000
    indoor = [f for k, _, f in plan if k == "indoor"]
    outdoor = [f for k, _, f in plan if k == "outdoor"]
    # ten different recipes of each kind, no folder twice
    assert len({f.rsplit("-", 1)[0] for f in indoor}) == 10 == len({f.rsplit("-", 1)[0] for f in outdoor})
    assert len({f for _, _, f in plan}) == 20
    n_var = 1 + len(SSN_NOISE_MODELS)
    assert main(["synth", "unused", "--preset", "ssn", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert (f"20 scenes (10 indoor, 10 outdoor) x 500 views = 10000 views, 512 x 424; variants clean, "
            f"{', '.join(SSN_NOISE_MODELS)} ({10000 * n_var} frames); storage compact") in out
    assert not Path("unused").exists()
    with pytest.raises(ValueError, match="unknown synth preset 'ssm'; valid: ssn"):
        preset("ssm")


def test_explicit_options_override_the_preset(capsys):
    assert main(["synth", "x", "--preset", "ssn", "--views", "2", "--outdoor", "0", "--noise", "gaussian",
                 "--storage", "npy", "--width", "64", "--height", "48", "--dry-run"]) == 0
    assert ("10 scenes (10 indoor, 0 outdoor) x 2 views = 20 views, 64 x 48; variants clean, gaussian "
            "(40 frames); storage npy") in capsys.readouterr().out
    assert main(["synth", "x", "--dry-run"]) == 0  # no preset: the old defaults
    assert ("20 scenes (10 indoor, 10 outdoor) x 25 views = 500 views, 512 x 424; variants clean, "
            "kinect_v2 (1000 frames); storage npy") in capsys.readouterr().out


# -- the codec ---------------------------------------------------------------------------


def test_octahedral_normals_max_error():
    rng = np.random.default_rng(7)
    n = rng.standard_normal((400_000, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    special = np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [1, 1, 1],
                        [-1, 1, -1], [1e-12, -1e-12, -1], [1, -1, 1e-9], [1, 1, -1e-9]], dtype=np.float64)
    n = np.concatenate([n, special / np.linalg.norm(special, axis=-1, keepdims=True)])
    codes = encode_normals(n)
    assert codes.dtype == np.uint16 and codes.shape == (n.shape[0], 2)
    back = decode_normals(codes[None], np.ones((1, n.shape[0]), bool))[0]
    assert back.dtype == np.float32
    err = _angles(n, back)
    assert err.max() < 0.003  # 0.0025 deg measured (float32 output included)
    assert 0.0008 < np.median(err) < 0.0016  # a 16-bit grid: the error is not zero either
    assert np.allclose(np.linalg.norm(back.astype(np.float64), axis=-1), 1.0, atol=1e-6)
    # float32 input codes as its float64 value; no surface -> (0, 0) -> NaN where invalid
    n32 = n.astype(np.float32)
    assert np.array_equal(encode_normals(n32), encode_normals(n32.astype(np.float64)))
    bad = np.array([[np.nan, 0, 1], [0, 0, 0], [np.inf, 0, 0]])
    assert np.array_equal(encode_normals(bad), np.zeros((3, 2), np.uint16))
    assert np.isnan(decode_normals(encode_normals(bad)[None], np.zeros((1, 3), bool))).all()
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        encode_normals(np.zeros((4, 2)))


def _depths(rng):
    h, w = 30, 41
    v, u = np.mgrid[0:h, 0:w]
    clean = (2.0 / (1.0 + 0.01 * u - 0.02 * v)).astype(np.float32)
    clean[3:9, 4:20] = 0.0
    mm = (np.rint((clean + rng.normal(0, 0.002, clean.shape)) / 0.001) * 0.001).astype(np.float32)
    mm[clean == 0] = 0.0
    odd = rng.normal(3.0, 1.0, (h, w)).astype(np.float32)
    odd.flat[:6] = [0.0, -1.5, np.nan, np.inf, -np.inf, 1e-30]  # every float32 survives, bit for bit
    big = (np.rint(rng.uniform(60.0, 80.0, (h, w)) / 0.001) * 0.001).astype(np.float32)  # beyond uint16 mm
    return {"clean": clean, "kv": mm, "odd": odd, "far": big}


def test_depth_codec_bit_identical_and_integers_where_exact(tmp_path):
    rng = np.random.default_rng(3)
    d = _depths(rng)
    normals = np.broadcast_to(np.array([0.0, 0.6, -0.8]), (*d["clean"].shape, 3)).copy()
    valid = d["clean"] > 0
    normals[~valid] = np.nan
    steps = {"kv": 0.001, "odd": 0.001, "far": 0.001}
    data = view_bytes(normals, valid, d, steps=steps)
    assert data == view_bytes(normals, valid, d, steps=steps)  # deterministic
    (tmp_path / "v.npz").write_bytes(data)
    n2, v2, got = read_view(tmp_path / "v.npz", list(d))
    for name, z in d.items():
        assert got[name].dtype == np.float32 and got[name].tobytes() == z.tobytes(), name
    assert np.array_equal(v2, valid) and np.isnan(n2[~valid]).all()
    assert _angles(n2[valid], normals[valid]).max() < 0.003
    codec = json.loads(zipfile.ZipFile(tmp_path / "v.npz").read("codec.json"))["members"]
    assert codec["kv"] == {"codec": "int", "dtype": "uint16", "predictor": "row", "step": 0.001}
    assert codec["odd"]["codec"] == "f32" and codec["far"]["codec"] == "f32"  # not exact / > 65.535 m
    assert codec["clean"] == {"codec": "f32", "dtype": "uint32", "predictor": "grad"}
    # a timestamp-free zip: np.load opens it, and the members are named by plane
    names = set(np.load(tmp_path / "v.npz").files)
    assert {"normals", "valid", "kv.0", "kv.1", "clean.3"} <= names and "kv.2" not in names
    with pytest.raises(ValueError, match="holds no 'nope'"):
        read_view(tmp_path / "v.npz", ["nope"])


# -- generation in both layouts ---------------------------------------------------------------


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    base = tmp_path_factory.mktemp("both")
    generate(base / "npy", **KW)
    generate(base / "compact", storage="compact", **KW)
    return base


def test_reader_reads_both_layouts_alike(both):
    meta = json.loads((both / "compact" / "dataset.json").read_text())
    assert meta["format_version"] == 2
    assert json.loads((both / "npy" / "dataset.json").read_text())["format_version"] == 1
    assert sorted(p.name for p in (both / "compact" / "indoor" / "living_room-00").iterdir()) == \
        ["scene.json", "views"]
    a, b = list(read_synthetic(both / "npy")), list(read_synthetic(both / "compact"))
    assert len(a) == 2 * 3 * 3 and [(f.group, f.name) for f in a] == [(f.group, f.name) for f in b]
    for x, y in zip(a, b, strict=True):
        assert x.depth.tobytes() == y.depth.tobytes() and np.array_equal(x.mask, y.mask)
        assert np.isnan(y.normals[~y.mask]).all()
        assert _angles(x.normals[x.mask], y.normals[y.mask]).max() < 0.003
        assert x.meta["variant"] == y.meta["variant"] and np.array_equal(x.meta["pose"], y.meta["pose"])
    one = list(read_synthetic(both / "compact" / "outdoor" / "street-00", variants=["kinect_v2"]))
    assert [f.group for f in one] == ["outdoor/street-00/kinect_v2"] * 3
    # kinect_v2 rounds to 1 mm: stored as integers
    codec = json.loads(zipfile.ZipFile(both / "compact" / "indoor" / "living_room-00" / "views" /
                                       "0000.npz").read("codec.json"))
    assert codec["members"]["kinect_v2"]["codec"] == "int"
    # smaller on disk
    size = {k: sum(p.stat().st_size for p in (both / k).rglob("*") if p.is_file())
            for k in ("npy", "compact")}
    assert size["compact"] < 0.35 * size["npy"]


def test_export_and_evaluate_from_compact(both, tmp_path, capsys):
    ea = export_3f2n(both / "npy", tmp_path / "a")
    eb = export_3f2n(both / "compact", tmp_path / "b")
    assert [p.relative_to(tmp_path / "a") for p in ea] == [p.relative_to(tmp_path / "b") for p in eb]
    ta, tb = _tree(tmp_path / "a"), _tree(tmp_path / "b")
    assert ta.keys() == tb.keys() and len(ta) == 2 * (1 + 2 * 3)
    assert all(ta[k] == tb[k] for k in ta if "/depth/" in k or k.endswith("params.txt"))
    means = {}
    for k in ("npy", "compact"):
        assert main(["evaluate", str(both / k), "-m", "3f2n", "--figures", "0", "-q",
                     "-o", str(tmp_path / f"ev-{k}")]) == 0
        means[k] = [r["mean_deg"] for r in read_results_csv(tmp_path / f"ev-{k}" / "results.csv")]
    capsys.readouterr()
    assert len(means["npy"]) == len(means["compact"]) == 18  # a row per frame: 2 scenes x 3 views x 3
    assert np.allclose(means["npy"], means["compact"], atol=0.003)


def test_other_storage_is_refused(both):
    with pytest.raises(ValueError, match="other settings"):
        generate(both / "compact", **KW)  # storage npy into a compact dataset
    with pytest.raises(ValueError, match="storage must be one of npy, compact; got 'zip'"):
        generate(both / "new", storage="zip", **KW)


def test_unknown_version_refused(tmp_path):
    generate(tmp_path / "d", storage="compact", **{**KW, "outdoor": 0, "views": 1})
    meta = json.loads((tmp_path / "d" / "dataset.json").read_text())
    (tmp_path / "d" / "dataset.json").write_text(json.dumps({**meta, "format_version": 9}))
    with pytest.raises(ValueError, match="format version 9; this depthnormals reads versions 1, 2"):
        list(read_synthetic(tmp_path / "d"))


@pytest.mark.parametrize("layout", ["npy", "compact"])
def test_a_truncated_view_file_is_named(both, tmp_path, layout):
    """A view file cut short (a copy interrupted, a full disk) stops the reader with an error
    naming the file; the npy layout raised numpy's bare "EOF: reading array header" before
    (found by `depthnormals evaluate` on such a copy, session 34)."""
    import shutil

    root = tmp_path / layout
    shutil.copytree(both / layout, root)
    scene = root / "indoor" / "living_room-00"
    victim = scene / ("views/0001.npz" if layout == "compact" else "kinect_v2/0001.npy")
    victim.write_bytes(victim.read_bytes()[:100])
    with pytest.raises(ValueError, match=f"{re.escape(str(victim))} is not a readable"):
        list(read_synthetic(root))


# -- resume, Dask ---------------------------------------------------------------------------


def test_interrupted_run_resumes_to_the_same_bytes(both, tmp_path, monkeypatch):
    """A run killed while writing view 1 of the second scene: no view file under its final
    name is partial (only a hidden temporary, as a SIGKILL would leave); the rerun removes the
    temporary, renders the rest and gives the uninterrupted run's bytes."""
    real = _views._write_compact
    calls = []

    def dying(path, *args, **kw):
        calls.append(path)
        if len(calls) == 5:
            (path.parent / f".{path.name}.abc123.tmp").write_bytes(b"PK\x03\x04 half a view")
            raise KeyboardInterrupt("killed")
        return real(path, *args, **kw)

    monkeypatch.setattr(_views, "_write_compact", dying)
    with pytest.raises(KeyboardInterrupt):
        generate(tmp_path / "r", storage="compact", **KW)
    monkeypatch.undo()
    views = tmp_path / "r" / "outdoor" / "street-00" / "views"
    assert sorted(p.name for p in views.iterdir()) == [".0001.npz.abc123.tmp", "0000.npz"]
    done = list(read_synthetic(tmp_path / "r" / "outdoor" / "street-00", variants=["clean"]))
    assert [f.name for f in done] == ["0000"]
    s = generate(tmp_path / "r", storage="compact", **KW)
    assert (s.written, s.skipped) == (2, 4)
    assert _tree(tmp_path / "r") == _tree(both / "compact")


def test_compact_on_local_cluster_equals_serial(both, tmp_path):
    pytest.importorskip("distributed")
    s = generate(tmp_path / "d", storage="compact", scheduler="local:2", batch_size=2, **KW)
    assert (s.written, s.skipped) == (6, 0)
    assert _tree(tmp_path / "d") == _tree(both / "compact")


def test_compiled_discontinuity_mask_equals_the_reference():
    from depthnormals.synth._kernels import discontinuity_mask as fast
    from depthnormals.synth.noise import discontinuity_mask as reference

    rng = np.random.default_rng(2)
    for _ in range(40):
        z = 2.0 + 0.01 * np.arange(17)[None, :] + rng.normal(0.0, 0.004, (13, 17))  # a smooth slope
        z[4:9, 6:12] *= rng.uniform(1.01, 1.5)  # a step
        z[rng.random(z.shape) < 0.03] = 0.0
        z.flat[rng.integers(0, z.size, 3)] = rng.choice([np.nan, np.inf, -np.inf, -1.0, 1e-300], 3)
        for jump in (0.02, 0.3):
            want = reference(z, jump=jump)
            assert 0 < want.sum() < want.size and np.array_equal(fast(z, jump=jump), want)
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        fast(np.zeros(5))
