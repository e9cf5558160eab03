"""Speed of the noise-aware 3F2N+ (``selection="auto"``) against OpenCV's FALS (issue 13 targets).

640x480 demo-room, one thread, clean and with Gaussian noise 0.1 z/f and 0.4 z/f (seed 0);
every case timed interleaved round-robin (``benchmarks/targets.py``), FALS
(``cv2.rgbd.RgbdNormals`` window 5, ``apply`` on ``depthTo3d`` points) on the same depth.
Targets: ``3f2n+`` (default ``selection="auto"``) <= 2.0x FALS on clean depth, <= 3.0x on noisy depth.

    python benchmarks/auto_speed.py [--repeats 30]
"""

from __future__ import annotations

import argparse

import numpy as np
from targets import _measure_all  # benchmarks/, the script's folder

import depthnormals as dn
from depthnormals.analytic import make_scene
from depthnormals.commands.bench import machine


def main() -> None:
    import cv2

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    dn.set_num_threads(1)
    cv2.setNumThreads(1)
    r = make_scene("demo-room").render()
    K = r.K.matrix
    fals = cv2.rgbd.RgbdNormals_create(480, 640, cv2.CV_32F, K, 5,
                                       cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_FALS)
    print(f"machine: {machine()}; 640x480 demo-room, 1 thread, median of {args.repeats}, "
          "cases interleaved")
    print(f"{'depth':<10} {'case':<34} {'CPU ms':>7} {'x FALS':>7}")
    for level in (0.0, 0.1, 0.4):
        d = r.depth.copy()
        if level:
            m = d > 0
            d[m] += np.random.default_rng(0).normal(size=int(m.sum())) * level * d[m] / r.K.fx
        d = d.astype(np.float32)
        pts = cv2.rgbd.depthTo3d(d, K)
        cases = [("opencv FALS w=5 (apply only)", lambda pts=pts: fals.apply(pts)),
                 ("3f2n+ curvature (default until #13)",
                  lambda d=d: dn.estimate_normals(d, K, selection="curvature", consistency=0.1)),
                 ("3f2n+ default (selection=auto)", lambda d=d: dn.estimate_normals(d, K)),
                 ("estimate_noise alone", lambda d=d: dn.estimate_noise(d, K))]
        res = _measure_all([fn for _, fn in cases], args.repeats)
        base = res[0][0]
        name = "clean" if not level else f"noise {level:g}"
        for (label, _), (cpu, _wall, _mn) in zip(cases, res, strict=True):
            print(f"{name:<10} {label:<34} {cpu:7.2f} {cpu / base:7.2f}")


if __name__ == "__main__":
    main()
