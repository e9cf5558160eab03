"""``depthnormals estimate``: normals of one depth file.

The command is two layers: :func:`add_arguments` / :func:`run` turn the command line into a
call of :func:`estimate_file`, which does the work (read, estimate, write) and returns an
:class:`EstimateReport`; the exit status follows from the report (:data:`EXIT_NO_VALID_PIXEL`
when the input has no valid depth).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HELP = "estimate the normals of depth images and write them (.npy, .png 16-bit, .vis.png, .ply)"

#: Exit status when no pixel of the input depth is valid (see ``depthnormals --help``).
EXIT_NO_VALID_PIXEL = 3
#: Seconds of compilation on a cold numba cache (see ``depthnormals.commands._firstrun``).
FIRST_RUN_S = 12


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("depth", type=Path, nargs="+",
                        help="depth file: .npy, .png (16-bit), .tif, .bin; or many: files, globs "
                             "('seq/*.png'), folders, dataset folders (then -o is a folder)")
    parser.add_argument("--intrinsics", "-K", type=Path, default=None,
                        help="intrinsics file: .json/.yaml (fx, fy, cx, cy or K) or 3F2N params.txt "
                             "(required for depth files; dataset folders bring their own)")
    parser.add_argument("-o", "--output", type=Path, required=True,
                        help="output: .npy (float32), .png (16-bit), .vis.png (8-bit picture) or .ply "
                             "(point cloud with normals); "
                             "with many inputs, a folder")
    parser.add_argument("--method", "-m", default=None, help="estimator (see `depthnormals methods`)")
    parser.add_argument("--depth-scale", type=float, default=None,
                        help="metres per unit of integer depth (e.g. 0.001 for millimetres)")
    parser.add_argument("--shape", type=parse_shape, default=None, metavar="H,W",
                        help="rows,columns of a raw .bin depth file (default 480,640, the 3F2N "
                             "format); for other formats it must match the file")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="estimator option, e.g. --option kernel=sobel (repeatable; JSON values)")
    many = parser.add_argument_group("many inputs (output folder -o DIR)")
    many.add_argument("--format", default="npy", choices=("npy", "png", "vis.png", "ply"),
                      help="output format of each frame (default npy)")
    many.add_argument("--no-resume", action="store_true",
                      help="recompute frames whose output exists (default: skip them)")
    many.add_argument("--quiet", "-q", action="store_true", help="no progress")
    many.add_argument("--scheduler", default=None, metavar="ADDRESS",
                      help="run on Dask: local, local:N (N worker processes) or tcp://host:port of "
                           "a running `dask scheduler` (needs the dask extra)")
    many.add_argument("--batch-size", type=int, default=16,
                      help="frames per Dask task (default 16)")


def parse_shape(text: str) -> tuple[int, int]:
    """``"480,640"`` -> ``(480, 640)`` (rows, columns)."""
    try:
        h, w = (int(x) for x in text.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"--shape must be H,W (rows,columns), e.g. 480,640; got {text!r}") from exc
    if h < 1 or w < 1:
        raise argparse.ArgumentTypeError(f"--shape must be positive; got {text!r}")
    return h, w


def parse_options(items: list[str]) -> dict:
    """``["a=1", "b=sobel"]`` -> ``{"a": 1, "b": "sobel"}`` (values parsed as JSON when possible)."""
    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"option {item!r} must look like KEY=VALUE")
        key, value = item.split("=", 1)
        try:
            out[key.strip().replace("-", "_")] = json.loads(value)
        except json.JSONDecodeError:
            out[key.strip().replace("-", "_")] = value
    return out


def _many(args: argparse.Namespace) -> bool:
    """The many-frames form: several inputs, a folder or glob, a scheduler, or -o an existing folder."""
    return (len(args.depth) > 1 or args.depth[0].is_dir() or args.output.is_dir()
            or args.scheduler is not None or any(c in str(args.depth[0]) for c in "*?["))


def run_many(args: argparse.Namespace) -> int:
    from ..io import read_intrinsics
    from ..jobs import run_estimate
    from ..registry import DEFAULT_METHOD

    if args.output.suffix.lower() in (".npy", ".png", ".ply") and not args.output.is_dir():
        raise ValueError(f"with many inputs (or --scheduler), -o is a folder; got the file name "
                         f"{args.output} (choose the format with --format)")
    K = read_intrinsics(args.intrinsics) if args.intrinsics is not None else None
    method = args.method or DEFAULT_METHOD
    s = run_estimate(args.depth, args.output, method=method, K=K, options=parse_options(args.option),
                     depth_scale=args.depth_scale, fmt=args.format, resume=not args.no_resume,
                     progress=not args.quiet, scheduler=args.scheduler, batch_size=args.batch_size)
    print(f"{args.output}: {s.planned} frames by {method} ({s.written} computed, {s.skipped} done "
          f"before) in {s.seconds:.1f} s")
    return 0


@dataclass(frozen=True)
class EstimateReport:
    """What :func:`estimate_file` did: output path, size, method, valid inputs and outputs, time."""

    output: Path
    shape: tuple[int, int]
    method: str
    valid_depth: int
    valid_normals: int
    ms: float


def estimate_file(depth_path: Path, intrinsics_path: Path, output: Path, *,
                  method: str | None = None, depth_scale: float | None = None,
                  shape: tuple[int, int] | None = None,
                  options: dict[str, Any] | None = None) -> EstimateReport:
    """Read one depth file and its intrinsics, estimate the normals, write them atomically.

    The normals are written even when no depth pixel is valid (then they are all NaN);
    ``valid_depth == 0`` in the report says so.
    """
    import time

    import numpy as np

    from ..io import read_depth, read_intrinsics, write_normals, write_ply
    from ..registry import DEFAULT_METHOD, estimate_normals

    depth = read_depth(depth_path, depth_scale=depth_scale, shape=shape)
    if shape is not None and depth.shape != tuple(shape):
        raise ValueError(f"{depth_path} holds a {depth.shape[0]} x {depth.shape[1]} depth map; "
                         f"--shape says {shape[0]} x {shape[1]}")
    K = read_intrinsics(intrinsics_path)
    method = method or DEFAULT_METHOD
    t0 = time.perf_counter()
    normals = estimate_normals(depth, K, method=method, **(options or {}))
    ms = (time.perf_counter() - t0) * 1e3
    if output.suffix.lower() == ".ply":  # a point cloud: valid points with their normals
        write_ply(output, depth, K, normals)
    else:
        write_normals(output, normals)
    valid_depth = int(np.count_nonzero(np.isfinite(depth) & (depth > 0)))
    valid = int(np.count_nonzero(np.isfinite(normals[..., 0])))
    return EstimateReport(output, depth.shape, method, valid_depth, valid, ms)


def run(args: argparse.Namespace) -> int:
    if _many(args):
        return run_many(args)
    args.depth = args.depth[0]
    if args.intrinsics is None:
        raise ValueError("--intrinsics/-K is required for a depth file")
    rep = estimate_file(args.depth, args.intrinsics, args.output, method=args.method,
                        depth_scale=args.depth_scale, shape=args.shape,
                        options=parse_options(args.option))
    print(f"{rep.output}: {rep.shape[1]}x{rep.shape[0]} normals by {rep.method} "
          f"({rep.valid_normals} valid pixels, {rep.ms:.1f} ms)")
    if rep.valid_depth == 0:
        print(f"depthnormals estimate: warning: no pixel of {args.depth} holds a valid depth "
              "(all are 0, negative, NaN or inf), so every normal is NaN; check the file, "
              "--depth-scale and --shape", file=sys.stderr)
        return EXIT_NO_VALID_PIXEL
    return 0
