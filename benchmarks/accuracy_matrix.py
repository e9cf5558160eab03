"""Accuracy matrix: every method on every visible dataset, with edge-band and coverage (issue 13).

Datasets (groups):
- ``tk``: the 3F2N torus-knot frame (``shared/data/3f2n-torusknot``);
- ``<scene>/<clean|noise0.1>``: the analytic scenes tilted-plane, box-on-floor, stairs,
  sphere-before-wall at 640x480, clean and with Gaussian noise 0.1 z/f (seed 0);
- ``<indoor|outdoor>/<variant>``: a synthetic benchmark folder (``--synth``), e.g.
  ``depthnormals synth /tmp/r13-synth --indoor 2 --outdoor 2 --views 4 --seed 0
  --noise gaussian,kinect_v2``.

Protocol: :class:`depthnormals.evaluate.Protocol` defaults (folded errors, 1-pixel border,
NaN estimates dropped and reported as coverage, edge band = within 2 px of a ground-truth
crease > 10 deg or depth jump > 5 %); the errors of a group's frames are pooled.

    python benchmarks/accuracy_matrix.py --methods "3f2n,3f2n+" --synth /tmp/r13-synth \
        --out /tmp/matrix.json [--metrics mean,median,a11,near,smooth,cov] [--pairs]

``--out`` accumulates: methods already in the file are not recomputed (``--force`` redoes).
``--pairs`` prints the ratio of mean errors "<x>+" / "<x>" for every base x listed with its
"+" form (``--plus-suffix '[selection=auto]'``: "<x>+[selection=auto]"; a ratio above 1.005
is marked ``!``; where both errors are below 0.001 deg both are printed).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import depthnormals as dn
from depthnormals.datasets import read_3f2n
from depthnormals.datasets.analytic import analytic_frames
from depthnormals.evaluate import Protocol, discontinuity_mask, parse_method_spec, score_frame
from depthnormals.evaluate._methods import split_method_list

FIXTURE = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "3f2n-torusknot"
SCENES = ("tilted-plane", "box-on-floor", "stairs", "sphere-before-wall")
METRICS = {"mean": "mean", "median": "median", "a11": "a11_25 (%)", "near": "edge band mean",
           "smooth": "smooth mean", "cov": "coverage (%)", "ms": "ms per frame"}


def frames(synth: str | None, which: set[str]):
    """(frame, group, clean depth for the edge band) of every dataset asked for."""
    if "tk" in which:
        for f in read_3f2n(FIXTURE):
            yield f, "tk", f.depth
    if "analytic" in which:
        for f in analytic_frames(scenes=SCENES):
            yield f, f.group, f.meta["clean_depth"]
    if synth and "synth" in which:
        from depthnormals.datasets.synthetic import read_synthetic

        clean: dict[str, np.ndarray] = {}
        for f in read_synthetic(synth):
            kind, scene, variant = f.group.split("/")
            key = f"{kind}/{scene}/{f.name}"
            if variant == "clean":
                clean[key] = f.depth
            yield f, f"{kind}/{variant}", clean.get(key, f.depth)


def run_method(label: str, data: list, proto: Protocol) -> dict[str, dict[str, float]]:
    spec = parse_method_spec(label)
    pooled: dict[str, dict[str, list]] = {}
    for f, group, _clean, near in data:
        t0 = time.perf_counter()
        n = dn.estimate_normals(f.depth, f.K, method=spec.method, **spec.options)
        ms = (time.perf_counter() - t0) * 1e3
        s = score_frame(n, f.normals, mask=f.mask, near=near, protocol=proto)
        used = np.isfinite(s.error)
        g = pooled.setdefault(group, {"err": [], "near": [], "scored": 0, "covered": 0, "ms": []})
        g["err"].append(s.error[used])
        g["near"].append(near[used])
        g["scored"] += s.scored
        g["covered"] += s.covered
        g["ms"].append(ms)
    out = {}
    for group, g in pooled.items():
        e = np.concatenate(g["err"])
        nr = np.concatenate(g["near"])
        out[group] = {"mean": float(e.mean()), "median": float(np.median(e)),
                      "a11": 100.0 * float(np.mean(e < 11.25)),
                      "near": float(e[nr].mean()) if nr.any() else float("nan"),
                      "smooth": float(e[~nr].mean()) if (~nr).any() else float("nan"),
                      "cov": 100.0 * g["covered"] / max(g["scored"], 1),
                      "ms": float(np.median(g["ms"]))}
    return out


def table(results: dict, labels: list[str], groups: list[str], metric: str) -> str:
    lines = [f"### {METRICS[metric]}", "", "| method | " + " | ".join(groups) + " |",
             "|---|" + "---:|" * len(groups)]
    for lab in labels:
        row = results[lab]
        vals = []
        for g in groups:
            col = [results[m][g][metric] for m in labels if g in results[m]]
            v = row.get(g, {}).get(metric, float("nan"))
            best = (max(col) if metric in ("a11", "cov") else min(col)) if col else None
            txt = f"{v:.3f}" if metric not in ("a11", "cov", "ms") else f"{v:.1f}"
            vals.append(f"**{txt}**" if (best is not None and v == best and metric != "ms") else txt)
        lines.append(f"| {lab} | " + " | ".join(vals) + " |")
    return "\n".join(lines)


def pairs(results: dict, labels: list[str], groups: list[str], suffix: str = "") -> str:
    lines = [f"### never hurts: mean error '<x>+{suffix}' / '<x>' ('!' > 1.005)", "",
             "| base | " + " | ".join(groups) + " |", "|---|" + "---:|" * len(groups)]
    for lab in labels:
        plus = lab.split("[", 1)
        plus = plus[0] + "+" + ("[" + plus[1] if len(plus) > 1 else suffix)
        if lab.split("[")[0].endswith("+") or plus not in results:
            continue
        cells = []
        for g in groups:
            a, b = results[plus][g]["mean"], results[lab][g]["mean"]
            if b < 1e-3:  # both exact (e.g. a clean plane): print the errors
                cells.append(f"{a:.4f}/{b:.4f}{'!' if a > b + 1e-3 else ''}")
                continue
            r = a / b
            cells.append(f"{r:.3f}{'!' if r > 1.005 else ''}")
        lines.append(f"| {lab} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--methods", required=True, help="comma-separated specs, e.g. 3f2n+[selection=auto]")
    p.add_argument("--synth", default=None, help="synthetic benchmark folder")
    p.add_argument("--datasets", default="tk,analytic,synth")
    p.add_argument("--out", default=None, help="JSON file to accumulate results in")
    p.add_argument("--force", action="store_true", help="recompute methods already in --out")
    p.add_argument("--metrics", default="mean")
    p.add_argument("--pairs", action="store_true")
    p.add_argument("--plus-suffix", default="",
                   help="options of the '+' forms in --pairs, e.g. '[selection=auto]'")
    p.add_argument("--threads", type=int, default=1)
    a = p.parse_args()
    dn.set_num_threads(a.threads)
    labels = split_method_list(a.methods)
    results: dict = {}
    if a.out and os.path.exists(a.out):
        results = json.loads(Path(a.out).read_text())["results"]
    proto = Protocol()
    todo = [m for m in labels if a.force or m not in results]
    if todo:
        data = []
        for f, group, clean in frames(a.synth, set(a.datasets.split(","))):
            near = discontinuity_mask(f.normals, clean, f.mask, radius=proto.edge_radius,
                                      edge_angle=proto.edge_angle, depth_jump=proto.depth_jump)
            data.append((f, group, clean, near))
        for lab in todo:
            t0 = time.perf_counter()
            results[lab] = run_method(lab, data, proto)
            print(f"# {lab}: {time.perf_counter() - t0:.1f} s", flush=True)
            if a.out:
                tmp = a.out + ".tmp"
                Path(tmp).write_text(json.dumps({"results": results}, indent=1))
                os.replace(tmp, a.out)
    groups: list[str] = []
    for lab in labels:
        for g in results[lab]:
            if g not in groups:
                groups.append(g)
    for metric in a.metrics.split(","):
        print(table(results, labels, groups, metric))
        print()
    if a.pairs:
        print(pairs(results, labels, groups, a.plus_suffix))


if __name__ == "__main__":
    main()
