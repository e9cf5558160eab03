"""Sensor models against real frames: the statistics that tell quantised, correlated depth apart.

For the real frames of ``../shared/data/real-sensors`` (Kinect v1 from TUM RGB-D and NYU v2,
SUN RGB-D's Xtion-class frame, KITTI's densified LiDAR) and for simulated indoor views with
each noise model of :mod:`depthnormals.synth.noise` (``kinect_v1``, ``kinect_v2``, ``tof``,
``realsense_d4xx``), prints one side-by-side table:

- ``zero d2``: the share of exactly-zero second differences ``z[i-1] - 2 z[i] + z[i+1]`` along
  rows and columns, over valid triples on smooth surfaces (both neighbouring jumps under 5 % of
  the depth). Quantised depth comes in plateaus, inside which it is exactly 0; noisy float
  depth gives 0 %.
- ``run med / mean``: plateau widths, the run lengths (px) of equal depth along rows, over the
  runs bounded on both sides by a smooth non-zero step (neither an edge nor a hole).
- ``step 2 m / 4 m``: the size (mm) of the non-zero depth jumps between adjacent plateau pixels
  (the two runs at least 2 px wide) on smooth surfaces, median in the depth bins 1.75-2.25 m and
  3.5-4.5 m; ``c`` the median of ``step / z^2`` (mm per m^2). Kinect v1 disparity quantisation
  of 1/8 px at ``f b = 580 x 0.075`` predicts ``c = 0.125 / 43.5 m^-1 = 2.87 mm/m^2``: 11.5 mm
  at 2 m, 46 mm at 4 m.
- ``ac1 .. ac8``: the autocorrelation at lags 1, 2, 4, 8 px of the residual of a plane fitted
  to ``1/z`` on non-overlapping 31 x 31 windows (all pixels valid, no jump above 5 %, residual
  RMS between 10 um and 1 % of the depth: the large planes of the frame), averaged over rows
  and columns and over windows.
- ``est. noise``: :func:`depthnormals.estimate_noise` (robust second differences of ``1/z``, in
  pixel footprints ``z / f``), median over the frames, and how many frames read exactly 0:
  the failure mode of quantised depth, whose plateaus have zero second differences.

The simulated views are rendered at 640 x 480 with the PrimeSense default intrinsics (fx = fy
= 525, the TUM frames' camera) from indoor scenes of the ``mixed`` set; every model is applied
to the same clean renders.

Run (13-22 s on the shared 2-core Xeon VM; results in docs/synthetic.md, "Sensor models
against real frames")::

    python benchmarks/sensor_stats.py [--views 3] [--scenes living_room,office,...] [--json OUT]
    python benchmarks/sensor_stats.py --models kinect_v1:window=1,kinect_v1:window=7,kinect_v1
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from depthnormals.camera import Intrinsics
from depthnormals.io import read_png

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real-sensors"
JUMP = 0.05  # relative jump that ends a smooth surface
TILE = 31
LAGS = tuple(range(1, 9))
SHOWN_LAGS = (1, 2, 4, 8)
PRIMESENSE = Intrinsics(525.0, 525.0, 319.5, 239.5)
SIZE = (480, 640)
MODELS = ("kinect_v1", "kinect_v2", "tof", "realsense_d4xx")
SCENES = ("furnished_living", "cluttered_office", "dining_table", "living_room", "office", "library")


# ------------------------------------------------------------------------------- readers ----

def _pgm16(path: Path, endian: str) -> np.ndarray:
    """16-bit binary PGM (P5, maxval > 255): the samples are the last 2 W H bytes."""
    data = path.read_bytes()
    head = data[:64].split()
    w, h = int(head[1]), int(head[2])
    return np.frombuffer(data, endian + "u2", count=w * h, offset=len(data) - 2 * w * h).reshape(h, w)


def _intrinsics(folder: Path) -> tuple[Intrinsics, float]:
    meta = json.loads((folder / "intrinsics.json").read_text())
    return Intrinsics(meta["fx"], meta["fy"], meta["cx"], meta["cy"]), float(meta["depth_scale"])


def real_frames(root: Path = REAL) -> list[tuple[str, str, np.ndarray, Intrinsics]]:
    """``(family, frame, depth in metres with 0 = invalid, K)`` of every real frame."""
    out = []

    def plain(folder, pattern, family):
        K, scale = _intrinsics(root / folder)
        for p in sorted((root / folder).glob(pattern)):
            raw = read_png(p) if p.suffix == ".png" else _pgm16(p, ">")
            z = raw.astype(np.float64) * scale
            z[raw == 65535] = 0.0
            out.append((family, f"{folder}/{p.name}", z, K))

    plain("tum_fr2_kinect1_slambook", "depth/*.png", "Kinect v1 TUM")
    plain("tum_kinect1_open3d", "TUM_depth.png", "Kinect v1 TUM")
    raw = _pgm16(root / "nyu_raw_kinect1_open3d" / "NYU_depth.pgm", "<").astype(np.float64)
    z = np.where(raw < 2047, 351.3 / np.maximum(1092.5 - raw, 1e-9), 0.0)
    out.append(("Kinect v1 NYU raw", "nyu_raw_kinect1_open3d/NYU_depth.pgm", np.where(z < 10, z, 0.0),
                _intrinsics(root / "nyu_raw_kinect1_open3d")[0]))
    plain("nyu_registered_kinect1_slambook", "depth/*.pgm", "Kinect v1 NYU registered")
    v = read_png(root / "sunrgbd_open3d" / "SUN_depth.png").astype(np.uint16)
    mm = (v >> 3) | (v << 13)
    out.append(("SUN RGB-D Xtion", "sunrgbd_open3d/SUN_depth.png", mm.astype(np.float64) * 1e-3,
                _intrinsics(root / "sunrgbd_open3d")[0]))
    plain("kitti_road_lidar_sne_roadseg", "depth_u16.png", "KITTI LiDAR (densified)")
    return out


# ---------------------------------------------------------------------------- statistics ----

def _smooth(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a > 0) & (b > 0) & (np.abs(a - b) <= JUMP * np.minimum(a, b))


def _equal(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(a - b) <= 1e-9 * np.maximum(a, 1.0)


def second_differences(z: np.ndarray) -> tuple[int, int]:
    """(zero, total) second differences over smooth valid triples, rows and columns."""
    zero = total = 0
    for a in (z, z.T):
        l, c, r = a[:, :-2], a[:, 1:-1], a[:, 2:]
        ok = _smooth(l, c) & _smooth(c, r)
        zero += int(np.count_nonzero(ok & _equal(l - c, c - r)))
        total += int(np.count_nonzero(ok))
    return zero, total


def plateaus(z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along rows: widths of the interior runs of equal depth (bounded by smooth steps), and
    the steps ``|dz|`` between two runs of width >= 2 with their depth."""
    h, w = z.shape
    eq = _equal(z[:, :-1], z[:, 1:]) & (z[:, :-1] > 0)
    step = _smooth(z[:, :-1], z[:, 1:]) & ~eq
    # run boundaries: a boundary after column j when not eq[j]
    brk = np.ones((h, w + 1), dtype=bool)
    brk[:, 1:-1] = ~eq
    rows, cols = np.nonzero(brk)  # row-major: consecutive entries of a row delimit its runs
    same = rows[1:] == rows[:-1]
    start, end, row = cols[:-1][same], cols[1:][same], rows[:-1][same]  # run = [start, end)
    width = end - start
    # bounded by a smooth step on both sides
    left_ok = np.zeros(width.shape, dtype=bool)
    right_ok = np.zeros(width.shape, dtype=bool)
    has_left = start > 0
    left_ok[has_left] = step[row[has_left], start[has_left] - 1]
    has_right = end < w
    right_ok[has_right] = step[row[has_right], end[has_right] - 1]
    interior = width[left_ok & right_ok & (z[row, start] > 0)]
    # steps between consecutive runs of one row, both >= 2 wide
    nxt = np.zeros(width.shape, dtype=bool)
    nxt[:-1] = (row[1:] == row[:-1]) & right_ok[:-1] & (width[:-1] >= 2) & (width[1:] >= 2)
    i = np.nonzero(nxt)[0]
    za, zb = z[row[i], end[i] - 1], z[row[i], end[i]]
    return interior, np.abs(zb - za), 0.5 * (za + zb)


