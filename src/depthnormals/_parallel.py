"""Row-band threading for the compiled kernels.

Kernels are serial numba functions compiled with ``nogil=True`` that process the rows
``[v0, v1)``; :func:`run_rows` splits an image into bands and runs them on a thread pool.
This keeps compile times low (numba's ``parallel=True`` re-optimises every callee inside the
gufunc: several seconds per kernel on a fresh install) while using every core.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

__all__ = ["get_num_threads", "run_rows", "set_num_threads", "thread_limit", "threads_here"]

_lock = threading.Lock()
_state: dict[str, Any] = {"threads": None, "pool": None, "pool_size": 0}
#: Per-thread cap on the row bands of :func:`run_rows` (see :func:`thread_limit`).
_local = threading.local()


def _default_threads() -> int:
    env = os.environ.get("DEPTHNORMALS_NUM_THREADS")
    if env:
        try:
            return max(1, int(env))
        except ValueError as exc:
            raise ValueError(f"DEPTHNORMALS_NUM_THREADS must be a positive integer; got {env!r}") from exc
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def get_num_threads() -> int:
    """Threads the estimators use (default: the CPUs available, or $DEPTHNORMALS_NUM_THREADS)."""
    if _state["threads"] is None:
        _state["threads"] = _default_threads()
    return _state["threads"]


def set_num_threads(n: int) -> None:
    """Set the threads used by every estimator (ours and numba's own parallel kernels).

    Parameters
    ----------
    n : int
        Number of threads, >= 1. ``1`` runs everything on the calling thread.
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"number of threads must be an integer >= 1; got {n!r}")
    _state["threads"] = n
    try:
        import numba

        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    except (ImportError, ValueError):  # pragma: no cover - numba is a core dependency
        pass


def _pool(size: int) -> ThreadPoolExecutor:
    with _lock:
        if _state["pool"] is None or _state["pool_size"] < size:
            if _state["pool"] is not None:
                _state["pool"].shutdown(wait=False)
            _state["pool"] = ThreadPoolExecutor(max_workers=size, thread_name_prefix="depthnormals")
            _state["pool_size"] = size
        return _state["pool"]


@contextlib.contextmanager
def thread_limit(n: int) -> Iterator[None]:
    """Cap the row bands of :func:`run_rows` to ``n`` threads for calls made on this thread.

    Thread-local, so workers that each run one whole frame (``depthnormals.batch``) run it
    serially inside without touching the setting of other threads: the pool never nests.
    """
    old = getattr(_local, "limit", None)
    _local.limit = n if old is None else min(n, old)
    try:
        yield
    finally:
        _local.limit = old


def threads_here() -> int:
    """:func:`get_num_threads`, capped by the :func:`thread_limit` of the calling thread."""
    limit = getattr(_local, "limit", None)
    return get_num_threads() if limit is None else min(limit, get_num_threads())


def run_rows(kernel: Callable[..., None], h: int, *args: Any, min_rows: int = 32) -> None:
    """Call ``kernel(v0, v1, *args)`` over bands of rows covering ``[0, h)``, in parallel."""
    n = min(threads_here(), max(1, h // min_rows))
    if n <= 1:
        kernel(0, h, *args)
        return
    step = -(-h // n)
    futures = [_pool(n).submit(kernel, v0, min(v0 + step, h), *args) for v0 in range(0, h, step)]
    for f in futures:
        f.result()
