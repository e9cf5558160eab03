"""Normals of many depth frames into a folder: plan (input, output) pairs, skip done, run.

What ``depthnormals estimate IN... -o DIR`` runs. :func:`plan_estimate` expands the inputs
(depth files, glob patterns, folders of depth files, dataset folders that
:func:`depthnormals.datasets.open` reads) into :class:`EstimateJob` s, one per frame, each
with its output path; :func:`run_estimate` drops the jobs whose output already exists
(outputs are written atomically, so a file that exists is complete and a killed run resumes
where it stopped), and runs the rest with :func:`depthnormals.cluster.map_batches`: on the
library's threads, one frame per thread, or on a Dask cluster.

Output names: a depth file keeps its path relative to the folder it was found in (the
folder given, the fixed part of a glob pattern, or its own folder), with the suffix of the
output format; a dataset frame is written as ``<group>/<name>``. Two inputs mapping to the
same output are refused.
"""

from __future__ import annotations

import glob
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from .camera import Intrinsics, as_intrinsics
from .io import DEPTH_SUFFIXES

__all__ = ["FORMATS", "EstimateJob", "EstimateSettings", "RunSummary", "estimate_job", "plan_estimate",
           "run_estimate"]

#: Output formats of the many-frames form (the suffix of each output file).
FORMATS = ("npy", "png", "vis.png", "ply")
_MAGIC = set("*?[")


@dataclass(frozen=True)
class EstimateSettings:
    """What every frame of a run shares: the method, its options, and the input scale."""

    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    depth_scale: float | None = None


@dataclass(frozen=True)
class EstimateJob:
    """One frame to do.

    Attributes
    ----------
    output : Path
        Where its normals go (suffix = format).
    K : Intrinsics
        Its camera.
    source : Path or None
        A depth file read by the worker (``depthnormals.io.read_depth``), or None when the
        depth is carried in ``depth`` (a frame of a dataset reader).
    depth : ndarray (H, W) or None
        The depth of a dataset frame, metres.
    label : str
        Name shown by the progress bar.
    """

    output: Path
    K: Intrinsics
    source: Path | None = None
    depth: np.ndarray | None = field(default=None, repr=False, compare=False)
    label: str = ""


@dataclass(frozen=True)
class RunSummary:
    """What :func:`run_estimate` did: frames planned, computed now, found done, seconds."""

    planned: int
    written: int
    skipped: int
    seconds: float


def _is_glob(text: str) -> bool:
    return any(c in _MAGIC for c in text)


def _glob_root(pattern: str) -> Path:
    parts = Path(pattern).parts
    fixed = []
    for part in parts[:-1]:
        if _is_glob(part):
            break
        fixed.append(part)
    return Path(*fixed) if fixed else Path(".")


def _depth_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in DEPTH_SUFFIXES)


def _dataset_frames(folder: Path) -> Iterator[Any] | None:
    """The frames of a dataset folder, or None when it holds no known dataset layout."""
    from . import datasets

    frames = iter(datasets.open(folder))
    try:
        first = next(frames)
    except StopIteration:
        return iter(())
    except ValueError as exc:
        if "no known dataset layout" in str(exc):
            return None
        raise

    def chain() -> Iterator[Any]:
        yield first
        yield from frames

    return chain()


def _stem(rel: Path) -> str:
    return rel.with_suffix("").as_posix()


def plan_estimate(inputs: Sequence[str | Path], out_dir: str | Path, *, K: Any = None,
                  fmt: str = "npy") -> Iterator[EstimateJob]:
    """The frames of ``inputs`` with their output paths under ``out_dir`` (lazily).

    Parameters
    ----------
    inputs : sequence of str or Path
        Depth files (``.npy``, ``.png``, ``.tif``, ``.bin``), glob patterns (``"seq/*.png"``,
        ``"**"`` recursive), folders of depth files (searched recursively), or dataset
        folders (:func:`depthnormals.datasets.open`; they bring their own intrinsics).
    out_dir : str or Path
        Output folder.
    K : intrinsics, optional
        Camera of the depth files (required when there are any).
    fmt : {"npy", "png", "vis.png", "ply"}
        Output format.

    Yields
    ------
    EstimateJob

    Raises
    ------
    FileNotFoundError
        An input that does not exist, or a glob that matches no depth file.
    ValueError
        A bad format, a depth file without ``K``, an empty folder, or two inputs with the same
        output path.
    """
    if fmt not in FORMATS:
        raise ValueError(f"output format {fmt!r} not known; use one of {', '.join(FORMATS)}")
    if isinstance(inputs, (str, Path)):
        inputs = [inputs]
    if not inputs:
        raise ValueError("no inputs given")
    out = Path(out_dir).absolute()  # workers of a cluster may run elsewhere
    cam = None if K is None else as_intrinsics(K)
    seen: dict[Path, str] = {}

    def job(output: Path, origin: str, **kw: Any) -> EstimateJob:
        if output in seen:
            raise ValueError(f"{origin} and {seen[output]} would both be written to {output}; "
                             "give them separate runs or output folders")
        seen[output] = origin
        return EstimateJob(output=output, **kw)

    def files(paths: Iterable[Path], root: Path) -> Iterator[EstimateJob]:
        if cam is None:
            raise ValueError("depth files need the camera: pass --intrinsics/-K (K=...)")
        for p in paths:
            rel = p.relative_to(root) if p.is_relative_to(root) else Path(p.name)
            yield job(out / f"{_stem(rel)}.{fmt}", str(p), K=cam, source=p.absolute(), label=str(rel))

    for item in inputs:
        text = str(item)
        path = Path(text)
        if _is_glob(text) and not path.exists():
            found = sorted(Path(p) for p in glob.glob(text, recursive=True)
                           if Path(p).is_file() and Path(p).suffix.lower() in DEPTH_SUFFIXES)
            if not found:
                raise FileNotFoundError(f"{text} matches no depth file ({', '.join(DEPTH_SUFFIXES)})")
            yield from files(found, _glob_root(text))
        elif path.is_file():
            yield from files([path], path.parent)
        elif path.is_dir():
            frames = _dataset_frames(path)
            if frames is None:
                found = _depth_files(path)
                if not found:
                    raise ValueError(f"{path} holds no dataset this library reads and no depth file "
                                     f"({', '.join(DEPTH_SUFFIXES)})")
                yield from files(found, path)
                continue
            for f in frames:
                rel = f"{f.group}/{f.name}" if f.group else f.name
                yield job(out / f"{rel}.{fmt}", f"{path}:{rel}", K=as_intrinsics(f.K), depth=f.depth,
                          label=rel)
        else:
            raise FileNotFoundError(f"input {text} does not exist")


