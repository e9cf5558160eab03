"""``depthnormals synth``: generate an SSN-like synthetic benchmark (clean + noisy variants)."""

from __future__ import annotations

import argparse
from pathlib import Path

#: Seconds of compilation on a cold numba cache (the rasteriser; see ``commands._firstrun``).
FIRST_RUN_S = 5

HELP = "render a synthetic benchmark: procedural indoor/outdoor scenes, clean and noisy depth"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", type=Path, help="output folder (new, empty, or an interrupted run to resume)")
    parser.add_argument("--indoor", type=int, default=10, help="number of indoor scenes (default 10)")
    parser.add_argument("--outdoor", type=int, default=10, help="number of outdoor scenes (default 10)")
    parser.add_argument("--views", type=int, default=25, help="views per scene (default 25)")
    parser.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    parser.add_argument("--noise", default="kinect_v2",
                        help="comma-separated noise models, each MODEL[:KEY=VALUE...]: gaussian "
                             "(sigma=M or sigma_px=X, default sigma_px=0.1), kinect_v1, kinect_v2, "
                             "realsense_d4xx (e.g. realsense_d4xx:baseline=0.055), tof; "
                             "'none' for clean only (default kinect_v2)")
    parser.add_argument("--mesh", action="append", default=[], type=Path, metavar="FILE",
                        help="add a user mesh scene (OBJ, PLY, STL, GLB; needs trimesh); repeatable")
    parser.add_argument("--width", type=int, default=512, help="image width (default 512, Kinect v2)")
    parser.add_argument("--height", type=int, default=424, help="image height (default 424)")
    parser.add_argument("--min-valid", type=float, default=0.9,
                        help="camera poses must see a surface in this share of pixels (default 0.9; "
                             "lower it for single-object meshes)")
    parser.add_argument("--median-depth", default="0.8,4.0", metavar="LO,HI",
                        help="camera poses must have their median depth in LO..HI metres (default 0.8,4.0)")
    parser.add_argument("--export-3f2n", type=Path, default=None, metavar="DIR",
                        help="also export the clean frames to the 3F2N format in DIR")
    parser.add_argument("--no-progress", action="store_true",
                        help="no progress on stderr (a bar on a terminal, one line per view otherwise)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="render on Dask: local, local:N (N worker processes) or tcp://host:port "
                             "of a running `dask scheduler` (needs the dask extra)")
    parser.add_argument("--batch-size", type=int, default=16, help="views per Dask task (default 16)")
    parser.add_argument("--scenes", default="procedural", choices=("procedural", "assets", "all"),
                        help="scene set: procedural recipes (default), recipes built from real asset "
                             "meshes (needs the assets extra: pip install 'depthnormals[assets]'), or all")


def run(args: argparse.Namespace) -> int:
    from ..camera import Intrinsics
    from ..render import KINECT_V2
    from ..synth import PoseConstraints, export_3f2n, generate

    noise = [] if args.noise.strip().lower() in ("", "none") else [s.strip() for s in args.noise.split(",")]
    if (args.width, args.height) == (512, 424):
        K = KINECT_V2
    else:  # same field of view as the Kinect v2, centred principal point
        f = KINECT_V2.fx * args.width / 512.0
        K = Intrinsics(f, f, (args.width - 1) / 2.0, (args.height - 1) / 2.0)
    try:
        lo, hi = (float(x) for x in args.median_depth.split(","))
    except ValueError as exc:
        raise ValueError(f"--median-depth must be LO,HI in metres; got {args.median_depth!r}") from exc
    constraints = PoseConstraints(min_valid=args.min_valid, median_depth=(lo, hi))
    summary = generate(args.out, indoor=args.indoor, outdoor=args.outdoor, views=args.views,
                       seed=args.seed, noise=noise, meshes=args.mesh, K=K,
                       size=(args.height, args.width), constraints=constraints,
                       progress=not args.no_progress, scheduler=args.scheduler,
                       batch_size=args.batch_size, scenes=args.scenes)
    print(f"{summary.root}: {summary.frames} views ({summary.written} rendered, {summary.skipped} "
          f"already there) in {summary.seconds:.1f} s; clean render {summary.render_ms_per_frame:.1f} "
          "ms per frame")
    if args.export_3f2n is not None:
        dirs = export_3f2n(summary.root, args.export_3f2n)
        print(f"exported {len(dirs)} scenes to {args.export_3f2n} (3F2N format)")
    return 0
