"""The box-fit's large centred window grows with the noise (:func:`depthnormals.ddm.auto.big_radius`).

Every box-fit frame (the default's noisy branch for independent noise) of the analytic scenes
at 640 x 480, scaled to 0.3 and 1.0 times their size, with the kinect_v2 and tof models of the
synthetic benchmark and Gaussian noise of 0.3, 1 and 3 footprints; with ``--synth DIR``, the
box-fit frames of those synthetic benchmark folders too (the exact normals, the folder's
masks). Per column the mean of the frames' mean angular errors with the large window fixed at
17 x 17 (the rule before session 30, computed in the same run) and with the rule, and FALS
11 x 11 on the same depth.

    python benchmarks/big_window.py [--synth /tmp/u-synth-s5 /tmp/u-ssn]

docs/3f2n-plus.md, "The large window grows with the noise (session 30)", has the numbers.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import depthnormals as dn
from depthnormals.analytic import make_scene
from depthnormals.ddm import auto, uncertainty
from depthnormals.synth import noise as sensor

K = dn.as_intrinsics((525.0, 525.0, 319.5, 239.5))
SCENES = ("demo-room", "box-on-floor", "stairs", "tilted-plane", "sphere-before-wall")


def _fixed(sigma: float) -> int:
    """The large radius before session 30: 8, or the small windows' if larger."""
    return max(auto.BIG_RADIUS, auto.box_radius(sigma))


def _errors(z, K, normals, mask) -> tuple[float, float, float]:
    out = []
    for rule in (_fixed, auto.big_radius):
        saved = auto.big_radius
        auto.big_radius = uncertainty.big_radius = rule
        try:
            out.append(dn.angular_error(dn.estimate_normals(z, K), normals))
        finally:
            auto.big_radius = uncertainty.big_radius = saved
    out.append(dn.angular_error(dn.estimate_normals(z, K, method="fals", window=11), normals))
    ok = np.logical_and.reduce([np.isfinite(e) for e in out]) & mask
    return tuple(float(e[ok].mean()) for e in out)


def _analytic():
    for name in SCENES:
        r = make_scene(name).render(K=K, shape=(480, 640))
        for scale in (0.3, 1.0):
            d0 = np.where(r.depth > 0, scale * r.depth, 0.0)
            for model in ("kinect_v2", "tof"):
                fn = getattr(sensor, f"{model}_noise")
                z = np.asarray(fn(d0, r.normals, K, rng=np.random.default_rng(1)))
                yield model, z, K, r.normals, d0 > 0
            rng = np.random.default_rng(2)
            for g in (0.3, 1.0, 3.0):
                z = np.where(d0 > 0, d0 * (1.0 + g * rng.standard_normal(d0.shape) / K.fx), 0.0)
                yield f"gaussian {g:g} px", z, K, r.normals, d0 > 0


def _synth(roots):
    from depthnormals.datasets import open as open_dataset

    for root in roots:
        for f in open_dataset(root):
            variant = f.group.split("/")[-1]
            if variant != "clean":
                yield f"{root} {variant}", f.depth, f.K, f.normals, f.mask


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--synth", nargs="*", default=[], help="synthetic benchmark folders")
    a = ap.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    cols: dict[str, list] = {}
    for source in (_analytic(), _synth(a.synth)):
        for label, z, cam, normals, mask in source:
            if dn.noise_profile(z, cam).branch != "box-fit":
                continue
            cols.setdefault(label, []).append(_errors(z, cam, normals, mask))
    print(f"{'column':40s} frames | 17x17 fixed   grows | FALS 11")
    for label, rows in cols.items():
        x = np.mean(rows, axis=0)
        print(f"{label:40s} {len(rows):6d} | {x[0]:11.3f} {x[1]:7.3f} | {x[2]:7.3f}")


if __name__ == "__main__":
    main()
