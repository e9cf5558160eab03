"""Storage and throughput of ``depthnormals synth --preset ssn`` (issue 16), on a sample.

Three parts, each printed with the load average of the machine at the time:

1. ``stages``: where the time of one view goes, warm, on ``--stage-views`` poses of the
   first indoor and outdoor recipes: the clean render, the Kinect v2 discontinuity mask
   (numpy reference and the compiled one the generator uses), its 3x3 sub-pixel render, the
   rest of the Kinect v2 model, the Gaussian model, and writing the view (``npy``: 5
   float32 ``.npy`` files; ``compact``: encoding + one ``.npz``), medians in ms.
2. ``runs``: ``generate`` of the sample (``--indoor`` + ``--outdoor`` scenes x ``--views``
   views, preset settings otherwise) serial and on ``local:2``, storage ``npy`` and
   ``compact``, interleaved over ``--rounds`` rounds, each into a fresh folder (poses
   included): seconds per view; the numba cache is warmed first.
3. ``size``: bytes per view of each storage, and the extrapolation to the preset's 10,000
   views (views of the sample are a fair draw: the same pose sampler and scenes).

    python benchmarks/synth_ssn.py [--indoor 1] [--outdoor 1] [--views 20] [--rounds 2]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from depthnormals.render import render_mesh, render_subsamples
from depthnormals.synth import generate, make_scene, preset, scene_names
from depthnormals.synth import noise as _noise
from depthnormals.synth._kernels import discontinuity_mask
from depthnormals.synth.poses import sample_poses


def _load() -> str:
    return "load {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def _ms(samples: list[float]) -> float:
    return 1e3 * statistics.median(samples)


def stages(views: int) -> None:
    from depthnormals._compact import view_bytes
    from depthnormals.io import write_bytes_atomic
    from depthnormals.synth.views import _save_npy

    p = preset("ssn")
    cam, (h, w) = p["K"], p["size"]
    kv2 = _noise.parse_noise_spec("kinect_v2")[1]
    gau = _noise.parse_noise_spec("gaussian")[1]
    t: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("indoor", "outdoor"):
            scene = make_scene(scene_names(kind)[0], seed=1)
            for pose in sample_poses(scene, views, rng=np.random.default_rng(0), K=cam, size=(h, w)):
                c = [time.perf_counter()]
                r = render_mesh(scene.vertices, scene.faces, cam, pose=pose, width=w, height=h)
                c.append(time.perf_counter())
                _noise.discontinuity_mask(r.depth)
                c.append(time.perf_counter())
                mask = discontinuity_mask(r.depth)
                c.append(time.perf_counter())
                sub = render_subsamples(scene.vertices, scene.faces, cam, pose=pose, width=w, height=h,
                                        factor=3, mask=mask)
                c.append(time.perf_counter())
                rng = np.random.default_rng(0)
                z2 = _noise.kinect_v2_noise(r.depth, r.normals, cam, rng=rng, subsamples=sub,
                                            **{k: v for k, v in kv2.items() if k != "supersample"})
                c.append(time.perf_counter())
                zg = _noise.gaussian_noise(r.depth, cam, rng=rng, sigma=gau["sigma"],
                                           sigma_px=gau["sigma_px"])
                c.append(time.perf_counter())
                for i, a in enumerate((r.normals.astype(np.float32), r.face >= 0, r.depth.astype(np.float32),
                                       z2.astype(np.float32), zg.astype(np.float32))):
                    _save_npy(Path(tmp) / f"{i}.npy", a)
                c.append(time.perf_counter())
                data = view_bytes(r.normals, r.face >= 0, {"clean": r.depth, "kinect_v2": z2, "gaussian": zg},
                                  steps={"kinect_v2": kv2["rounding"]})
                c.append(time.perf_counter())
                write_bytes_atomic(Path(tmp) / "v.npz", data)
                c.append(time.perf_counter())
                names = ("render", "kinect_v2 mask (numpy reference)", "kinect_v2 mask (compiled)",
                         "kinect_v2 sub-pixel render", "kinect_v2 rest",
                         "gaussian", "write npy (5 files)", "encode compact", "write compact (1 file)")
                for name, a, b in zip(names, c[:-1], c[1:], strict=True):
                    t.setdefault(name, []).append(b - a)
    print(f"stages, median ms per view over {2 * views} views ({_load()}):")
    for name, v in t.items():
        print(f"  {name:34s} {_ms(v):7.1f}")


def _du(root: Path) -> int:
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())


def runs(indoor: int, outdoor: int, views: int, rounds: int) -> None:
    p = preset("ssn")
    kw = {**p, "indoor": indoor, "outdoor": outdoor, "views": views, "progress": False}
    n = (indoor + outdoor) * views
    with tempfile.TemporaryDirectory() as tmp:
        generate(Path(tmp) / "warm", **{**kw, "indoor": 1, "outdoor": 0, "views": 1})  # numba cache
        res: dict[tuple[str, str], list[float]] = {}
        size: dict[str, int] = {}
        for r in range(rounds):
            for storage in ("compact", "npy"):
                for sched in (None, "local:2"):
                    out = Path(tmp) / f"{storage}-{sched}-{r}"
                    la = _load()
                    s = generate(out, **{**kw, "storage": storage}, scheduler=sched)
                    res.setdefault((storage, str(sched)), []).append(s.seconds / n)
                    size[storage] = _du(out)
                    print(f"  round {r} {storage:7s} {sched or 'serial':8s} {s.seconds:6.1f} s "
                          f"{s.seconds / n:6.3f} s/view ({la})", flush=True)
        print(f"runs: {indoor} indoor + {outdoor} outdoor scenes x {views} views = {n} views; "
              f"median s/view -> 10,000 views ({_load()}):")
        for (storage, sched), v in res.items():
            m = statistics.median(v)
            print(f"  {storage:7s} {sched:8s} {m:6.3f} s/view -> {m * 1e4 / 60:6.1f} min")
        print("size per view (incl. scene.json, dataset.json) -> 10,000 views:")
        for storage, b in size.items():
            print(f"  {storage:7s} {b / n / 1e6:6.3f} MB/view -> {b / n * 1e4 / 1e9:6.2f} GB")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--indoor", type=int, default=1)
    ap.add_argument("--outdoor", type=int, default=1)
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--stage-views", type=int, default=5)
    ap.add_argument("--skip-runs", action="store_true")
    a = ap.parse_args()
    stages(a.stage_views)
    if not a.skip_runs:
        runs(a.indoor, a.outdoor, a.views, a.rounds)


if __name__ == "__main__":
    main()
