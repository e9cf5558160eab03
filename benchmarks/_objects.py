"""Object views for the 6D-pose and point-cloud-completion benchmarks (issue 25).

Shared by ``benchmarks/pose6d.py`` and ``benchmarks/completion.py``: LineMOD-like views of
single objects on a table, rendered with the library's z-buffer renderer
(:func:`depthnormals.render.render_mesh`) from the asset meshes of ``synth``
(:mod:`depthnormals.synth.assets`, the meshes shipped in the pybullet wheel), with

- a colour image: per-face albedo (a colour per object, +-8 % per face, so low-poly faces show
  as faint texture) times Lambertian shading under one random light, ambient 0.3, and
  Gaussian pixel noise (sigma 0.02);
- depth with the ``kinect_v1``, ``tof`` and ``realsense_d4xx`` sensor models of
  :mod:`depthnormals.synth.noise` (view i gets model i mod 3, defaults of each model);
- the object mask (pixels whose visible face is the object's: the segmentation a pose
  pipeline is given), the object-to-camera pose (R, t) and the ground-truth normals.

The object stands upright on the table (z up) at a random yaw; two distractor boxes stand
0.12-0.25 m away; the camera is 0.6-1.0 m away at 25-65 deg elevation and any azimuth, and
looks at the object's centre +-2 cm. Objects are resized so that their longest side is
12 cm (LineMOD's objects are 10-30 cm). The object frame is the centre of the object's
bounding box, axes of the mesh (z up).

The views are generated once per parameter set and cached (``.npz``, written atomically) in
``cache_dir``; :func:`object_views` returns them.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

import depthnormals as dn

#: The objects: the pybullet mug and teddy, the lego brick and five of pybullet's random
#: objects (none has a rotational symmetry; the mug's handle is hidden from some views).
OBJECTS = ("mug", "teddy", "lego", "object_008", "object_034", "object_123", "object_213", "object_278")
#: Longest side of every object after resizing, metres.
OBJECT_SIZE = 0.12
#: Sensor models, one per view in turn.
SENSORS = ("kinect_v1", "tof", "realsense_d4xx")
#: Bump when the rendering changes (invalidates caches).
VERSION = 1


def intrinsics(size: int) -> dn.Intrinsics:
    """Square images of ``size`` px; f = 4.2 size px (a 12 cm object at 0.8 m spans ~40 % of it)."""
    f = 4.2 * size
    return dn.Intrinsics(f, f, (size - 1) / 2.0, (size - 1) / 2.0)


def object_mesh(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (object frame: bounding-box centre, longest side :data:`OBJECT_SIZE`) and faces."""
    from depthnormals.synth.assets import load_asset

    V, F = load_asset(name)
    lo, hi = V.min(0), V.max(0)
    V = (V - (lo + hi) / 2) * (OBJECT_SIZE / float((hi - lo).max()))
    return np.ascontiguousarray(V), np.ascontiguousarray(F)


def surface_points(name: str, n: int, *, seed: int = 0) -> np.ndarray:
    """(n, 3) float64 points sampled uniformly (by area) on the object's surface, object frame."""
    V, F = object_mesh(name)
    tri = V[F]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(F), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    a, b, c = 1 - s, s * (1 - r2), s * r2
    return a[:, None] * tri[pick, 0] + b[:, None] * tri[pick, 1] + c[:, None] * tri[pick, 2]


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _colour(name: str) -> np.ndarray:
    h = int(hashlib.sha256(name.encode()).hexdigest()[:8], 16)
    rgb = np.array([(h >> 0) & 255, (h >> 8) & 255, (h >> 16) & 255], dtype=np.float64) / 255.0
    return 0.25 + 0.7 * rgb


def _noise(
    model: str, depth: np.ndarray, normals: np.ndarray, K: Any, rng: np.random.Generator
) -> np.ndarray:
    from depthnormals.synth import kinect_v1_noise, realsense_d4xx_noise, tof_noise

    fn = {"kinect_v1": kinect_v1_noise, "tof": tof_noise, "realsense_d4xx": realsense_d4xx_noise}[model]
    z = fn(depth, normals, K, rng=rng)
    return np.where(np.isfinite(z) & (z > 0), z, 0.0)


