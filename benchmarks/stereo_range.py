"""The default where active stereo's noise grows with depth: the pair-by-pair excess.

Every analytic scene at 640 x 480 scaled to 0.3, 0.6 and 1.0 times its size (a room of
0.4-1.8 m to 1.3-6.5 m), two seeds, with the realsense_d4xx model of the synthetic benchmark
and three variants of it (the D455's baseline of 95 mm, a subpixel error of 0.05 px, a 7x7
matching window with the D415's baseline), and the kinect_v2 and tof models as controls. Per
row: the image-wide excess and the pair-by-pair one (``noise_profile(...).excess`` and
``.local_excess``), the branch, the default's mean angular error and that of the rule
before session 30 (the image-wide excess alone, computed in the same run), the expected-error
map's mean, and FALS (11 x 11) and PCL's covariance-matrix normals on the same depth.

    python benchmarks/stereo_range.py [--rows]

``--rows`` prints every frame; by default only the frames whose branch the pair-by-pair
excess changes, then a summary per sensor model. docs/3f2n-plus.md, "Correlated noise the
image-wide excess misses (session 30)", has the numbers.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import depthnormals as dn
from depthnormals.analytic import make_scene, scene_names
from depthnormals.ddm import auto, uncertainty
from depthnormals.ddm.noise import noise_pass
from depthnormals.ddm.support import support_profile
from depthnormals.kernels.depth import prepare
from depthnormals.synth import noise as sensor

K = dn.as_intrinsics((525.0, 525.0, 319.5, 239.5))
MODELS = {
    "realsense_d4xx": (sensor.realsense_d4xx_noise, {}),
    "realsense b95": (sensor.realsense_d4xx_noise, {"baseline": 0.095}),
    "realsense sub.05": (sensor.realsense_d4xx_noise, {"subpixel": 0.05}),
    "realsense w7": (sensor.realsense_d4xx_noise, {"baseline": 0.055, "window": 7}),
    "kinect_v2": (sensor.kinect_v2_noise, {}),
    "tof": (sensor.tof_noise, {}),
}
PEERS = (("fals", {"window": 11}), ("pcl-covariance-matrix", {}))


def _image_wide_rule(noise, prof) -> bool:
    """The choice before session 30: the image-wide excess alone."""
    return (noise.plateaus and noise.quant > noise.iid) or not prof.excess() <= auto.EXCESS


def _default(z: np.ndarray, rule=None):
    if rule is None:
        return dn.estimate_normals(z, K, return_uncertainty=True)
    saved = auto.needs_measured_support
    auto.needs_measured_support = uncertainty.needs_measured_support = rule
    try:
        return dn.estimate_normals(z, K, return_uncertainty=True)
    finally:
        auto.needs_measured_support = uncertainty.needs_measured_support = saved


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", action="store_true", help="print every frame")
    a = ap.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    head = (f"{'scene':19s} {'x':>4s} {'model':16s} seed | excess local branch   | before   now  map | "
            "fals-11  pcl-cov")
    print(head)
    summary: dict[str, list] = {m: [] for m in MODELS}
    for name in scene_names():
        r = make_scene(name).render(K=K, shape=(480, 640))
        for scale in (0.3, 0.6, 1.0):
            d0 = np.where(r.depth > 0, scale * r.depth, 0.0)
            for model, (fn, kw) in MODELS.items():
                for seed in (1, 2):
                    z = np.asarray(fn(d0, r.normals, K, rng=np.random.default_rng(seed), **kw))
                    p = dn.noise_profile(z, K)
                    if p.branch == "planes":
                        continue
                    n, u = _default(z)
                    old = _default(z, _image_wide_rule)[0]
                    errs = [dn.angular_error(x, r.normals) for x in
                            [n, old] + [dn.estimate_normals(z, K, method=m, **o) for m, o in PEERS]]
                    ok = np.logical_and.reduce([np.isfinite(e) for e in errs])
                    means = [float(e[ok].mean()) for e in errs]
                    changed = _measured_before(z) != (p.branch == "measured-support")
                    summary[model].append((changed, *means, float(np.nanmean(u[ok]))))
                    if a.rows or changed:
                        print(f"{name:19s} {scale:4.1f} {model:16s} {seed:4d} | {p.excess:6.2f} "
                              f"{p.local_excess:5.2f} {p.branch[:8]:8s} | {means[1]:6.2f} {means[0]:5.2f} "
                              f"{float(np.nanmean(u[ok])):4.1f} | {means[2]:7.2f} {means[3]:8.2f}"
                              + ("  changed" if changed else ""))
    print("\nper model: frames (branch changed) | mean error before -> now | fals-11  pcl-cov")
    for model, rows in summary.items():
        x = np.array(rows)
        print(f"{model:16s} {len(rows):3d} ({int(x[:, 0].sum()):2d}) | {x[:, 2].mean():6.2f} -> "
              f"{x[:, 1].mean():5.2f} | {x[:, 3].mean():7.2f} {x[:, 4].mean():8.2f}")


def _measured_before(z: np.ndarray) -> bool:
    """Whether the rule before session 30 took the measured support on ``z``."""
    zz, cam = prepare(z, K, None)
    p = noise_pass(zz, cam.fx, cam.fy)
    return _image_wide_rule(p, support_profile(zz, cam.fx, cam.fy, cam.cx, cam.cy, p.sigma))


if __name__ == "__main__":
    main()