def _write(path: Path, normals: np.ndarray, depth: np.ndarray, K: Intrinsics) -> None:
    from . import io

    if path.name.lower().endswith(".ply"):
        write_ply = getattr(io, "write_ply", None)
        if write_ply is None:
            raise ValueError("PLY output needs depthnormals.io.write_ply, which this version lacks")
        write_ply(path, depth, K, normals)
    else:
        io.write_normals(path, normals)


def estimate_job(job: EstimateJob, settings: EstimateSettings) -> str:
    """Read, estimate and write one frame (atomically); returns the output path.

    The unit of work of :func:`run_estimate`, run on a worker thread or a Dask worker.
    """
    from .io import read_depth
    from .registry import estimate_normals

    if job.source is not None:
        depth = read_depth(job.source, depth_scale=settings.depth_scale)
    else:
        depth = job.depth
    normals = estimate_normals(depth, job.K, method=settings.method, **dict(settings.options))
    job.output.parent.mkdir(parents=True, exist_ok=True)
    _write(job.output, normals, depth, job.K)
    return str(job.output)


def run_estimate(inputs: Sequence[str | Path], out_dir: str | Path, *, method: str, K: Any = None,
                 options: Mapping[str, Any] | None = None, depth_scale: float | None = None,
                 fmt: str = "npy", resume: bool = True, progress: bool = False,
                 scheduler: str | None = None, batch_size: int = 16, client: Any = None) -> RunSummary:
    """Estimate the normals of every frame of ``inputs`` into ``out_dir``.

    Parameters
    ----------
    inputs, out_dir, K, fmt
        See :func:`plan_estimate`.
    method : str
        A name from :func:`depthnormals.methods`.
    options : mapping, optional
        Options of the method.
    depth_scale : float, optional
        Metres per unit of integer depth files (e.g. 0.001 for millimetre PNGs).
    resume : bool, default True
        Skip frames whose output exists (complete: every output is written atomically);
        False recomputes and replaces them.
    progress : bool, default False
        Progress on stderr (:class:`depthnormals.cluster.Progress`).
    scheduler : str, optional
        ``"local"``, ``"local:N"`` or ``"tcp://host:port"``: run on Dask
        (:func:`depthnormals.cluster.connect`); default on this machine's threads. Workers
        must see the input and output paths (a shared file system on several machines).
    batch_size : int, default 16
        Frames per Dask task.
    client : distributed.Client, optional
        An open client to use instead of ``scheduler``.

    Returns
    -------
    RunSummary
    """
    from ._progress import Progress
    from .cluster import connect, map_batches
    from .registry import get_estimator

    get_estimator(method[:-1] if method.endswith("+") else method)  # a bad name fails before any work
    settings = EstimateSettings(method, dict(options or {}), depth_scale)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    counts = {"planned": 0, "skipped": 0}

    def todo() -> Iterator[EstimateJob]:
        for job in plan_estimate(inputs, out, K=K, fmt=fmt):
            counts["planned"] += 1
            if resume and job.output.is_file():
                counts["skipped"] += 1
                bar.update(f"{job.label} (done before)")
                continue
            yield job

    func = partial(estimate_job, settings=settings)
    with Progress("estimate", unit="frame", enabled=progress) as bar:
        def on_done(job: EstimateJob, _: str) -> None:
            bar.update(job.label)

        if client is not None:
            results = map_batches(func, todo(), client=client, batch_size=batch_size, on_done=on_done)
        elif scheduler is not None:
            with connect(scheduler) as cl:
                results = map_batches(func, todo(), client=cl, batch_size=batch_size, on_done=on_done)
        else:
            results = map_batches(func, todo(), on_done=on_done)
    if counts["planned"] == 0:
        raise ValueError(f"the inputs {', '.join(map(str, inputs))} hold no frame")
    return RunSummary(counts["planned"], len(results), counts["skipped"], time.perf_counter() - t0)
