"""Every estimator on faces narrower than about 5 px, and the map there (session 40, issue 24).

The default map's misses on the preset's ``kinect_v1`` and ``realsense_d4xx`` columns lie on
the pixels within 3 px of a face narrower than about 5 px (``uncertainty_calibration.py
--thin``; :func:`uncertainty_calibration.thin_labels` on the exact normals): there the map
reads about half the observed error, elsewhere it passes. This script asks whether those
faces are in the depth at all: per sensor column of a ``depthnormals synth`` dataset, the mean
angular error (deg, against the exact normals, the dataset's mask) of each method on the thin
part and on the rest, over the pixels where every method gives a normal (PCL's estimators
abstain by jumps, which are most of the thin part), and the default's map (``3f2n+`` with
``return_uncertainty=True``, its mean prediction) on the same pixels.

    for N in gaussian kinect_v1 kinect_v2 tof realsense_d4xx; do
        depthnormals synth /tmp/u-ssn --preset ssn --views 4 --noise $N; done
    python benchmarks/thin_faces.py /tmp/u-ssn --every 3 [--json out.json]

``--every K`` scores every K-th view (all variants of a view together).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

import depthnormals as dn
from depthnormals.evaluate import parse_method_spec
from depthnormals.evaluate._methods import split_method_list

sys.path.insert(0, str(Path(__file__).resolve().parent))
from uncertainty_calibration import thin_labels  # the --thin split, one definition

PEERS = "3f2n,d2nt,fals,pcl-covariance-matrix,plane-svd"
DEFAULT = "3f2n+"


class Part:
    """Sums over one part (thin or resolved) of one column: pixels, each method's error sum and
    the default's predicted error sum."""

    def __init__(self, methods: list[str]) -> None:
        self.pixels = 0
        self.err = dict.fromkeys(methods, 0.0)
        self.pred = 0.0

    def add(self, mask: np.ndarray, errs: dict[str, np.ndarray], pred: np.ndarray) -> None:
        self.pixels += int(mask.sum())
        for m, e in errs.items():
            self.err[m] += float(e[mask].sum(dtype=np.float64))
        self.pred += float(pred[mask].sum(dtype=np.float64))

    def means(self) -> dict[str, Any]:
        n = max(self.pixels, 1)
        return {"pixels": self.pixels, "predicted": self.pred / n,
                "error": {m: s / n for m, s in self.err.items()}}


def thin_table(frames, methods: list[str]) -> dict[str, dict[str, Part]]:
    """``{variant: {"thin": Part, "resolved": Part}}`` over ``frames`` (synthetic frames with
    exact normals; the clean variant included): the pixels where every method of ``methods``
    (``DEFAULT`` first, whose map is read too) gives a normal, split by :func:`thin_labels`."""
    specs = {m: parse_method_spec(m) for m in methods}
    out: dict[str, dict[str, Part]] = {}
    for f in frames:
        variant = f.meta.get("variant", f.group.rsplit("/", 1)[-1])
        errs, pred = {}, None
        for m, s in specs.items():
            if m == DEFAULT:
                n, pred = dn.estimate_normals(f.depth, f.K, method=s.method,
                                              return_uncertainty=True, **s.options)
            else:
                n = dn.estimate_normals(f.depth, f.K, method=s.method, **s.options)
            errs[m] = dn.angular_error(n, f.normals)
        common = np.ones(f.depth.shape, dtype=bool) if f.mask is None else f.mask.copy()
        for e in errs.values():
            common &= np.isfinite(e)
        thin = thin_labels(f.normals)
        parts = out.setdefault(variant, {"thin": Part(methods), "resolved": Part(methods)})
        parts["thin"].add(common & thin, errs, pred)
        parts["resolved"].add(common & ~thin, errs, pred)
    return out


def main(argv: list[str] | None = None) -> int:
    from depthnormals.datasets.synthetic import read_synthetic

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--methods", default=PEERS, help=f"peers of {DEFAULT} (comma-separated specs)")
    ap.add_argument("--every", type=int, default=1, help="score every K-th view")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args(argv)
    if a.every < 1:
        ap.error("--every must be at least 1")
    methods = [DEFAULT, *[m for m in split_method_list(a.methods) if m != DEFAULT]]
    views: dict[tuple[str, str], int] = {}

    def picked(f) -> bool:
        view = (f.group.rsplit("/", 1)[0], f.name)
        return views.setdefault(view, len(views)) % a.every == 0

    table = thin_table((f for f in read_synthetic(a.dataset) if picked(f)), methods)
    result = {v: {k: p.means() for k, p in parts.items()} for v, parts in table.items()}
    for v, parts in result.items():
        t, r = parts["thin"], parts["resolved"]
        share = 100.0 * t["pixels"] / max(t["pixels"] + r["pixels"], 1)
        print(f"\n{v}: thin part {t['pixels']} px ({share:.1f} % of the common pixels)")
        print(f"  {'method':28s} {'thin':>8s} {'rest':>8s}")
        for m in methods:
            print(f"  {m:28s} {t['error'][m]:8.2f} {r['error'][m]:8.2f}")
        print(f"  {DEFAULT + ' map (predicted)':28s} {t['predicted']:8.2f} {r['predicted']:8.2f}")
    if a.json:
        from depthnormals.io import write_bytes_atomic

        write_bytes_atomic(a.json, json.dumps({"dataset": str(a.dataset), "every": a.every,
                                               "methods": methods, "columns": result},
                                              indent=1).encode())
    return 0


if __name__ == "__main__":
    sys.exit(main())