def residual_autocorrelation(z: np.ndarray, *, tile: int = TILE, max_rel_rms: float = 0.01) -> np.ndarray:
    """Mean autocorrelation (lags ``LAGS``, rows and columns averaged) of the residual of a
    plane fitted to ``1/z`` on each accepted ``tile x tile`` window; shape (n_windows, len(LAGS))."""
    h, w = z.shape
    v, u = np.mgrid[0:tile, 0:tile].astype(np.float64)
    A = np.stack([u.ravel(), v.ravel(), np.ones(tile * tile)], axis=1)
    pinv = np.linalg.pinv(A)
    out = []
    for v0 in range(0, h - tile + 1, tile):
        for u0 in range(0, w - tile + 1, tile):
            p = z[v0:v0 + tile, u0:u0 + tile]
            if not np.all(p > 0):
                continue
            if not (np.all(_smooth(p[:, :-1], p[:, 1:])) and np.all(_smooth(p[:-1], p[1:]))):
                continue
            fit = 1.0 / (A @ (pinv @ (1.0 / p).ravel())).reshape(tile, tile)
            r = p - fit
            r = r - r.mean()
            rms = np.sqrt(np.mean(r ** 2))
            if rms < 1e-5 or rms > max_rel_rms * p.mean():  # 10 um: a clean plane's rounding
                continue
            var = np.sum(r ** 2)
            out.append([0.5 * (np.sum(r[:, :-k] * r[:, k:]) + np.sum(r[:-k] * r[k:])) / var for k in LAGS])
    return np.asarray(out, dtype=np.float64).reshape(-1, len(LAGS))


