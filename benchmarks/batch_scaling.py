"""Batch scaling (issue 15): ``estimate_normals`` on an (N, H, W) stack with 1 thread vs 2.

Frames: the analytic demo room, box on floor, stairs and sphere before a wall at 640x480
(``depthnormals.analytic``), cycled to N frames, each with its own Gaussian noise (0.1 z/f,
seed = frame index) and 2 % random holes. The 1-thread and 2-thread runs are interleaved and
repeated; each run is timed whole (``time.perf_counter``); the ratio is median(1 thread) /
median(2 threads), with the ratio of the best (least disturbed) runs and the per-round ratios
printed beside it. CPU/wall is the process CPU
time over the wall time: about 1.0 and 2.0 on an idle machine; less means the run was starved
by other processes and its ratio understates the scaling (with the kernel's autogroup
scheduling, a busy machine gives a session the same share whatever its thread count). CPU
ms/frame equal at 1 and 2 threads means the threads add no work of their own. Also timed: the same frames
as N single calls with 2 threads (the row-band parallelism inside each frame), for reference.

    python benchmarks/batch_scaling.py [--frames 64] [--method 3f2n+] [--rounds 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import depthnormals as dn
from depthnormals.analytic import make_scene
from depthnormals.evaluate import machine_description

K = dn.Intrinsics(525.0, 525.0, 319.5, 239.5)
SCENES = ("demo-room", "box-on-floor", "stairs", "sphere-before-wall")


def frames(n: int, shape=(480, 640)) -> np.ndarray:
    """``n`` noisy frames with holes, float32 (N, H, W)."""
    base = [make_scene(name).render(K=K, shape=shape).depth for name in SCENES]
    out = np.empty((n, *shape), np.float32)
    for i in range(n):
        rng = np.random.default_rng(i)
        z = base[i % len(base)].copy()
        ok = np.isfinite(z) & (z > 0)
        z[ok] += rng.normal(0.0, 1.0, ok.sum()) * 0.1 * z[ok] / K.fx
        z[rng.random(z.shape) < 0.02] = 0.0
        out[i] = np.where(np.isfinite(z), z, 0.0)
    return out


def timed(fn, cpu: list[float]) -> float:
    """Wall seconds of ``fn()``; its process CPU seconds (all threads) appended to ``cpu``."""
    c0, t0 = time.process_time(), time.perf_counter()
    fn()
    wall = time.perf_counter() - t0
    cpu.append(time.process_time() - c0)
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=64)
    parser.add_argument("--method", default="3f2n+")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    z = frames(args.frames)
    dn.estimate_normals(z[:2, :64, :64], K, method=args.method)  # compile outside the clock
    names = ("1 thread", "2 threads", "single calls, 2 threads")
    times: dict[str, list[float]] = {n: [] for n in names}
    cpu: dict[str, list[float]] = {n: [] for n in names}
    for _ in range(args.rounds):
        dn.set_num_threads(1)
        times[names[0]].append(timed(lambda: dn.estimate_normals(z, K, method=args.method), cpu[names[0]]))
        dn.set_num_threads(2)
        times[names[1]].append(timed(lambda: dn.estimate_normals(z, K, method=args.method), cpu[names[1]]))
        times[names[2]].append(
            timed(lambda: [dn.estimate_normals(f, K, method=args.method) for f in z], cpu[names[2]]))
    print(f"{args.frames} frames {z.shape[2]}x{z.shape[1]}, method {args.method}, "
          f"{args.rounds} interleaved rounds; {machine_description()}")
    for name, ts in times.items():
        med = statistics.median(ts)
        cores = statistics.median(c / t for c, t in zip(cpu[name], ts, strict=True))
        ms = 1e3 * statistics.median(cpu[name]) / args.frames
        print(f"  {name:<24} median {med:7.3f} s  ({args.frames / med:6.1f} frames/s)  "
              f"CPU/wall {cores:.2f}  CPU {ms:.1f} ms/frame  runs {' '.join(f'{t:.3f}' for t in ts)}")
    per_round = [a / b for a, b in zip(times["1 thread"], times["2 threads"], strict=True)]
    ratio = statistics.median(times["1 thread"]) / statistics.median(times["2 threads"])
    rounds = " ".join(f"{r:.2f}" for r in per_round)
    best = min(times["1 thread"]) / min(times["2 threads"])
    print(f"speed-up 2 threads / 1 thread: {ratio:.2f}x of the medians, {best:.2f}x of the best runs "
          f"(per round {rounds})")


if __name__ == "__main__":
    main()
