"""The CLI is a thin layer: the same numbers as the library, clear errors, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.cli import main


@pytest.fixture
def inputs(tmp_path):
    v, u = np.mgrid[0:20, 0:24].astype(np.float64)
    z = (2.0 / (1.0 + 0.002 * (u - 11.5) - 0.001 * (v - 9.5))).astype(np.float32)
    z[3, 4] = 0.0
    np.save(tmp_path / "depth.npy", z)
    (tmp_path / "k.json").write_text(json.dumps({"fx": 300.0, "fy": 310.0, "cx": 11.5,
                                                 "cy": 9.5}))
    return tmp_path, z, (300.0, 310.0, 11.5, 9.5)


def test_methods_lists_every_name(capsys):
    assert main(["methods", "--names-only"]) == 0
    out = capsys.readouterr().out.split()
    assert tuple(out) == dn.methods()
    assert main(["methods"]) == 0
    out = capsys.readouterr().out
    for name in dn.methods():
        assert name in out
    assert "kernel_size" in out and "variant" in out


@pytest.mark.parametrize("method, opts", [(None, []), ("3f2n", ["kernel=sobel", "aggregate=mean"]),
                                          ("d2nt", ["variant=basic"])])
def test_estimate_writes_the_library_result(inputs, method, opts, capsys):
    folder, z, K = inputs
    out = folder / "n.npy"
    argv = ["estimate", str(folder / "depth.npy"), "--intrinsics", str(folder / "k.json"),
            "-o", str(out)]
    if method:
        argv += ["--method", method]
    for o in opts:
        argv += ["--option", o]
    assert main(argv) == 0
    options = dict(o.split("=") for o in opts)
    want = dn.estimate_normals(z, K, **({"method": method} if method else {}), **options)
    np.testing.assert_array_equal(np.load(out), want)
    assert np.isnan(want[3, 4]).all() and np.isfinite(want[10, 10]).all()
    assert str(out) in capsys.readouterr().out


def test_estimate_takes_the_camera_inline(inputs):
    """``-K fx,fy,cx,cy`` gives what the same camera's file gives, in one file and many."""
    folder, z, K = inputs
    inline = ",".join(f"{x:g}" for x in K)
    assert main(["estimate", str(folder / "depth.npy"), "-K", inline, "-o",
                 str(folder / "a.npy"), "-q"]) == 0
    np.testing.assert_array_equal(np.load(folder / "a.npy"), dn.estimate_normals(z, K))
    (folder / "in").mkdir()
    np.save(folder / "in" / "d.npy", z)
    assert main(["estimate", str(folder / "in"), "-K", inline, "-o", str(folder / "many"),
                 "-q"]) == 0
    np.testing.assert_array_equal(np.load(folder / "many" / "d.npy"), np.load(folder / "a.npy"))


def test_estimate_png_output(inputs):
    folder, z, K = inputs
    out = folder / "n.png"
    assert main(["estimate", str(folder / "depth.npy"), "-K", str(folder / "k.json"),
                 "-o", str(out)]) == 0
    got = dn.io.read_normals(out)
    want = dn.estimate_normals(z, K)
    assert np.nanmax(dn.angular_error(got, want)) < 3e-3


@pytest.mark.parametrize("extra, message", [
    (["--method", "nope"], "unknown method 'nope'; valid methods: 3f2n"),
    (["--option", "kernal=fd"], "unknown option(s) ['kernal']"),
    (["--option", "kernel=laplace"], "unknown kernel 'laplace'"),
    (["--option", "kernel"], "KEY=VALUE"),
])
def test_estimate_bad_arguments(inputs, extra, message, capsys):
    folder, _, _ = inputs
    code = main(["estimate", str(folder / "depth.npy"), "--intrinsics", str(folder / "k.json"),
                 "-o", str(folder / "n.npy"), *extra])
    assert code == 1
    err = capsys.readouterr().err
    assert "depthnormals estimate: error:" in err and message in err
    assert not (folder / "n.npy").exists()


def test_estimate_missing_files(inputs, capsys):
    folder, _, _ = inputs
    assert main(["estimate", str(folder / "nope.npy"), "-K", str(folder / "k.json"),
                 "-o", str(folder / "n.npy")]) == 1
    assert "does not exist" in capsys.readouterr().err
    assert main(["estimate", str(folder / "depth.npy"), "-K", str(folder / "k.json"),
                 "-o", str(folder / "no" / "n.npy")]) == 0  # the output's folder is created
    assert (folder / "no" / "n.npy").is_file()


@pytest.mark.parametrize("argv", [["estimate", "d.npy"], ["frobnicate"], ["estimate"],
                                  ["methods", "--bogus"]])
def test_usage_errors_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "usage: depthnormals" in err and "error:" in err


def test_no_command_prints_help(capsys):
    assert main([]) == 2
    assert "usage: depthnormals" in capsys.readouterr().out


def test_python_m_version():
    res = subprocess.run([sys.executable, "-m", "depthnormals", "--version"],
                         capture_output=True, text=True, timeout=120, check=False)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == f"depthnormals {dn.__version__}"