def frame_stats(frames: list[np.ndarray], Ks: list[Intrinsics]) -> dict:
    """The pooled statistics of a list of depth maps (metres, 0 = invalid) and cameras."""
    from depthnormals import estimate_noise

    zero = total = 0
    widths, steps, zs, acs, est = [], [], [], [], []
    for z, K in zip(frames, Ks, strict=True):
        z = np.where(np.isfinite(z) & (z > 0), z, 0.0).astype(np.float64)
        est.append(float(estimate_noise(z, K)))
        a, b = second_differences(z)
        zero, total = zero + a, total + b
        wd, st, zm = plateaus(z)
        widths.append(wd)
        steps.append(st)
        zs.append(zm)
        acs.append(residual_autocorrelation(z))
    widths = np.concatenate(widths)
    steps, zs = np.concatenate(steps), np.concatenate(zs)
    ac = np.concatenate(acs)

    def step_at(lo, hi):
        sel = (zs >= lo) & (zs < hi)
        return float(np.median(steps[sel]) * 1e3) if np.count_nonzero(sel) >= 20 else None

    return {
        "frames": len(frames),
        "zero_d2": zero / total if total else None,
        "triples": total,
        "run_median": float(np.median(widths)) if widths.size else None,
        "run_mean": float(np.mean(widths)) if widths.size else None,
        "runs": int(widths.size),
        "step_2m_mm": step_at(1.75, 2.25),
        "step_4m_mm": step_at(3.5, 4.5),
        "step_c_mm_per_m2": float(np.median(steps / zs ** 2) * 1e3) if steps.size >= 20 else None,
        "steps": int(steps.size),
        "autocorr": ({str(k): float(a) for k, a in zip(LAGS, ac.mean(axis=0), strict=True)}
                     if len(ac) else None),
        "windows": len(ac),
        "estimate_noise": est,
        "estimate_noise_median": float(np.median(est)),
        "estimate_noise_zero": sum(e == 0 for e in est),
    }


# ----------------------------------------------------------------------------- simulated ----

def simulated_views(scenes: tuple[str, ...], views: int, seed: int) -> list:
    """Clean renders (RenderResult) of ``views`` poses of each indoor scene, 640 x 480, fx = 525."""
    from depthnormals.render import render_mesh
    from depthnormals.synth import make_scene, sample_poses

    out = []
    for i, name in enumerate(scenes):
        scene = make_scene(name, seed=seed + i)
        poses = sample_poses(scene, views, rng=np.random.default_rng([seed, i]), K=PRIMESENSE, size=SIZE)
        for pose in poses:
            r = render_mesh(scene.vertices, scene.faces, PRIMESENSE, pose=pose, width=SIZE[1],
                            height=SIZE[0])
            out.append((scene, pose, r))
    return out


