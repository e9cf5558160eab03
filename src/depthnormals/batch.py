"""Batches of depth frames: one frame per worker thread, each frame serial inside.

:func:`estimate_normals_batch` is what :func:`depthnormals.estimate_normals` runs for an
``(N, H, W)`` depth stack. Frames are spread over :func:`depthnormals.get_num_threads`
threads; inside each worker the row-band pool of :mod:`depthnormals._parallel` is capped to
one thread (:func:`depthnormals._parallel.thread_limit`, thread-local), so the two levels of
parallelism never nest and every frame is computed exactly as a single call computes it.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

import numpy as np

from ._parallel import _pool, thread_limit, threads_here
from .camera import Intrinsics, as_intrinsics

__all__ = ["estimate_normals_batch", "frame_intrinsics", "map_threads"]

T = TypeVar("T")
R = TypeVar("R")


def frame_intrinsics(K: Any, n: int) -> list[Intrinsics]:
    """The intrinsics of each of ``n`` frames.

    Parameters
    ----------
    K : Intrinsics, array (3, 3), (fx, fy, cx, cy), mapping, array (N, 3, 3) or a sequence of N of those
        One camera for every frame, or one per frame.
    n : int
        Number of frames.

    Returns
    -------
    list of Intrinsics, length ``n``
    """
    if isinstance(K, np.ndarray) and K.ndim == 3:
        if K.shape != (n, 3, 3):
            raise ValueError(f"per-frame K must have shape (N, 3, 3) = ({n}, 3, 3); got {K.shape}")
        return [as_intrinsics(k) for k in K]
    if isinstance(K, (list, tuple)) and K and all(
            isinstance(k, (Intrinsics, np.ndarray, list, tuple, dict)) for k in K):
        if len(K) != n:
            raise ValueError(f"K gives {len(K)} cameras for {n} frames; pass one camera, or one per frame")
        return [as_intrinsics(k) for k in K]
    cam = as_intrinsics(K)
    return [cam] * n


def map_threads(func: Callable[[T], R], items: Sequence[T], *, threads: int | None = None,
                on_done: Callable[[int, R], None] | None = None) -> list[R]:
    """``[func(x) for x in items]`` on up to ``threads`` worker threads, each serial inside.

    Every worker pulls the next item from a shared counter and runs ``func`` under
    ``thread_limit(1)``, so the estimators inside run on the worker thread alone. With one
    thread (or one item) the items run in order on the calling thread, with the row-band
    pool as usual. ``on_done(index, result)`` is called on the calling thread as items finish.
    Exceptions are re-raised on the calling thread (the first one, after the workers stop).

    Parameters
    ----------
    func : callable
        The unit of work.
    items : sequence
        Its inputs.
    threads : int, optional
        Worker threads; default :func:`depthnormals.get_num_threads` (capped by the
        thread's :func:`~depthnormals._parallel.thread_limit`: nested calls stay serial).
    on_done : callable, optional
        Progress callback.

    Returns
    -------
    list
        The results, in the order of ``items``.
    """
    n = len(items)
    workers = min(threads_here() if threads is None else int(threads), n)
    results: list[Any] = [None] * n
    if workers <= 1:
        for i, item in enumerate(items):
            results[i] = func(item)
            if on_done is not None:
                on_done(i, results[i])
        return results
    lock = threading.Lock()
    counter: Iterator[int] = iter(range(n))
    failed = threading.Event()
    events: queue.SimpleQueue = queue.SimpleQueue()

    def next_index() -> int | None:
        with lock:
            return None if failed.is_set() else next(counter, None)

    def worker() -> None:
        try:
            with thread_limit(1):
                while (i := next_index()) is not None:
                    results[i] = func(items[i])
                    events.put(("done", i))
        except BaseException as exc:
            failed.set()
            events.put(("error", exc))
        finally:
            events.put(("exit", None))

    for _ in range(workers):
        _pool(workers).submit(worker)
    error: BaseException | None = None
    running = workers
    try:
        while running:
            kind, value = events.get()
            if kind == "exit":
                running -= 1
            elif kind == "error":
                error = error or value
            elif on_done is not None and error is None:
                on_done(value, results[value])
    except BaseException:
        failed.set()  # the workers stop after their current item
        raise
    if error is not None:
        raise error
    return results


def estimate_normals_batch(estimate: Callable[..., Any], depth: Any, K: Any, *, method: str,
                           depth_scale: float | None = None, return_uncertainty: bool = False,
                           **options: Any) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Normals of a stack of depth frames, frames spread over threads.

    Parameters
    ----------
    estimate : callable
        The single-frame dispatcher, ``estimate(depth, K, method=..., depth_scale=..., **options)``
        (:func:`depthnormals.estimate_normals`, which passes itself: this layer does not import
        the registry).
    depth : array_like, shape (N, H, W)
        N planar depth frames, metres (or integer units with ``depth_scale``).
    K : Intrinsics, array (3, 3), (fx, fy, cx, cy), array (N, 3, 3) or sequence of N Intrinsics
        One camera for all frames, or one per frame (pixels, 0-based pixel centres).
    method : str
        A name from :func:`depthnormals.methods`.
    depth_scale : float, optional
        Metres per unit of integer depth.
    return_uncertainty : bool, default False
        ``estimate`` returns ``(normals, uncertainty)`` per frame (the registry then passes its
        single-frame ``return_uncertainty=True`` path), and so does this function.
    **options
        Options of the method, as for :func:`depthnormals.estimate_normals`.

    Returns
    -------
    normals : ndarray, shape (N, H, W, 3), float32
        ``normals[i]`` is bit for bit ``estimate_normals(depth[i], K_i, method=method, ...)``.
    uncertainty : ndarray, shape (N, H, W), float32
        Only with ``return_uncertainty=True``: ``uncertainty[i]`` is the single call's map of
        frame i (expected angular error, degrees, NaN where the normal is NaN).

    Notes
    -----
    Every 3-D array is a stack here; :func:`depthnormals.estimate_normals` decides first
    whether a 3-D depth is a stack, one single-channel image ``(H, W, 1)`` or a colour image
    (its ``stack`` argument).
    """
    arr = depth if isinstance(depth, np.ndarray) else np.asarray(depth)  # (a masked stack stays one)
    if arr.ndim != 3:
        raise ValueError(f"a batch of depth frames must have shape (N, H, W); got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"the batch of depth frames is empty (shape {arr.shape})")
    n, h, w = arr.shape
    cams = frame_intrinsics(K, n)
    out = np.empty((n, h, w, 3), dtype=np.float32)
    unc = np.empty((n, h, w), dtype=np.float32) if return_uncertainty else None

    def one(i: int) -> None:
        result = estimate(arr[i], cams[i], method=method, depth_scale=depth_scale, **options)
        if unc is None:
            out[i] = result
        else:
            out[i], unc[i] = result

    map_threads(one, range(n))
    return out if unc is None else (out, unc)
