"""``depthnormals estimate`` with many inputs: files, globs, folders, datasets; resume; atomic."""

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
from depthnormals import jobs
from depthnormals.cli import main

K = (60.0, 62.0, 15.5, 11.5)
SRC = str(Path(__file__).resolve().parents[1] / "src")


def _frame(i: int, shape=(24, 32)) -> np.ndarray:
    """A tilted plane, different for every ``i``, with a hole."""
    v, u = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    z = (2.0 + 0.1 * i) / (1.0 + 0.004 * (i + 1) * (u - K[2]) / K[0] - 0.003 * (v - K[3]) / K[1])
    z = z.astype(np.float32)
    z[3 + i % 5, 4] = 0.0
    return z


@pytest.fixture
def tree(tmp_path):
    """in/a/0.npy, in/a/1.npy, in/b/0.npy (two files named 0.npy), k.json."""
    files = {}
    for k, rel in enumerate(("a/0.npy", "a/1.npy", "b/0.npy")):
        p = tmp_path / "in" / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        np.save(p, _frame(k))
        files[rel] = _frame(k)
    (tmp_path / "k.json").write_text(json.dumps(dict(zip(("fx", "fy", "cx", "cy"), K, strict=True))))
    return tmp_path, files


def _expect(z: np.ndarray, method: str = "3f2n+") -> np.ndarray:
    return dn.estimate_normals(z, K, method=method)


def test_folder_keeps_relative_paths_and_equals_the_library(tree, capsys):
    root, files = tree
    out = root / "out"
    assert main(["estimate", str(root / "in"), "-K", str(root / "k.json"), "-o", str(out), "-q"]) == 0
    assert "3 frames by 3f2n+ (3 computed, 0 done before)" in capsys.readouterr().out
    for rel, z in files.items():
        got = np.load(out / rel)
        assert got.tobytes() == _expect(z).tobytes()


def test_glob_and_files_with_options_and_png(tree, capsys):
    root, files = tree
    out = root / "out"
    argv = ["estimate", str(root / "in" / "a" / "*.npy"), "-K", str(root / "k.json"), "-o", str(out),
            "-m", "3f2n", "--option", "kernel=sobel", "--format", "png", "-q"]
    assert main(argv) == 0
    assert sorted(p.name for p in out.iterdir()) == ["0.png", "1.png", jobs.INPUTS_LOG, jobs.MANIFEST]
    want = dn.estimate_normals(files["a/1.npy"], K, method="3f2n", kernel="sobel")
    np.testing.assert_allclose(dn.io.read_normals(out / "1.png"), want, atol=3e-5)
    # two plain files: named after themselves; same name twice is refused
    out2 = root / "out2"
    assert main(["estimate", str(root / "in" / "a" / "1.npy"), str(root / "in" / "b" / "0.npy"),
                 "-K", str(root / "k.json"), "-o", str(out2), "-q"]) == 0
    assert sorted(p.name for p in out2.iterdir()) == ["0.npy", "1.npy", jobs.INPUTS_LOG, jobs.MANIFEST]
    capsys.readouterr()
    assert main(["estimate", str(root / "in" / "a" / "0.npy"), str(root / "in" / "b" / "0.npy"),
                 "-K", str(root / "k.json"), "-o", str(root / "out3"), "-q"]) == 1
    assert "would both be written to" in capsys.readouterr().err


def test_resume_skips_complete_outputs(tree, capsys):
    root, files = tree
    out = root / "out"
    argv = ["estimate", str(root / "in"), "-K", str(root / "k.json"), "-o", str(out), "-q"]
    assert main(argv) == 0
    (out / "a" / "1.npy").unlink()
    marker = out / "b" / "0.npy"
    np.save(marker, np.zeros((2, 2, 3), np.float32))  # an existing output is taken as done
    capsys.readouterr()
    assert main(argv) == 0
    assert "(1 computed, 2 done before)" in capsys.readouterr().out
    assert np.load(out / "a" / "1.npy").tobytes() == _expect(files["a/1.npy"]).tobytes()
    assert np.load(marker).shape == (2, 2, 3)
    assert main([*argv, "--no-resume"]) == 0
    assert "(3 computed, 0 done before)" in capsys.readouterr().out
    assert np.load(marker).tobytes() == _expect(files["b/0.npy"]).tobytes()