def render_view(name: str, rng: np.random.Generator, *, size: int, sensor: str | None) -> dict[str, Any]:
    """One view of object ``name``: rgb, noisy depth (clean for ``sensor=None``), mask, pose,
    ground-truth normals."""
    from depthnormals.render import look_at, render_mesh
    from depthnormals.synth.meshes import box, merge, quad

    V, F = object_mesh(name)
    h = float(V[:, 2].max() - V[:, 2].min())
    yaw = rng.uniform(0, 2 * np.pi)
    Rw = _rot_z(yaw)
    tw = np.array([0.0, 0.0, h / 2])
    parts = [(V @ Rw.T + tw, F), quad([(-1.5, -1.5, 0), (1.5, -1.5, 0), (1.5, 1.5, 0), (-1.5, 1.5, 0)])]
    for _ in range(2):
        a, r = rng.uniform(0, 2 * np.pi), rng.uniform(0.12, 0.25)
        c = np.array([r * np.cos(a), r * np.sin(a)])
        half = rng.uniform(0.02, 0.05, size=2)
        parts.append(box((*(c - half), 0.0), (*(c + half), rng.uniform(0.04, 0.12))))
    Vs, Fs = merge(parts)
    n_obj = len(F)
    dist, elev, azim = rng.uniform(0.6, 1.0), np.radians(rng.uniform(25, 65)), rng.uniform(0, 2 * np.pi)
    target = tw + rng.uniform(-0.02, 0.02, size=3)
    eye = target + dist * np.array([np.cos(elev) * np.cos(azim), np.cos(elev) * np.sin(azim), np.sin(elev)])
    T = look_at(eye, target)
    K = intrinsics(size)
    r = render_mesh(Vs, Fs, K, pose=T, width=size, height=size)
    Rc = T[:3, :3]
    R = Rc.T @ Rw  # object -> camera
    t = Rc.T @ (tw - eye)
    # colour: per-face albedo x Lambertian shading (normals face the camera, the light too)
    albedo = np.empty((len(Fs), 3))
    albedo[:n_obj] = _colour(name) * (1 + rng.uniform(-0.08, 0.08, size=(n_obj, 1)))
    albedo[n_obj : n_obj + 2] = (0.55, 0.45, 0.35)  # table
    albedo[n_obj + 2 :] = rng.uniform(0.2, 0.9, size=(len(Fs) - n_obj - 2, 3))
    light = np.array([rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8), -1.0])
    light /= np.linalg.norm(light)
    valid = r.face >= 0
    shade = np.clip(np.nan_to_num(r.normals) @ light, 0, None)
    rgb = np.where(valid[..., None], albedo[np.maximum(r.face, 0)] * (0.3 + 0.7 * shade[..., None]), 0.0)
    rgb = np.clip(rgb + rng.normal(0, 0.02, size=rgb.shape), 0, 1)
    depth = r.depth if sensor is None else _noise(sensor, r.depth, r.normals, K, rng)
    return {
        "rgb": rgb.transpose(2, 0, 1).astype(np.float32),
        "depth": depth.astype(np.float32),
        "mask": valid & (r.face < n_obj),
        "R": R.astype(np.float32),
        "t": t.astype(np.float32),
        "normals": r.normals.astype(np.float16),
    }


