"""``depthnormals evaluate``: run estimators over a dataset and write tables and figures."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

#: Seconds of compilation on a cold numba cache, for 3f2n+ (see ``commands._firstrun``).
FIRST_RUN_S = 14

HELP = ("evaluate estimators on a dataset: results.csv, summary tables, figures "
        "(resumes an interrupted run)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", type=Path,
                        help="dataset folder (any layout `depthnormals.datasets.open` reads)")
    parser.add_argument("--methods", "-m", required=True,
                        help="comma-separated names from `depthnormals methods`, options in "
                             "brackets: 3f2n,d2nt,\"3f2n[aggregate=mean]\"")
    parser.add_argument("--out", "-o", type=Path, required=True, help="output folder")
    parser.add_argument("--errors", choices=("folded", "signed"), default="folded",
                        help="fold errors above 90 deg (3F2N protocol, default) or not")
    parser.add_argument("--border", type=int, default=1,
                        help="border width in pixels left out of the score (default 1)")
    parser.add_argument("--invalid", choices=("drop", "score90"), default="drop",
                        help="NaN estimates: dropped, coverage reported (default), or scored "
                             "as 90 deg")
    parser.add_argument("--edge-radius", type=int, default=2,
                        help="'near a discontinuity' radius in pixels (default 2)")
    parser.add_argument("--edge-angle", type=float, default=10.0,
                        help="ground-truth crease threshold in degrees (default 10)")
    parser.add_argument("--depth-jump", type=float, default=0.05,
                        help="relative depth jump that makes an occlusion edge (default 0.05)")
    parser.add_argument("--option", action="append", default=[], metavar="METHOD:KEY=VALUE",
                        help="option for one method (label or name), e.g. 3f2n:kernel=sobel "
                             "(repeatable; JSON values)")
    parser.add_argument("--frames", type=int, default=None,
                        help="evaluate only the first N frames")
    parser.add_argument("--group-levels", default=None, metavar="I,J,...",
                        help="summarise by these '/'-separated components of the group names "
                             "(0-based), e.g. 0,2: indoor/room-03/clean -> indoor/clean")
    parser.add_argument("--figures", type=int, default=3,
                        help="Fig. 3 layouts for the first frame of up to N groups (default 3; "
                             "0: no figures; skipped with a warning when matplotlib is missing)")
    parser.add_argument("--figure-method", default=None,
                        help="method whose estimate is panel (iii) (default: the last)")
    parser.add_argument("--error-vmax", type=float, default=20.0,
                        help="top of the error colour scale in degrees (default 20)")
    parser.add_argument("--threads", type=int, default=None,
                        help="threads of the estimators (default: all cores; recorded in "
                             "settings.json)")
    parser.add_argument("--no-resume", action="store_true",
                        help="recompute every (frame, method) even if an earlier run finished it")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="estimate and score on Dask: local, local:N (N worker processes) or "
                             "tcp://host:port of a running `dask scheduler` (needs the dask extra)")
    parser.add_argument("--batch-size", type=int, default=8, help="frames per Dask task (default 8)")
    parser.add_argument("--reference", choices=("gt", "planes"), default="gt",
                        help="score against the ground-truth normals (default) or, for real "
                             "sensor data without them, against the frame's large planes "
                             "(planes.json, planes.md, one figure per frame; docs/evaluation.md)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the plane reference's RANSAC (--reference planes)")


def parse_method_options(items: list[str]) -> dict[str, dict]:
    """``["3f2n:kernel=sobel"]`` -> ``{"3f2n": {"kernel": "sobel"}}`` (JSON values)."""
    from .estimate import parse_options

    out: dict[str, dict] = {}
    for item in items:
        if ":" not in item.split("=", 1)[0]:
            raise ValueError(f"--option {item!r} must look like METHOD:KEY=VALUE")
        method, rest = item.split(":", 1)
        out.setdefault(method.strip(), {}).update(parse_options([rest]))
    return out


def _levels(text: str | None) -> list[int] | None:
    if text is None:
        return None
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError as exc:
        raise ValueError(f"--group-levels {text!r} must be comma-separated integers") from exc


def figures_or_skip(requested: int, command: str = "evaluate") -> int:
    """``requested`` if matplotlib can be imported, else 0 after ONE warning on stderr."""
    if requested <= 0:
        return requested
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print(f"depthnormals {command}: warning: matplotlib is not installed, so the figures "
              "are skipped (tables and results are written as usual); pip install "
              "'depthnormals[plot]' to draw them, or pass --figures 0 to silence this",
              file=sys.stderr)
        return 0
    return requested


def run_planes(args: argparse.Namespace) -> int:
    """``--reference planes``: :func:`depthnormals.evaluate.run_plane_evaluation`."""
    from ..evaluate import run_plane_evaluation

    res = run_plane_evaluation(
        args.dataset, args.methods, args.out, method_options=parse_method_options(args.option),
        frames=args.frames, figures=figures_or_skip(args.figures) > 0, seed=args.seed,
        threads=args.threads, progress=not args.quiet)
    print(res.table.strip())
    print(f"\n{len(res.frames)} frames -> {res.out_dir / 'planes.json'}, planes.md"
          + (f", {len(res.figures)} figures" if res.figures else ""))
    return 0


def _require_truth(dataset: Path) -> None:
    """A dataset without ground-truth normals (real sensors, TUM, ...) needs ``--reference
    planes``; say so before any estimate runs."""
    from .. import datasets

    if not dataset.exists():
        return  # run_evaluation reports the missing path
    first = next(iter(datasets.open(dataset)), None)
    if first is not None and first.normals is None:
        raise ValueError(f"{dataset} has no ground-truth normals ({first.meta.get('format', '?')} "
                         "layout); score it against its planes with --reference planes")


def run(args: argparse.Namespace) -> int:
    from ..cluster import check_batch_size
    from ..evaluate import Protocol, run_evaluation, summary_markdown

    if getattr(args, "reference", "gt") == "planes":
        return run_planes(args)
    _require_truth(args.dataset)

    protocol = Protocol(folded=args.errors == "folded", border=args.border, invalid=args.invalid,
                        edge_radius=args.edge_radius, edge_angle=args.edge_angle,
                        depth_jump=args.depth_jump)
    resume = not args.no_resume
    check_batch_size(args.batch_size)  # refused with or without a scheduler
    if args.scheduler is not None:  # the (frame, method) parts on Dask; the run below reuses them
        from ..evaluate._cluster import compute_parts

        compute_parts(args.dataset, args.methods, args.out, scheduler=args.scheduler, protocol=protocol,
                      method_options=parse_method_options(args.option), frames=args.frames,
                      resume=resume, batch_size=args.batch_size, progress=not args.quiet)
        resume = True
    res = run_evaluation(
        args.dataset, args.methods, args.out, protocol=protocol,
        method_options=parse_method_options(args.option), frames=args.frames,
        group_levels=_levels(args.group_levels),
        figures=figures_or_skip(args.figures), figure_method=args.figure_method,
        error_vmax=args.error_vmax, threads=args.threads, resume=resume,
        progress=not args.quiet,
    )
    labels = [m["label"] for m in res.settings["methods"]]
    table = summary_markdown(res.summary, labels).split("\n\n## ")[1]
    print("## " + table.strip())
    print(f"\n{len(res.rows)} rows ({res.computed} computed, {res.reused} reused from an "
          f"earlier run) -> {res.out_dir / 'results.csv'}, summary.md, summary.json, "
          f"settings.json" + (f", {len(res.figures)} figures" if res.figures else ""))
    return 0
