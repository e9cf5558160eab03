"""sha256 of every method's output on three scenes, two dtypes and two thread counts.

A behaviour-preserving refactor must leave every hash unchanged:

    PYTHONPATH=src python3 benchmarks/golden_hashes.py --write /tmp/golden.json   # before
    PYTHONPATH=src python3 benchmarks/golden_hashes.py --check /tmp/golden.json   # after

Cases: every name in ``methods()`` with its defaults, plus the module option sets the tests use
(correlation kendall / pearson / none, crf on / off, consistency None, selection plane-fit, two
CRF passes) on ``3f2n+`` (the fused path) and ``d2nt+`` (the generic path), and SDA-SNE's own
``iterations`` on ``sda-sne`` and ``sda-sne+``. Scenes: the 3F2N torus-knot frame, the analytic
box on a floor, and a noisy sphere before a wall with holes. Keys name the meaning of an option,
not its spelling, so a renamed option keeps its key (``crf_passes`` below).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

import depthnormals as dn
from depthnormals.analytic import make_scene

DATA = Path("/work/shared/data/3f2n-torusknot")
ROUGH_K = (131.25, 131.25, 79.5, 59.5)

#: The one intended change (issue 12, option names): before, ``sda-sne+`` had no way to set the
#: module's CRF passes (its ``iterations`` was SDA-SNE's), so this case ran SDA-SNE with two
#: rounds; now ``crf_iterations=2`` reaches the module.
EXPECTED_CHANGE = "sda-sne+|crf-passes-2|"

MODULE_SETS = {
    "kendall": {"correlation": "kendall"},
    "pearson-crf": {"correlation": "pearson", "crf": True},
    "kendall-crf": {"correlation": "kendall", "crf": True},
    "none-crf": {"correlation": "none", "crf": True},
    "kendall-prose-crf": {"correlation": "kendall-prose", "crf": True},
    "consistency-none": {"consistency": None},
    "plane-fit": {"selection": "plane-fit"},
    "plane-fit-crf": {"selection": "plane-fit", "crf": True, "correlation": "kendall"},
    "crf-passes-2": {"crf": True, "correlation": "kendall", "crf_passes": 2},
    "crf-passes-2-none": {"crf": True, "crf_passes": 2},
    "max": {"curvature": "max", "crf": True},
    "square": {"neighbourhood": "square"},
}


def _spell(options: dict) -> dict:
    """The module's CRF pass count under its current spelling."""
    out = dict(options)
    if "crf_passes" in out:
        names = dn.ddm.module_defaults()
        key = "crf_iterations" if "crf_iterations" in names else "iterations"
        out[key] = out.pop("crf_passes")
    return out


def scenes() -> dict[str, tuple[np.ndarray, object]]:
    from depthnormals.datasets import read_3f2n

    frame = next(iter(read_3f2n(DATA)))
    r = make_scene("box-on-floor").render(shape=(90, 120), K=(100.0, 100.0, 59.5, 44.5))
    rng = np.random.default_rng(7)
    z = make_scene("sphere-before-wall").render(K=ROUGH_K, shape=(120, 160)).depth.copy()
    z += rng.normal(0.0, 0.01, z.shape) * (z > 0)
    z[rng.random(z.shape) < 0.03] = 0.0
    z[40:47, 60:70] = np.nan
    return {"torusknot": (np.asarray(frame.depth), frame.K), "box": (r.depth, r.K),
            "noisy": (z, ROUGH_K)}


def cases() -> list[tuple[str, str, dict]]:
    out = [(m, "defaults", {}) for m in dn.methods()]
    for base in ("3f2n+", "d2nt+"):
        out += [(base, k, v) for k, v in MODULE_SETS.items()]
    out += [("sda-sne", "sda-iterations-2", {"iterations": 2}),
            ("sda-sne+", "sda-iterations-2", {"iterations": 2}),
            ("sda-sne+", "crf-passes-2", MODULE_SETS["crf-passes-2"]),
            ("3f2n", "mean-5", {"aggregate": "mean", "kernel_size": 5}),
            ("3f2n+", "mean", {"aggregate": "mean"}),
            ("3f2n+", "sobel", {"kernel": "sobel"})]
    return out


def compute(quick: bool = False, match: str = "") -> dict[str, str]:
    result = {}
    sc = scenes()
    for threads in (1, 2):
        dn.set_num_threads(threads)
        for sname, (depth, K) in sc.items():
            if quick and sname == "torusknot":
                continue
            for dtype in (np.float32, np.float64):
                d = np.asarray(depth, dtype=dtype)
                for method, label, opts in cases():
                    if match and not f"{method}|{label}".startswith(match):
                        continue
                    n = dn.estimate_normals(d, K, method=method, **_spell(opts))
                    key = f"{method}|{label}|{sname}|{np.dtype(dtype).name}|t{threads}"
                    result[key] = hashlib.sha256(np.ascontiguousarray(n).tobytes()).hexdigest()
    return result


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", type=Path)
    g.add_argument("--check", type=Path)
    p.add_argument("--quick", action="store_true", help="skip the torus-knot frame")
    p.add_argument("--match", default="", help="only the cases whose 'method|label' starts so")
    a = p.parse_args()
    got = compute(a.quick, a.match)
    if a.write:
        a.write.write_text(json.dumps(got, indent=1, sort_keys=True))
        print(f"{len(got)} hashes written to {a.write}")
        return 0
    want = json.loads(a.check.read_text())
    bad = [k for k in got if want.get(k) != got[k]]
    expected = [k for k in bad if k.startswith(EXPECTED_CHANGE)]
    bad = [k for k in bad if not k.startswith(EXPECTED_CHANGE)]
    print(f"{len(got)} hashes compared, {len(bad)} differ"
          f" (+ {len(expected)} expected: {EXPECTED_CHANGE}*)")
    for k in bad[:40]:
        print("  DIFF", k)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
