"""A description of the machine and software, for the sidecar JSON of results."""

from __future__ import annotations

import os
import platform
import sys
from importlib import metadata
from typing import Any

__all__ = ["machine_description"]


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def machine_description() -> dict[str, Any]:
    """CPU model, core counts, OS, Python and the versions of the numeric packages.

    Returns
    -------
    dict
        JSON-ready: ``cpu``, ``logical_cores``, ``usable_cores``, ``numba_threads``,
        ``platform``, ``python`` and ``packages`` (name -> version, None if absent).
    """
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        usable = os.cpu_count()
    try:
        import numba

        threads = int(numba.get_num_threads())
    except ImportError:  # pragma: no cover - numba is a dependency
        threads = None
    return {
        "cpu": _cpu_model(),
        "logical_cores": os.cpu_count(),
        "usable_cores": usable,
        "numba_threads": threads,
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "packages": {d: _version(d) for d in (
            "depthnormals", "numpy", "numba", "opencv-contrib-python-headless",
            "open3d", "open3d-cpu", "kornia", "torch", "matplotlib")},
    }
