"""Dask scaling (issue 15): frames/s of ``run_estimate`` serial vs on a LocalCluster.

The frames of ``benchmarks/batch_scaling.py`` (analytic scenes at 640x480, noise, holes) are
written as ``.npy`` files; each run reads them, estimates (``3f2n+`` by default) and writes
``.npy`` normals into a fresh folder, exactly as ``depthnormals estimate IN -o DIR`` does.
Compared at equal cores:

- serial, 1 thread      vs  LocalCluster of 1 worker process (1 thread);
- serial, 2 threads     vs  LocalCluster of 2 worker processes (1 thread each),

with tasks of ``--batch`` frames. Both clusters are started (and every worker warmed up on
one frame) before the clock; the runs are interleaved and repeated, and the medians
compared: overhead = median(cluster) / median(serial) - 1, for the wall time and for the CPU
time (this process, which holds the LocalCluster's scheduler, plus every worker process; on
a machine shared with other jobs the CPU time is the steadier of the two).

    python benchmarks/dask_scaling.py [--frames 64] [--batch 16] [--rounds 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from batch_scaling import K, frames

import depthnormals as dn
from depthnormals.evaluate import machine_description
from depthnormals.jobs import run_estimate


def main() -> None:
    from distributed import Client

    from depthnormals.cluster import local_cluster

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=64)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--method", default="3f2n+")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        src = root / "in"
        src.mkdir()
        for i, z in enumerate(frames(args.frames)):
            np.save(src / f"{i:04d}.npy", z)
        runs = iter(range(10**6))

        def worker_cpu(client) -> float:
            return 0.0 if client is None else sum(client.run(time.process_time).values())

        def run(name: str, client=None) -> None:
            c0, w0, t0 = time.process_time(), worker_cpu(client), time.perf_counter()
            s = run_estimate([src], root / f"out{next(runs)}", method=args.method, K=K,
                             batch_size=args.batch, scheduler=client)
            times[name].append(time.perf_counter() - t0)
            cpu[name].append(time.process_time() - c0 + worker_cpu(client) - w0)
            assert s.written == args.frames

        clusters = {n: local_cluster(n, threads=1) for n in (1, 2)}
        clients = {n: Client(c) for n, c in clusters.items()}
        try:
            one = [src / "0000.npy"]
            for c in clients.values():  # load the compiled kernels in every worker
                c.run(lambda: run_estimate(one, root / "warm", method=args.method, K=K, resume=False))
            dn.estimate_normals(np.load(one[0]), K, method=args.method)
            names = ("serial, 1 thread", "LocalCluster, 1 worker", "serial, 2 threads",
                     "LocalCluster, 2 workers")
            times: dict[str, list[float]] = {n: [] for n in names}
            cpu: dict[str, list[float]] = {n: [] for n in names}
            for _ in range(args.rounds):
                dn.set_num_threads(1)
                run(names[0])
                run(names[1], clients[1])
                dn.set_num_threads(2)
                run(names[2])
                run(names[3], clients[2])
        finally:
            for c in clients.values():
                c.close()
            for c in clusters.values():
                c.close()
    print(f"{args.frames} frames 640x480 (.npy in and out), {args.method}, tasks of {args.batch} frames, "
          f"{args.rounds} interleaved rounds; {machine_description()['cpu']}, "
          f"{machine_description()['usable_cores']} cores")
    med = {n: statistics.median(ts) for n, ts in times.items()}
    mcpu = {n: statistics.median(cs) for n, cs in cpu.items()}
    for n, ts in times.items():
        print(f"  {n:<24} {args.frames / med[n]:6.1f} frames/s  (median {med[n]:.3f} s; runs "
              f"{' '.join(f'{t:.3f}' for t in ts)}); CPU {1e3 * mcpu[n] / args.frames:.1f} ms/frame")
    for serial, dask in ((names[0], names[1]), (names[2], names[3])):
        print(f"overhead {dask} vs {serial}: wall {100 * (med[dask] / med[serial] - 1):+.1f} %, "
              f"CPU {100 * (mcpu[dask] / mcpu[serial] - 1):+.1f} %")


if __name__ == "__main__":
    main()
