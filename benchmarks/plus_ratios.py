"""Error ratios "<name>+" / "<name>" on the analytic scenes and the torus-knot frame (issue 3).

Frames: box-on-floor, stairs, sphere-before-wall at 640x480, clean and with Gaussian noise
0.1 z/f (seed 0) (``depthnormals.datasets.analytic.analytic_frames``); mean angular error over
all valid pixels. Torus knot: the 3F2N protocol (background and 1-pixel border masked,
folded, NaN dropped).

    python benchmarks/plus_ratios.py [--methods d2nt,3f2n] [--options '{"consistency": null}']
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import depthnormals as dn
from depthnormals.datasets import read_3f2n
from depthnormals.datasets.analytic import analytic_frames

FIXTURE = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "3f2n-torusknot"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--methods", default="d2nt,3f2n")
    parser.add_argument("--options", default="{}", help="JSON options of the '+' forms")
    args = parser.parse_args()
    opts = json.loads(args.options)
    frames = list(analytic_frames(0.1, 0))
    tk = next(iter(read_3f2n(FIXTURE)))
    mask = tk.mask.copy()
    mask[0, :] = mask[-1, :] = mask[:, 0] = mask[:, -1] = False

    def tk_error(n: np.ndarray) -> float:
        e = dn.angular_error(n, tk.normals, folded=True)[mask]
        return float(np.mean(e[np.isfinite(e)]))

    print("ratio '<name>+' / '<name>':", " | ".join(f.group for f in frames), "| torus knot (deg)")
    for base in args.methods.split(","):
        ratios = []
        for f in frames:
            e0 = dn.normal_metrics(dn.estimate_normals(f.depth, f.K, method=base), f.normals).mean
            e1 = dn.normal_metrics(dn.estimate_normals(f.depth, f.K, method=base + "+", **opts),
                                   f.normals).mean
            ratios.append(e1 / e0)
        plus = tk_error(dn.estimate_normals(tk.depth, tk.K, method=base + "+", **opts))
        print(f"{base + '+':<18}", " ".join(f"{r:.3f}" for r in ratios),
              f"| {plus:.4f} (base {tk_error(dn.estimate_normals(tk.depth, tk.K, method=base)):.4f})")


if __name__ == "__main__":
    main()
