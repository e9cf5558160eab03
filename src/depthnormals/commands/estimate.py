"""``depthnormals estimate``: normals of one depth file."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "estimate the normals of depth images and write them (.npy, .png 16-bit, .vis.png)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("depth", type=Path, nargs="+",
                        help="depth file: .npy, .png (16-bit), .tif, .bin; or many: files, globs "
                             "('seq/*.png'), folders, dataset folders (then -o is a folder)")
    parser.add_argument("--intrinsics", "-K", type=Path, default=None,
                        help="intrinsics file: .json/.yaml (fx, fy, cx, cy or K) or 3F2N params.txt "
                             "(required for depth files; dataset folders bring their own)")
    parser.add_argument("-o", "--output", type=Path, required=True,
                        help="output: .npy (float32), .png (16-bit) or .vis.png (8-bit picture); "
                             "with many inputs, a folder")
    parser.add_argument("--method", "-m", default=None, help="estimator (see `depthnormals methods`)")
    parser.add_argument("--depth-scale", type=float, default=None,
                        help="metres per unit of integer depth (e.g. 0.001 for millimetres)")
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


def run(args: argparse.Namespace) -> int:
    import time

    if _many(args):
        return run_many(args)
    args.depth = args.depth[0]
    if args.intrinsics is None:
        raise ValueError("--intrinsics/-K is required for a depth file")

    from ..io import read_depth, read_intrinsics, write_normals
    from ..registry import DEFAULT_METHOD, estimate_normals

    depth = read_depth(args.depth, depth_scale=args.depth_scale)
    K = read_intrinsics(args.intrinsics)
    method = args.method or DEFAULT_METHOD
    t0 = time.perf_counter()
    normals = estimate_normals(depth, K, method=method, **parse_options(args.option))
    ms = (time.perf_counter() - t0) * 1e3
    write_normals(args.output, normals)
    valid = int((normals[..., 0] == normals[..., 0]).sum())
    print(f"{args.output}: {normals.shape[1]}x{normals.shape[0]} normals by {method} "
          f"({valid} valid pixels, {ms:.1f} ms)")
    return 0
