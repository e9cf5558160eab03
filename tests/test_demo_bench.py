"""The demo and bench commands: they run, print real numbers and write what they say."""

from __future__ import annotations

import json

import numpy as np
import pytest

from depthnormals._png import read_png
from depthnormals.cli import main


def test_demo_writes_four_panel_picture_and_metrics(tmp_path, capsys):
    out = tmp_path / "demo.png"
    assert main(["demo", "--size", "160x120", "-o", str(out), "--json", "--baseline", "3f2n"]) == 0
    report = json.loads(capsys.readouterr().out)
    img = read_png(out)
    # four 160 x 120 panels with titles above and colour bars below (tests/test_cli_newcomer.py)
    assert img.shape[1:] == (4 * 160 + 3 * 4, 3) and img.shape[0] > 120 and img.dtype == np.uint8
    for method, r in report["results"].items():
        # clean analytic scene: almost every pixel is exact, errors concentrate at edges
        assert 0.0 <= r["median"] < 0.01, method
        assert r["coverage"] == 1.0
        assert 0.0 < r["mean"] < 5.0
    assert not list(tmp_path.glob(".*tmp"))  # written atomically, no leftovers


def test_demo_noise_raises_the_error(tmp_path, capsys):
    args = ["demo", "--size", "160x120", "-o", str(tmp_path / "d.png"), "--json", "--baseline", "none",
            "--method", "3f2n"]
    main(args)
    clean = json.loads(capsys.readouterr().out)["results"]["3f2n"]["median"]
    main([*args, "--noise", "0.5"])
    noisy = json.loads(capsys.readouterr().out)["results"]["3f2n"]["median"]
    assert noisy > clean + 0.5


def test_demo_rejects_bad_size(tmp_path, capsys):
    assert main(["demo", "--size", "big", "-o", str(tmp_path / "x.png")]) == 1
    assert "640x480" in capsys.readouterr().err


def test_bench_prints_a_row_per_method_with_ratios(capsys):
    pytest.importorskip("cv2")
    assert main(["bench", "--sizes", "96x64", "--repeats", "1", "--methods", "3f2n,d2nt"]) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines() if line[:1].isalnum()}
    assert "opencv-fals" in rows and "3f2n" in rows and "d2nt" in rows
    ms, ratio = float(rows["3f2n"][0]), float(rows["3f2n"][1])
    assert ms > 0 and ratio > 0


@pytest.mark.parametrize("argv, message", [
    (["demo", "--noise", "-1"], "--noise must be finite and >= 0"),
    (["demo", "--noise", "nan"], "--noise must be finite and >= 0"),
    (["demo", "-o", "{tmp}/picture.txt"], "must end in .png"),
    (["bench", "--repeats", "0"], "--repeats must be >= 1"),
    (["bench", "--warmup", "-1"], "--warmup must be >= 0"),
    (["ablate", "--analytic", "--table", "1", "--noise", "-0.1"], "noise must be finite and >= 0"),
    # without a scheduler the batch size is unused: 0 and -3 ran as if unset (session 30)
    (["synth", "{tmp}/s", "--views", "1", "--indoor", "1", "--outdoor", "0", "--batch-size", "0"],
     "batch_size must be an integer >= 1"),
    (["estimate", "{shared}/3f2n-torusknot", "-o", "{tmp}/e", "--batch-size", "-3"],
     "batch_size must be an integer >= 1"),
    (["evaluate", "{shared}/3f2n-torusknot", "--methods", "3f2n", "--out", "{tmp}/v", "--batch-size", "0"],
     "batch_size must be an integer >= 1"),
])
def test_bad_numbers_are_refused_not_read_another_way(tmp_path, capsys, argv, message):
    """Before: a negative demo noise ran noise-free and printed "noise -1 z/f"; --repeats 0
    timed one run (the compile included) and printed "medians of 0 runs"; a .txt output
    got a PNG; a negative ablation noise added noise of the opposite sign."""
    if any("{shared}" in a for a in argv):
        from conftest import SHARED_DATA

        if not SHARED_DATA.is_dir():
            pytest.skip(f"shared data folder {SHARED_DATA} is absent")
        argv = [a.replace("{shared}", str(SHARED_DATA)) for a in argv]
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    if argv[0] == "demo" and "-o" not in argv:
        argv += ["-o", str(tmp_path / "d.png")]
    assert main(argv) == 1
    assert message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
