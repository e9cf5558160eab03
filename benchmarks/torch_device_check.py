"""What the torch path promises, checked on a device in one run (a lent GPU's few minutes).

1. The default's normals and its expected-error map, ``depthnormals.torch.estimate_normals(...,
   backend="torch", return_uncertainty=True)`` on ``--device``, against the numba library's
   frame by frame: the 34 small frames of ``tests/test_torch_default_parity.py`` (analytic
   scenes clean, in millimetres, with Gaussian noise and each sensor model) in float64 and
   float32, and every real frame under ``--real`` (default the shared real-sensor folders and
   ``tests/data``'s time-of-flight and active-stereo frames), batched by size: mean and 99.9th
   percentile of the angle between the normals (limits 0.01 / 0.1 deg), NaN patterns, the
   map's largest relative difference (limit 1e-3).
2. The stacked neighbour loops of an accelerator (``_common.stack_width``) against one at a
   time, and ``depthnormals.torch.undistort_depth`` against ``depthnormals.undistort_depth``
   on the Azure Kinect frame's stored grid and lens: each equal to the bit.
3. The time of a batch of 8 640x480 kinect_v1 frames, with and without the map, beside the
   numba library's per frame on the same machine.

Prints OK / FAIL per part and "ALL OK" at the end. To carry the shared frames to a lent
machine, copy ``../shared/data/real-sensors`` into an ignored folder of the checkout and pass
it to ``--real``.

    python benchmarks/torch_device_check.py [--device cuda] [--real DIR ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import depthnormals as dn
import depthnormals.torch as dt
from depthnormals.analytic import make_scene
from depthnormals.datasets.realsensors import read_realsensors
from depthnormals.synth.noise import _rays as unit_rays
from depthnormals.torch import _common
from test_torch_default_parity import FRAMES, K_SMALL, MODELS

parser = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
parser.add_argument("--device", default="cuda")
parser.add_argument("--real", nargs="*", type=Path,
                    default=[Path(__file__).resolve().parents[2] / "shared/data/real-sensors",
                             Path(__file__).resolve().parents[1] / "tests/data"])
args = parser.parse_args()
dev = torch.device(args.device)


def sync() -> None:
    if dev.type == "cuda":
        torch.cuda.synchronize()


def check(depths, Ks, label, worst) -> bool:
    """Normals and map of ``depths`` (one batch on the device) against the numba library's."""
    z = torch.from_numpy(np.stack(depths))[:, None].to(dev)
    K = torch.from_numpy(np.stack([dn.as_intrinsics(k).matrix for k in Ks])).to(dev)
    n, u = dt.estimate_normals(z, K, backend="torch", return_uncertainty=True)
    assert n.device.type == dev.type and u.device.type == dev.type
    b = n.permute(0, 2, 3, 1).double().cpu().numpy()
    ub = u[:, 0].cpu().numpy()
    bad = []
    for i, (d, k) in enumerate(zip(depths, Ks, strict=True)):
        a, ua = dn.estimate_normals(d, k, return_uncertainty=True)
        na, nb = np.isnan(a).any(-1), np.isnan(b[i]).any(-1)
        worst["nan"] = max(worst["nan"], int((na != nb).sum()))
        worst["unan"] = max(worst["unan"], int((np.isnan(ua) != np.isnan(ub[i])).sum()))
        if (na != nb).any():
            bad.append(f"{i}: NaN differs at {int((na != nb).sum())}")
        ok = ~na & ~nb
        if not ok.any():
            continue
        err = dn.angular_error(a[ok][None].astype(np.float64), b[i][ok][None])[0]
        rays = unit_rays(d.shape, dn.as_intrinsics(k))[ok]
        grazing = np.abs(np.einsum("...i,...i->...", a[ok], rays)) < 1e-6  # the tie's either side
        err = np.where(grazing, np.minimum(err, 180.0 - err), err)
        m, p = float(err.mean()), float(np.percentile(err, 99.9))
        both = ~np.isnan(ua) & ~np.isnan(ub[i])
        rel = (float(np.max(np.abs(ua[both] - ub[i][both]) / np.maximum(ua[both], 1e-6)))
               if both.any() else 0.0)
        worst["mean"], worst["p999"] = max(worst["mean"], m), max(worst["p999"], p)
        worst["map_rel"] = max(worst["map_rel"], rel)
        if m > 0.01 or p > 0.1 or rel > 1e-3:
            bad.append(f"{i}: mean {m:.2e} p999 {p:.2e} map {rel:.2e}")
    print(f"{label}: {len(depths)} frames, {'OK' if not bad else 'FAIL ' + '; '.join(bad[:6])}", flush=True)
    return not bad


