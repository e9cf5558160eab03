"""Speed of depthnormals.torch beside kornia's depth_to_normals and the numba library.

CPU: the 640x480 torus-knot frame of the 3F2N dataset, one thread everywhere
(``torch.set_num_threads(1)``, ``depthnormals.set_num_threads(1)``), gradients off, two
warm-up calls, then N repeats per case interleaved round-robin (load on a shared machine hits
every case alike). Prints the median and minimum wall time per frame and each median as a
multiple of kornia's measured in the same run. ``--compile`` adds torch.compile'd cases
(inductor; a cold compile takes minutes on a small machine).

GPU (when CUDA is available): a batch of 64 frames at 640x480, frames per second (CUDA
events, after warm-up) of each method eager and compiled and of kornia, and the share of the
card's memory bandwidth: minimal bytes moved per frame (read depth 4 B/pixel, write normals
12 B/pixel) x frames/s / peak bandwidth (``--peak-gbs``, else a table of known cards).
Without CUDA it prints "no GPU: not measured".

    python benchmarks/torch_speed.py [FRAME_DIR] [--repeats N] [--compile] [--peak-gbs GB/s]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch

import depthnormals as dn
import depthnormals.torch as dt
from depthnormals.evaluate import machine_description

METHODS = ("3f2n", "d2nt", "sne-roadseg", "3f2n+", "d2nt+")
#: peak memory bandwidth in GB/s of cards we may be lent (vendor figures)
PEAK_GBS = {"H100 80GB HBM3": 3350.0, "H100 PCIe": 2000.0, "H100": 3350.0, "H200": 4800.0,
            "A100-SXM4-80GB": 2039.0, "A100": 1555.0}
BYTES_PER_PIXEL = 4 + 12  # read float32 depth, write 3 float32 components


def kornia_normals():
    from kornia.geometry.depth import depth_to_normals

    return depth_to_normals


def cpu_cases(z: np.ndarray, K: np.ndarray, compile_: bool) -> dict:
    kornia = kornia_normals()
    zt = torch.from_numpy(z)[None, None]
    Kt = torch.from_numpy(K.astype(np.float32))
    cases = {"kornia depth_to_normals": lambda: kornia(zt, Kt[None])}
    for m in METHODS:
        cases[f"torch {m}"] = lambda m=m: dt.estimate_normals(zt, Kt, method=m)
    for m in METHODS:
        cases[f"numba {m}"] = lambda m=m: dn.estimate_normals(z, K, method=m)
    if compile_:
        for m in ("3f2n", "3f2n+"):
            f = torch.compile(lambda d, m=m: dt.estimate_normals(d, Kt, method=m))
            t0 = time.perf_counter()
            f(zt)
            print(f"compiled torch {m}: first call (compile) {time.perf_counter() - t0:.1f} s")
            cases[f"torch {m} (torch.compile)"] = lambda f=f: f(zt)
    return cases


def run_cpu(z: np.ndarray, K: np.ndarray, repeats: int, compile_: bool) -> None:
    torch.set_num_threads(1)
    dn.set_num_threads(1)
    with torch.no_grad():
        cases = cpu_cases(z, K, compile_)
        for f in cases.values():
            f()
            f()
        times: dict[str, list[float]] = {k: [] for k in cases}
        for _ in range(repeats):
            for name, f in cases.items():
                t0 = time.perf_counter()
                f()
                times[name].append(time.perf_counter() - t0)
    ref = statistics.median(times["kornia depth_to_normals"])
    h, w = z.shape
    print(f"\nCPU, one thread, {w}x{h}, {repeats} interleaved repeats, gradients off")
    print(f"{'case':34s} {'median ms':>10s} {'min ms':>8s} {'x kornia':>9s}")
    for name, t in times.items():
        med = statistics.median(t)
        print(f"{name:34s} {med * 1e3:10.2f} {min(t) * 1e3:8.2f} {med / ref:9.2f}")


def _fps(f, batch: int, reps: int) -> float:
    for _ in range(3):
        f()
    torch.cuda.synchronize()
    start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
    start.record()
    for _ in range(reps):
        f()
    end.record()
    torch.cuda.synchronize()
    return batch * reps / (start.elapsed_time(end) / 1e3)


def run_gpu(z: np.ndarray, K: np.ndarray, batch: int, reps: int, peak_gbs: float | None) -> None:
    if not torch.cuda.is_available():
        print("\nGPU: no GPU: not measured (run this script on a CUDA machine for the GPU rows)")
        return
    name = torch.cuda.get_device_name()
    if peak_gbs is None:
        peak_gbs = next((v for k, v in PEAK_GBS.items() if k in name), None)
    zt = torch.from_numpy(z)[None, None].repeat(batch, 1, 1, 1).cuda()
    Kt = torch.from_numpy(K.astype(np.float32)).cuda()
    h, w = z.shape
    per_frame = BYTES_PER_PIXEL * h * w
    kornia = kornia_normals()
    cases = {"kornia depth_to_normals": lambda: kornia(zt, Kt[None].expand(batch, 3, 3))}
    for m in METHODS:
        cases[f"torch {m}"] = lambda m=m: dt.estimate_normals(zt, Kt, method=m)
        f = torch.compile(lambda d, m=m: dt.estimate_normals(d, Kt, method=m))
        cases[f"torch {m} (torch.compile)"] = lambda f=f: f(zt)
    print(f"\nGPU {name}, batch {batch} at {w}x{h}, peak {peak_gbs} GB/s, "
          f"{per_frame / 1e6:.2f} MB moved per frame at least")
    print(f"{'case':34s} {'frames/s':>10s} {'bandwidth share':>16s}")
    with torch.no_grad():
        for label, f in cases.items():
            fps = _fps(f, batch, reps)
            share = f"{per_frame * fps / (peak_gbs * 1e9):.1%}" if peak_gbs else "peak unknown"
            print(f"{label:34s} {fps:10.0f} {share:>16s}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("frame", nargs="?", default="/work/shared/data/3f2n-torusknot")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--compile", action="store_true", help="add torch.compile'd CPU cases")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--gpu-repeats", type=int, default=20)
    ap.add_argument("--peak-gbs", type=float, default=None)
    args = ap.parse_args()
    fr = next(dn.datasets.read_3f2n(args.frame))
    z = fr.depth.astype(np.float32)
    K = np.asarray(fr.K, dtype=np.float64)
    print(machine_description())
    print(f"torch {torch.__version__}")
    run_cpu(z, K, args.repeats, args.compile)
    run_gpu(z, K, args.batch, args.gpu_repeats, args.peak_gbs)


if __name__ == "__main__":
    main()
