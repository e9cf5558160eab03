"""What a new user meets on the command line: exit codes, clear messages, progress that
reads well in a log, the first-run announcement, pictures that explain themselves.

Every command runs in-process through ``main(argv) -> int``; slow work is avoided by small
inputs, or by replacing a command's ``run`` where only the CLI layer is under test.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import types

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.cli import EXIT_NO_VALID_PIXEL, main
from depthnormals.commands import _firstrun

TORUSKNOT = "3f2n-torusknot"


@pytest.fixture
def k_json(tmp_path):
    path = tmp_path / "k.json"
    path.write_text(json.dumps({"fx": 300.0, "fy": 310.0, "cx": 11.5, "cy": 9.5}))
    return path


def _plane(h: int = 20, w: int = 24) -> np.ndarray:
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    return (2.0 / (1.0 + 0.002 * (u - 11.5) - 0.001 * (v - 9.5))).astype(np.float32)


# ------------------------------------------------------------------------------ exit codes

def test_help_documents_the_exit_codes(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "exit status: 0 success; 1 error" in out and "3 no pixel of the input depth" in out


@pytest.mark.parametrize("value", [0.0, np.nan, -1.0, np.inf])
def test_estimate_all_invalid_warns_and_exits_3(tmp_path, k_json, capsys, value):
    np.save(tmp_path / "d.npy", np.full((20, 24), value, np.float32))
    out = tmp_path / "n.npy"
    rc = main(["estimate", str(tmp_path / "d.npy"), "-K", str(k_json), "-o", str(out)])
    assert rc == EXIT_NO_VALID_PIXEL == 3
    err = capsys.readouterr().err
    assert "warning: no pixel of" in err and "d.npy" in err
    assert np.isnan(np.load(out)).all()          # the (all-NaN) answer is still written


def test_estimate_one_valid_pixel_is_exit_3(tmp_path, k_json, capsys):
    """One policy for all-NaN output: a lone valid pixel has no normal either."""
    z = np.zeros((20, 24), np.float32)
    z[5, 5] = 2.0
    np.save(tmp_path / "d.npy", z)
    assert main(["estimate", str(tmp_path / "d.npy"), "-K", str(k_json),
                 "-o", str(tmp_path / "n.npy")]) == 3
    assert "none has a valid neighbour" in capsys.readouterr().err


# ------------------------------------------------------------------- --shape for raw .bin

def test_estimate_shape_reads_raw_bin(tmp_path, k_json, capsys):
    z = _plane(20, 24)
    z.astype("<f4").tofile(tmp_path / "d.bin")
    out = tmp_path / "n.npy"
    argv = ["estimate", str(tmp_path / "d.bin"), "-K", str(k_json), "-o", str(out)]
    assert main(argv) == 1                       # the 3F2N default 480 x 640 does not fit
    assert "expected 480 x 640" in capsys.readouterr().err
    assert main([*argv, "--shape", "20,24"]) == 0
    want = dn.estimate_normals(z, (300.0, 310.0, 11.5, 9.5))
    np.testing.assert_array_equal(np.load(out), want)
    assert main([*argv, "--shape", "24,20"]) == 0    # same size, other shape: read as given
    assert np.load(out).shape == (24, 20, 3)
    np.save(tmp_path / "d.npy", z)
    assert main(["estimate", str(tmp_path / "d.npy"), "-K", str(k_json), "-o", str(out),
                 "--shape", "10,48"]) == 1
    assert "--shape says 10 x 48" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["20x24", "20", "a,b", "0,5"])
def test_estimate_bad_shape_is_a_usage_error(tmp_path, k_json, capsys, bad):
    with pytest.raises(SystemExit) as exc:
        main(["estimate", "d.bin", "-K", str(k_json), "-o", "n.npy", "--shape", bad])
    assert exc.value.code == 2
    assert "--shape" in capsys.readouterr().err


# --------------------------------------------------------------- intrinsics file messages

@pytest.mark.parametrize("text, says", [
    ("{fx: 300, fy: 310", "not valid JSON"),
    ('{"f": 300}', "needs keys fx, fy, cx, cy or K"),
    ('{"fx": -300, "fy": 310, "cx": 11.5, "cy": 9.5}', "focal lengths must be > 0"),
    ('{"K": [1, 2, 3]}', "holds 9 (3x3) or 12 (3x4) numbers"),
])
def test_malformed_intrinsics_name_the_file_and_a_valid_one(tmp_path, capsys, text, says):
    np.save(tmp_path / "d.npy", _plane())
    bad = tmp_path / "camera-K.json"
    bad.write_text(text)
    assert main(["estimate", str(tmp_path / "d.npy"), "-K", str(bad),
                 "-o", str(tmp_path / "n.npy")]) == 1
    err = capsys.readouterr().err
    assert str(bad) in err and says in err
    assert 'a valid file looks like {"fx": 525.0' in err


# ----------------------------------------------------------- evaluate without matplotlib

def test_evaluate_without_matplotlib_skips_figures_with_one_warning(shared_data, tmp_path,
                                                                     monkeypatch, capsys):
    folder = shared_data / TORUSKNOT
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent")
    for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)      # import matplotlib -> ImportError
    out = tmp_path / "ev"
    rc = main(["evaluate", str(folder), "-m", "d2nt", "-o", str(out), "-q"])
    assert rc == 0
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "matplotlib is not installed" in warnings[0]
    assert "figures are skipped" in warnings[0] and "--figures 0" in warnings[0]
    assert (out / "results.csv").is_file() and (out / "summary.md").is_file()
    assert not (out / "figures").exists()
    assert json.loads((out / "settings.json").read_text())["figures"]["count"] == 0
    # asking for no figures: no warning at all
    assert main(["evaluate", str(folder), "-m", "d2nt", "-o", str(out), "-q",
                 "--figures", "0"]) == 0
    assert "warning" not in capsys.readouterr().err


# ----------------------------------------------------------------------------- progress

def _lines(err: str, prefix: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith(prefix)]


def test_synth_progress_is_one_line_per_view_in_a_log(tmp_path, capsys):
    assert main(["synth", str(tmp_path / "s"), "--indoor", "1", "--outdoor", "0", "--views",
                 "2", "--width", "128", "--height", "106", "--noise", "none", "--scenes", "procedural"]) == 0
    err = capsys.readouterr().err
    assert "\r" not in err
    assert _lines(err, "synth:") == ["synth: 1/2 view", "synth: 2/2 view"]


def test_bench_reports_progress_and_the_threads_it_pinned(tmp_path, capsys):
    out = tmp_path / "b.json"
    assert main(["bench", "--methods", "3f2n,d2nt", "--sizes", "32x24", "--repeats", "1",
                 "--warmup", "0", "--threads", "1", "--peers", "none", "--json", str(out)]) == 0
    err = capsys.readouterr().err
    assert _lines(err, "bench:") == ["bench: 1/2 3f2n at 32x24, 1 thread(s)",
                                     "bench: 2/2 d2nt at 32x24, 1 thread(s)"]
    data = json.loads(out.read_text())
    assert data["threads_pinned"]["1"]["depthnormals"] == 1
    assert main(["bench", "--methods", "3f2n", "--sizes", "32x24", "--repeats", "1",
                 "--warmup", "0", "--threads", "1", "--peers", "none", "-q"]) == 0
    assert not _lines(capsys.readouterr().err, "bench:")


def test_bench_threads_pin_open3d_opencv_and_ours(monkeypatch):
    """--threads N pins Open3D (utility.set_max_threads, its TBB pool), OpenCV and our pool."""
    from depthnormals.commands import bench

    calls: list[int] = []
    state = {"n": 0}

    def set_max_threads(n):
        calls.append(n)
        state["n"] = n

    fake = types.SimpleNamespace(utility=types.SimpleNamespace(
        set_max_threads=set_max_threads, get_max_threads=lambda: state["n"]))
    monkeypatch.setitem(sys.modules, "open3d", fake)
    cv2 = pytest.importorskip("cv2")
    before_cv, before_ours = cv2.getNumThreads(), dn.get_num_threads()
    try:
        pinned = bench._set_threads(1)
        assert calls == [1] and pinned["open3d"] == 1
        assert cv2.getNumThreads() == 1 and pinned["opencv"] == 1
        assert dn.get_num_threads() == 1 and pinned["depthnormals"] == 1
        # an Open3D without the call is reported, not silently skipped
        monkeypatch.setitem(sys.modules, "open3d", types.SimpleNamespace(utility=object()))
        assert "not pinned" in bench._set_threads(1)["open3d"]
    finally:
        cv2.setNumThreads(before_cv)
        dn.set_num_threads(before_ours)


def test_ablate_reports_progress(monkeypatch, capsys):
    from depthnormals.analytic import make_scene
    from depthnormals.commands import ablate
    from depthnormals.datasets import Frame

    def small_frames(noise=0.1, seed=0):
        r = make_scene("box-on-floor").render(K=(60.0, 60.0, 31.5, 23.5), shape=(48, 64))
        K = np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1.0]])
        yield Frame(r.depth, r.normals.astype(np.float32), K, r.depth > 0, "0", "box/clean")

    monkeypatch.setattr(ablate, "analytic_frames", small_frames)
    assert main(["ablate", "--analytic", "--table", "1", "--kernels", "fd"]) == 0
    captured = capsys.readouterr()
    assert _lines(captured.err, "ablate:") == [
        f"ablate: frame 1 box/clean/0: {agg} x fd x 6 curvatures"
        for agg in ("median", "mean", "trimean", "trimmed-mean")]
    assert captured.out.startswith("Table 1")
    # -q silences it (table 1 again: table 2 would compile its correlation and CRF variants for
    # this frame's dtype, about a minute of a fresh CI run, for the same flag)
    assert main(["ablate", "--analytic", "--table", "1", "--kernels", "fd", "-q"]) == 0
    assert not _lines(capsys.readouterr().err, "ablate:")


# ------------------------------------------------------------------ first-run announcement

def test_first_run_announced_once_on_an_empty_cache(tmp_path, monkeypatch, capsys):
    import numba

    from depthnormals.commands import demo, methods

    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "empty-cache"))
    monkeypatch.setattr(_firstrun, "_announced", False)
    monkeypatch.setattr(demo, "run", lambda args: 0)       # the CLI layer only
    assert _firstrun.kernel_cache_state() == "cold"
    assert main(["methods", "--names-only"]) == 0            # compiles nothing: says nothing
    assert "compiling" not in capsys.readouterr().err
    assert main(["demo"]) == 0
    err = capsys.readouterr().err
    assert err.splitlines() == [
        f"depthnormals demo: compiling kernels, first run only (about {demo.FIRST_RUN_S} s)"]
    assert main(["demo"]) == 0                               # once per process
    assert "compiling" not in capsys.readouterr().err
    assert methods.__dict__.get("FIRST_RUN_S") is None


_KERNEL = textwrap.dedent("""
    import numba

    @numba.njit(cache=True)
    def plus_one(x):
        return x + 1
    """)


def test_kernel_cache_state_follows_numba(tmp_path, monkeypatch):
    """cold before numba compiled the kernels, warm after, stale once every kernel module
    changed (one unchanged module keeps it warm: numba leaves old index files behind, so a
    per-module rule would announce forever); the index files are found where numba itself
    writes them (NUMBA_CACHE_DIR)."""
    import os

    import numba

    pkg, cache = tmp_path / "pkg", tmp_path / "cache"
    pkg.mkdir()
    (pkg / "kern_a.py").write_text(_KERNEL)
    (pkg / "kern_b.py").write_text(_KERNEL)
    (pkg / "plain.py").write_text("x = 1\n")
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(cache))
    assert _firstrun.kernel_cache_state(pkg) == "cold"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(pkg)}
    subprocess.run([sys.executable, "-c", "import kern_a, kern_b; "
                    "assert kern_a.plus_one(1) == kern_b.plus_one(1) == 2"],
                   env=env, check=True, timeout=120)
    assert list(cache.rglob("kern_a.*.nbi")) and list(cache.rglob("kern_b.*.nbi"))
    assert _firstrun.kernel_cache_state(pkg) == "warm"
    (pkg / "kern_a.py").write_text(_KERNEL + "\n# edited\n")
    assert _firstrun.kernel_cache_state(pkg) == "warm"
    (pkg / "kern_b.py").write_text(_KERNEL + "\n# edited too\n")
    assert _firstrun.kernel_cache_state(pkg) == "stale"



def test_kernel_cache_state_is_warm_for_the_package_once_compiled():
    """The package's own kernels carry :mod:`depthnormals._numba_cache`'s stamp (numba's, paired
    with the digest of the package's compiled code): once one is compiled and cached the state
    is warm. Until session 34 the check compared numba's bare stamp, read every index of the
    package as stale, and every command announced "compiling kernels, first run only" on every
    run (since the stamp pair came in)."""
    import numpy as np

    import depthnormals as dn

    dn.estimate_normals(np.full((8, 8), 2.0), (50.0, 50.0, 3.5, 3.5), method="3f2n")
    assert _firstrun.kernel_cache_state() == "warm"


# ---------------------------------------------------------------------------- pictures

def test_demo_picture_has_titles_and_colour_bars(tmp_path, capsys):
    from depthnormals._png import read_png
    from depthnormals.commands.demo import ERROR_VMAX_DEG
    from depthnormals.registry import DEFAULT_METHOD
    from depthnormals.viz import colorize, text_mask

    out = tmp_path / "demo.png"
    assert main(["demo", "--size", "160x120", "-o", str(out), "--baseline", "none"]) == 0
    img = read_png(out)
    w, gap = 160, 4
    assert img.shape[1] == 4 * w + 3 * gap
    title_h = 11                                  # 7-pixel font at scale 1, 4 pixels of margin
    assert img.shape[0] > title_h + 120 + 20      # title band, the pictures, colour bars
    head, foot = img[:title_h], img[title_h + 120:]
    titles = ["depth (m)", "ground truth", f"estimate {DEFAULT_METHOD}", "angular error (deg)"]
    for i, title in enumerate(titles):
        cols = head[:, i * (w + gap):i * (w + gap) + w]
        ink = (cols == 0).all(axis=-1)
        assert ink.sum() == text_mask(title).sum(), title       # exactly the title's pixels
    # under the error panel: the inferno ramp from 0 to ERROR_VMAX_DEG degrees
    err_bar = foot[2:8, 3 * (w + gap):3 * (w + gap) + w]
    ramp = colorize(np.tile(np.linspace(0, ERROR_VMAX_DEG, w), (6, 1)), vmin=0.0,
                    vmax=ERROR_VMAX_DEG, cmap="inferno")
    np.testing.assert_array_equal(err_bar, ramp)
    # under the depth panel a viridis ramp; nothing under the normal maps
    assert (foot[2:8, :w] != 255).any(axis=-1).all()
    assert (foot[:, w + gap:3 * w + 2 * gap] == 255).all()
    assert "titled, with colour bars" in capsys.readouterr().out


def test_text_mask_and_colorbar():
    from depthnormals.viz import colorbar, colorize, text_mask

    m = text_mask("1.5 deg", scale=2)
    assert m.shape == (14, 2 * (6 * 7 - 1)) and m.dtype == bool
    assert m[:, :10].sum() == 4 * (1 + 2 + 1 + 1 + 1 + 1 + 3)    # the "1" glyph, scaled by 2
    bar = colorbar(100, vmin=2.0, vmax=4.0, cmap="viridis", label="depth (m)")
    ends = colorize(np.array([[2.0, 4.0]]), vmin=2.0, vmax=4.0)
    np.testing.assert_array_equal(bar[2, [0, 99]], ends[0])


def test_fig3_has_a_depth_colour_bar_in_units(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    from depthnormals.analytic import make_scene
    from depthnormals.evaluate._figures import plot_fig3

    bars = []
    real = Figure.colorbar

    def spy(self, *args, **kwargs):
        bars.append(real(self, *args, **kwargs))
        return bars[-1]

    monkeypatch.setattr(Figure, "colorbar", spy)
    r = make_scene("box-on-floor").render(K=(60.0, 60.0, 31.5, 23.5), shape=(48, 64))
    err = np.zeros(r.depth.shape)
    plot_fig3(tmp_path / "f.png", r.depth, r.normals, r.depth > 0, r.normals, "x", {"x": err})
    labels = [b.ax.get_xlabel() or b.ax.get_ylabel() for b in bars]
    assert labels == ["depth (dataset units; m for metric data)", "angular error (deg)"]
    assert (tmp_path / "f.png").stat().st_size > 1000
