"""Share of pixels near a discontinuity (issue 16), per scene and per split, of generated datasets.

A pixel is near a discontinuity when, within 2 px (Chebyshev), two 4-neighbours differ in
ground-truth normal by more than 10 deg, in depth by more than 5 % of the nearer depth, or
one of them is invalid (:func:`depthnormals.evaluate.discontinuity_share`). Real 3F2N frames
(held out from this repository): 22 % Easy, 46 % Medium, 82 % Hard.

Per scene: the pooled share over its views (near pixels / valid pixels) and the median of
its per-view shares. Per split (indoor / outdoor): the median over scenes of the pooled share,
and the median over all views of the per-view share.

    depthnormals synth OUT --scenes assets --indoor 7 --outdoor 5 --views 10 --noise none
    python benchmarks/discontinuity_share.py OUT [OUT2 ...] [--variant clean] [--max-views N]
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

from depthnormals.evaluate import synth_discontinuity_shares


def report(root: Path, *, variant: str, max_views: int | None) -> dict:
    """Print the table of one dataset; return the per-split medians."""
    shares = synth_discontinuity_shares(root, variant=variant, max_views=max_views)
    meta = json.loads((root / "dataset.json").read_text())
    scene_set = meta["settings"].get("scenes", "procedural")
    print(f"\n{root} (scene set {scene_set}, variant {variant})")
    print(f"{'scene':34s} {'views':>5s} {'pooled':>7s} {'median':>7s}")
    for s in shares:
        print(f"{s.scene:34s} {len(s.frames):5d} {100 * s.pooled:6.1f}% "
              f"{100 * statistics.median(s.frames):6.1f}%")
    out = {}
    for kind in ("indoor", "outdoor", "mesh"):
        sel = [s for s in shares if s.kind == kind]
        if not sel:
            continue
        by_scene = statistics.median(s.pooled for s in sel)
        by_view = statistics.median(f for s in sel for f in s.frames)
        out[kind] = (by_scene, by_view)
        print(f"{kind:8s} median over {len(sel)} scenes {100 * by_scene:5.1f}%, "
              f"over {sum(len(s.frames) for s in sel)} views {100 * by_view:5.1f}%")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("roots", nargs="+", type=Path, help="datasets written by `depthnormals synth`")
    parser.add_argument("--variant", default="clean", help="clean (default) or a noise model folder")
    parser.add_argument("--max-views", type=int, default=None, help="first N views of each scene")
    args = parser.parse_args(argv)
    for root in args.roots:
        report(root, variant=args.variant, max_views=args.max_views)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
