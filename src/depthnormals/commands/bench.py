"""``depthnormals bench``: milliseconds per frame of every estimator beside OpenCV, same run."""

from __future__ import annotations

import argparse
import platform
import time

HELP = ("time every estimator at 640x480 and 512x424 (single thread by default) beside "
        "OpenCV's RgbdNormals FALS measured in the same run; prints ratios")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--methods", default=None,
                        help="comma-separated method names (default: every registered base method)")
    parser.add_argument("--sizes", default="640x480,512x424", help="comma-separated WxH sizes")
    parser.add_argument("--repeats", type=int, default=15, help="timed runs per method (median)")
    parser.add_argument("--threads", type=int, default=1, help="threads for numba and OpenCV")
    parser.add_argument("--scene", default="demo-room", help="analytic scene to time on")


def _median_ms(fn, repeats: int) -> float:
    fn()
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    times.sort()
    return 1e3 * times[len(times) // 2]


def machine() -> str:
    """One line describing this machine."""
    import os

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}, " \
           f"Python {platform.python_version()}"


def run(args: argparse.Namespace) -> int:
    import numba
    import numpy as np

    from ..analytic import DEFAULT_K, DEFAULT_SHAPE, make_scene
    from ..registry import estimate_normals, methods
    from .demo import parse_size

    names = args.methods.split(",") if args.methods else list(methods(refined=False))
    sizes = [parse_size(s) for s in args.sizes.split(",")]
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    try:
        import cv2

        cv2.setNumThreads(args.threads)
        has_cv = hasattr(cv2, "rgbd")
        cv_version = cv2.__version__
    except ImportError:
        has_cv = False
        cv_version = None
    print(f"machine: {machine()}; threads: {args.threads}; numba {numba.__version__}; "
          f"OpenCV {cv_version or 'not installed'}")
    table: dict[str, dict[tuple[int, int], float]] = {}
    ref: dict[tuple[int, int], float] = {}
    for h, w in sizes:
        K = DEFAULT_K.scaled(w / DEFAULT_SHAPE[1])
        depth = make_scene(args.scene).render(K, (h, w)).depth.astype(np.float32)
        if has_cv:
            Km = K.matrix
            fals = cv2.rgbd.RgbdNormals_create(h, w, cv2.CV_32F, Km, 5,
                                               cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_FALS)
            points = cv2.rgbd.depthTo3d(depth, Km)
            ref[(h, w)] = _median_ms(lambda f=fals, p=points: f.apply(p), args.repeats)
        for name in names:
            table.setdefault(name, {})[(h, w)] = _median_ms(
                lambda n=name, d=depth, k=K: estimate_normals(d, k, method=n), args.repeats)
    head = "".join(f"{f'{w}x{h} ms':>14}{'ratio':>8}" for h, w in sizes)
    print(f"{'method':<20}{head}")
    if has_cv:
        print(f"{'opencv-fals (w=5)':<20}" + "".join(f"{ref[s]:14.2f}{1.0:8.2f}" for s in sizes))
    for name, row in table.items():
        cells = ""
        for s in sizes:
            ratio = row[s] / ref[s] if s in ref else float("nan")
            cells += f"{row[s]:14.2f}{ratio:8.2f}"
        print(f"{name:<20}{cells}")
    print("ratio = ms / OpenCV FALS ms at the same size (lower is faster); OpenCV times apply() on "
          "precomputed points (depthTo3d not counted), ours the whole call from depth")
    return 0
