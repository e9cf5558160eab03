"""``depthnormals synth``: generate an SSN-like synthetic benchmark (clean + noisy variants)."""

from __future__ import annotations

import argparse
from pathlib import Path

#: Seconds of compilation on a cold numba cache (the rasteriser; see ``commands._firstrun``).
FIRST_RUN_S = 5

HELP = "render a synthetic benchmark: asset-mesh and procedural indoor/outdoor scenes, clean and noisy depth"

#: Values of the options a preset may set, when neither the preset nor the command line does.
DEFAULTS = {"indoor": 10, "outdoor": 10, "views": 25, "noise": "kinect_v2", "width": 512, "height": 424,
            "storage": "npy", "scenes": "mixed"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", type=Path, help="output folder (new, empty, or an interrupted run to resume)")
    parser.add_argument("--preset", default=None, choices=("ssn",),
                        help="named settings, overridden by options given explicitly: ssn = 10 indoor + "
                             "10 outdoor scenes x 500 views, 512 x 424, clean + the SSN noise models "
                             "(depthnormals.synth.presets.SSN_NOISE_MODELS), --storage compact")
    parser.add_argument("--indoor", type=int, default=None, help="number of indoor scenes (default 10)")
    parser.add_argument("--outdoor", type=int, default=None, help="number of outdoor scenes (default 10)")
    parser.add_argument("--views", type=int, default=None, help="views per scene (default 25)")
    parser.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    parser.add_argument("--noise", default=None,
                        help="comma-separated noise models, each MODEL[:KEY=VALUE...]: gaussian "
                             "(sigma=M or sigma_px=X, default sigma_px=0.1), kinect_v1, kinect_v2, "
                             "realsense_d4xx (e.g. realsense_d4xx:baseline=0.055), tof; "
                             "'none' for clean only (default kinect_v2)")
    parser.add_argument("--mesh", action="append", default=[], type=Path, metavar="FILE",
                        help="add a user mesh scene (OBJ, PLY, STL, GLB; needs trimesh); repeatable")
    parser.add_argument("--width", type=int, default=None, help="image width (default 512, Kinect v2)")
    parser.add_argument("--height", type=int, default=None, help="image height (default 424)")
    parser.add_argument("--storage", default=None, choices=("npy", "compact"),
                        help="npy: float32 .npy files (format 1, ~5.4 MB per 512 x 424 view with 2 noise "
                             "models); compact: one .npz per view (format 2, ~0.8 MB; normals octahedral "
                             "< 0.003 deg, depth bit-identical) (default npy; compact with --preset ssn)")
    parser.add_argument("--dry-run", action="store_true",
                        help="print the plan (scenes, views, variants, storage) and write nothing")
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
    parser.add_argument("--scenes", default=None, choices=("procedural", "assets", "all", "mixed"),
                        help="scene set: mixed (default: the asset-mesh recipes first, then the "
                             "procedural ones most cluttered first; needs the assets extra: pip install "
                             "'depthnormals[assets]'), procedural (the easy procedural recipes only; "
                             "no extra), assets (asset-mesh recipes only) or all (procedural first)")


def resolve(args: argparse.Namespace) -> dict:
    """The values of the presettable options: the command line's, else the preset's, else
    :data:`DEFAULTS` (``noise`` as the command-line text)."""
    values = dict(DEFAULTS)
    if args.preset is not None:
        from ..synth.presets import preset

        p = preset(args.preset)
        values.update({k: p[k] for k in ("indoor", "outdoor", "views", "storage", "scenes")})
        values["noise"] = ",".join(p["noise"]) or "none"
        values["height"], values["width"] = p["size"]
    values.update({k: getattr(args, k) for k in DEFAULTS if getattr(args, k) is not None})
    return values


def _print_plan(v: dict, noise: list[str]) -> None:
    from ..synth import scene_plan

    plan = scene_plan(v["indoor"], v["outdoor"], scenes=v["scenes"])
    variants = ["clean", *(s.split(":")[0] for s in noise)]
    print(f"plan: {len(plan)} scenes ({v['indoor']} indoor, {v['outdoor']} outdoor) x {v['views']} views = "
          f"{len(plan) * v['views']} views, {v['width']} x {v['height']}; variants {', '.join(variants)} "
          f"({len(plan) * v['views'] * len(variants)} frames); storage {v['storage']}; scenes {v['scenes']}")


def run(args: argparse.Namespace) -> int:
    from ..camera import Intrinsics
    from ..render import KINECT_V2
    from ..synth import PoseConstraints, export_3f2n, generate

    v = resolve(args)
    noise = [] if v["noise"].strip().lower() in ("", "none") else [s.strip() for s in v["noise"].split(",")]
    if args.dry_run:
        _print_plan(v, noise)
        return 0
    if (v["width"], v["height"]) == (512, 424):
        K = KINECT_V2
    else:  # same field of view as the Kinect v2, centred principal point
        f = KINECT_V2.fx * v["width"] / 512.0
        K = Intrinsics(f, f, (v["width"] - 1) / 2.0, (v["height"] - 1) / 2.0)
    try:
        lo, hi = (float(x) for x in args.median_depth.split(","))
    except ValueError as exc:
        raise ValueError(f"--median-depth must be LO,HI in metres; got {args.median_depth!r}") from exc
    constraints = PoseConstraints(min_valid=args.min_valid, median_depth=(lo, hi))
    summary = generate(args.out, indoor=v["indoor"], outdoor=v["outdoor"], views=v["views"],
                       seed=args.seed, noise=noise, meshes=args.mesh, K=K,
                       size=(v["height"], v["width"]), constraints=constraints,
                       progress=not args.no_progress, scheduler=args.scheduler,
                       batch_size=args.batch_size, storage=v["storage"], scenes=v["scenes"])
    print(f"{summary.root}: {summary.frames} views ({summary.written} rendered, {summary.skipped} "
          f"already there) in {summary.seconds:.1f} s; clean render {summary.render_ms_per_frame:.1f} "
          "ms per frame")
    if args.export_3f2n is not None:
        dirs = export_3f2n(summary.root, args.export_3f2n)
        print(f"exported {len(dirs)} scenes to {args.export_3f2n} (3F2N format)")
    return 0
