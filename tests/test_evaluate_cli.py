"""``depthnormals evaluate``: the thin command over run_evaluation."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json

import pytest

from depthnormals import cli
from depthnormals.commands import evaluate as cmd
from depthnormals.evaluate import read_results_csv


def _run(argv: list[str]) -> int:
    """Run the command through its own parser (independent of the other commands)."""
    parser = argparse.ArgumentParser()
    cmd.add_arguments(parser)
    return cmd.run(parser.parse_args(argv))


def test_registered_in_cli():
    assert "evaluate" in cli.COMMANDS


def test_cli_writes_outputs(shared_data, tmp_path, capsys):
    folder = shared_data / "3f2n-torusknot"
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent")
    out = tmp_path / "ev"
    rc = _run([str(folder), "--methods", "3f2n,3f2n[aggregate=mean],d2nt", "--out", str(out),
               "--figures", "0", "--option", "d2nt:variant=basic", "--quiet"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "| 3f2n[aggregate=mean] |" in text and "3 computed, 0 reused" in text
    means = {r["method"]: round(r["mean_deg"], 4) for r in read_results_csv(out / "results.csv")}
    # references of tests/test_reference_torusknot.py (3F2N fd median / mean, D2NT basic)
    assert means == {"3f2n": 2.8424, "3f2n[aggregate=mean]": 3.4771, "d2nt": 2.8651}
    assert {p.name for p in out.iterdir()} >= {"results.csv", "summary.md", "summary.json",
                                               "settings.json", "parts"}
    # run again: everything is reused
    assert _run([str(folder), "-m", "3f2n,3f2n[aggregate=mean],d2nt", "-o", str(out),
                 "--figures", "0", "--option", "d2nt:variant=basic", "-q"]) == 0
    assert "0 computed, 3 reused" in capsys.readouterr().out


def test_cli_bad_option(tmp_path):
    with pytest.raises(ValueError, match="METHOD:KEY=VALUE"):
        cmd.parse_method_options(["kernel=fd"])
    assert cmd.parse_method_options(["3f2n:kernel=sobel", "3f2n:kernel_size=5"]) == {
        "3f2n": {"kernel": "sobel", "kernel_size": 5}}


def test_main_reports_errors(tmp_path, capsys):
    for name in cli.COMMANDS:     # main() builds every command; others may not exist yet
        try:
            importlib.import_module(f"depthnormals.commands.{name}")
        except ImportError:
            pytest.skip(f"command module {name!r} is not there yet")
    rc = cli.main(["evaluate", str(tmp_path / "missing"), "-m", "3f2n", "-o", str(tmp_path)])
    assert rc == 1
    assert "does not exist" in capsys.readouterr().err


def test_bench_threads_peers_json(tmp_path, capsys):
    pytest.importorskip("cv2")
    from depthnormals.commands import bench

    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    out = tmp_path / "bench.json"
    args = parser.parse_args(["--methods", "3f2n", "--sizes", "64x48,32x24", "--repeats", "3",
                              "--warmup", "1", "--threads", "1,all", "--json", str(out),
                              "--peers", "opencv-fals,opencv-linemod,kornia"])
    assert bench.run(args) == 0
    text = capsys.readouterr().out
    assert text.count("# threads:") == len(bench._parse_threads("1,all"))
    data = json.loads(out.read_text())
    runs = {(r["threads"], r["method"]): r for r in data["runs"]}
    assert (1, "3f2n") in runs and (1, "opencv-fals") in runs and (1, "opencv-linemod") in runs
    assert runs[(1, "3f2n")]["64x48_ms"] > 0 and runs[(1, "opencv-fals")]["32x24_ms"] > 0
    assert data["machine"]["logical_cores"] >= 1
    if importlib.util.find_spec("kornia") is None:
        assert "not installed" in data["peers_missing"]["kornia"]
    with pytest.raises(ValueError, match="unknown peer"):
        bench.run(parser.parse_args(["--peers", "pcl"]))
    with pytest.raises(ValueError, match="--threads"):
        bench._parse_threads("one")
