"""``depthnormals estimate``: normals of one depth file."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "estimate the normals of a depth image and write them (.npy, .png 16-bit, .vis.png)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("depth", type=Path, help="depth file: .npy, .png (16-bit), .tif, .bin")
    parser.add_argument("--intrinsics", "-K", type=Path, required=True,
                        help="intrinsics file: .json/.yaml (fx, fy, cx, cy or K) or 3F2N params.txt")
    parser.add_argument("-o", "--output", type=Path, required=True,
                        help="output: .npy (float32), .png (16-bit) or .vis.png (8-bit picture)")
    parser.add_argument("--method", "-m", default=None, help="estimator (see `depthnormals methods`)")
    parser.add_argument("--depth-scale", type=float, default=None,
                        help="metres per unit of integer depth (e.g. 0.001 for millimetres)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="estimator option, e.g. --option kernel=sobel (repeatable; JSON values)")


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


def run(args: argparse.Namespace) -> int:
    import time

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
