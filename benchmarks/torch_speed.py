"""Speed of depthnormals.torch beside kornia's depth_to_normals and the numba library.

CPU: the 640x480 torus-knot frame of the 3F2N dataset, one thread everywhere
(``torch.set_num_threads(1)``, ``depthnormals.set_num_threads(1)``), gradients off, two
warm-up calls, then N repeats per case interleaved round-robin (load on a shared machine hits
every case alike). Prints the median and minimum wall time per frame and each median as a
multiple of kornia's measured in the same run. ``--compile`` adds torch.compile'd cases
(inductor; a cold compile takes minutes on a small machine).

Batched CPU (``--cpu-batch N``, default 8): kornia's ``depth_to_normals`` against our torch
default ``3f2n+`` eager on a batch of N copies of the frame, one thread, and with
``--compile`` the same default under ``torch.compile``; ms per batch and per frame and the
ratio to kornia, as a markdown table.

GPU (``--gpu``): a batch of ``--batch`` frames (default 64) at 640x480, float32, on
``--device`` (default ``cuda``): frames per second (CUDA events after warm-up; wall time on
a CPU device) of our ``3f2n``, ``d2nt`` and the default ``3f2n+`` (eager, and with
``--compile`` also compiled) beside kornia's ``depth_to_normals`` and, when Open3D was built
with CUDA, its normal map (``Image.create_vertex_map`` + ``create_normal_map``, frame by
frame), and the share of the card's memory bandwidth: minimal bytes moved per frame (read
depth 4 B/pixel, write normals 12 B/pixel) x frames/s / peak (``--peak-gbs``, else a table of
known cards); printed as a markdown table. Without CUDA, ``--device cpu --batch 2 --repeats 2``
checks that the mode runs; a run without ``--gpu`` on a CUDA machine prints the command.

    python benchmarks/torch_speed.py [FRAME_DIR] [--repeats N] [--compile] [--cpu-batch 8]
    python benchmarks/torch_speed.py --gpu [--compile] [--batch 64] [--repeats 20] [--peak-gbs GB/s]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

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
    for m in METHODS:  # the torch implementation (backend "auto" would hand a CPU tensor to numba)
        cases[f"torch {m}"] = lambda m=m: dt.estimate_normals(zt, Kt, method=m, backend="torch")
    for m in METHODS:
        cases[f"numba {m}"] = lambda m=m: dn.estimate_normals(z, K, method=m)
    if compile_:
        for m in ("3f2n", "3f2n+"):
            f = torch.compile(lambda d, m=m: dt.estimate_normals(d, Kt, method=m, backend="torch"))
            t0 = time.perf_counter()
            f(zt)
            print(f"compiled torch {m}: first call (compile) {time.perf_counter() - t0:.1f} s")
            cases[f"torch {m} (torch.compile)"] = lambda f=f: f(zt)
    return cases


def _interleaved(cases: dict, repeats: int, *, warmups: int) -> dict[str, list[float]]:
    """Wall seconds of every case, ``warmups`` calls each first, then ``repeats`` rounds
    interleaved (load on the shared machine hits every case alike)."""
    for f in cases.values():
        for _ in range(warmups):
            f()
    times: dict[str, list[float]] = {k: [] for k in cases}
    for _ in range(repeats):
        for name, f in cases.items():
            t0 = time.perf_counter()
            f()
            times[name].append(time.perf_counter() - t0)
    return times


def run_cpu(z: np.ndarray, K: np.ndarray, repeats: int, compile_: bool) -> None:
    torch.set_num_threads(1)
    dn.set_num_threads(1)
    with torch.no_grad():
        times = _interleaved(cpu_cases(z, K, compile_), repeats, warmups=2)
    ref = statistics.median(times["kornia depth_to_normals"])
    h, w = z.shape
    print(f"\nCPU, one thread, {w}x{h}, {repeats} interleaved repeats, gradients off")
    print(f"{'case':34s} {'median ms':>10s} {'min ms':>8s} {'x kornia':>9s}")
    for name, t in times.items():
        med = statistics.median(t)
        print(f"{name:34s} {med * 1e3:10.2f} {min(t) * 1e3:8.2f} {med / ref:9.2f}")


GPU_COMMAND = "python benchmarks/torch_speed.py --gpu --compile --batch 64 --repeats 20"


def _table(title: str, header: tuple[str, ...], rows: list[tuple[str, ...]]) -> None:
    print(f"\n{title}\n")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(row) + " |")


def run_cpu_batch(z: np.ndarray, K: np.ndarray, batch: int, repeats: int, compile_: bool) -> None:
    """kornia against our torch default (eager, and compiled with ``compile_``) on a batch."""
    torch.set_num_threads(1)
    kornia = kornia_normals()
    zt = torch.from_numpy(z)[None, None].repeat(batch, 1, 1, 1)
    Kt = torch.from_numpy(K.astype(np.float32))
    Kb = Kt[None].expand(batch, 3, 3)
    cases = {"kornia depth_to_normals": lambda: kornia(zt, Kb),
             "depthnormals.torch 3f2n+ (backend auto: numba on a CPU tensor)":
                 lambda: dt.estimate_normals(zt, Kt, method="3f2n+"),
             "depthnormals.torch 3f2n+ (backend torch, eager)":
                 lambda: dt.estimate_normals(zt, Kt, method="3f2n+", backend="torch")}
    compile_s = None
    with torch.no_grad():
        if compile_:
            fc = torch.compile(lambda d: dt.estimate_normals(d, Kt, method="3f2n+", backend="torch"))
            t0 = time.perf_counter()
            fc(zt)
            compile_s = time.perf_counter() - t0
            cases["depthnormals.torch 3f2n+ (backend torch, torch.compile)"] = lambda: fc(zt)
        times = _interleaved(cases, repeats, warmups=1)
    ref = statistics.median(times["kornia depth_to_normals"])
    h, w = z.shape
    rows = []
    for name, t in times.items():
        med = statistics.median(t)
        label = name if "compile" not in name else f"{name}, compile {compile_s:.0f} s"
        rows.append((label, f"{med * 1e3:.1f}", f"{med * 1e3 / batch:.1f}", f"{med / ref:.2f}"))
    _table(f"CPU, one thread, batch {batch} at {w}x{h} float32, {repeats} interleaved repeats, "
           "gradients off", ("case", "ms per batch", "ms per frame", "x kornia"), rows)


def _timer(device: torch.device):
    """``elapsed(f, reps)``: seconds for ``reps`` calls of ``f`` on ``device``."""
    if device.type == "cuda":
        def elapsed(f, reps):
            torch.cuda.synchronize(device)
            start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
            start.record()
            for _ in range(reps):
                f()
            end.record()
            torch.cuda.synchronize(device)
            return start.elapsed_time(end) / 1e3
    else:
        def elapsed(f, reps):
            t0 = time.perf_counter()
            for _ in range(reps):
                f()
            return time.perf_counter() - t0
    return elapsed


def open3d_case(z: np.ndarray, K: np.ndarray, batch: int):
    """Open3D's CUDA normal map of ``batch`` frames (one at a time), or None without CUDA."""
    try:
        import open3d as o3d
    except ImportError:
        return None
    if not o3d.core.cuda.is_available():
        return None
    dev = o3d.core.Device("CUDA:0")
    frames = [o3d.t.geometry.Image(o3d.core.Tensor(z, device=dev)) for _ in range(batch)]
    Ko = o3d.core.Tensor(np.asarray(K, np.float64))

    def run():
        for im in frames:
            im.create_vertex_map(Ko, invalid_fill=0.0).create_normal_map(invalid_fill=0.0)
        o3d.core.cuda.synchronize()
    return run


