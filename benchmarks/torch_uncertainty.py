"""``depthnormals.torch`` with ``return_uncertainty=True`` on a device: parity with the numba
library's map and the cost of the map, per batch.

For every 640x480 frame of a real-sensor folder (default ``../shared/data/real-sensors``):
the (1, 1, H, W) map of ``depthnormals.torch.estimate_normals(d, K, return_uncertainty=True)``
with ``d`` on ``--device``, against ``depthnormals.estimate_normals(depth, K,
return_uncertainty=True)``: the largest relative difference and whether the NaN patterns
agree (the map is computed on the host by the same code, so it should be bit-equal). Then a
batch of up to 8 of those frames (a K per frame): the least of ``--repeats`` wall times of the
torch default without and with the map, and of the numba library's default over the same
frames, at 1 and at all of the library's threads.

    python benchmarks/torch_uncertainty.py [--device cuda] [--real DIR] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import torch

import depthnormals as dn
import depthnormals.torch as dt
from depthnormals.datasets import open as open_dataset

ROOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "real-sensors"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--real", type=Path, default=ROOT)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    dev = torch.device(a.device)

    def sync() -> None:
        if dev.type == "cuda":
            torch.cuda.synchronize(dev)

    name = torch.cuda.get_device_name(dev) if dev.type == "cuda" else "cpu"
    print(f"device {name}, torch {torch.__version__}, host cores {os.cpu_count()}")
    frames = [f for f in open_dataset(a.real) if f.depth.shape == (480, 640)]
    worst, same = 0.0, True
    for f in frames:
        _, u0 = dn.estimate_normals(f.depth, f.K, return_uncertainty=True)
        d = torch.from_numpy(np.asarray(f.depth, np.float32))[None, None].to(dev)
        _, u = dt.estimate_normals(d, torch.as_tensor(np.asarray(f.K, np.float64)),
                                   return_uncertainty=True)
        uu = u[0, 0].cpu().numpy()
        ok = np.isfinite(u0) & np.isfinite(uu)
        rel = float(np.max(np.abs(uu[ok] - u0[ok]) / np.maximum(u0[ok], 1e-6))) if ok.any() else 0.0
        nan_ok = np.array_equal(np.isnan(u0), np.isnan(uu)) and u.device.type == dev.type
        worst, same = max(worst, rel), same and nan_ok
        print(f"  {f.group!s:40s} largest relative difference {rel:.2e}, same NaN {nan_ok}")
    print(f"{len(frames)} frames: largest relative difference {worst:.2e}, NaN patterns agree {same}")
    batch = frames[:8]
    depth = np.stack([np.asarray(f.depth, np.float32) for f in batch])
    ks = torch.as_tensor(np.stack([np.asarray(f.K, np.float64) for f in batch]))
    d = torch.from_numpy(depth)[:, None].to(dev)

    def best(fn) -> float:
        fn()
        sync()
        t = []
        for _ in range(a.repeats):
            s = time.perf_counter()
            fn()
            sync()
            t.append(time.perf_counter() - s)
        return min(t) * 1e3

    print(f"\n| library threads | torch default (ms / {len(batch)} frames) | with the map | ratio "
          "| numba default |")
    print("|---|---|---|---|---|")
    for threads in sorted({1, os.cpu_count() or 1}):
        dn.set_num_threads(threads)
        plain = best(lambda: dt.estimate_normals(d, ks))
        mapped = best(lambda: dt.estimate_normals(d, ks, return_uncertainty=True))
        numba = best(lambda: dn.estimate_normals(depth, ks.numpy(), stack=True))
        print(f"| {threads} | {plain:.1f} | {mapped:.1f} | {mapped / plain:.2f}x | {numba:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
