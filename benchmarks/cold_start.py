"""Cold start: the first ``estimate_normals`` call per method, and ``depthnormals demo``, each in
a fresh process with an empty numba cache (``NUMBA_CACHE_DIR`` pointed at a new folder).

    PYTHONPATH=src python3 benchmarks/cold_start.py [--methods 3f2n+,d2nt] [--demo] [--src src]

Prints one line per case: import time and the first call's wall time (compile + run), in
seconds, the same call again in the same process (warm), so compile = first - warm, and the
CPU seconds of the first call and of the whole process (the figures that survive a loaded
machine: numba compiles on one thread).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
c0 = time.process_time()
import numpy as np
import depthnormals as dn
from depthnormals.analytic import make_scene
t1 = time.perf_counter()
r = make_scene("demo-room").render()
depth = r.depth.astype(np.float32)
t2 = time.perf_counter()
c2 = time.process_time()
dn.estimate_normals(depth, r.K, method=sys.argv[1])
t3 = time.perf_counter()
c3 = time.process_time()
dn.estimate_normals(depth, r.K, method=sys.argv[1])
t4 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "first": t3 - t2, "warm": t4 - t3, "first_cpu": c3 - c2,
                  "total_cpu": time.process_time() - c0}))
"""


def _env(src: str, cache: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = src
    env["NUMBA_CACHE_DIR"] = cache
    return env


def cold_call(method: str, src: str) -> dict[str, float]:
    with tempfile.TemporaryDirectory(prefix="nbcache-") as cache:
        out = subprocess.run([sys.executable, "-c", _CHILD, method], env=_env(src, cache),
                             capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def cold_demo(src: str) -> tuple[float, float]:
    with tempfile.TemporaryDirectory(prefix="nbcache-") as cache, \
            tempfile.TemporaryDirectory(prefix="demo-") as tmp:
        t0 = time.perf_counter()
        c0 = os.times()
        subprocess.run([sys.executable, "-m", "depthnormals", "demo", "--output",
                        str(Path(tmp) / "demo.png")], env=_env(src, cache), capture_output=True,
                       check=True)
        c1 = os.times()
        cpu = (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)
        return time.perf_counter() - t0, cpu


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--methods", default="", help="comma-separated (default: every method)")
    p.add_argument("--demo", action="store_true", help="also time `depthnormals demo` cold")
    p.add_argument("--src", default="src", help="source folder to put first on PYTHONPATH")
    a = p.parse_args()
    src = str(Path(a.src).resolve())
    if a.methods:
        names = a.methods.split(",")
    else:
        sys.path.insert(0, src)
        import depthnormals as dn

        names = list(dn.methods())
    print(f"source {src}; 640x480 demo-room float32; seconds; empty numba cache per case")
    print("first: wall of the first call; first cpu: its CPU time (compile is one thread, so on a "
          "loaded machine this is the figure to compare); process cpu: the whole child")
    print(f"{'method':<18}{'import':>8}{'first':>8}{'warm':>8}{'first cpu':>10}{'process cpu':>12}")
    for m in names:
        r = cold_call(m, src)
        print(f"{m:<18}{r['import']:8.2f}{r['first']:8.2f}{r['warm']:8.3f}{r['first_cpu']:10.2f}"
              f"{r['total_cpu']:12.2f}", flush=True)
    if a.demo:
        wall, cpu = cold_demo(src)
        print(f"{'demo':<18}{'':>8}{wall:8.2f}{'':>8}{'':>10}{cpu:12.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
