"""Real sensor frames scored on their planes: our estimators beside OpenCV and Open3D.

For every folder of ``../shared/data/real-sensors`` (Kinect v1, Xtion, densified LiDAR; no
ground truth), each frame's plane reference (``depthnormals.evaluate.plane_reference``, the
threshold from ``sensor_threshold``: Kinect z^2 model, 5 cm for LiDAR) scores every method on
the plane interiors (>= 5 px inside) and rims (1-4 px inside): mean angular error (deg) and
coverage; and in the bands by the planes' creases (``crease_band``: within 10 px of the line
where two planes over 30 deg apart meet, each pixel against the face it sees by geometry),
which the plane reference leaves out. Prints one table per measure (methods x folders, and the
mean over folders), then the single-thread time of ``3f2n+`` against OpenCV's FALS (window 7)
per frame, the two interleaved in the same run (median of ``--repeats``; thread CPU time
beside wall time, as in ``benchmarks/targets.py``: the shared VM moves wall-clock medians).

Every estimate is turned to face the camera (``dot(n, X) < 0``), as ours are, so the peers'
arbitrary signs do not count as errors; zero vectors count as missing.

A folder whose ``intrinsics.json`` gives the lens's ``distortion`` (``tests/data/azure_kinect_tof``,
a time-of-flight frame) is read undistorted (``depthnormals.undistort_depth``); with
``--lens-ignored`` every method is also scored on the stored grid read as a pinhole image, on
the same reference (its normals carried onto the undistorted grid by the same pixel map).

    python benchmarks/real_sensors.py [--methods 3f2n+,opencv-fals-7] [--json OUT]
                                      [--repeats 5] [--root ../shared/data/real-sensors ...]
                                      [--lens-ignored]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

import depthnormals as dn
from depthnormals.camera import backproject
from depthnormals.datasets import open as open_dataset
from depthnormals.evaluate import (
    crease_band,
    plane_reference,
    score_creases,
    score_planes,
    sensor_threshold,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from targets import fals_apply, measure_all

ROOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "real-sensors"


def _ours(method: str, **options) -> Callable:
    return lambda depth, K: dn.estimate_normals(depth, K, method=method, **options)


def _opencv_fals(window: int) -> Callable:
    def run(depth, K):
        import cv2

        h, w = depth.shape
        est = cv2.rgbd.RgbdNormals_create(h, w, cv2.CV_32F, np.asarray(K, np.float64), window,
                                          cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_FALS)
        return est.apply(cv2.rgbd.depthTo3d(np.ascontiguousarray(depth, np.float32), K))

    return run


def _open3d_normal_map(depth, K):
    import open3d as o3d

    image = o3d.t.geometry.Image(o3d.core.Tensor(np.ascontiguousarray(depth, np.float32)))
    intr = o3d.core.Tensor(np.asarray(K, dtype=np.float64))
    vmap = image.create_vertex_map(intr, invalid_fill=0.0)
    return vmap.create_normal_map(invalid_fill=0.0).as_tensor().numpy()


def _open3d_knn30(depth, K):
    import open3d as o3d

    pts = backproject(depth, K)
    ok = np.isfinite(pts[..., 2])
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts[ok]))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=30))
    cloud.orient_normals_towards_camera_location(np.zeros(3))
    out = np.full(pts.shape, np.nan)
    out[ok] = np.asarray(cloud.normals)
    return out


def _box_fit(depth, K):
    from depthnormals.ddm.boxfit import box_fit_normals

    return box_fit_normals(depth, K, radius=8)


#: label -> (depth float32 metres, K 3x3) -> normals (H, W, 3)
METHODS: dict[str, Callable] = {
    "3f2n+": _ours("3f2n+"),
    "opencv-fals-5": _opencv_fals(5),
    "opencv-fals-7": _opencv_fals(7),
    "fals-11": _ours("fals", window=11),
    "pcl-average-3d-gradient": _ours("pcl-average-3d-gradient"),
    "open3d-normal-map": _open3d_normal_map,
    "open3d-knn30": _open3d_knn30,
    "box-fit-8 (reference)": _box_fit,
}


def _facing(normals: np.ndarray, depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Normals (float64) turned to face the camera; zero-length or non-finite -> NaN."""
    n = np.asarray(normals, np.float64)[..., :3].copy()
    pts = backproject(depth, K)
    bad = ~np.all(np.isfinite(n), axis=-1) | (np.linalg.norm(n, axis=-1) == 0)
    with np.errstate(invalid="ignore"):
        flip = np.einsum("...i,...i->...", n, pts) > 0
    n[flip] *= -1.0
    n[bad] = np.nan
    return n


