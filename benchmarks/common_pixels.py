"""Mean error of the default ``3f2n+`` against other methods on the pixels both cover (issue 13).

A method that abstains (NaN: LINE-MOD at depth jumps, the PCL estimators at jumps and borders, a
"+" form keeping its base's abstentions) is scored on fewer pixels, and the pixels it leaves out
are the hard ones. This script pairs ``3f2n+`` with each method and pools the errors over the
pixels where both give a normal, per scene kind and noise variant of a ``depthnormals synth``
dataset (``evaluate.Protocol()`` defaults: folded errors, 1-pixel border).

    depthnormals synth /tmp/r13-synth --indoor 2 --outdoor 2 --views 4 --seed 0 --noise gaussian,kinect_v2
    python benchmarks/common_pixels.py /tmp/r13-synth --variants gaussian,kinect_v2
"""

from __future__ import annotations

import argparse

import numpy as np

import depthnormals as dn
from depthnormals.datasets.synthetic import read_synthetic
from depthnormals.evaluate import Protocol, parse_method_spec, score_frame
from depthnormals.evaluate._methods import split_method_list

PEERS = ("sne-roadseg+,d2nt+,sda-sne+,cross-product+,fals+,line-mod+,pcl-average-3d-gradient+,"
         "pcl-covariance-matrix+,pcl-average-3d-gradient,fals,line-mod,3f2n+[selection=plane-fit]")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset")
    p.add_argument("--variants", default="gaussian,kinect_v2")
    p.add_argument("--methods", default=PEERS)
    p.add_argument("--reference", default="3f2n+")
    args = p.parse_args()
    proto = Protocol()
    labels = [args.reference, *split_method_list(args.methods)]
    specs = {m: parse_method_spec(m) for m in labels}
    pooled: dict[tuple[str, str], list[list[np.ndarray]]] = {}  # (errors of the reference, of m)
    for f in read_synthetic(args.dataset, variants=args.variants.split(",")):
        kind, _scene, variant = f.group.split("/")
        err = {}
        for m, s in specs.items():
            n = dn.estimate_normals(f.depth, f.K, method=s.method, **s.options)
            err[m] = score_frame(n, f.normals, mask=f.mask, protocol=proto).error
        for m in labels[1:]:
            both = np.isfinite(err[args.reference]) & np.isfinite(err[m])
            a, b = pooled.setdefault((f"{kind}/{variant}", m), [[], []])
            a.append(err[args.reference][both])
            b.append(err[m][both])
    print(f"| group | method | pixels both cover | {args.reference} | method | {args.reference} wins |")
    print("|---|---|---:|---:|---:|:---:|")
    for (group, m), (a, b) in sorted(pooled.items()):
        ea, eb = np.concatenate(a), np.concatenate(b)
        print(f"| {group} | `{m}` | {ea.size} | {ea.mean():.3f} | {eb.mean():.3f} | "
              f"{'yes' if ea.mean() <= eb.mean() else '**no**'} |")


if __name__ == "__main__":
    main()
