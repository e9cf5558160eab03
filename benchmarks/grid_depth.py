"""The default on depth stored on a grid (millimetre PNGs): error, branch and map.

Part 1 (no data needed): demo-room at 640 x 480, Gaussian depth noise (mm) then rounding to a
grid (mm), every combination; per row the branch, the noise level, the default's mean and p90
angular error, its expected-error map's mean, and OpenCV-free peers (our FALS windows 5 and 11,
plain 3F2N) on the same depth.

Part 2 (``--synth DIR``): the clean views of a ``depthnormals synth`` folder rounded to
``--grid`` mm: the default's mean error and the calibration of its map (deciles of the
prediction, mean observed error per decile, the issue-24 rule: within +-25 %, or 0.5 deg where
both are below 2; Spearman).

    python benchmarks/grid_depth.py [--synth /tmp/u-synth-s5 --grid 1 --views 24]

docs/3f2n-plus.md, "Depth on a grid (session 29)", has the numbers (before: git ce0e37b).
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import depthnormals as dn
from depthnormals.analytic import make_scene


def _on_grid(depth: np.ndarray, q_mm: float) -> np.ndarray:
    q = q_mm / 1000.0
    return np.where(depth > 0, np.round(depth / q) * q if q else depth, 0).astype(np.float32)


def matrix() -> None:
    K = dn.as_intrinsics((525.0, 525.0, 319.5, 239.5))
    r = make_scene("demo-room").render(K=K, shape=(480, 640))
    rng = np.random.default_rng(0)
    print("noise mm  grid mm | branch            sigma  | 3f2n+ mean   p90 |  map | fals-5 fals-11  3f2n")
    for s in (0.0, 0.1, 0.3, 1.0):
        for q in (0.0, 0.1, 1.0, 2.0):
            z = _on_grid(r.depth + s / 1000.0 * rng.standard_normal(r.depth.shape), q)
            n, u = dn.estimate_normals(z, K, return_uncertainty=True)
            e = dn.angular_error(n, r.normals)
            p = dn.noise_profile(z, K)
            peers = [np.nanmean(dn.angular_error(dn.estimate_normals(z, K, method=m, **o), r.normals))
                     for m, o in (("fals", {}), ("fals", {"window": 11}), ("3f2n", {}))]
            print(f"{s:8.1f} {q:8.1f} | {p.branch:16s} {p.sigma:6.3f} | {np.nanmean(e):10.3f} "
                  f"{np.nanpercentile(e, 90):5.3f} | {np.nanmean(u):4.2f} | "
                  + " ".join(f"{x:6.3f}" for x in peers))


def _rank(a: np.ndarray) -> np.ndarray:
    r = np.empty(a.size)
    r[np.argsort(a, kind="stable")] = np.arange(a.size)
    return r


def calibration(root: str, q_mm: float, views: int) -> None:
    from depthnormals.datasets import open as open_dataset

    obs, pred, branches, k = [], [], {}, 0
    for f in open_dataset(root):
        if not f.group.endswith("/clean"):
            continue
        if k == views:
            break
        k += 1
        z = _on_grid(f.depth, q_mm)
        n, u = dn.estimate_normals(z, f.K, return_uncertainty=True)
        b = dn.noise_profile(z, f.K).branch
        branches[b] = branches.get(b, 0) + 1
        e = dn.angular_error(n, f.normals)
        m = np.isfinite(e) & np.isfinite(u) & f.mask
        obs.append(e[m])
        pred.append(u[m])
    o, p = np.concatenate(obs), np.concatenate(pred)
    print(f"\n{root}: {k} clean views rounded to {q_mm:g} mm; branches {branches}; "
          f"mean error {o.mean():.3f} deg, mean map {p.mean():.3f}")
    passed = 0
    for i, b in enumerate(np.array_split(np.argsort(p, kind="stable"), 10)):
        po, oo = p[b].mean(), o[b].mean()
        ok = abs(oo - po) <= 0.25 * po or (po < 2 and oo < 2 and abs(oo - po) <= 0.5)
        passed += ok
        print(f"  bin {i + 1:2d} predicted {po:7.3f} observed {oo:7.3f} {'yes' if ok else 'NO'}")
    print(f"  bins passed {passed}/10, Spearman {np.corrcoef(_rank(p), _rank(o))[0, 1]:.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--synth", help="a depthnormals synth folder for part 2")
    parser.add_argument("--grid", type=float, default=1.0, help="grid of part 2, mm")
    parser.add_argument("--views", type=int, default=24, help="clean views of part 2")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    dn.set_num_threads(1)
    matrix()
    if args.synth:
        calibration(args.synth, args.grid, args.views)


if __name__ == "__main__":
    main()
