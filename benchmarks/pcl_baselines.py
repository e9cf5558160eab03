"""Accuracy, coverage and single-thread speed of the PCL integral-image baselines and the plain
cross product, beside FALS and the 3F2N family (issue 13, "the complete comparison").

Accuracy: the analytic scenes box-on-floor, stairs, sphere-before-wall at 640x480, clean and
with Gaussian noise 0.1 z/f (seed 0) (``depthnormals.datasets.analytic.analytic_frames``), all
valid pixels but a 1-pixel border, folded; and the 3F2N torus-knot frame (background and
1-pixel border masked, folded). Errors pool the pixels with a finite estimate; coverage is
the share of scored pixels that got one. "edge": pixels within 2 px of a crease (> 10 deg)
or a depth jump (``evaluate.discontinuity_mask``), "smooth": the others.

Speed: 640x480 demo-room, 1 thread, thread CPU time, median of ``--repeats``, every case
interleaved with OpenCV's FALS (``cv2.rgbd``, window 5, ``apply`` on precomputed points).

    python benchmarks/pcl_baselines.py [--repeats 20] [--no-speed] [--no-accuracy]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import depthnormals as dn
from depthnormals.commands.bench import machine
from depthnormals.datasets import read_3f2n
from depthnormals.datasets.analytic import analytic_frames
from depthnormals.evaluate._protocol import discontinuity_mask

sys.path.insert(0, str(Path(__file__).resolve().parent))
from targets import _measure_all

FIXTURE = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "3f2n-torusknot"

PCL = ("pcl-average-3d-gradient", "pcl-covariance-matrix", "pcl-average-depth-change",
       "pcl-simple-3d-gradient")
CASES = [
    *((m, {}) for m in PCL),
    ("pcl-average-3d-gradient", {"border_policy": "ignore"}),
    ("pcl-covariance-matrix", {"border_policy": "ignore"}),
    ("pcl-covariance-matrix", {"depth_dependent_smoothing": True}),
    ("cross-product", {}),
    ("cross-product", {"difference": "forward"}),
    ("fals", {}),
    ("plane-svd", {}),
    ("d2nt", {}),
    ("sda-sne", {}),
    ("3f2n+", {}),
]


def _label(method, opts):
    return method + ("" if not opts else " " + ",".join(f"{k}={v}" for k, v in opts.items()))


def _row(n, truth, depth, score, near):
    err = dn.angular_error(n, truth, folded=True)
    ok = score & np.isfinite(err)
    e = err[ok]
    return (float(e.mean()), float(np.median(e)), 100 * float(np.mean(e < 11.25)),
            float(err[ok & near].mean()), float(err[ok & ~near].mean()),
            100 * ok.sum() / score.sum())


def accuracy() -> None:
    frames = [(f.group, f.depth, f.normals, f.mask, f.K) for f in analytic_frames(0.1, 0)]
    if FIXTURE.is_dir():
        tk = next(iter(read_3f2n(FIXTURE)))
        frames.append(("torus-knot", tk.depth, tk.normals, tk.mask, tk.K))
    for group, depth, truth, mask, K in frames:
        score = mask.copy()
        score[0] = score[-1] = False
        score[:, 0] = score[:, -1] = False
        near = discontinuity_mask(truth, depth, mask)
        print(f"\n{group}: {score.sum()} scored pixels, {near[score].mean():.1%} near an edge")
        print(f"{'method':<48}{'mean':>8}{'median':>8}{'<11.25%':>9}{'edge':>8}{'smooth':>8}"
              f"{'cover%':>8}")
        for method, opts in CASES:
            n = dn.estimate_normals(depth, K, method=method, **opts)
            r = _row(n, truth, depth, score, near)
            print(f"{_label(method, opts):<48}{r[0]:8.3f}{r[1]:8.3f}{r[2]:9.2f}{r[3]:8.3f}"
                  f"{r[4]:8.3f}{r[5]:8.2f}")


def speed(repeats: int) -> None:
    import cv2

    from depthnormals.analytic import make_scene

    dn.set_num_threads(1)
    cv2.setNumThreads(1)
    r = make_scene("demo-room").render()
    depth = r.depth.astype(np.float32)
    K = r.K.matrix
    fals = cv2.rgbd.RgbdNormals_create(480, 640, cv2.CV_32F, K, 5,
                                       cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_FALS)
    points = cv2.rgbd.depthTo3d(depth, K)
    cases = [c for c in CASES if c[0] != "sda-sne"]
    fns = [lambda: fals.apply(points)]
    fns += [lambda m=m, o=o: dn.estimate_normals(depth, K, method=m, **o) for m, o in cases]
    res = _measure_all(fns, repeats)
    ref = res[0]
    print(f"\nmachine: {machine()}; 640x480 demo-room, 1 thread, median of {repeats}, "
          "cases interleaved")
    print(f"{'case':<48}{'CPU ms':>9}{'x FALS':>8}{'wall ms':>9}")
    print(f"{'opencv FALS w=5 (apply only)':<48}{ref[0]:9.2f}{1.0:8.2f}{ref[1]:9.2f}")
    for (m, o), t in zip(cases, res[1:], strict=True):
        print(f"{_label(m, o):<48}{t[0]:9.2f}{t[0] / ref[0]:8.2f}{t[1]:9.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--no-speed", action="store_true")
    parser.add_argument("--no-accuracy", action="store_true")
    args = parser.parse_args()
    if not args.no_accuracy:
        accuracy()
    if not args.no_speed:
        speed(args.repeats)


if __name__ == "__main__":
    main()