print("torch", torch.__version__, dev, flush=True)
worst = {"mean": 0.0, "p999": 0.0, "nan": 0, "map_rel": 0.0, "unan": 0}
ok = True
for dtype in (np.float64, np.float32):
    ok &= check([z.astype(dtype) for _, z in FRAMES], [K_SMALL] * len(FRAMES),
                f"analytic/synthetic {np.dtype(dtype).name}", worst)
frames = [f for root in args.real for f in read_realsensors(root)]
by: dict = {}
for f in frames:
    by.setdefault(f.depth.shape, []).append(f)
for shape, g in by.items():
    for dtype in (np.float64, np.float32):
        ok &= check([f.depth.astype(dtype) for f in g], [f.K for f in g],
                    f"real {shape} {np.dtype(dtype).name}", worst)
print("worst", worst, flush=True)

# the stacked neighbour loops (as this device runs them) against one at a time: the same bits
z = torch.from_numpy(np.stack([z for label, z in FRAMES if "clean" not in label]))[:, None].to(dev)
stacked = dt.estimate_normals(z, K_SMALL, backend="torch")
saved = _common.STACK_ELEMENTS
_common.STACK_ELEMENTS = 1
try:
    single = dt.estimate_normals(z, K_SMALL, backend="torch")
finally:
    _common.STACK_ELEMENTS = saved
same = torch.equal(torch.nan_to_num(stacked), torch.nan_to_num(single))
print(f"stacked neighbour loops against one at a time: {'OK, equal to the bit' if same else 'FAIL'}",
      flush=True)
ok &= same

azure = Path(__file__).resolve().parents[1] / "tests/data/azure_kinect_tof"
dist = json.loads((azure / "intrinsics.json").read_text())["distortion"]
for f in read_realsensors(azure, undistort=False):
    a = dn.undistort_depth(f.depth.astype(np.float64), f.K, dist)
    t = torch.from_numpy(f.depth.astype(np.float64))[None, None].to(dev)
    b = dt.undistort_depth(t, f.K, dist)[0, 0].cpu().numpy()
    same = bool(np.array_equal(a, b, equal_nan=True))
    print(f"undistort_depth: {'OK, equal to the bit' if same else 'FAIL'}", flush=True)
    ok &= same

K = (525.0, 525.0, 319.5, 239.5)
r = make_scene("demo-room").render(K=K, shape=(480, 640))
zs = [np.asarray(MODELS["kinect_v1"](r.depth, r.normals, K, rng=np.random.default_rng(s)), np.float32)
      for s in range(8)]
z = torch.from_numpy(np.stack(zs))[:, None].to(dev)
for unc in (False, True):
    for _ in range(3):
        dt.estimate_normals(z, K, backend="torch", return_uncertainty=unc)
    sync()
    t = time.perf_counter()
    for _ in range(10):
        dt.estimate_normals(z, K, backend="torch", return_uncertainty=unc)
    sync()
    g = (time.perf_counter() - t) / 80
    dn.estimate_normals(zs[0], K, return_uncertainty=unc)
    t = time.perf_counter()
    for s in range(8):
        dn.estimate_normals(zs[s], K, return_uncertainty=unc)
    c = (time.perf_counter() - t) / 8
    print(f"640x480 kinect_v1, map {unc}: torch {dev.type} {g * 1e3:.2f} ms a frame (batch 8), "
          f"numba {c * 1e3:.2f} ms a frame, x{c / g:.1f}", flush=True)
print("ALL OK" if ok else "SOME FAIL")