def test_progress_lines_without_a_terminal(tree, capsys):
    root, _ = tree
    assert main(["estimate", str(root / "in"), "-K", str(root / "k.json"), "-o", str(root / "o")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("estimate: ") for line in err)
    assert sorted(line.split()[1] for line in err) == ["1", "2", "3"]


def test_dataset_folder(tmp_path, capsys):
    from depthnormals.datasets import open as open_dataset
    from depthnormals.synth import generate

    generate(tmp_path / "ds", indoor=1, outdoor=0, views=2, size=(30, 40), noise=(),
             K=(22.0, 22.0, 19.5, 14.5), progress=False)
    out = tmp_path / "out"
    assert main(["estimate", str(tmp_path / "ds"), "-o", str(out), "-m", "d2nt", "-q"]) == 0
    frames = list(open_dataset(tmp_path / "ds"))
    assert len(frames) == 2
    for f in frames:
        got = np.load(out / f.group / f"{f.name}.npy")
        assert got.tobytes() == dn.estimate_normals(f.depth, f.K, method="d2nt").tobytes()


def test_bad_inputs(tree, capsys):
    root, _ = tree
    k = ["-K", str(root / "k.json")]
    assert main(["estimate", str(root / "in" / "*.png"), *k, "-o", str(root / "o"), "-q"]) == 1
    assert "matches no depth file" in capsys.readouterr().err
    assert main(["estimate", str(root / "in"), "-o", str(root / "o"), "-q"]) == 1
    assert "--intrinsics" in capsys.readouterr().err
    (root / "empty").mkdir()
    assert main(["estimate", str(root / "empty"), *k, "-o", str(root / "o"), "-q"]) == 1
    assert "no depth file" in capsys.readouterr().err
    assert main(["estimate", str(root / "in"), *k, "-o", str(root / "o"), "-m", "nope", "-q"]) == 1
    assert "unknown method 'nope'" in capsys.readouterr().err
    assert main(["estimate", str(root / "in"), *k, "-o", str(root / "n.npy"), "-q"]) == 1
    assert "-o is a folder" in capsys.readouterr().err and not (root / "n.npy").exists()
    with pytest.raises(ValueError, match="format"):
        next(jobs.plan_estimate([root / "in"], root / "o", K=K, fmt="jpg"))


def test_failed_write_leaves_no_output(tree, monkeypatch):
    root, _ = tree
    real = np.save

    def half_then_fail(fh, arr, **kw):
        real(fh, arr, **kw)
        raise OSError("disk full")

    monkeypatch.setattr(np, "save", half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        jobs.run_estimate([root / "in" / "a" / "0.npy"], root / "o", method="3f2n", K=K)
    assert not (root / "o").exists()  # neither the output, its temporary file, nor the folder


def test_killed_run_resumes_to_the_same_files(tmp_path):
    """SIGKILL mid-run: every output that exists is complete; a second run finishes the rest."""
    frames = tmp_path / "in"
    frames.mkdir()
    n = 120
    for i in range(n):
        np.save(frames / f"{i:03d}.npy", _frame(i % 7, shape=(120, 160)))
    (tmp_path / "k.json").write_text(json.dumps(dict(zip(("fx", "fy", "cx", "cy"), K, strict=True))))
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "depthnormals", "estimate", str(frames), "-K", str(tmp_path / "k.json"),
            "-o", str(out), "-m", "sda-sne", "-q"]
    env = {**os.environ, "PYTHONPATH": SRC, "DEPTHNORMALS_NUM_THREADS": "1"}
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None and len(list(out.glob("*.npy"))) < 3:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    done = sorted(out.glob("*.npy"))
    print(f"killed after {len(done)} of {n} frames")
    for p in done:  # complete files only
        want = dn.estimate_normals(_frame(int(p.stem) % 7, shape=(120, 160)), K, method="sda-sne")
        assert np.load(p).tobytes() == want.tobytes()
    leftovers = [p.name for p in out.iterdir() if p.suffix != ".npy"
                 and p.name not in (jobs.MANIFEST, jobs.INPUTS_LOG)]
    assert all(name.startswith(".") and name.endswith(".tmp") for name in leftovers), leftovers
    # an output whose inputs-log line the kill cut off (written, not yet logged) is done again
    logged = set(jobs._read_inputs_log(out))
    assert logged <= {p.name for p in done}
    assert len(logged) >= max(1, len(done) - (os.cpu_count() or 1))  # at most one a thread
    res = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=300, check=True)
    assert f"{n} frames by sda-sne ({n - len(logged)} computed, {len(logged)} done before)" in res.stdout
    assert len(list(out.glob("*.npy"))) == n
