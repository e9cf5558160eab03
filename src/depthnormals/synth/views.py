"""One view of a synthetic scene: the unit of work of :func:`depthnormals.synth.generate`.

Serial or on a Dask worker (:mod:`depthnormals.synth._cluster`), every view is rendered from the
same seeds by :func:`_write_view` and written atomically, so both give the same bytes.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..io import atomic_write, write_bytes_atomic
from ..render import render_mesh, render_subsamples
from . import noise as _noise
from ._kernels import discontinuity_mask
from .poses import sample_poses
from .scenes import Scene

#: Scene kinds in the seed sequence (seed, kind, scene, stream, view).
_KIND_ID = {"indoor": 0, "outdoor": 1, "mesh": 2}


def _rng(seed: int, *keys: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), *map(int, keys)]))


def _save_npy(path: Path, arr: np.ndarray) -> None:
    with atomic_write(path) as fh:
        np.save(fh, arr, allow_pickle=False)


def _write_json(path: Path, data: dict) -> None:
    write_bytes_atomic(path, (json.dumps(data, indent=1, sort_keys=True) + "\n").encode())


def _write_view(sdir: Path, scene: Scene, pose: np.ndarray, view: int, models: dict, seed: int, kid: int,
                i: int, cam, size: tuple[int, int], near: float, storage: str = "npy") -> float | None:
    """Render view ``view`` of a scene and write its files (atomically); None if all exist.

    Returns the seconds of the clean render. The unit of work of :func:`generate`, serial
    or on a Dask worker (``depthnormals.synth._cluster``): the same bytes either way.
    ``storage`` is ``"npy"`` (format version 1, one float32 ``.npy`` per array) or
    ``"compact"`` (version 2, one ``views/0000.npz`` per view, :mod:`depthnormals._compact`).
    """
    done = _view_files(sdir, view, models, storage)
    if all(p.is_file() for p in done):
        return None
    h, w = size
    t0 = time.perf_counter()
    r = render_mesh(scene.vertices, scene.faces, cam, pose=pose, width=w, height=h, near=near)
    seconds = time.perf_counter() - t0
    if not np.any(r.face >= 0):
        raise ValueError(f"{sdir.parent.name}/{sdir.name} view {view}: the camera sees nothing")
    noisy = {}
    subs: dict[int, np.ndarray | None] = {}  # sub-pixel renders, shared by the models of a view
    for name, st in models.items():
        rng = _rng(seed, kid, i, 2 + _noise.MODELS.index(name), view)
        noisy[name] = _apply_model(name, st, r, scene, pose, cam, size, near, rng, subs)
    if storage == "compact":
        _write_compact(done[0], r, noisy, models)
        return seconds
    _save_npy(done[0], r.normals.astype(np.float32))
    _save_npy(done[1], r.face >= 0)
    _save_npy(done[2], r.depth.astype(np.float32))
    for k, name in enumerate(models):
        _save_npy(done[3 + k], noisy[name].astype(np.float32))
    return seconds


#: Storage layouts: name -> on-disk format version (docs/synthetic.md).
STORAGES = {"npy": 1, "compact": 2}


def _write_compact(path: Path, r, noisy: dict, models: dict) -> None:
    """One view as ``views/0000.npz``; depth of a model with a ``rounding`` step stored as integers."""
    from .._compact import write_view

    steps = {name: st.get("rounding") for name, st in models.items()}
    write_view(path, r.normals, r.face >= 0, {"clean": r.depth, **noisy}, steps=steps)


def _view_files(sdir: Path, view: int, models: dict, storage: str = "npy") -> list[Path]:
    if storage == "compact":
        return [sdir / "views" / f"{view:04d}.npz"]
    name = f"{view:04d}.npy"
    return [sdir / "normals" / name, sdir / "valid" / name, sdir / "clean" / name,
            *[sdir / m / name for m in models]]


def _prepare_scene_dir(sdir: Path, models: dict, storage: str = "npy") -> None:
    """Create the scene's view folders; remove temporary files a killed run left behind.

    Atomic writes go through hidden ``.<name>.*.tmp`` files beside the target; a process
    killed mid-write (SIGKILL, power loss) leaves one, never a partial file under the final
    name. Two runs into the same folder at once are not supported.
    """
    subs = ("views",) if storage == "compact" else ("normals", "valid", "clean", *models)
    for sub in subs:
        (sdir / sub).mkdir(parents=True, exist_ok=True)
        for tmp in (sdir / sub).glob(".*.tmp"):
            tmp.unlink(missing_ok=True)


def _scene_poses(sdir: Path, scene: Scene, kind: str, scene_seed: int | None, seed: int, kid: int,
                 i: int, views: int, cam, size, near, constraints) -> np.ndarray:
    info = sdir / "scene.json"
    if info.is_file():
        data = json.loads(info.read_text())
        poses = np.asarray(data["poses"], dtype=np.float64)
        if poses.shape == (views, 4, 4):
            return poses
        raise ValueError(f"{info} holds {poses.shape[0]} poses; expected {views}")
    poses = sample_poses(scene, views, rng=_rng(seed, kid, i, 1), K=cam, size=size,
                         constraints=constraints)
    sdir.mkdir(parents=True, exist_ok=True)
    data = {"name": sdir.name, "kind": kind, **scene.meta, "scene_seed": scene_seed,
            "n_faces": int(scene.faces.shape[0]), "n_vertices": int(scene.vertices.shape[0]),
            "K": {"fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy}, "size": list(size),
            "near": near, "pose_convention": "camera-to-world, OpenCV camera axes, world z up, metres",
            "poses": poses.tolist()}
    _write_json(info, data)
    return poses


def _apply_model(name: str, st: dict, r, scene: Scene, pose, cam, size, near, rng,
                 subs: dict | None = None) -> np.ndarray:
    """Noisy depth of model ``name`` (settings ``st``) for the render ``r``; ``subs`` caches
    the sub-pixel renders by factor across the models of one view (they depend only on the
    view and the factor: kinect_v2 and tof share theirs)."""
    subs = {} if subs is None else subs
    if name == "gaussian":
        return _noise.gaussian_noise(r.depth, cam, rng=rng, sigma=st["sigma"], sigma_px=st["sigma_px"])
    if name == "kinect_v1":
        return _noise.kinect_v1_noise(r.depth, r.normals, cam, rng=rng, **st)
    if name == "realsense_d4xx":
        return _noise.realsense_d4xx_noise(r.depth, r.normals, cam, rng=rng, **st)
    sub = _subsamples(st["supersample"], r, scene, pose, cam, size, near, subs)
    if name == "tof":
        return _noise.tof_noise(r.depth, r.normals, cam, rng=rng, subsamples=sub,
                                **{k: v for k, v in st.items() if k != "supersample"})
    return _noise.kinect_v2_noise(r.depth, r.normals, cam, rng=rng, subsamples=sub,
                                  min_range=st["min_range"], max_range=st["max_range"],
                                  dropout_deg=st["dropout_deg"],
                                  dropout_width_deg=st["dropout_width_deg"], rounding=st["rounding"])


def _subsamples(factor: int, r, scene: Scene, pose, cam, size, near, subs: dict) -> np.ndarray | None:
    """Sub-pixel depth near discontinuities (flying pixels), None for ``factor`` 1; rendered
    once per factor and view (``subs``)."""
    if factor <= 1:
        return None
    if factor not in subs:
        h, w = size
        subs[factor] = render_subsamples(scene.vertices, scene.faces, cam, pose=pose, width=w,
                                         height=h, factor=factor, mask=discontinuity_mask(r.depth),
                                         near=near)
    return subs[factor]
