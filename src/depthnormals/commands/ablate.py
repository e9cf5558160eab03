"""``depthnormals ablate``: the 3F2N+ paper's ablation tables on any dataset folder.

Table 1 (the paper's Table I): central tendency x gradient filter x depth curvature, each
cell 3F2N with that filter and third filter, followed by the curvature selection of the DDM.
Table 2 (the paper's Table II): 3F2N vs 3F2N + Pearson vs 3F2N + Kendall (selections alone),
plus the readings and the full CRF. Errors: mean angular error in degrees, folded, over the
frame's valid ground truth minus a 1-pixel border, mean of the per-frame means per group.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..datasets.analytic import analytic_frames

#: Seconds of compilation on a cold numba cache (see ``depthnormals.commands._firstrun``).
FIRST_RUN_S = 80

HELP = "print the 3F2N+ ablation tables (Table I / II of the paper) for a dataset folder"

TABLE1_AGGREGATES = ("median", "mean", "trimean", "trimmed-mean")
TABLE1_CURVATURES = ("normal", "gauss", "max", "mean", "pixel-mean")
#: The paper's selections: every row but the last passes ``selection="curvature"`` (the
#: module's default is the noise-aware ``"auto"`` since issue 13, which is the box-fit on
#: noisy depth); the last row is that default.
_PAPER = {"selection": "curvature"}
TABLE2_ROWS = (
    ("3F2N", None),
    ("3F2N+ w/ Pearson", {**_PAPER, "curvature": "none", "correlation": "pearson", "crf": False}),
    ("3F2N+ w/ Kendall", {**_PAPER, "curvature": "none", "correlation": "kendall", "crf": False}),
    ("3F2N+ w/ Kendall (prose: argmax)",
     {**_PAPER, "curvature": "none", "correlation": "kendall-prose", "crf": False}),
    ("3F2N+ mean curvature (paper: plain arg-min)",
     {**_PAPER, "self_weight": 1.0, "consistency": None}),
    ("3F2N+ mean curvature, self_weight 0.8", {**_PAPER, "consistency": None}),
    ("3F2N+ mean curvature + consistency 0.1", {**_PAPER, "consistency": 0.1}),
    ("3F2N+ mean + Kendall + CRF",
     {**_PAPER, "correlation": "kendall", "crf": True, "consistency": None}),
    ("3F2N+ mean + Pearson + CRF",
     {**_PAPER, "correlation": "pearson", "crf": True, "consistency": None}),
    ("3F2N+ mean + CRF (no correlation)",
     {**_PAPER, "correlation": "none", "crf": True, "consistency": None}),
    ("3F2N+ default (selection auto)", {}),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", type=Path, nargs="?", default=None,
                        help="any dataset folder depthnormals.datasets.open reads")
    parser.add_argument("--table", type=int, choices=(1, 2), required=True,
                        help="1: central tendency x filter x curvature; 2: correlations")
    parser.add_argument("--analytic", action="store_true",
                        help="use the built-in analytic scenes (clean and noisy) instead")
    parser.add_argument("--kernels", default="fd,roberts",
                        help="gradient filters for table 1 (comma-separated; default fd,roberts)")
    parser.add_argument("--noise", type=float, default=0.1,
                        help="noise of the noisy analytic frames, in units of z / f (default 0.1)")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    parser.add_argument("--limit", type=int, default=None, help="at most this many frames")
    parser.add_argument("--quiet", "-q", action="store_true",
                        help="no progress on stderr (one line per frame and table-1 row group "
                             "otherwise)")


def _score(n: np.ndarray, frame) -> float:
    from ..metrics import normal_metrics

    m = frame.mask.copy()
    m[0] = m[-1] = False
    m[:, 0] = m[:, -1] = False
    return normal_metrics(n, frame.normals, mask=m, folded=True).mean


def _print(title: str, groups: list[str], rows: list[tuple[str, dict[str, list[float]]]]) -> None:
    width = max(len(r[0]) for r in rows) + 2
    col = max(10, *(len(g) + 2 for g in groups))
    print(title)
    print("".ljust(width) + "".join(g.rjust(col) for g in groups))
    for label, vals in rows:
        print(label.ljust(width) + "".join(f"{np.mean(vals[g]):{col}.3f}" for g in groups))


def run(args: argparse.Namespace) -> int:
    from .. import datasets
    from .._progress import Progress
    from ..ddm import discontinuity_discrimination
    from ..estimators import three_filters_to_normal

    if args.analytic == (args.dataset is not None):
        raise ValueError("pass a DATASET folder or --analytic (exactly one)")
    frames = analytic_frames(args.noise, args.seed) if args.analytic else datasets.open(args.dataset)
    kernels = [k.strip() for k in args.kernels.split(",") if k.strip()]
    bar = Progress("ablate", unit="step", enabled=not args.quiet)
    results: dict[str, dict[str, list[float]]] = {}
    groups: list[str] = []
    for i, fr in enumerate(frames):
        if args.limit is not None and i >= args.limit:
            break
        g = fr.group or "all"
        if g not in groups:
            groups.append(g)
        if args.table == 1:
            for agg in TABLE1_AGGREGATES:
                bar.update(line=f"ablate: frame {i + 1} {g}/{fr.name}: {agg} x "
                                f"{', '.join(kernels)} x {len(TABLE1_CURVATURES) + 1} curvatures")
                for ker in kernels:
                    base = three_filters_to_normal(fr.depth, fr.K, kernel=ker, aggregate=agg)
                    label = f"{agg:<13} {ker:<8} none"
                    results.setdefault(label, {}).setdefault(g, []).append(_score(base, fr))
                    for curv in TABLE1_CURVATURES:
                        # the paper's selection: plain arg-min, the pixel winning ties
                        n = discontinuity_discrimination(base, fr.depth, fr.K, curvature=curv,
                                                         selection="curvature", self_weight=1.0,
                                                         consistency=None)
                        label = f"{agg:<13} {ker:<8} {curv}"
                        results.setdefault(label, {}).setdefault(g, []).append(_score(n, fr))
        else:
            bar.update(line=f"ablate: frame {i + 1} {g}/{fr.name}: {len(TABLE2_ROWS)} rows")
            base = three_filters_to_normal(fr.depth, fr.K)
            for label, opts in TABLE2_ROWS:
                n = base if opts is None else discontinuity_discrimination(
                    base, fr.depth, fr.K, **opts)
                results.setdefault(label, {}).setdefault(g, []).append(_score(n, fr))
    bar.close()
    if not groups:
        raise ValueError("the dataset has no frames")
    title = ("Table 1: e_A (deg) by central tendency, gradient filter, depth curvature"
             if args.table == 1 else "Table 2: e_A (deg), 3F2N vs correlation-based DDM")
    _print(title, groups, list(results.items()))
    return 0