def object_views(
    n: int,
    *,
    seed: int,
    size: int = 64,
    objects: tuple[str, ...] = OBJECTS,
    cache_dir: Path | None = None,
    log: Any = None,
    noise: bool = True,
) -> dict[str, np.ndarray]:
    """``n`` views (object i mod len(objects), sensor i mod 3), cached in ``cache_dir``.

    ``noise=False``: the same views with the renderer's exact depth (no sensor model).

    Returns
    -------
    dict
        ``rgb`` (n, 3, S, S) float32 in [0, 1]; ``depth`` (n, S, S) float32 metres, 0 = none;
        ``mask`` (n, S, S) bool; ``obj`` (n,) int64 index into ``objects``; ``sensor`` (n,)
        int64 index into :data:`SENSORS`; ``R`` (n, 3, 3), ``t`` (n, 3) float32 object ->
        camera; ``normals`` (n, S, S, 3) float16 ground truth (NaN = none).
    """
    from depthnormals.io import atomic_write

    spec = {"v": VERSION, "n": n, "seed": seed, "size": size, "objects": list(objects)}
    key = json.dumps(spec if noise else {**spec, "noise": False})
    path = None
    if cache_dir is not None:
        cache_dir = Path(cache_dir)
        cache_dir.mkdir(parents=True, exist_ok=True)
        path = cache_dir / f"views-{hashlib.sha256(key.encode()).hexdigest()[:12]}.npz"
        if path.is_file():
            with np.load(path) as z:
                if log is not None:
                    log(f"views: {n} from the cache {path}")
                return {k: z[k] for k in z.files if k != "key"}
    t0 = time.perf_counter()
    out: dict[str, list] = {k: [] for k in ("rgb", "depth", "mask", "R", "t", "normals", "obj", "sensor")}
    for i in range(n):
        rng = np.random.default_rng([seed, i])
        o, s = i % len(objects), i % len(SENSORS)
        v = render_view(objects[o], rng, size=size, sensor=SENSORS[s] if noise else None)
        for k in ("rgb", "depth", "mask", "R", "t", "normals"):
            out[k].append(v[k])
        out["obj"].append(o)
        out["sensor"].append(s)
        if log is not None and (i + 1) % max(1, n // 4) == 0:
            log(f"views: {i + 1}/{n} rendered ({time.perf_counter() - t0:.0f} s)")
    views = {
        k: np.stack(v) if k not in ("obj", "sensor") else np.asarray(v, dtype=np.int64)
        for k, v in out.items()
    }
    if path is not None:
        with atomic_write(path) as fh:
            np.savez(fh, key=np.array(key), **views)
    return views


def masked_points(
    views: dict[str, np.ndarray], K: dn.Intrinsics, n_points: int, *, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points back-projected from the object mask's pixels with a depth.

    ``n_points`` pixels per view are drawn (with replacement when fewer) with ``seed``.

    Returns
    -------
    idx : ndarray (N, n_points) int64
        Flat pixel indices of the drawn points (for gathering per-pixel features).
    xyz : ndarray (N, 3, n_points) float64
        Camera-frame points, metres (zeros for a view with no such pixel).
    ok : ndarray (N,) bool
        Views with at least one such pixel.
    """
    n, s = views["depth"].shape[0], views["depth"].shape[-1]
    v, u = np.mgrid[0:s, 0:s]
    rng = np.random.default_rng(seed)
    idx = np.zeros((n, n_points), dtype=np.int64)
    ok = np.zeros(n, dtype=bool)
    for i in range(n):
        cand = np.flatnonzero(views["mask"][i].ravel() & (views["depth"][i].ravel() > 0))
        if cand.size:
            idx[i] = rng.choice(cand, n_points, replace=cand.size < n_points)
            ok[i] = True
    z = np.take_along_axis(views["depth"].reshape(n, -1).astype(np.float64), idx, 1) * ok[:, None]
    x = (u.ravel()[idx] - K.cx) / K.fx * z
    y = (v.ravel()[idx] - K.cy) / K.fy * z
    return idx, np.stack([x, y, z], 1), ok


def gather(img: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """(N, C, P) values of (N, C, H, W) images at the flat pixel indices ``idx`` (N, P)."""
    n, c = img.shape[:2]
    return np.take_along_axis(img.reshape(n, c, -1), idx[:, None].repeat(c, 1), 2)


def estimated_normals(depth: np.ndarray, K: dn.Intrinsics, method: str) -> np.ndarray:
    """(N, 3, H, W) float32 normals of noisy depth (N, H, W), 0 where none.

    ``"3f2n+"``: ``depthnormals.estimate_normals(depth, K, method="3f2n+")`` (the library's
    default); ``"fals"``: OpenCV's ``cv2.rgbd.RgbdNormals`` FALS (window 5) on ``depthTo3d``
    points, turned to face the camera.
    """
    if method == "3f2n+":
        n = dn.estimate_normals(depth, K, method="3f2n+")
    elif method == "fals":
        import cv2

        h, w = depth.shape[1:]
        Km = np.array([[K.fx, 0, K.cx], [0, K.fy, K.cy], [0, 0, 1]], dtype=np.float32)
        est = cv2.rgbd.RgbdNormals_create(
            h, w, cv2.CV_32F, Km, 5, cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_FALS
        )
        n = np.empty((*depth.shape, 3), dtype=np.float32)
        for i, d in enumerate(depth):
            p = cv2.rgbd.depthTo3d(np.ascontiguousarray(d, dtype=np.float32), Km)
            m = np.asarray(est.apply(p), dtype=np.float32)
            flip = np.sum(m * p, axis=-1) > 0  # face the camera: n . X < 0
            m[flip] *= -1
            m[~(d > 0)] = np.nan
            n[i] = m
    else:
        raise ValueError(f"unknown normal estimator {method!r}")
    n = np.where(np.isfinite(n).all(-1, keepdims=True), n, 0.0)
    return np.ascontiguousarray(n.transpose(0, 3, 1, 2), dtype=np.float32)


def normal_source(name: str) -> str | None:
    """The normal estimator an input uses (``"3f2n+"``, ``"fals"``), or None."""
    return next((m for m in ("3f2n+", "fals") if name.endswith(m)), None)


def views_and_normals(args: Any, inputs: Any, log) -> tuple:
    """The training and test views (``args.train`` / ``args.test`` at ``args.size``, cached
    in ``args.cache``, sensor noise unless ``args.clean``), the camera, and the normals of
    every estimator the ``inputs`` use on both, with their error on the test objects (logged):
    ``(train, test, K, normals_train, normals_test, errors)``."""
    tr = object_views(args.train, seed=0, size=args.size, cache_dir=args.cache, log=log, noise=not args.clean)
    te = object_views(args.test, seed=1, size=args.size, cache_dir=args.cache, log=log, noise=not args.clean)
    K = intrinsics(args.size)
    needed = sorted({normal_source(n) for n in inputs} - {None})
    n_tr = {m: estimated_normals(tr["depth"], K, m) for m in needed}
    n_te = {m: estimated_normals(te["depth"], K, m) for m in needed}
    errors = {m: normal_error(n_te[m], te) for m in n_te}
    log("normal error on the test objects (deg): " + ", ".join(f"{k} {v:.1f}" for k, v in errors.items()))
    return tr, te, K, n_tr, n_te, errors


def save_figure(fig: Any, path: Path) -> None:
    """Lay out ``fig``, write it to ``path`` as a PNG atomically, close it."""
    import matplotlib.pyplot as plt

    from depthnormals.io import atomic_write

    fig.tight_layout()
    with atomic_write(path) as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)


def normal_error(est: np.ndarray, views: dict[str, np.ndarray], *, on_object: bool = True) -> float:
    """Mean angular error (deg) of (N, 3, H, W) normals on the object pixels where both exist."""
    e = est.transpose(0, 2, 3, 1).astype(np.float64)
    g = views["normals"].astype(np.float64)
    ok = np.isfinite(g).all(-1) & (np.abs(e).sum(-1) > 0) & (views["depth"] > 0)
    if on_object:
        ok &= views["mask"]
    g = g[ok] / np.linalg.norm(g[ok], axis=-1, keepdims=True)
    return float(np.mean(dn.angular_error(e[ok][None], g[None])))


def _betainc(a: float, b: float, x: float) -> float:
    """Regularised incomplete beta I_x(a, b) (continued fraction, Numerical Recipes 6.4)."""
    import math

    if x <= 0:
        return 0.0
    if x >= 1:
        return 1.0
    if x > (a + 1) / (a + b + 2):
        return 1.0 - _betainc(b, a, 1.0 - x)
    lbeta = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log(1 - x)
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1)
    d = 1.0 / (d if abs(d) > 1e-300 else 1e-300)
    f = d
    for m in range(1, 300):
        for num in (
            m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
            -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1)),
        ):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > 1e-300 else 1e-300)
            c = 1.0 + num / c
            c = c if abs(c) > 1e-300 else 1e-300
            f *= c * d
        if abs(c * d - 1.0) < 1e-14:
            break
    return math.exp(lbeta) * f / a


def welch_p(a: Any, b: Any) -> float:
    """Two-sided p of Welch's t-test of samples ``a`` and ``b`` (nan when undefined)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.size < 2 or b.size < 2:
        return float("nan")
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    if va + vb == 0:
        return float("nan")
    t = (a.mean() - b.mean()) / np.sqrt(va + vb)
    df = (va + vb) ** 2 / (va**2 / (a.size - 1) + vb**2 / (b.size - 1))
    return float(_betainc(df / 2, 0.5, df / (df + t * t)))


def sd(a: Any) -> float:
    """Sample standard deviation (nan for one value)."""
    a = np.asarray(a, dtype=np.float64)
    return float(np.std(a, ddof=1)) if a.size > 1 else float("nan")


def write_report(out: Path, table: str, args: Any, K: dn.Intrinsics, *, wall: float,
                 errors: Any, **extra: Any) -> None:
    """The benchmark's table (markdown, ``out``) and its JSON sidecar (``out`` with
    ``.json``), both written atomically: the settings, the object set, the camera, the
    versions, the wall time, the normals' error on the objects, then ``extra`` (the
    benchmark's own sizes, p-values and per-seed results)."""
    import platform

    import torch

    from depthnormals.io import write_bytes_atomic

    out.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(out, (table + "\n").encode())
    meta = {
        "settings": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
        "objects": list(OBJECTS),
        "object_size_m": OBJECT_SIZE,
        "sensors": list(SENSORS),
        "K": [K.fx, K.fy, K.cx, K.cy],
        "depthnormals": dn.__version__,
        "torch": torch.__version__,
        "machine": platform.machine(),
        "wall_s": round(wall, 1),
        "normal_error_on_object_deg": errors,
        **extra,
    }
    write_bytes_atomic(out.with_suffix(".json"), (json.dumps(meta, indent=1) + "\n").encode())
