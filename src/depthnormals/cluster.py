"""Many frames on this machine's threads or on a Dask cluster: one way to map work to outputs.

The commands that work frame by frame (``estimate``, ``synth``; ``evaluate`` once its
per-frame unit is split out) describe each unit of work as a small picklable item whose
result is written to disk by the worker itself (atomically, see
:func:`depthnormals.io.atomic_write`), and hand the items to :func:`map_batches`:

- without a scheduler, items run on the library's threads (:func:`depthnormals.batch.map_threads`:
  one item per thread, each serial inside);
- with a Dask ``distributed.Client`` (:func:`connect`), items are grouped into tasks of
  ``batch_size`` items so that the scheduler's overhead (about a millisecond a task) stays
  small beside the work, at most a few tasks per worker are in flight (memory stays bounded
  whatever the number of frames), and results stream back in completion order. A task lost
  with its worker is re-run elsewhere by Dask; as outputs are written atomically and each
  item is deterministic, a re-run writes the same bytes.

Scheduler addresses (:func:`parse_scheduler`): ``local`` (a ``distributed.LocalCluster`` of
one single-threaded worker process per core), ``local:N`` (N worker processes) or
``tcp://host:port`` (an existing ``dask scheduler``). Dask is imported only here, and only
when a scheduler is asked for (``pip install 'depthnormals[dask]'``).

Every worker must run the same build of the library as the caller, or its outputs would
pass for this run's (``estimate`` and ``synth`` record the caller's code digest): before any
task, :func:`map_batches` asks every worker for the digest of its ``depthnormals`` modules
(:func:`depthnormals._fingerprint.code_fingerprint`), and each task checks it again on its
worker before it starts (a worker that joined later); another build stops the run with
:class:`WorkerCodeMismatch` before that worker computes or writes anything.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from itertools import islice
from typing import Any, TypeVar

__all__ = ["SchedulerSpec", "WorkerCodeMismatch", "check_batch_size", "connect", "local_cluster",
           "map_batches", "parse_scheduler"]

T = TypeVar("T")
R = TypeVar("R")

#: Frames per Dask task unless told otherwise (see benchmarks/dask_scaling.py).
DEFAULT_BATCH = 16
#: Tasks kept in flight per worker thread: enough to hide the round trip, few enough to bound memory.
_INFLIGHT_PER_THREAD = 2
#: glibc malloc settings of the worker processes we start. Dask's default
#: (``MALLOC_TRIM_THRESHOLD_=65536``) fixes the mmap threshold at 128 KiB, so every frame-sized
#: temporary is a fresh mmap, page-faulted in again: 42,700 minor faults and about +30 % CPU
#: per 16 frames of 640x480 3f2n+ measured in a worker, against 5 faults in a plain process.
#: With these (the values glibc's own heuristic reaches in a plain process) the worker's
#: compute thread costs what the serial run costs (benchmarks/dask_scaling.py).
WORKER_MALLOC_ENV = {"MALLOC_MMAP_THRESHOLD_": "33554432", "MALLOC_TRIM_THRESHOLD_": "268435456"}


class WorkerCodeMismatch(ValueError):
    """A Dask worker runs another build of depthnormals than the caller (module docstring)."""


@dataclass(frozen=True)
class SchedulerSpec:
    """A parsed ``--scheduler`` value.

    Attributes
    ----------
    address : str or None
        ``tcp://host:port`` (or any address ``distributed.Client`` accepts) of a running
        scheduler; None for a local cluster.
    workers : int or None
        Worker processes of a local cluster (None: one per core).
    """

    address: str | None = None
    workers: int | None = None

    @property
    def local(self) -> bool:
        """True when a LocalCluster is started for the run."""
        return self.address is None


def parse_scheduler(text: str) -> SchedulerSpec:
    """Parse ``local``, ``local:N`` or a scheduler address such as ``tcp://10.0.0.5:8786``.

    Raises
    ------
    ValueError
        Anything else, with the accepted forms.
    """
    if not isinstance(text, str):
        raise TypeError(f"scheduler must be a string; got {type(text).__name__}")
    s = text.strip()
    m = re.fullmatch(r"local(?::(\d+))?", s)
    if m:
        n = None if m.group(1) is None else int(m.group(1))
        if n is not None and n < 1:
            raise ValueError(f"scheduler {text!r}: local:N needs N >= 1 worker processes")
        return SchedulerSpec(workers=n)
    if re.fullmatch(r"(tcp|tls|inproc|ucx|ws|wss)://\S+", s):
        return SchedulerSpec(address=s)
    raise ValueError(f"scheduler {text!r} not understood; use 'local', 'local:N' (N worker processes) "
                     "or the address of a running `dask scheduler`, e.g. tcp://10.0.0.5:8786")


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


@contextlib.contextmanager
def connect(scheduler: str | SchedulerSpec) -> Iterator[Any]:
    """A ``distributed.Client`` for ``scheduler``, closed (with its local cluster) on exit.

    A local cluster (:func:`local_cluster`) has ``N`` worker processes (default: one per
    core) with one thread each. Workers of a remote scheduler
    keep their own settings (set ``DEPTHNORMALS_NUM_THREADS`` where they are started).
    """
    spec = parse_scheduler(scheduler) if isinstance(scheduler, str) else scheduler
    try:
        from distributed import Client
    except ImportError as exc:
        raise ImportError("--scheduler needs Dask: pip install 'depthnormals[dask]'") from exc
    if spec.local:
        cluster = local_cluster(spec.workers or _cores())
        try:
            with Client(cluster) as client:
                yield client
        finally:
            cluster.close()
    else:
        with Client(spec.address, timeout="30s") as client:
            yield client


def local_cluster(n_workers: int, *, threads: int | None = None) -> Any:
    """A ``distributed.LocalCluster`` of ``n_workers`` single-threaded worker processes.

    Each worker runs the estimators with ``threads`` row-band threads (default
    ``max(1, cores // n_workers)``: together they use the cores once) and the malloc settings
    of :data:`WORKER_MALLOC_ENV`; the scheduler's HTTP server listens on a free port (with
    ``dashboard_address=None`` it would still try 8787, and warn when another cluster has it).
    The caller closes it.
    """
    import dask
    from distributed import LocalCluster

    env = {"DEPTHNORMALS_NUM_THREADS": str(threads or max(1, _cores() // n_workers))}
    # set before the worker processes start (distributed's "pre-spawn-environ"); an explicit
    # value in os.environ still wins there, as distributed documents
    spawn = {f"distributed.nanny.pre-spawn-environ.{k}": v for k, v in WORKER_MALLOC_ENV.items()}
    with dask.config.set(spawn):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                            dashboard_address=":0", env=env)


def _worker_code() -> str:
    """The digest of this process's ``depthnormals`` modules (run on each worker)."""
    from ._fingerprint import code_fingerprint

    return code_fingerprint()


def _mismatch(worker: str, code: str, here: str) -> WorkerCodeMismatch:
    return WorkerCodeMismatch(
        f"Dask worker {worker} runs another build of depthnormals than this process (code {code}, "
        f"here {here}): install the same version on every worker, or restart the workers started "
        "before an upgrade; nothing was computed there")


def _check_workers(client: Any, here: str) -> None:
    """Refuse a cluster whose connected workers run another build (module docstring)."""
    try:
        found = client.run(_worker_code)
    except Exception as exc:  # a worker without this check: an older build, or none at all
        raise WorkerCodeMismatch(f"a Dask worker cannot run depthnormals' build check ({exc!r}): it "
                                 "runs another build of depthnormals, or none; install the same "
                                 "version on every worker") from exc
    for worker, code in sorted(found.items()):
        if code != here:
            raise _mismatch(worker, code, here)


def _run_batch(func: Callable[[T], R], items: Sequence[T], code: str) -> list[R]:
    """One Dask task: ``func`` on each item, on the worker, once its library code is checked
    to be ``code``'s. A worker running several tasks at once (threads > 1) runs each serially
    inside, as the threads of :func:`map_threads` do."""
    from ._parallel import thread_limit

    try:
        from distributed import get_worker

        worker = get_worker()
        threads, address = worker.state.nthreads, str(worker.address)
    except (ImportError, ValueError, AttributeError):
        threads, address = 1, "?"
    if _worker_code() != code:
        raise _mismatch(address, _worker_code(), code)
    with thread_limit(1) if threads > 1 else contextlib.nullcontext():
        return [func(item) for item in items]


def _chunks(items: Iterable[T], size: int) -> Iterator[list[T]]:
    it = iter(items)
    while chunk := list(islice(it, size)):
        yield chunk


def check_batch_size(batch_size: Any) -> int:
    """``batch_size`` (items per Dask task) if it is an integer >= 1, else ValueError: the one
    check of :func:`map_batches` and of the entry points that take one, which refuse it with
    or without a scheduler (unused without one, it was read as if unset)."""
    if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
        raise ValueError(f"batch_size must be an integer >= 1; got {batch_size!r}")
    return batch_size


def map_batches(func: Callable[[T], R], items: Iterable[T], *, client: Any = None,
                batch_size: int = DEFAULT_BATCH, on_done: Callable[[T, R], None] | None = None,
                threads: int | None = None) -> list[R]:
    """Run ``func`` on every item, on this machine's threads or on a Dask cluster.

    Parameters
    ----------
    func : callable
        ``func(item) -> result``, importable at module level (Dask pickles it); it should
        write its own output atomically and return something small.
    items : iterable
        The units of work; consumed lazily (an iterator of frames read from disk is fine).
    client : distributed.Client, optional
        Run on this cluster (see :func:`connect`); default: locally on threads.
    batch_size : int, default 16
        Items per Dask task.
    on_done : callable, optional
        ``on_done(item, result)`` on the calling thread as each item finishes (any order).
    threads : int, optional
        Local threads (default :func:`depthnormals.get_num_threads`).

    Returns
    -------
    list
        The results in completion order.
    """
    check_batch_size(batch_size)
    results: list[R] = []

    def done(item: T, result: R) -> None:
        results.append(result)
        if on_done is not None:
            on_done(item, result)

    if client is None:
        from ._parallel import threads_here
        from .batch import map_threads

        n = threads_here() if threads is None else threads
        # bounded chunks so that an iterator of frames is never read whole into memory
        for chunk in _chunks(items, max(1, n) * 32):
            map_threads(func, chunk, threads=n, on_done=lambda i, r, c=chunk: done(c[i], r))
        return results

    from distributed import as_completed

    here = _worker_code()
    _check_workers(client, here)
    slots = max(1, sum(client.nthreads().values())) * _INFLIGHT_PER_THREAD
    batches = _chunks(items, batch_size)
    pending = as_completed()
    owner: dict[str, list[T]] = {}

    def submit(n: int) -> None:
        for batch in islice(batches, n):
            fut = client.submit(_run_batch, func, batch, here, pure=False)
            owner[fut.key] = batch
            pending.add(fut)

    submit(slots)
    try:
        for fut in pending:
            batch = owner.pop(fut.key)
            for item, result in zip(batch, fut.result(), strict=True):
                done(item, result)
            fut.release()
            submit(1)
    except BaseException:
        for fut in list(pending.futures):
            fut.cancel()
        raise
    return results
