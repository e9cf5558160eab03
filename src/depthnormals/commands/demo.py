"""``depthnormals demo``: the main job on a built-in analytic scene, no data needed."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

#: Top of the error colour scale of the demo picture (degrees).
ERROR_VMAX_DEG = 30.0
#: Seconds of compilation on a cold numba cache (see ``depthnormals.commands._firstrun``).
FIRST_RUN_S = 12

HELP = ("render a built-in analytic scene, estimate its normals, print the error metrics and "
        "write a picture (depth | ground truth | estimate | angular error)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..analytic import scene_names

    parser.add_argument("--scene", default="demo-room", choices=scene_names(),
                        help="analytic scene (default demo-room)")
    parser.add_argument("--method", "-m", default=None,
                        help="estimator (default: the library default; see `depthnormals methods`)")
    parser.add_argument("--baseline", default="3f2n",
                        help="a second method to compare with (default 3f2n; 'none' to skip)")
    parser.add_argument("--noise", type=float, default=0.0,
                        help="Gaussian depth noise, sigma as a multiple of the pixel footprint z/f")
    parser.add_argument("--seed", type=int, default=0, help="noise seed")
    parser.add_argument("--size", default="640x480", help="image size WxH (default 640x480)")
    parser.add_argument("-o", "--output", type=Path, default=Path("depthnormals-demo.png"),
                        help="picture to write (PNG; default depthnormals-demo.png)")
    parser.add_argument("--json", action="store_true", help="print the metrics as JSON")


def demo_picture(depth, truth, estimate, error, *, label: str):
    """Depth | ground truth | estimate | angular error, titled, colour bars under depth (metres)
    and error (degrees, 0 to :data:`ERROR_VMAX_DEG`); RGB uint8."""
    import numpy as np

    from ..viz import colorize, error_to_rgb8, normals_to_rgb8, titled_panel

    z = np.where(depth > 0, depth, np.nan)
    ok = np.isfinite(z)
    lo, hi = (np.percentile(z[ok], [1, 99]) if ok.any() else (0.0, 1.0))
    return titled_panel(
        [colorize(z, vmin=lo, vmax=hi, cmap="viridis"), normals_to_rgb8(truth),
         normals_to_rgb8(estimate), error_to_rgb8(error, vmax=ERROR_VMAX_DEG)],
        ["depth (m)", "ground truth", f"estimate {label}", "angular error (deg)"],
        colorbars=[{"vmin": float(lo), "vmax": float(hi), "cmap": "viridis", "label": "depth (m)"},
                   None, None,
                   {"vmin": 0.0, "vmax": ERROR_VMAX_DEG, "cmap": "inferno",
                    "label": "angular error (deg)"}])


def parse_size(text: str) -> tuple[int, int]:
    """``"640x480"`` -> ``(480, 640)`` (rows, columns)."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError as exc:
        raise ValueError(f"size must look like 640x480; got {text!r}") from exc
    if w < 1 or h < 1:
        raise ValueError(f"size must be positive; got {text!r}")
    return h, w


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from .._validate import check_real
    from ..analytic import DEFAULT_K, DEFAULT_SHAPE, make_scene
    from ..io import write_png
    from ..metrics import angular_error, normal_metrics
    from ..registry import DEFAULT_METHOD, estimate_normals

    h, w = parse_size(args.size)
    check_real(args.noise, "--noise", minimum=0.0, hint="sigma in units of z/f; 0: none")
    if args.output.suffix.lower() != ".png":
        raise ValueError(f"the picture is a PNG: -o must end in .png; got {args.output}")
    K = DEFAULT_K.scaled(w / DEFAULT_SHAPE[1]) if (h, w) != DEFAULT_SHAPE else DEFAULT_K
    render = make_scene(args.scene).render(K, (h, w))
    depth = render.depth.astype(np.float32)
    if args.noise > 0:
        rng = np.random.default_rng(args.seed)
        sigma = args.noise * depth / K.fx
        depth = np.where(depth > 0, depth + rng.normal(size=depth.shape) * sigma, 0).astype(np.float32)
    methods = [args.method or DEFAULT_METHOD]
    if args.baseline and args.baseline != "none" and args.baseline not in methods:
        methods.append(args.baseline)
    results = {}
    estimates = {}
    for method in methods:
        estimate_normals(depth[:8, :8], K, method=method)  # compile / warm up
        t0 = time.perf_counter()
        n = estimate_normals(depth, K, method=method)
        ms = (time.perf_counter() - t0) * 1e3
        estimates[method] = n
        results[method] = {**normal_metrics(n, render.normals).as_dict(), "ms": ms}
    main = methods[0]
    err = angular_error(estimates[main], render.normals)
    picture = demo_picture(depth, render.normals, estimates[main], err, label=main)
    write_png(args.output, picture)
    if args.json:
        print(json.dumps({"scene": args.scene, "size": [w, h], "noise": args.noise,
                          "results": results, "picture": str(args.output)}, indent=2))
        return 0
    print(f"scene {args.scene} {w}x{h}, noise {args.noise:g} z/f; all pixels with ground truth")
    print(f"{'method':<16}{'mean':>8}{'median':>8}{'rmse':>8}{'<11.25':>8}{'<30':>8}{'cover':>8}{'ms':>8}")
    for method, r in results.items():
        print(f"{method:<16}{r['mean']:8.3f}{r['median']:8.3f}{r['rmse']:8.3f}"
              f"{100 * r['a11_25']:7.1f}%{100 * r['a30']:7.1f}%{100 * r['coverage']:7.1f}%{r['ms']:8.1f}")
    print(f"wrote {args.output}: depth (m) | ground truth | {main} | angular error "
          f"(0-{ERROR_VMAX_DEG:g} deg), titled, with colour bars")
    return 0