def simulate(spec: str, renders: list, seed: int) -> list[np.ndarray]:
    """Noisy depth of the noise spec ``spec`` (``"kinect_v1"``, ``"kinect_v1:window=7"``, ...)
    for every render; each view has its own generator from (seed, model, view)."""
    from depthnormals.render import render_subsamples
    from depthnormals.synth import noise

    model, st = noise.parse_noise_spec(spec)
    out = []
    for j, (scene, pose, r) in enumerate(renders):
        rng = np.random.default_rng([seed, 7, noise.MODELS.index(model), j])
        if model == "kinect_v1":
            out.append(noise.kinect_v1_noise(r.depth, r.normals, PRIMESENSE, rng=rng, **st))
        elif model == "realsense_d4xx":
            out.append(noise.realsense_d4xx_noise(r.depth, r.normals, PRIMESENSE, rng=rng, **st))
        elif model in ("kinect_v2", "tof"):
            factor = st.pop("supersample", 3)
            sub = None if factor <= 1 else render_subsamples(
                scene.vertices, scene.faces, PRIMESENSE, pose=pose, width=SIZE[1], height=SIZE[0],
                factor=factor, mask=noise.discontinuity_mask(r.depth))
            fn = noise.kinect_v2_noise if model == "kinect_v2" else noise.tof_noise
            out.append(fn(r.depth, r.normals, PRIMESENSE, rng=rng, subsamples=sub, **st))
            st["supersample"] = factor
        else:
            out.append(noise.gaussian_noise(r.depth, PRIMESENSE, rng=rng, **st))
    return out


# --------------------------------------------------------------------------------- table ----

def _fmt(x, spec):
    width = int(spec.split(".")[0])
    return f"{'-':>{width}s}" if x is None else format(x, spec)


def table(rows: list[tuple[str, dict]]) -> str:
    head = (f"{'depth source':34s} {'n':>2s} {'zero d2':>8s} {'run med':>7s} {'mean':>5s} "
            f"{'step 2m':>7s} {'4m':>5s} {'c':>5s} " + " ".join(f"{'ac' + str(k):>5s}" for k in SHOWN_LAGS)
            + f" {'win':>4s} {'est. noise':>12s}")
    lines = [head, "-" * len(head)]
    for name, s in rows:
        ac = s["autocorr"] or {}
        zd2 = None if s["zero_d2"] is None else 100 * s["zero_d2"]
        lines.append(
            f"{name:34s} {s['frames']:2d} {_fmt(zd2, '7.1f')}% "
            f"{_fmt(s['run_median'], '7.0f')} {_fmt(s['run_mean'], '5.1f')} "
            f"{_fmt(s['step_2m_mm'], '7.1f')} {_fmt(s['step_4m_mm'], '5.1f')} "
            f"{_fmt(s['step_c_mm_per_m2'], '5.2f')} "
            + " ".join(_fmt(ac.get(str(k)), '5.2f') for k in SHOWN_LAGS) + f" {s['windows']:4d}"
            + f" {s['estimate_noise_median']:5.3f} ({s['estimate_noise_zero']}/{s['frames']} 0)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--real", type=Path, default=REAL, help="folder of the real frames")
    ap.add_argument("--scenes", default=",".join(SCENES), help="indoor scenes (comma-separated)")
    ap.add_argument("--views", type=int, default=3, help="views per scene")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--models", default=",".join(MODELS),
                    help="noise specs, comma-separated (e.g. kinect_v1,kinect_v1:window=7)")
    ap.add_argument("--json", type=Path, help="write every statistic here")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    if args.real.is_dir():
        families: dict[str, list] = {}
        for family, _, z, K in real_frames(args.real):
            families.setdefault(family, []).append((z, K))
        rows += [(f"real: {k}", frame_stats(*zip(*v, strict=True))) for k, v in families.items()]
    else:
        print(f"no real frames at {args.real}; simulated only", file=sys.stderr)
    renders = simulated_views(tuple(s for s in args.scenes.split(",") if s), args.views, args.seed)
    cams = [PRIMESENSE] * len(renders)
    rows.append(("sim: clean", frame_stats([r.depth for _, _, r in renders], cams)))
    for m in (m for m in args.models.split(",") if m):
        rows.append((f"sim: {m}", frame_stats(simulate(m, renders, args.seed), cams)))
    print(table(rows))
    print(f"({len(renders)} simulated views, 640 x 480, fx = 525; {time.perf_counter() - t0:.0f} s)")
    if args.json:
        args.json.write_text(json.dumps({name: s for name, s in rows}, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
