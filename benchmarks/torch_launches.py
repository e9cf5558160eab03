"""Kernel launches and time per call of the torch default on sensor depth, by batch size.

Eager torch on a GPU launches one kernel per tensor operation, and the default ``3f2n+`` on
noisy depth is thousands of small operations: at small batches a call is bound by their launch
cost (~10 us each of host time), not by the GPU's work. This script counts the operations of
one call (a ``TorchDispatchMode`` that counts every aten operation; any device, the CPU
included, so the count can be checked without a GPU) and, on ``--device cuda``, times calls of
batch 1, 8 and 32 (``--batches``; minimum of ``--repeats`` after two warm-ups, ``torch.cuda.synchronize``
around each), with and without ``return_uncertainty``.

The frames: the analytic demo room at 640x480 with a sensor model of
``depthnormals.synth.noise`` (``--models``, default ``kinect_v1`` (the measured support and
its face switch) and ``tof`` (the box-fit)), a new noise draw per frame.

    python benchmarks/torch_launches.py                      # operation counts, CPU
    python benchmarks/torch_launches.py --device cuda        # and the times on a GPU
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from torch.utils._python_dispatch import TorchDispatchMode

import depthnormals.torch as dt
from depthnormals.analytic import make_scene
from depthnormals.evaluate import machine_description
from depthnormals.synth import noise as sensor

K = (525.0, 525.0, 319.5, 239.5)


class _Count(TorchDispatchMode):
    """Counts the aten operations dispatched inside it."""

    def __init__(self):
        super().__init__()
        self.n = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.n += 1
        return func(*args, **(kwargs or {}))


def frames(model: str, count: int) -> np.ndarray:
    """``count`` float32 640x480 frames of the demo room through the sensor model ``model``."""
    r = make_scene("demo-room").render(K=K, shape=(480, 640))
    noise = getattr(sensor, f"{model}_noise")
    return np.stack([np.asarray(noise(r.depth, r.normals, K, rng=np.random.default_rng(s)), np.float32)
                     for s in range(count)])


def count_ops(z: torch.Tensor, **kw) -> int:
    """The aten operations of one call (after a warm-up call), of the path an accelerator
    takes (on the CPU with its neighbour loops stacked as there: ``_common.STACK_ON_CPU``)."""
    from depthnormals.torch import _common

    was = getattr(_common, "STACK_ON_CPU", False)
    _common.STACK_ON_CPU = True
    try:
        dt.estimate_normals(z, K, **kw)
        with _Count() as c:
            dt.estimate_normals(z, K, **kw)
    finally:
        _common.STACK_ON_CPU = was
    return c.n


def time_call(z: torch.Tensor, repeats: int, **kw) -> float:
    """Least wall seconds of a call, synchronised."""
    for _ in range(2):
        dt.estimate_normals(z, K, **kw)
    best = float("inf")
    for _ in range(repeats):
        torch.cuda.synchronize()
        t = time.perf_counter()
        dt.estimate_normals(z, K, **kw)
        torch.cuda.synchronize()
        best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--models", default="kinect_v1,tof")
    parser.add_argument("--batches", default="1,8,32")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    dev = torch.device(args.device)
    batches = [int(b) for b in args.batches.split(",")]
    print(f"machine: {machine_description()}; torch {torch.__version__}, device {dev}"
          + (f" ({torch.cuda.get_device_name(dev)})" if dev.type == "cuda" else ""))
    print("\n| sensor model | operations a call (batch 2, backend torch, the accelerator's path) |")
    print("|---|---|")
    stacks = {m: frames(m, max(batches)) for m in args.models.split(",")}
    for model, zs in stacks.items():
        z = torch.from_numpy(zs[:2])[:, None].to(dev)
        print(f"| {model} | {count_ops(z, backend='torch')} |")
    if dev.type != "cuda":
        print("\n(times only with --device cuda)")
        return
    print("\n| sensor model | batch | ms a call | ms a frame | with the map, ms a call | ms a frame |")
    print("|---|---|---|---|---|---|")
    for model, zs in stacks.items():
        for b in batches:
            z = torch.from_numpy(zs[:b])[:, None].to(dev)
            t0 = time_call(z, args.repeats)
            t1 = time_call(z, args.repeats, return_uncertainty=True)
            print(f"| {model} | {b} | {t0 * 1e3:.1f} | {t0 / b * 1e3:.2f} | {t1 * 1e3:.1f} "
                  f"| {t1 / b * 1e3:.2f} |", flush=True)


if __name__ == "__main__":
    main()
