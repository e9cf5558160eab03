"""``depthnormals evaluate --scheduler``: the (frame, method) parts computed on Dask.

:func:`run_evaluation` stores one part per finished (frame, method) and reuses every part it
finds (that is how it resumes). :func:`compute_parts` computes the missing parts on a Dask
cluster, frames ``batch_size`` to a task, each part written atomically by its worker under
the key the serial run uses; the command then runs :func:`run_evaluation`, which finds every
part done and writes ``results.csv``, the summaries and the figures as a serial run does
(``ms`` measured on the workers).

:func:`_frame_parts` is the part-computing half of ``_run._evaluate_frame`` (no tally, no
figures), built from the same pieces: ``_part_keys``, ``_estimate``, ``_near_mask``, ``_row``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import partial
from itertools import islice
from pathlib import Path
from typing import Any

from ..datasets import Frame
from ._methods import MethodSpec, resolve_methods
from ._protocol import Protocol, score_frame
from ._run import _estimate, _near_mask, _part_keys, _row
from ._store import PartStore

__all__ = ["compute_parts"]

_warmed: set[str] = set()  # per worker process: methods already compiled and run once


def _frame_parts(frame: Frame, *, specs: Sequence[MethodSpec], protocol: Protocol, dataset_id: str,
                 parts: str, resume: bool) -> int:
    """Compute and store the missing parts of one frame (on a worker); returns how many."""
    store = PartStore(Path(parts))
    near = None
    done = 0
    for spec, key in zip(specs, _part_keys(store, dataset_id, frame, specs, protocol), strict=True):
        if resume and store.load(key) is not None:
            continue
        est, ms = _estimate(spec, frame, _warmed)
        if near is None:
            near = _near_mask(frame, protocol)
        score = score_frame(est, frame.normals, mask=frame.mask, near=near, protocol=protocol)
        store.save(key, _row(frame, spec.label, score, ms), score.hist)
        done += 1
    return done


def compute_parts(dataset: str | Path, methods: str | Sequence[str], out_dir: str | Path, *,
                  scheduler: str, protocol: Protocol,
                  method_options: Mapping[str, Mapping[str, Any]] | None = None,
                  frames: int | None = None, resume: bool = True, batch_size: int = 8,
                  progress: bool = False) -> int:
    """Compute the (frame, method) parts of an evaluation on Dask; returns how many.

    Parameters
    ----------
    dataset : str or Path
        A dataset folder (:func:`depthnormals.datasets.open`).
    methods, method_options, frames
        As for :func:`depthnormals.evaluate.run_evaluation`.
    out_dir : str or Path
        The evaluation's output folder (parts go to ``out_dir/parts``).
    scheduler : str
        ``"local"``, ``"local:N"`` or ``"tcp://host:port"`` (:func:`depthnormals.cluster.connect`).
    protocol : Protocol
        The scoring protocol (part keys include it).
    resume : bool, default True
        Skip parts that exist; False recomputes them.
    batch_size : int, default 8
        Frames per Dask task.
    progress : bool, default False
        Progress on stderr.
    """
    from .. import datasets
    from .._progress import Progress
    from ..cluster import connect, map_batches

    specs = resolve_methods(methods, method_options)
    path = Path(dataset)
    if not path.exists():
        raise FileNotFoundError(f"dataset path {path} does not exist")
    dataset_id = str(path.resolve())
    parts = Path(out_dir).absolute() / "parts"
    store = PartStore(parts)

    def todo():
        for frame in islice(datasets.open(path), frames):
            if resume and all(store.load(k) is not None
                              for k in _part_keys(store, dataset_id, frame, specs, protocol)):
                continue
            yield frame

    func = partial(_frame_parts, specs=specs, protocol=protocol, dataset_id=dataset_id, parts=str(parts),
                   resume=resume)
    with connect(scheduler) as client, Progress("evaluate", unit="part", enabled=progress) as bar:
        done = map_batches(func, todo(), client=client, batch_size=batch_size,
                           on_done=lambda f, _: bar.update(f"{f.group}/{f.name}"))
    return int(sum(done))