def run_gpu(z: np.ndarray, K: np.ndarray, device: str, batch: int, reps: int, compile_: bool,
            peak_gbs: float | None) -> None:
    """Frames/s of our methods beside kornia and Open3D on ``device``, a markdown table."""
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        print(f"\nGPU: no CUDA device here: not measured. On a CUDA machine run\n    {GPU_COMMAND}")
        return
    name = torch.cuda.get_device_name(dev) if dev.type == "cuda" else f"device {device}"
    if peak_gbs is None and dev.type == "cuda":
        peak_gbs = next((v for k, v in PEAK_GBS.items() if k in name), None)
    zt = torch.from_numpy(z)[None, None].repeat(batch, 1, 1, 1).to(dev)
    Kt = torch.from_numpy(K.astype(np.float32)).to(dev)
    Kb = Kt[None].expand(batch, 3, 3)
    h, w = z.shape
    per_frame = BYTES_PER_PIXEL * h * w
    kornia = kornia_normals()
    cases = {"kornia depth_to_normals": lambda: kornia(zt, Kb)}
    o3d_run = open3d_case(z, K, batch) if dev.type == "cuda" else None
    if o3d_run is not None:
        cases["Open3D create_normal_map (CUDA, per frame)"] = o3d_run
    for m in ("3f2n", "d2nt", "3f2n+"):
        cases[f"torch {m}"] = lambda m=m: dt.estimate_normals(zt, Kt, method=m)
        if compile_:
            f = torch.compile(lambda d, m=m: dt.estimate_normals(d, Kt, method=m))
            cases[f"torch {m} (torch.compile)"] = lambda f=f: f(zt)
    # the default on sensor-like depth: its noisy branches (independent noise on this frame:
    # the box-fit; the analytic demo room at 640x480 with the kinect_v1 model: the measured
    # support, radius 16); each checked to take that branch
    from depthnormals.analytic import make_scene
    from depthnormals.synth.noise import kinect_v1_noise

    rng = np.random.default_rng(0)
    noisy = (z + rng.normal(size=z.shape) * 0.3 * z / K[0, 0]).astype(np.float32)
    room = make_scene("demo-room").render()
    kinect = np.asarray(kinect_v1_noise(room.depth, room.normals, room.K, rng=np.random.default_rng(1)),
                        dtype=np.float32)
    for label, d, k, branch in (("gaussian noise 0.3 px: box-fit", noisy, K, "box-fit"),
                                ("demo room, kinect_v1 model: measured support", kinect,
                                 np.asarray(room.K.matrix), "measured-support")):
        assert dn.noise_profile(d, k).branch == branch, (label, dn.noise_profile(d, k).branch)
        dd = torch.from_numpy(d)[None, None].repeat(batch, 1, 1, 1).to(dev)
        kt = torch.from_numpy(k.astype(np.float32)).to(dev)
        cases[f"torch 3f2n+ ({label})"] = lambda dd=dd, kt=kt: dt.estimate_normals(dd, kt)
        if compile_:
            fn = torch.compile(lambda x, kt=kt: dt.estimate_normals(x, kt))
            cases[f"torch 3f2n+ ({label}, torch.compile)"] = lambda fn=fn, dd=dd: fn(dd)
    elapsed = _timer(dev)
    rows = []
    with torch.no_grad():
        for label, f in cases.items():
            for _ in range(3):  # warm-up (and compilation)
                f()
            fps = batch * reps / elapsed(f, reps)
            share = f"{per_frame * fps / (peak_gbs * 1e9):.1%}" if peak_gbs else "peak unknown"
            rows.append((label, f"{fps:.0f}" if fps >= 100 else f"{fps:.2f}", share))
    if o3d_run is None:
        rows.append(("Open3D create_normal_map", "not measured (no Open3D CUDA build)", ""))
    _table(f"{name}, batch {batch} at {w}x{h} float32, {reps} repeats, peak {peak_gbs} GB/s, "
           f"{per_frame / 1e6:.2f} MB moved per frame at least",
           ("case", "frames/s", "bandwidth share"), rows)
    if dev.type != "cuda":
        print(f"\n(not a GPU: this checks that the mode runs.) On a CUDA machine run\n    {GPU_COMMAND}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("frame", nargs="?", default="/work/shared/data/3f2n-torusknot")
    ap.add_argument("--repeats", type=int, default=None,
                    help="repeats per case (default 15 on the CPU, 20 with --gpu)")
    ap.add_argument("--compile", action="store_true", help="add torch.compile'd cases")
    ap.add_argument("--cpu-batch", type=int, default=8, help="batch of the batched CPU table")
    ap.add_argument("--gpu", action="store_true", help="the GPU table instead of the CPU ones")
    ap.add_argument("--device", default="cuda", help="device of the --gpu table (cpu: a dry run)")
    ap.add_argument("--batch", type=int, default=64, help="batch of the --gpu table")
    ap.add_argument("--peak-gbs", type=float, default=None)
    args = ap.parse_args()
    if Path(args.frame).is_dir():
        fr = next(dn.datasets.read_3f2n(args.frame))
        z, K = fr.depth.astype(np.float32), np.asarray(fr.K, dtype=np.float64)
        print(f"frame: {args.frame}")
    else:  # e.g. a lent GPU machine without the shared data folder
        from depthnormals.analytic import make_scene

        r = make_scene("demo-room").render()
        z, K = r.depth.astype(np.float32), np.asarray(r.K.matrix, dtype=np.float64)
        print(f"frame: {args.frame} is absent; the analytic demo-room scene at 640x480 instead")
    print(machine_description())
    print(f"torch {torch.__version__}")
    if args.gpu:
        run_gpu(z, K, args.device, args.batch, args.repeats or 20, args.compile, args.peak_gbs)
        return
    run_cpu(z, K, args.repeats or 15, args.compile)
    run_cpu_batch(z, K, args.cpu_batch, args.repeats or 15, args.compile)
    if torch.cuda.is_available():
        print(f"\nCUDA is available: for the GPU table run\n    {GPU_COMMAND}")


if __name__ == "__main__":
    main()
