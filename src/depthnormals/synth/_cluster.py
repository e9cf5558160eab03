"""``generate(..., scheduler=...)``: the synthetic benchmark rendered on a Dask cluster.

Two rounds of :func:`depthnormals.cluster.map_batches`: the camera poses of each scene whose
``scene.json`` is missing (one scene a task: pose sampling renders many candidates), then
every view whose files are not all there, in tasks of ``batch_size`` views of the same
scene. Each view is written by the same function as in the serial run
(:func:`depthnormals.synth.views._write_view`) from the same seeds, so the files are
byte-identical whatever the worker, and a re-run (after a lost worker, or a killed run)
writes the same bytes again.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Intrinsics
from .catalog import make_scene, recipe_of_folder
from .poses import PoseConstraints
from .scenes import Scene, load_mesh_scene

__all__ = ["generate_on_cluster"]


@dataclass(frozen=True)
class _SceneTask:
    root: str
    kind: str
    index: int
    folder: str
    mesh: str | None
    seed: int
    views: int
    models: dict
    cam: Intrinsics
    size: tuple[int, int]
    near: float
    constraints: PoseConstraints
    storage: str = "npy"

    @property
    def sdir(self) -> Path:
        return Path(self.root) / self.kind / self.folder


@dataclass(frozen=True)
class _ViewTask:
    scene: _SceneTask
    view: int


def _scene_seed(t: _SceneTask) -> int | None:
    from .views import _KIND_ID

    if t.kind == "mesh":
        return None
    return int(np.random.SeedSequence([t.seed, _KIND_ID[t.kind], t.index, 0]).generate_state(1)[0])


@functools.lru_cache(maxsize=4)
def _scene(kind: str, folder: str, seed: int | None, mesh: str | None) -> Scene:
    """The scene (cached per worker process: consecutive views share it)."""
    if kind == "mesh":
        return load_mesh_scene(mesh)
    return make_scene(recipe_of_folder(folder), seed=seed)


def _poses_task(t: _SceneTask) -> str:
    from .views import _KIND_ID, _scene_poses

    seed = _scene_seed(t)
    scene = _scene(t.kind, t.folder, seed, t.mesh)
    _scene_poses(t.sdir, scene, t.kind, seed, t.seed, _KIND_ID[t.kind], t.index, t.views, t.cam, t.size,
                 t.near, t.constraints)
    return t.folder


def _view_task(v: _ViewTask) -> float | None:
    from .views import _KIND_ID, _write_view

    t = v.scene
    seed = _scene_seed(t)
    scene = _scene(t.kind, t.folder, seed, t.mesh)
    poses = np.asarray(json.loads((t.sdir / "scene.json").read_text())["poses"], dtype=np.float64)
    return _write_view(t.sdir, scene, poses[v.view], v.view, t.models, t.seed, _KIND_ID[t.kind], t.index,
                       t.cam, t.size, t.near, t.storage)


def generate_on_cluster(scheduler: str, root: Path, plan: list[tuple[str, int, str]], meshes: list[str],
                        views: int, seed: int, models: dict, cam: Intrinsics, size: tuple[int, int],
                        near: float, constraints: PoseConstraints, *, progress: bool,
                        batch_size: int, storage: str = "npy") -> tuple[int, int, float]:
    """Render ``plan`` into ``root`` on ``scheduler``; returns (written, skipped, render seconds)."""
    from .._progress import Progress
    from ..cluster import connect, map_batches
    from .views import _prepare_scene_dir, _view_files

    root = Path(root).absolute()
    tasks = [_SceneTask(str(root), kind, i, folder, meshes[i] if kind == "mesh" else None, seed, views,
                        models, cam, tuple(size), float(near), constraints, storage)
             for kind, i, folder in plan]
    for t in tasks:
        _prepare_scene_dir(t.sdir, models, storage)
    todo = [_ViewTask(t, v) for t in tasks for v in range(views)
            if not all(p.is_file() for p in _view_files(t.sdir, v, models, storage))]
    skipped = len(tasks) * views - len(todo)
    seconds: list[float] = []
    bar = Progress("synth", total=len(todo), unit="view", enabled=progress)
    with connect(scheduler) as client, bar:
        need_poses = [t for t in tasks if not (t.sdir / "scene.json").is_file()]
        map_batches(_poses_task, need_poses, client=client, batch_size=1)

        def done(v: _ViewTask, s: Any) -> None:
            if s is not None:
                seconds.append(s)
            bar.update(f"{v.scene.kind}/{v.scene.folder} {v.view}")

        map_batches(_view_task, todo, client=client, batch_size=batch_size, on_done=done)
    return len(seconds), skipped + len(todo) - len(seconds), float(sum(seconds))
