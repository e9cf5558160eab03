"""Speed of the 3F2N+ discontinuity discrimination module against OpenCV FALS (window 5).

640x480 torus-knot frame of the 3F2N dataset, single thread (depthnormals and OpenCV), two
warm-up calls, then N repeats per case, interleaved round-robin so that load on a shared
machine hits every case alike. Prints median and min wall time and median process CPU time
per call, each also as a multiple of FALS measured in the same run.

    python benchmarks/ddm_speed.py [FRAME_DIR] [--repeats N]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import cv2
import numba
import numpy as np

import depthnormals as dn
from depthnormals.ddm import discontinuity_discrimination as ddm
from depthnormals.evaluate import machine_description


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("frame", nargs="?", default="/work/shared/data/3f2n-torusknot")
    ap.add_argument("--repeats", type=int, default=41)
    args = ap.parse_args()
    dn.set_num_threads(1)
    cv2.setNumThreads(1)
    fr = next(dn.datasets.read_3f2n(args.frame))
    d = fr.depth.astype(np.float32)
    K = np.asarray(fr.K, dtype=np.float32)
    h, w = d.shape
    fals = cv2.rgbd.RgbdNormals_create(h, w, cv2.CV_32F, K, 5,
                                       cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_FALS)
    pts = cv2.rgbd.depthTo3d(d, K)
    base = dn.estimate_normals(d, fr.K, method="3f2n")
    cases = {
        "FALS (OpenCV, window 5), apply only": lambda: fals.apply(pts),
        "3F2N fd-median": lambda: dn.estimate_normals(d, fr.K, method="3f2n"),
        "DDM default (mean curvature), module alone": lambda: ddm(base, d, fr.K),
        "DDM pixel-mean, module alone": lambda: ddm(base, d, fr.K, curvature="pixel-mean"),
        "DDM mean + Kendall + CRF, module alone":
            lambda: ddm(base, d, fr.K, correlation="kendall", crf=True),
        "3f2n+ default (3F2N + DDM)": lambda: dn.estimate_normals(d, fr.K, method="3f2n+"),
        "3f2n+ curvature-only, paper's selection (consistency=None)":
            lambda: dn.estimate_normals(d, fr.K, method="3f2n+", consistency=None),
        "3f2n+ full, paper's (Kendall + CRF, consistency=None)":
            lambda: dn.estimate_normals(d, fr.K, method="3f2n+", correlation="kendall",
                                        crf=True, consistency=None),
        "3f2n+ full with consistency (Kendall + CRF)":
            lambda: dn.estimate_normals(d, fr.K, method="3f2n+", correlation="kendall",
                                        crf=True),
    }
    wall: dict[str, list[float]] = {k: [] for k in cases}
    cpu: dict[str, list[float]] = {k: [] for k in cases}
    for f in cases.values():
        f()
        f()
    for _ in range(args.repeats):
        for name, f in cases.items():
            c0 = time.process_time()
            t0 = time.perf_counter()
            f()
            wall[name].append(time.perf_counter() - t0)
            cpu[name].append(time.process_time() - c0)
    ref = "FALS (OpenCV, window 5), apply only"
    rmed, rmin, rcpu = (np.median(wall[ref]), np.min(wall[ref]), np.median(cpu[ref]))
    print(f"machine: {platform.machine()} {machine_description()['cpu']}, {os.cpu_count()} CPUs; numba "
          f"{numba.__version__}, OpenCV {cv2.__version__}, numpy {np.__version__}; {w}x{h}, "
          f"1 thread, {args.repeats} repeats")
    print("| case | median ms | min ms | CPU ms (median) | median / FALS | min / FALS "
          "| CPU / FALS |")
    print("|---|---|---|---|---|---|---|")
    for name in cases:
        md, mn, cp = np.median(wall[name]), np.min(wall[name]), np.median(cpu[name])
        print(f"| {name} | {md * 1e3:.2f} | {mn * 1e3:.2f} | {cp * 1e3:.2f} | {md / rmed:.2f}x "
              f"| {mn / rmin:.2f}x | {cp / rcpu:.2f}x |")


if __name__ == "__main__":
    main()
