"""Speed and accuracy of the comparison family, side by side with peers, in one run.

Usage: python benchmarks/family.py [--repeats N]

Single thread (numba and OpenCV), 640x480 box-on-floor analytic scene, one warm-up call,
median of the repeats. Wall time and process (CPU) time are both reported: on a shared,
loaded machine the CPU time is the fairer of the two.
"""

from __future__ import annotations

import argparse
import platform
import time

import numba
import numpy as np

import depthnormals as dn
from depthnormals.analytic import make_scene, planar_interior

FAMILY = ("sda-sne", "sne-roadseg", "fals", "sri", "line-mod", "plane-svd", "plane-pca",
          "vector-svd", "area-weighted", "angle-weighted", "3f2n", "d2nt")


def timed(f, repeats):
    f()
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        f()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return 1000 * float(np.median(wall)), 1000 * float(np.median(cpu))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    numba.set_num_threads(1)
    r = make_scene("box-on-floor").render()
    depth = r.depth.astype(np.float32)
    K = r.K.matrix
    inner = planar_interior(r, 6)
    rows = []
    for m in FAMILY:
        n = dn.estimate_normals(depth, K, method=m)
        wall, cpu = timed(lambda m=m: dn.estimate_normals(depth, K, method=m), args.repeats)
        err = dn.angular_error(n, r.normals)[inner]
        rows.append((m, wall, cpu, float(np.nanmean(err)), float(np.isnan(err).mean())))
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
            wall, cpu = timed(call, args.repeats)
            err = dn.angular_error(n, r.normals, folded=True)[inner]
            rows.append((name, wall, cpu, float(np.nanmean(err)), float(np.isnan(err).mean())))
    except (ImportError, AttributeError) as exc:
        print(f"(OpenCV rgbd not available: {exc})")
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}, numba {numba.__version__}, 1 thread")
    print("| method | wall ms | CPU ms | mean error on planar interiors (deg) | NaN share there |")
    print("|---|---:|---:|---:|---:|")
    for m, wall, cpu, e, nan in rows:
        print(f"| {m} | {wall:.2f} | {cpu:.2f} | {e:.4f} | {nan:.3f} |")


if __name__ == "__main__":
    main()
