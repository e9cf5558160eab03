"""``depthnormals estimate``: normals of one depth file.

The command is two layers: :func:`add_arguments` / :func:`run` turn the command line into a
call of :func:`estimate_file`, which does the work (read, estimate, write) and returns an
:class:`EstimateReport`; the exit status follows from the report (:data:`EXIT_NO_VALID_PIXEL`
when the input has no valid depth).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HELP = "estimate the normals of depth images and write them (.npy, .png 16-bit, .vis.png, .ply)"

#: Output suffixes of the one-file form, and what each holds.
OUTPUTS = ".npy (float32), .png (16-bit), .vis.png (8-bit picture) or .ply (point cloud with normals)"

#: Exit status when no pixel of the input depth is valid (see ``depthnormals --help``).
EXIT_NO_VALID_PIXEL = 3
#: Seconds of compilation on a cold numba cache (see ``depthnormals.commands._firstrun``).
FIRST_RUN_S = 12


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("depth", type=Path, nargs="+",
                        help="depth file: .npy, .png (16-bit), .pgm (NYU raw), .tif, .bin; or many: files, "
                             "globs ('seq/*.png'), folders, dataset folders or files (a ROS bag, "
                             "a RealSense recording) (then -o is a folder; colour images found "
                             "there are skipped and counted)")
    parser.add_argument("--intrinsics", "-K", type=Path, default=None,
                        help="camera file: .json/.yaml (fx, fy, cx, cy, K or P; ROS camera_info; Open3D "
                             "intrinsic_matrix; optional depth_scale, invalid, max_depth) or .txt (3x3 K, "
                             "3x4 P, or 3F2N params.txt), or the camera inline as fx,fy,cx,cy "
                             "(e.g. -K 525,525,319.5,239.5) (required for depth files; dataset "
                             "folders bring their own)")
    parser.add_argument("-o", "--output", type=Path, required=True,
                        help="output: .npy (float32), .png (16-bit), .vis.png (8-bit picture) or .ply "
                             "(point cloud with normals); "
                             "with many inputs, a folder")
    parser.add_argument("--method", "-m", default=None, help="estimator (see `depthnormals methods`)")
    parser.add_argument("--depth-scale", type=float, default=None,
                        help="metres per unit of integer depth (e.g. 0.001 for millimetres); default "
                             "the camera file's depth_scale")
    parser.add_argument("--invalid", type=parse_codes, default=None, metavar="V[,V...]",
                        help="raw depth values that mark invalid pixels, e.g. 65535 or 0,2047 (default "
                             "the camera file's invalid list; 0, NaN and inf are always invalid)")
    parser.add_argument("--max-depth", type=float, default=None, metavar="METRES",
                        help="depth beyond this is invalid (default the camera file's max_depth, else none)")
    parser.add_argument("--distortion", type=parse_distortion, default=None,
                        metavar="K1,K2,P1,P2[,K3[,K4,K5,K6]]",
                        help="the lens distortion of the depth images, OpenCV's order (4, 5, 8 or 12 "
                             "numbers): each is resampled onto the pinhole grid of its camera first "
                             "(nearest pixel), dataset frames too (a real-sensor folder or ROS bag "
                             "that gives its own lens is undistorted by its reader, and such a frame "
                             "refuses it: it would be undone twice); default the camera file's "
                             "distortion, else none")
    parser.add_argument("--vis", default="3f2n", choices=("3f2n", "open3d"),
                        help=".vis.png colouring: 3f2n = (1 - n) / 2 (default, the 3F2N papers'), "
                             "open3d = (n + 1) / 2 (Open3D's and most viewers')")
    parser.add_argument("--shape", type=parse_shape, default=None, metavar="H,W",
                        help="rows,columns of a raw .bin depth file (default 480,640, the 3F2N "
                             "format); for other formats it must match the file")
    parser.add_argument("--uncertainty", action="store_true",
                        help="also write the expected angular error (deg, float32) of every normal to "
                             "<name>.uncertainty.npy beside the output (3f2n+, fals, PCL's modes, "
                             "plane-svd, plane-pca); "
                             "a .ply output also gets it as the per-point float 'uncertainty'")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="estimator option, e.g. --option kernel=sobel (repeatable; JSON values)")
    many = parser.add_argument_group("many inputs (output folder -o DIR)")
    many.add_argument("--format", default="npy", choices=("npy", "png", "vis.png", "ply"),
                      help="output format of each frame (default npy)")
    many.add_argument("--no-resume", action="store_true",
                      help="recompute every frame, also over outputs of other settings (default: "
                           "skip outputs whose folder manifest holds the same settings, refuse "
                           "a folder made with other ones)")
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


def parse_codes(text: str) -> tuple[float, ...]:
    """``"0,65535"`` -> ``(0.0, 65535.0)``: the raw values of ``--invalid``."""
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"--invalid must be comma-separated numbers, e.g. 65535 or 0,2047; got {text!r}") from exc


def parse_distortion(text: str) -> tuple[float, ...]:
    """``"0.1,-0.2,0,0"`` -> ``(0.1, -0.2, 0.0, 0.0)``: the coefficients of ``--distortion``
    (4, 5, 8 or 12, OpenCV's order)."""
    from ..camera import check_distortion

    try:
        return check_distortion([float(x) for x in text.split(",") if x.strip()], "--distortion")
    except (TypeError, ValueError) as exc:
        raise argparse.ArgumentTypeError(
            f"--distortion must be 4, 5, 8 or 12 comma-separated numbers in OpenCV's order "
            f"(k1,k2,p1,p2[,k3[,k4,k5,k6[,s1,s2,s3,s4]]]); got {text!r}") from exc


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
    """The many-frames form: several inputs, a folder or glob, a dataset file (a ROS bag, NYU's
    labeled ``.mat``), a scheduler, or -o an existing folder."""
    from ..jobs import is_dataset_file

    return (len(args.depth) > 1 or args.depth[0].is_dir() or args.output.is_dir()
            or args.scheduler is not None or any(c in str(args.depth[0]) for c in "*?[")
            or is_dataset_file(args.depth[0]))


@dataclass(frozen=True)
class ReadSettings:
    """How depth files are read: the command line's values, else the camera file's."""

    depth_scale: float | None
    invalid: tuple[float, ...]
    max_depth: float | None
    distortion: tuple[float, ...] = ()


def read_settings(args: argparse.Namespace, camera: Any) -> ReadSettings:
    """``--depth-scale`` / ``--invalid`` / ``--max-depth`` / ``--distortion``, each defaulting
    to the camera file's ``depth_scale`` / ``invalid`` / ``max_depth`` / ``distortion``
    (:func:`depthnormals.io.read_camera_file`)."""
    from .._validate import check_positive
    from ..camera import lens_distortion

    encoding = _encoding(camera)
    if encoding != "linear":
        raise ValueError(f"{camera.source} declares the depth encoding {encoding!r}, which a depth file "
                         "read with -K cannot decode (linear depth only); pass the folder that holds "
                         "it as the input instead (its dataset reader decodes it), without -K")
    scale = args.depth_scale if args.depth_scale is not None else getattr(camera, "depth_scale", None)
    invalid = args.invalid if args.invalid is not None else getattr(camera, "invalid", ())
    max_depth = args.max_depth if args.max_depth is not None else getattr(camera, "max_depth", None)
    check_positive(scale, "--depth-scale", allow_none=True)
    check_positive(max_depth, "--max-depth", allow_none=True)
    dist = args.distortion if args.distortion is not None else getattr(camera, "distortion", ())
    ros = getattr(camera, "ros_distortion", ())
    if ros and args.distortion is None and not dist:
        print(f"depthnormals estimate: note: {camera.source} gives the lens distortion D = "
              f"{list(ros)} (ROS camera_info), which is not applied: ROS depth topics are taken as "
              "rectified (image_rect); for an image_raw stream pass --distortion "
              f"{','.join(format(c, '.10g') for c in ros)}", file=sys.stderr)
    other = getattr(camera, "ros_other_lens", "")
    if other and args.distortion is None and not dist:
        print(f"depthnormals estimate: note: {camera.source} gives a lens distortion of model "
              f"{other!r} (ROS camera_info), which is not applied: ROS depth topics are taken as "
              "rectified (image_rect), and depthnormals.undistort_depth cannot undo it as given "
              "(OpenCV's models, plumb_bob / rational_polynomial / Brown Conrady, with 4, 5, 8 or "
              "12 finite coefficients); "
              "rectify an image_raw stream first", file=sys.stderr)
    return ReadSettings(scale, tuple(invalid), max_depth, lens_distortion(dist))


def _encoding(camera: Any) -> str:
    """The depth encoding a camera file declares (``"linear"`` unless it says otherwise)."""
    if camera is None or (camera.encoding is None and camera.raw_format is None):
        return "linear"
    from ..datasets.realsensors import encoding_of

    info = {"encoding": camera.encoding, "raw_format": camera.raw_format}
    return encoding_of({k: v for k, v in info.items() if v is not None})


def run_many(args: argparse.Namespace) -> int:
    from ..io import read_camera_file
    from ..jobs import run_estimate
    from ..registry import DEFAULT_METHOD

    if args.output.suffix.lower() in (".npy", ".png", ".ply") and not args.output.is_dir():
        raise ValueError(f"with many inputs (or --scheduler), -o is a folder; got the file name "
                         f"{args.output} (choose the format with --format)")
    camera = read_camera_file(args.intrinsics) if args.intrinsics is not None else None
    rs = read_settings(args, camera)
    method = args.method or DEFAULT_METHOD
    s = run_estimate(args.depth, args.output, method=method, K=None if camera is None else camera.K,
                     options=parse_options(args.option), depth_scale=rs.depth_scale, fmt=args.format,
                     resume=not args.no_resume, progress=not args.quiet, scheduler=args.scheduler,
                     batch_size=args.batch_size, invalid=rs.invalid, max_depth=rs.max_depth, vis=args.vis,
                     uncertainty=args.uncertainty, distortion=rs.distortion)
    print(f"{args.output}: {s.planned} frames by {method} ({s.written} computed, {s.skipped} done "
          f"before) in {s.seconds:.1f} s")
    if s.not_depth:
        shown = "; ".join(f"{p}: {why}" for p, why in s.not_depth[:5])
        more = f"; and {len(s.not_depth) - 5} more" if len(s.not_depth) > 5 else ""
        print(f"depthnormals estimate: skipped {len(s.not_depth)} file(s) that are not depth images "
              f"({shown}{more})", file=sys.stderr)
    if s.stale:
        print(f"depthnormals estimate: warning: {len(s.stale)} output(s) in {args.output} were made "
              f"with other or unknown settings and not recomputed by this run (e.g. {s.stale[0]}); the "
              "folder gets no manifest, so the next run recomputes every frame; remove them or use "
              "a new output folder", file=sys.stderr)
    if s.no_normal:
        n = len(s.no_normal)
        shown = ", ".join(s.no_normal[:5]) + (f" and {n - 5} more" if n > 5 else "")
        print(f"depthnormals estimate: warning: {len(s.no_normal)} output(s) hold no finite normal (all "
              f"NaN: no valid depth, or no valid pixel with a valid neighbour): {shown}; check the files, "
              "--depth-scale, --invalid and --max-depth", file=sys.stderr)
        return EXIT_NO_VALID_PIXEL
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


def check_output(output: Path) -> None:
    """Refuse an output name whose format is unknown, before any work."""
    name = output.name.lower()
    if not name.endswith((".npy", ".png", ".ply")):
        suffix = output.suffix or "(no suffix)"
        raise ValueError(f"-o {output}: unknown output format {suffix!r}; use {OUTPUTS}")


def estimate_file(depth_path: Path, intrinsics_path: Path, output: Path, *,
                  method: str | None = None, depth_scale: float | None = None,
                  shape: tuple[int, int] | None = None,
                  options: dict[str, Any] | None = None, invalid: tuple[float, ...] = (),
                  max_depth: float | None = None, vis: str = "3f2n",
                  uncertainty: bool = False,
                  distortion: tuple[float, ...] = ()) -> EstimateReport:
    """Read one depth file and its intrinsics, estimate the normals, write them atomically.

    With ``uncertainty``, the expected angular error of every normal goes to
    ``<name>.uncertainty.npy`` beside ``output`` (:func:`depthnormals.jobs.uncertainty_path`),
    and a ``.ply`` output carries it per point (``float uncertainty``, :func:`depthnormals.io.write_ply`).
    With ``distortion`` (OpenCV's order) the depth is first resampled onto the pinhole grid of
    the intrinsics (:func:`depthnormals.undistort_depth`); the outputs are on that grid.

    The normals are written even when none is finite (``valid_normals == 0`` in the report
    says so; ``valid_depth == 0`` when no depth pixel is valid). The output's folder is
    created when missing, and removed again when the write fails.
    """
    import time

    import numpy as np

    from ..io import read_depth, read_intrinsics, write_normals, write_ply
    from ..jobs import normals_and_uncertainty, uncertainty_path, write_uncertainty
    from ..registry import DEFAULT_METHOD

    check_output(output)
    depth = read_depth(depth_path, depth_scale=depth_scale, shape=shape, invalid=invalid,
                       max_depth=max_depth)
    if shape is not None and depth.shape != tuple(shape):
        raise ValueError(f"{depth_path} holds a {depth.shape[0]} x {depth.shape[1]} depth map; "
                         f"--shape says {shape[0]} x {shape[1]}")
    K = read_intrinsics(intrinsics_path)
    if distortion:
        from ..camera import undistort_depth

        depth = undistort_depth(depth, K, distortion)
    method = method or DEFAULT_METHOD
    t0 = time.perf_counter()
    try:
        normals, unc = normals_and_uncertainty(depth, K, method, options or {}, uncertainty)
    except (ValueError, TypeError) as exc:
        raise type(exc)(f"{depth_path}: {exc}") from exc
    ms = (time.perf_counter() - t0) * 1e3
    created = _make_parents(output.parent)
    try:
        if unc is not None:
            write_uncertainty(uncertainty_path(output), unc)
        if output.name.lower().endswith(".ply"):  # a point cloud: valid points with their normals
            write_ply(output, depth, K, normals, uncertainty=unc)
        else:
            write_normals(output, normals, vis=vis)
    except BaseException:
        if unc is not None:
            with contextlib.suppress(OSError):
                uncertainty_path(output).unlink()
        for folder in reversed(created):
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise
    valid_depth = int(np.count_nonzero(np.isfinite(depth) & (depth > 0)))
    valid = int(np.count_nonzero(np.isfinite(normals[..., 0])))
    return EstimateReport(output, depth.shape, method, valid_depth, valid, ms)


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; returns those created, outermost first."""
    missing = []
    p = folder
    while not p.exists() and p != p.parent:
        missing.append(p)
        p = p.parent
    folder.mkdir(parents=True, exist_ok=True)
    return list(reversed(missing))


def run(args: argparse.Namespace) -> int:
    from ..io import read_camera_file

    if _many(args):
        return run_many(args)
    args.depth = args.depth[0]
    if args.intrinsics is None:
        raise ValueError("--intrinsics/-K is required for a depth file")
    check_output(args.output)
    rs = read_settings(args, read_camera_file(args.intrinsics))
    rep = estimate_file(args.depth, args.intrinsics, args.output, method=args.method,
                        depth_scale=rs.depth_scale, shape=args.shape,
                        options=parse_options(args.option), invalid=rs.invalid, max_depth=rs.max_depth,
                        vis=args.vis, uncertainty=args.uncertainty, distortion=rs.distortion)
    print(f"{rep.output}: {rep.shape[1]}x{rep.shape[0]} normals by {rep.method} "
          f"({rep.valid_normals} valid pixels, {rep.ms:.1f} ms)")
    if rep.valid_normals == 0:
        if rep.valid_depth == 0:
            why = (f"no pixel of {args.depth} holds a valid depth (all are 0, negative, NaN or inf, "
                   "or removed by --invalid / --max-depth)")
        else:
            why = (f"{args.depth} has {rep.valid_depth} valid depth pixel(s), but none has a valid "
                   f"neighbour ({rep.shape[0]} x {rep.shape[1]} pixels)")
        print(f"depthnormals estimate: warning: {why}, so every normal is NaN (written to {rep.output}); "
              "check the file, --depth-scale and --shape", file=sys.stderr)
        return EXIT_NO_VALID_PIXEL
    return 0
