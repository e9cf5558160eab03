"""Speed and accuracy of the comparison family, side by side with peers, in one run.

Usage: python benchmarks/family.py [--repeats N] [--methods a,b,...]

Single thread (``depthnormals.set_num_threads(1)``, ``cv2.setNumThreads(1)``), 640x480
box-on-floor analytic scene, one warm-up call, then median and minimum of the repeats.
Wall time and process (CPU) time are both reported: on a shared, loaded machine the CPU
time and the minimum are the fairer numbers.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numba
import numpy as np

import depthnormals as dn
from depthnormals.analytic import make_scene, planar_interior

FAMILY = ("sda-sne", "sne-roadseg", "fals", "sri", "line-mod", "plane-svd", "plane-pca",
          "vector-svd", "area-weighted", "angle-weighted", "3f2n", "d2nt")


def timed(f, repeats):
    """(median wall, min wall, median CPU, min CPU) in ms, after one warm-up call."""
    f()
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        f()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    w, c = 1000 * np.array(wall), 1000 * np.array(cpu)
    return float(np.median(w)), float(w.min()), float(np.median(c)), float(c.min())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--methods", default=",".join(FAMILY),
                    help="comma-separated subset of the estimators (OpenCV rows always run)")
    args = ap.parse_args()
    dn.set_num_threads(1)
    r = make_scene("box-on-floor").render()
    depth = r.depth.astype(np.float32)
    K = r.K.matrix
    inner = planar_interior(r, 6)
    rows = []
    for m in args.methods.split(","):
        n = dn.estimate_normals(depth, K, method=m)
        t = timed(lambda m=m: dn.estimate_normals(depth, K, method=m), args.repeats)
        err = dn.angular_error(n, r.normals)[inner]
        rows.append((m, *t, float(np.nanmean(err)), float(np.isnan(err).mean())))
    try:
        import cv2
        cv2.setNumThreads(1)
        k32 = K.astype(np.float32)
        meth = {"opencv fals": cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_FALS,
                "opencv sri": cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_SRI,
                "opencv line-mod": cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_LINEMOD}
        for name, mm in meth.items():
            est = cv2.rgbd.RgbdNormals_create(480, 640, cv2.CV_32F, k32, 5, mm)
            if "line-mod" in name:
                def call(est=est):
                    return est.apply(depth)
            else:
                def call(est=est):  # from depth, as ours: depthTo3d included
                    return est.apply(cv2.rgbd.depthTo3d(depth, k32))
            n = call()
            t = timed(call, args.repeats)
            err = dn.angular_error(n, r.normals, folded=True)[inner]
            rows.append((name, *t, float(np.nanmean(err)), float(np.isnan(err).mean())))
            if name == "opencv fals":  # the same, points precomputed (apply only)
                pts = cv2.rgbd.depthTo3d(depth, k32)
                t = timed(lambda est=est, pts=pts: est.apply(pts), args.repeats)
                rows.append(("opencv fals, apply only", *t, rows[-1][-2], rows[-1][-1]))
    except (ImportError, AttributeError) as exc:
        print(f"(OpenCV rgbd not available: {exc})")
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"{os.cpu_count()} CPUs, python {platform.python_version()}, numba {numba.__version__}, "
          f"1 thread, {args.repeats} repeats, load average {os.getloadavg()[0]:.1f}")
    print("| method | wall ms median | wall ms min | CPU ms median | CPU ms min "
          "| mean error on planar interiors (deg) | NaN share there |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for m, wm, wn, cm, cn, e, nan in rows:
        print(f"| {m} | {wm:.2f} | {wn:.2f} | {cm:.2f} | {cn:.2f} | {e:.4f} | {nan:.3f} |")


if __name__ == "__main__":
    main()