def _lens_ignored(frame, label: str) -> np.ndarray:
    """``label``'s normals of ``frame`` computed on its stored (distorted) grid, read as a
    pinhole image, and carried onto the undistorted grid by the pixel map of
    ``depthnormals.undistort_depth`` (each pixel takes the normal of the stored pixel its ray
    lands on: the normal of the same surface point)."""
    from depthnormals.datasets.realsensors import read_realsensors

    (raw,) = [f for f in read_realsensors(Path(frame.meta["depth_file"]).parent, undistort=False)
              if f.name == frame.name]
    depth = raw.depth.astype(np.float32)
    est = _facing(METHODS[label](depth, raw.K), depth, raw.K)
    h, w = depth.shape
    probe = dn.undistort_depth(np.arange(h * w, dtype=np.float64).reshape(h, w), raw.K,
                               frame.meta["undistorted"])
    idx = np.where(np.isfinite(probe), probe, -1).astype(np.int64)
    flat = est.reshape(-1, 3)
    return np.where((idx >= 0)[..., None], flat[np.maximum(idx, 0)], np.nan)


def accuracy(root: Path, labels: list[str], seed: int, lens_ignored: bool = False) -> dict:
    """folder -> label -> mean over the folder's frames of interior / rim / coverage; with
    ``lens_ignored``, for the folders whose ``intrinsics.json`` gives a lens distortion, also
    ``"<label> (lens ignored)"``: the method on the stored grid read as a pinhole image, scored
    on the same reference (:func:`_lens_ignored`)."""
    per: dict[str, dict[str, list[dict]]] = {}
    planes: dict[str, int] = {}
    for frame in open_dataset(root):
        ref = plane_reference(frame.depth, frame.K, seed=seed,
                              threshold=sensor_threshold(frame.meta))
        band = crease_band(frame.depth, frame.K, ref)
        planes[frame.group] = planes.get(frame.group, 0) + ref.n_planes
        depth = frame.depth.astype(np.float32)
        runs = [(label, False) for label in labels]
        if lens_ignored and frame.meta.get("undistorted"):
            runs += [(label, True) for label in labels]
        for label, ignored in runs:
            if ignored:
                est = _lens_ignored(frame, label)
                label = f"{label} (lens ignored)"
            else:
                est = _facing(METHODS[label](depth, frame.K), depth, frame.K)
            score = score_planes(est, ref)
            creases = score_creases(est, band)
            score.update({f"crease_{k}": creases[k] for k in ("mean", "near_mean", "far_mean")})
            per.setdefault(frame.group, {}).setdefault(label, []).append(score)
    out: dict = {}
    for group, by_label in per.items():
        out[group] = {"planes": planes[group]}
        for label, scores in by_label.items():
            out[group][label] = {k: _nanmean([s[k] for s in scores])
                                 for k in ("interior_mean", "rim_mean", "interior_median",
                                           "rim_median", "coverage", "crease_mean",
                                           "crease_near_mean", "crease_far_mean")}
            out[group][label]["frames"] = len(scores)
    return out


def speed(root: Path, repeats: int) -> list[dict]:
    """Single-thread ms of 3f2n+ and OpenCV FALS window 7 per frame, interleaved."""
    import cv2

    dn.set_num_threads(1)
    cv2.setNumThreads(1)
    rows = []
    for frame in open_dataset(root):
        depth = frame.depth.astype(np.float32)
        K = frame.K
        h, w = depth.shape
        (ours_cpu, ours_wall, _), (cv_cpu, cv_wall, _) = measure_all(
            [lambda d=depth, k=K: dn.estimate_normals(d, k, method="3f2n+"),
             fals_apply(depth, K, 7)], repeats)
        rows.append({"group": frame.group, "frame": frame.name, "size": f"{w}x{h}",
                     "3f2n+_cpu_ms": ours_cpu, "3f2n+_wall_ms": ours_wall,
                     "opencv-fals-7_cpu_ms": cv_cpu, "opencv-fals-7_wall_ms": cv_wall,
                     "ratio_cpu": ours_cpu / cv_cpu, "ratio_wall": ours_wall / cv_wall})
    return rows


def _nanmean(values: list[float]) -> float:
    """Mean of the finite values (a frame without a crease has none), NaN when none is."""
    v = np.asarray(values, dtype=np.float64)
    return float(v[np.isfinite(v)].mean()) if np.isfinite(v).any() else float("nan")


def _table(acc: dict, labels: list[str], key: str, scale: float = 1.0, digits: int = 2) -> str:
    groups = list(acc)
    head = "| method | " + " | ".join(groups) + " | mean over folders |"
    lines = [head, "|---|" + "---:|" * (len(groups) + 1)]
    for label in labels:
        vals = [acc[g][label][key] * scale if label in acc[g] else float("nan") for g in groups]
        cells = [f"{v:.{digits}f}" if np.isfinite(v) else "-" for v in vals]
        mean = float(np.nanmean(vals)) if np.isfinite(vals).any() else float("nan")
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {mean:.{digits}f} |")
    return "\n".join(lines)


