"""Every output knows how it was made: never "done before" for different work.

`depthnormals estimate` writes a manifest per output folder and refuses a resumed run with
other settings or another build of the library (saying how to force it), and recomputes an
output older than its depth file; `evaluate` keys each stored part by its settings, the
frame's data and the library's code (a rerun recomputes what differs); `synth` refuses a
folder made with other settings or resumed by another build of the library.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from depthnormals import jobs
from depthnormals._fingerprint import array_digest, code_fingerprint
from depthnormals._png import encode_png
from depthnormals.analytic import make_scene
from depthnormals.cli import main

K = (50.0, 50.0, 23.5, 17.5)


@pytest.fixture
def folder(tmp_path):
    """Three 16-bit millimetre PNGs and a camera file."""
    z = make_scene("sphere-before-wall").render(K=K, shape=(36, 48)).depth
    (tmp_path / "in").mkdir()
    for i in range(3):
        mm = np.round(z * 1000 * (1 + 0.01 * i)).astype(np.uint16)
        (tmp_path / "in" / f"{i}.png").write_bytes(encode_png(mm))
    (tmp_path / "k.json").write_text(json.dumps(dict(zip(("fx", "fy", "cx", "cy"), K, strict=True))))
    return tmp_path


def _run(folder, *extra):
    return main(["estimate", str(folder / "in"), "-K", str(folder / "k.json"), "-o", str(folder / "out"),
                 "--depth-scale", "0.001", "-q", *extra])


def test_rerun_with_another_method_is_refused_and_says_how_to_force(folder, capsys):
    assert _run(folder) == 0
    first = {p.name: p.read_bytes() for p in (folder / "out").glob("*.npy")}
    capsys.readouterr()
    assert _run(folder, "-m", "fals") == 1
    err = capsys.readouterr().err
    assert "other settings" in err and '"3f2n+" before, "fals" now' in err and "--no-resume" in err
    assert {p.name: p.read_bytes() for p in (folder / "out").glob("*.npy")} == first  # untouched
    assert _run(folder, "-m", "fals", "--no-resume") == 0
    assert "3 frames by fals (3 computed, 0 done before)" in capsys.readouterr().out
    assert all(first[p.name] != p.read_bytes() for p in (folder / "out").glob("*.npy"))
    assert _run(folder, "-m", "fals") == 0       # the same settings now: resumed
    assert "(0 computed, 3 done before)" in capsys.readouterr().out


@pytest.mark.parametrize("extra", [("--depth-scale", "0.002"), ("--option", "aggregate=mean"),
                                   ("--max-depth", "5"), ("--invalid", "65535"), ("--format", "png")])
def test_any_other_setting_is_refused(folder, capsys, extra):
    assert _run(folder) == 0
    capsys.readouterr()
    argv = ["estimate", str(folder / "in"), "-K", str(folder / "k.json"), "-o", str(folder / "out"), "-q",
            "--depth-scale", "0.001", *extra]
    assert main(argv) == 1
    assert "other settings" in capsys.readouterr().err


def test_other_intrinsics_are_refused(folder, capsys):
    assert _run(folder) == 0
    (folder / "k.json").write_text(json.dumps({"fx": 60.0, "fy": 60.0, "cx": 23.5, "cy": 17.5}))
    capsys.readouterr()
    assert _run(folder) == 1
    assert "intrinsics" in capsys.readouterr().err


def test_manifest_records_how_the_outputs_were_made(folder):
    import depthnormals as dn

    assert _run(folder, "--option", "kernel=sobel", "-m", "3f2n") == 0
    data = json.loads((folder / "out" / jobs.MANIFEST).read_text())
    assert data["library_version"] == dn.__version__
    assert data["settings"] == {
        "method": "3f2n", "options": {"kernel": "sobel"}, "depth_scale": 0.001, "invalid": [],
        "max_depth": None, "intrinsics": {"fx": 50.0, "fy": 50.0, "cx": 23.5, "cy": 17.5},
        "format": "npy", "vis": None, "library_code": code_fingerprint()}


def test_outputs_of_another_build_of_the_library_are_refused(folder, capsys, monkeypatch):
    """An edited or upgraded library (the same version string between development builds)
    does not take the outputs of the old one as done."""
    assert _run(folder) == 0
    capsys.readouterr()
    monkeypatch.setattr(jobs, "code_fingerprint", lambda: "0" * 24)
    assert _run(folder) == 1
    err = capsys.readouterr().err
    assert "library_code" in err and "--no-resume" in err
    assert _run(folder, "--no-resume") == 0
    assert "(3 computed, 0 done before)" in capsys.readouterr().out


def test_an_output_older_than_its_depth_file_is_recomputed(folder, capsys):
    import os

    assert _run(folder) == 0
    capsys.readouterr()
    src = folder / "in" / "1.png"
    out = folder / "out" / "1.npy"
    t = src.stat().st_mtime_ns - 10**9
    os.utime(out, ns=(t, t))  # the depth rewritten after its output was
    assert _run(folder) == 0
    assert "(1 computed, 2 done before)" in capsys.readouterr().out
    assert out.stat().st_mtime_ns > src.stat().st_mtime_ns
    assert _run(folder) == 0
    assert "(0 computed, 3 done before)" in capsys.readouterr().out


def test_evaluate_scores_a_rewritten_frame_and_an_edited_library_again(tmp_path, monkeypatch):
    """A frame rewritten under the same name, or the same frame under another build of the
    library, is scored again: before session 28 the stored part of the first was returned
    (a clean plane's 1e-4 deg for its noisy rewrite)."""
    from depthnormals.analytic import tilted_plane
    from depthnormals.datasets import Frame
    from depthnormals.evaluate import _run as run_mod
    from depthnormals.evaluate import run_evaluation

    r = tilted_plane((0.0, -0.6, -0.8), 2.0).render(shape=(30, 40))

    def frames(noise):
        d = r.depth * (1 + noise * np.random.default_rng(0).standard_normal(r.depth.shape))
        return [Frame(d.astype(np.float32), r.normals, r.K, np.isfinite(r.depth), "f0", "g")]

    out = tmp_path / "ev"
    a = run_evaluation(frames(0.0), "3f2n", out, dataset_name="x", figures=0)
    b = run_evaluation(frames(0.01), "3f2n", out, dataset_name="x", figures=0)
    assert (b.computed, b.reused) == (1, 0)
    assert a.rows[0]["mean_deg"] < 0.01 < 1.0 < b.rows[0]["mean_deg"]
    c = run_evaluation(frames(0.01), "3f2n", out, dataset_name="x", figures=0)
    assert (c.computed, c.reused) == (0, 1) and c.rows[0]["mean_deg"] == b.rows[0]["mean_deg"]
    monkeypatch.setattr(run_mod, "code_fingerprint", lambda: "0" * 24)
    d = run_evaluation(frames(0.01), "3f2n", out, dataset_name="x", figures=0)
    assert (d.computed, d.reused) == (1, 0)


def test_array_digest_tells_every_difference():
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    base = array_digest(a, None)
    assert array_digest(a.copy(), None) == base
    assert array_digest(np.asfortranarray(a), None) == base  # the values, not the layout
    b = a.copy()
    b[2, 3] = np.nextafter(b[2, 3], np.float32(100))
    for other in (array_digest(b, None), array_digest(a.reshape(4, 3), None),
                  array_digest(a.astype(np.float64), None), array_digest(a, a), array_digest(a),
                  array_digest(None, a)):
        assert other != base
    assert len(code_fingerprint()) == 24 and code_fingerprint() == code_fingerprint()


def test_outputs_without_a_manifest_are_recomputed(folder, capsys):
    """Outputs of unknown provenance (an older version, another tool) are never 'done'."""
    out = folder / "out"
    out.mkdir()
    for i in range(3):
        np.save(out / f"{i}.npy", np.zeros((36, 48, 3), np.float32))
    assert _run(folder) == 0
    assert "(3 computed, 0 done before)" in capsys.readouterr().out
    assert np.isfinite(np.load(out / "0.npy")).any()
    assert (out / jobs.MANIFEST).is_file()


def test_api_raises_settings_mismatch(folder):
    files = sorted((folder / "in").glob("*.png"))
    jobs.run_estimate(files, folder / "o", method="d2nt", K=K, depth_scale=0.001)
    with pytest.raises(jobs.SettingsMismatch, match="resume=False"):
        jobs.run_estimate(files, folder / "o", method="d2nt", K=K, depth_scale=0.002)
    s = jobs.run_estimate(files, folder / "o", method="d2nt", K=K, depth_scale=0.002, resume=False)
    assert (s.written, s.skipped) == (3, 0)


def test_evaluate_rerun_with_another_protocol_recomputes(tmp_path, capsys):
    from depthnormals.synth import generate

    generate(tmp_path / "ds", indoor=1, outdoor=0, views=2, size=(30, 40), noise=(),
             K=(22.0, 22.0, 19.5, 14.5), progress=False, scenes="procedural")
    base = ["evaluate", str(tmp_path / "ds"), "-m", "d2nt", "-o", str(tmp_path / "ev"), "-q",
            "--figures", "0"]
    assert main(base) == 0
    assert "(2 computed, 0 reused" in capsys.readouterr().out
    assert main([*base, "--border", "3"]) == 0
    assert "(2 computed, 0 reused" in capsys.readouterr().out
    assert main([*base, "--border", "3"]) == 0
    assert "(0 computed, 2 reused" in capsys.readouterr().out
    assert main([*base, "--option", "d2nt:variant=mnr", "--border", "3"]) == 0
    assert "(2 computed, 0 reused" in capsys.readouterr().out


def test_synth_rerun_with_other_settings_is_refused(tmp_path, capsys):
    base = ["synth", str(tmp_path / "s"), "--indoor", "1", "--outdoor", "0", "--views", "1", "--width",
            "48", "--height", "36", "--noise", "none", "--scenes", "procedural", "--no-progress"]
    assert main(base) == 0
    capsys.readouterr()
    assert main([*base, "--seed", "1"]) == 1
    err = capsys.readouterr().err
    assert "other settings" in err and "another output folder" in err


def test_synth_resume_by_another_build_of_the_library_is_refused(tmp_path, capsys, monkeypatch):
    """Its views would mix with the other build's; a folder of before session 28 (no digest
    recorded) still resumes."""
    from depthnormals.synth import writer

    base = ["synth", str(tmp_path / "s"), "--indoor", "1", "--outdoor", "0", "--views", "1", "--width",
            "48", "--height", "36", "--noise", "none", "--scenes", "procedural", "--no-progress"]
    assert main(base) == 0
    assert main(base) == 0  # the same build: resumes (nothing left to do)
    capsys.readouterr()
    monkeypatch.setattr(writer, "code_fingerprint", lambda: "0" * 24)
    assert main(base) == 1
    err = capsys.readouterr().err
    assert "another build" in err and "another output folder" in err
    sidecar = tmp_path / "s" / "dataset.json"
    meta = json.loads(sidecar.read_text())
    del meta["library_code"]
    sidecar.write_text(json.dumps(meta))
    assert main(base) == 0


def test_forced_run_over_fewer_frames_does_not_vouch_for_the_rest(folder, capsys):
    """--no-resume with other settings on 2 of 3 frames: the third output is stale, so the
    folder gets no manifest and the next run recomputes everything (never 'done before')."""
    assert _run(folder) == 0
    two = [str(folder / "in" / "0.png"), str(folder / "in" / "1.png")]
    argv = ["estimate", *two, "-K", str(folder / "k.json"), "-o", str(folder / "out"), "-q",
            "--depth-scale", "0.001", "-m", "fals", "--no-resume"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "1 output(s)" in err and "2.npy" in err and "not recomputed" in err
    assert not (folder / "out" / jobs.MANIFEST).exists()
    assert _run(folder, "-m", "fals") == 0
    assert "(3 computed, 0 done before)" in capsys.readouterr().out
    assert json.loads((folder / "out" / jobs.MANIFEST).read_text())["settings"]["method"] == "fals"


def test_a_regenerated_dataset_read_into_the_same_folder_is_computed_again(tmp_path, capsys):
    """A dataset folder's frames carry no depth file of their own to date; the inputs log
    records each frame's digest, so frames regenerated under the same names are computed
    again (before: all 'done before', the old normals kept)."""
    import shutil

    import depthnormals as dn
    from depthnormals.datasets import open as open_dataset
    from depthnormals.synth import generate

    ds, out = tmp_path / "ds", tmp_path / "out"
    argv = ["estimate", str(ds), "-o", str(out), "-m", "d2nt", "-q"]
    kw = dict(indoor=1, outdoor=0, views=2, size=(30, 40), noise=(), K=(22.0, 22.0, 19.5, 14.5),
              progress=False)
    generate(ds, seed=0, **kw)
    assert main(argv) == 0
    assert main(argv) == 0
    assert "(0 computed, 2 done before)" in capsys.readouterr().out
    shutil.rmtree(ds)
    generate(ds, seed=1, **kw)
    assert main(argv) == 0
    assert "(2 computed, 0 done before)" in capsys.readouterr().out
    for f in open_dataset(ds):
        got = np.load(out / f.group / f"{f.name}.npy")
        assert got.tobytes() == dn.estimate_normals(f.depth, f.K, method="d2nt").tobytes()
    log = (out / jobs.INPUTS_LOG).read_text().splitlines()
    assert len(log) == 2  # compacted: one line an output
    assert main(argv) == 0
    assert "(0 computed, 2 done before)" in capsys.readouterr().out


def test_a_depth_file_replaced_by_an_older_copy_is_computed_again(folder, capsys):
    """make's rule misses a depth file replaced by another with an older time (``cp -p``,
    rsync, an unpacked archive); the inputs log's size and time do not."""
    import os

    assert _run(folder) == 0
    capsys.readouterr()
    src = folder / "in" / "1.png"
    z = make_scene("tilted-plane").render(K=K, shape=(36, 48)).depth
    src.write_bytes(encode_png(np.round(z * 1000).astype(np.uint16)))
    t = (folder / "out" / "1.npy").stat().st_mtime_ns - 10**9
    os.utime(src, ns=(t, t))  # older than the output it replaces
    assert _run(folder) == 0
    assert "(1 computed, 2 done before)" in capsys.readouterr().out
    import depthnormals as dn

    want = dn.estimate_normals(dn.io.read_depth(src, depth_scale=0.001), K)
    assert np.load(folder / "out" / "1.npy").tobytes() == want.tobytes()


def test_a_torn_or_missing_inputs_log_line_recomputes_only_that_output(folder, capsys):
    """A run killed between writing an output and logging it: that output alone is done again;
    a line cut short is ignored."""
    assert _run(folder) == 0
    capsys.readouterr()
    log = folder / "out" / jobs.INPUTS_LOG
    lines = log.read_text().splitlines()
    assert len(lines) == 3 and all(json.loads(line)["input"].startswith("file ") for line in lines)
    log.write_text("\n".join(lines[:2]) + "\n" + lines[2][:17])  # the last line torn
    assert _run(folder) == 0
    assert "(1 computed, 2 done before)" in capsys.readouterr().out
    assert len(log.read_text().splitlines()) == 3
