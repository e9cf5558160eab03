"""``depthnormals bench``: milliseconds per frame of every estimator beside its peers, same run.

Peers, each measured when installed (a note says which are not): OpenCV ``cv2.rgbd``
``RgbdNormals`` FALS, SRI and LINE-MOD; Open3D's tensor normal map
(``t.geometry.Image.create_vertex_map().create_normal_map()``) and its KNN
``PointCloud.estimate_normals``; kornia's ``depth_to_normals``. Every time is the median of
``--repeats`` runs after ``--warmup`` untimed runs; ratios are to OpenCV FALS at the same size
and thread count.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

HELP = ("time every estimator at 640x480 and 512x424, single thread and all cores, beside the "
        "peers installed (OpenCV RgbdNormals FALS/SRI/LINE-MOD, Open3D, kornia); prints ratios")

REF = "opencv-fals"
#: Seconds of compilation on a cold numba cache (every method; see ``commands._firstrun``).
FIRST_RUN_S = 140


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--methods", default=None,
                        help="comma-separated method names (default: every registered method, "
                             "'+' forms included)")
    parser.add_argument("--sizes", default="640x480,512x424", help="comma-separated WxH sizes")
    parser.add_argument("--repeats", type=int, default=15, help="timed runs per method (median)")
    parser.add_argument("--warmup", type=int, default=2, help="untimed runs before timing")
    parser.add_argument("--threads", default="1,all",
                        help="comma-separated thread counts; each pins ours (numba and the "
                             "row-band pool), OpenCV, torch and Open3D; 'all' = every core "
                             "(default 1,all)")
    parser.add_argument("--scene", default="demo-room", help="analytic scene to time on")
    parser.add_argument("--peers", default="all",
                        help="comma-separated peers to time (opencv-fals, opencv-sri, "
                             "opencv-linemod, open3d-normal-map, open3d-knn, kornia), 'all' or "
                             "'none'")
    parser.add_argument("--json", type=str, default=None, metavar="PATH",
                        help="also write every number and the machine description as JSON")
    parser.add_argument("--quiet", "-q", action="store_true",
                        help="no progress on stderr (one line per timed method otherwise)")


def _median_ms(fn: Callable[[], object], repeats: int, warmup: int = 2) -> float:
    for _ in range(max(warmup, 0)):
        fn()
    times = []
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    times.sort()
    n = len(times)
    mid = times[n // 2] if n % 2 else 0.5 * (times[n // 2 - 1] + times[n // 2])
    return 1e3 * mid


def machine() -> str:
    """One line describing this machine."""
    from ..evaluate import machine_description

    m = machine_description()
    return (f"{m['cpu']}, {m['logical_cores']} logical cores ({m['usable_cores']} usable), "
            f"{m['platform']}, Python {m['python']}")


# ------------------------------------------------------------------------------- the peers
# Each factory takes (depth float32 (H, W) in metres, K 3x3 float64) and returns
# (callable to time, what is timed); it raises ImportError when the peer is not installed.

def _opencv(method: str) -> Callable:
    def make(depth, K):
        import cv2

        if not hasattr(cv2, "rgbd"):
            raise ImportError("cv2.rgbd missing: pip install opencv-contrib-python-headless")
        h, w = depth.shape
        code = getattr(cv2.rgbd, f"RgbdNormals_RGBD_NORMALS_METHOD_{method}")
        est = cv2.rgbd.RgbdNormals_create(h, w, cv2.CV_32F, K, 5, code)
        if method == "LINEMOD":  # LINE-MOD reads depth itself (3-channel points crash it)
            return (lambda: est.apply(depth)), "apply() on depth, window 5"
        points = cv2.rgbd.depthTo3d(depth, K)
        return (lambda: est.apply(points)), "apply() on depthTo3d points (not timed), window 5"

    return make


def _open3d_normal_map(depth, K):
    import numpy as np
    import open3d as o3d

    image = o3d.t.geometry.Image(o3d.core.Tensor(np.ascontiguousarray(depth)))
    intr = o3d.core.Tensor(np.asarray(K, dtype=np.float64))

    def fn():
        return image.create_vertex_map(intr, invalid_fill=0.0).create_normal_map(invalid_fill=0.0)

    return fn, "t.geometry vertex map + normal map from the depth image"


def _open3d_knn(depth, K):
    import numpy as np
    import open3d as o3d

    from ..camera import backproject

    pts = backproject(depth, K).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1) & (pts[:, 2] > 0)].astype(np.float64)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    param = o3d.geometry.KDTreeSearchParamKNN(knn=9)
    return (lambda: cloud.estimate_normals(param)), \
        "legacy PointCloud.estimate_normals, KNN 9 (cloud built outside the timing)"


def _kornia(depth, K):
    import kornia
    import numpy as np
    import torch

    d = torch.from_numpy(np.ascontiguousarray(depth, dtype=np.float32))[None, None]
    k = torch.from_numpy(np.asarray(K, dtype=np.float32))[None]

    def fn():
        with torch.no_grad():
            return kornia.geometry.depth.depth_to_normals(d, k)

    return fn, "geometry.depth.depth_to_normals on CPU float32"


PEERS: dict[str, Callable] = {
    "opencv-fals": _opencv("FALS"),
    "opencv-sri": _opencv("SRI"),
    "opencv-linemod": _opencv("LINEMOD"),
    "open3d-normal-map": _open3d_normal_map,
    "open3d-knn": _open3d_knn,
    "kornia": _kornia,
}


def _set_threads(n: int) -> dict[str, int | str]:
    """Pin every library that times: ours (row-band pool and numba), OpenCV, torch, Open3D.

    Libraries not imported are left alone (a peer imports its library before timing). Returns
    what each library was set to, or why it could not be, for the JSON report.
    """
    import sys

    from .._parallel import get_num_threads, set_num_threads

    set_num_threads(n)  # our row-band pool and numba's own threads
    pinned: dict[str, int | str] = {"depthnormals": get_num_threads()}
    if "cv2" in sys.modules:
        cv2 = sys.modules["cv2"]
        cv2.setNumThreads(n)
        pinned["opencv"] = int(cv2.getNumThreads())
    if "torch" in sys.modules:
        torch = sys.modules["torch"]
        torch.set_num_threads(n)
        pinned["torch"] = int(torch.get_num_threads())
    o3d = sys.modules.get("open3d")
    if o3d is not None:
        utility = getattr(o3d, "utility", None)
        if hasattr(utility, "set_max_threads"):  # Open3D >= 0.20: bounds its TBB pool
            utility.set_max_threads(n)
            pinned["open3d"] = int(utility.get_max_threads())
        else:
            pinned["open3d"] = "not pinned: this Open3D has no utility.set_max_threads"
    return pinned


def _parse_threads(text: str) -> list[int]:
    import numba

    out = []
    for item in str(text).split(","):
        item = item.strip().lower()
        if item == "all":
            out.append(int(numba.config.NUMBA_NUM_THREADS))
            continue
        try:
            n = int(item)
        except ValueError as exc:
            raise ValueError(f"--threads takes integers or 'all'; got {item!r}") from exc
        if n < 1:
            raise ValueError(f"--threads must be >= 1; got {n}")
        out.append(n)
    return list(dict.fromkeys(out))


def run(args: argparse.Namespace) -> int:
    import numba
    import numpy as np

    from .._parallel import get_num_threads
    from .._progress import Progress
    from ..analytic import DEFAULT_K, DEFAULT_SHAPE, make_scene
    from ..evaluate import machine_description
    from ..registry import estimate_normals, methods
    from .demo import parse_size

    previous_threads = get_num_threads()
    # Start numba's thread pool before a peer loads its own TBB (Open3D ships an older one,
    # which numba would then pick up and reject with a NumbaWarning).
    numba.get_num_threads()
    if args.repeats < 1:
        raise ValueError(f"--repeats must be >= 1 (timed runs per method); got {args.repeats}")
    if args.warmup < 0:
        raise ValueError(f"--warmup must be >= 0; got {args.warmup}")
    names = args.methods.split(",") if args.methods else list(methods())
    sizes = [parse_size(s) for s in args.sizes.split(",")]
    thread_list = _parse_threads(args.threads)
    if args.peers == "none":
        peer_names: list[str] = []
    elif args.peers == "all":
        peer_names = list(PEERS)
    else:
        peer_names = [p.strip() for p in args.peers.split(",")]
        unknown = [p for p in peer_names if p not in PEERS]
        if unknown:
            raise ValueError(f"unknown peer(s) {unknown}; valid peers: {', '.join(PEERS)}")
    # Import what is installed once, before timing; note what is not.
    notes: dict[str, str] = {}
    depth0 = make_scene(args.scene).render(DEFAULT_K.scaled(0.1), (48, 64)).depth.astype("f4")
    for p in list(peer_names):
        try:
            PEERS[p](depth0, DEFAULT_K.scaled(0.1).matrix)
        except ImportError as exc:
            notes[p] = f"not installed ({exc.name or exc})"
            peer_names.remove(p)
    try:
        import cv2

        cv_version = cv2.__version__
    except ImportError:
        cv_version = None
    print(f"machine: {machine()}; numba {numba.__version__}; "
          f"OpenCV {cv_version or 'not installed'}; threads: {', '.join(map(str, thread_list))}")
    result: dict = {"machine": machine_description(), "scene": args.scene,
                    "repeats": args.repeats, "warmup": args.warmup, "reference": REF,
                    "peers_missing": notes, "peers_timed": {}, "runs": [], "threads_pinned": {}}
    bar = Progress("bench", total=len(thread_list) * len(sizes) * (len(peer_names) + len(names)),
                   unit="timing", enabled=not args.quiet)
    for threads in thread_list:
        result["threads_pinned"][str(threads)] = _set_threads(threads)
        table: dict[str, dict[tuple[int, int], float]] = {}
        for h, w in sizes:
            K = DEFAULT_K.scaled(w / DEFAULT_SHAPE[1])
            depth = make_scene(args.scene).render(K, (h, w)).depth.astype(np.float32)
            for p in peer_names:
                bar.update(f"{threads} thread(s) {w}x{h} {p}",
                           line=f"bench: {bar.count + 1}/{bar.total} {p} at {w}x{h}, "
                                f"{threads} thread(s)")
                try:
                    fn, what = PEERS[p](depth, K.matrix)
                    table.setdefault(p, {})[(h, w)] = _median_ms(fn, args.repeats, args.warmup)
                    result["peers_timed"][p] = what
                except Exception as exc:  # a peer's own failure must not stop the bench
                    notes[p] = f"failed: {type(exc).__name__}: {exc}"
            for name in names:
                bar.update(f"{threads} thread(s) {w}x{h} {name}",
                           line=f"bench: {bar.count + 1}/{bar.total} {name} at {w}x{h}, "
                                f"{threads} thread(s)")
                table.setdefault(name, {})[(h, w)] = _median_ms(
                    lambda n=name, d=depth, k=K: estimate_normals(d, k, method=n),
                    args.repeats, args.warmup)
        ref = table.get(REF, {})
        head = "".join(f"{f'{w}x{h} ms':>14}{'ratio':>8}" for h, w in sizes)
        print(f"\n# threads: {threads}")
        print(f"{'method':<20}{head}")
        order = [p for p in peer_names if p in table] + [n for n in names if n not in PEERS]
        for name in order:
            row = table[name]
            cells = ""
            for s in sizes:
                ms = row.get(s, float("nan"))
                ratio = ms / ref[s] if s in ref else float("nan")
                cells += f"{ms:14.2f}{ratio:8.2f}"
            print(f"{name:<20}{cells}")
            result["runs"].append({"threads": threads, "method": name, "peer": name in PEERS,
                                   **{f"{w}x{h}_ms": row.get((h, w)) for h, w in sizes}})
    bar.close()
    _set_threads(previous_threads)
    print(f"\nratio = ms / {REF} ms at the same size and threads (lower is faster); medians of "
          f"{args.repeats} runs after {args.warmup} warm-up runs. OpenCV FALS/SRI time apply() on "
          "precomputed points (depthTo3d not counted), ours the whole call from depth.")
    for p, what in result["peers_timed"].items():
        print(f"# {p}: {what}")
    for p, why in notes.items():
        print(f"# {p}: {why}")
    if args.json:
        from pathlib import Path

        from ..evaluate._store import write_json

        result["peers_missing"] = notes
        write_json(Path(args.json), result)
    return 0