def _git_state() -> str:
    """HEAD and whether src/ has uncommitted changes (the estimators change under work)."""
    import subprocess

    repo = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, text=True,
                              capture_output=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "src"], cwd=repo,
                               text=True, capture_output=True, check=True).stdout.split("\n")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    changed = [line[3:] for line in dirty if line.strip()]
    return head + (f" + uncommitted {', '.join(changed)}" if changed else "")


def main(argv: list[str] | None = None) -> int:
    from depthnormals.commands.bench import machine

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", type=Path, nargs="+", default=[ROOT],
                        help="real sensor folder(s) (each a folder of them, or one; their "
                             "folders in one table, e.g. ../shared/data/real-sensors tests/data)")
    parser.add_argument("--methods", default=",".join(METHODS),
                        help=f"comma-separated, from: {', '.join(METHODS)}")
    parser.add_argument("--json", type=Path, default=None, metavar="OUT",
                        help="write every number, the machine and the command here")
    parser.add_argument("--repeats", type=int, default=5, help="timing repeats per frame")
    parser.add_argument("--seed", type=int, default=0, help="seed of the plane reference")
    parser.add_argument("--no-speed", action="store_true", help="skip the timing")
    parser.add_argument("--lens-ignored", action="store_true",
                        help="for folders with a lens distortion, also score each method on the "
                             "stored grid read as a pinhole image, on the same reference")
    args = parser.parse_args(argv)
    labels = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in labels if m not in METHODS]
    if unknown:
        parser.error(f"unknown method(s) {', '.join(unknown)}; use {', '.join(METHODS)}")
    for root in args.root:
        if not root.is_dir():
            parser.error(f"{root} does not exist")
    print(f"machine: {machine()}; plane reference seed {args.seed}; "
          f"{', '.join(str(r) for r in args.root)}; "
          f"git {_git_state()}")
    acc: dict = {}
    for root in args.root:
        acc.update(accuracy(root, labels, args.seed, args.lens_ignored))
    if args.lens_ignored:  # the rows of the folders that have them
        labels = labels + [f"{m} (lens ignored)" for m in labels
                           if any(f"{m} (lens ignored)" in acc[g] for g in acc)]
    print("\nplanes per folder: " + ", ".join(f"{g} {acc[g]['planes']}" for g in acc))
    print("\n### interior mean error (deg), >= 5 px inside the planes\n")
    print(_table(acc, labels, "interior_mean"))
    print("\n### rim mean error (deg), 1-4 px inside\n")
    print(_table(acc, labels, "rim_mean"))
    print("\n### crease bands: mean error (deg) within 10 px of where two planes over 30 deg "
          "apart meet, each pixel against the face it sees (crease_band; frames without one "
          "left out)\n")
    print(_table(acc, labels, "crease_mean"))
    print("\n### crease bands, the 3 px by the line\n")
    print(_table(acc, labels, "crease_near_mean"))
    print("\n### crease bands, 3-10 px from the line\n")
    print(_table(acc, labels, "crease_far_mean"))
    print("\n### coverage (% of plane pixels with an estimate)\n")
    print(_table(acc, labels, "coverage", 100.0, 1))
    timing: list[dict] = []
    if not args.no_speed:
        timing = [row for root in args.root for row in speed(root, args.repeats)]
        print(f"\n### 1 thread, 3f2n+ vs OpenCV FALS window 7, median of {args.repeats} "
              "(interleaved)\n")
        print("| frame | size | 3f2n+ ms (cpu / wall) | OpenCV FALS 7 ms (cpu / wall) "
              "| ratio cpu | ratio wall |")
        print("|---|---|---:|---:|---:|---:|")
        for r in timing:
            print(f"| {r['group']}/{r['frame']} | {r['size']} | {r['3f2n+_cpu_ms']:.1f} / "
                  f"{r['3f2n+_wall_ms']:.1f} | {r['opencv-fals-7_cpu_ms']:.1f} / "
                  f"{r['opencv-fals-7_wall_ms']:.1f} | {r['ratio_cpu']:.2f} | {r['ratio_wall']:.2f} |")
        ratios = [r["ratio_cpu"] for r in timing]
        print(f"\nmedian ratio (cpu) {np.median(ratios):.2f}, range {min(ratios):.2f}-{max(ratios):.2f}")
    if args.json is not None:
        from depthnormals.io import write_bytes_atomic

        write_bytes_atomic(args.json, json.dumps({"machine": machine(), "git": _git_state(),
                                         "command": "python benchmarks/real_sensors.py "
                                                    + " ".join(argv if argv is not None
                                                               else sys.argv[1:]),
                                         "methods": labels,
                                         "seed": args.seed, "accuracy": acc, "speed": timing},
                                        indent=2, default=float).encode() + b"\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
