"""The session-19 prototype of the face switch: each pixel by a crease takes the face whose plane
explains its own 3x3 (numpy; measured here).

Since session 31 the rule is in the library, the last step of the measured-support branch
(``depthnormals.ddm.faceswitch``: without the tile gate below, which changed nothing measurable
on the frames that run it, and with a margin, the other face's fit below 0.7 times its own
face's; docs/benchmarks.md section 22): this script now runs on an output that has it, and
compares the prototype's second pass with it (``--fit 1e30`` and the library's ``MARGIN = 1.0``
give the library's decisions: tests/test_ddm_faceswitch.py checks the kernel against a numpy
reference of the same rule).

Why: within 10 px of the creases of the real frames' planes (``evaluate.crease_band``) the
default errs more than PCL's average-3D-gradient (docs/benchmarks.md section 16, "Session 19"):
its windows, chosen by their residual, carry a face's normal several pixels onto its neighbour
face before the fallback's 5-standard-deviation test stops them, and on real Kinect v1 / Xtion
creases further than on the synthetic models.

The rule (:func:`refine`), per valid pixel ``p`` whose 3x3 holds no depth jump (no neighbour
more than ``jump`` of its depth away): every pixel ``q`` carries the plane of its output normal
``n_q`` through the centroid ``c_q`` of its own 3x3's back-projected points. Over ``p`` itself
and the eight pixels ``span`` px away (rows, columns, diagonals), the mean square distance of
``p``'s 3x3 points to each such plane,
``n_q^T C_p n_q + (n_q . (c_p - c_q))^2`` (``C_p`` the 3x3's covariance), is split into the
planes within ``angle`` of ``n_p`` (its own face; the least is ``same``) and the others (the
least is ``other``, from ``q*``). ``p`` takes ``n_{q*}`` where ``other < same`` and ``other <
fit T``, ``T`` the lower median of ``same`` over the pixel's 32 x 32 tile (the noise scale of
a plane's 3x3 there): the other face's plane must explain the pixel's neighbourhood as well as
a plane explains a typical one. One pass, on the output of ``estimate_normals(depth, K)``.

    python benchmarks/crease_refinement.py [--real ../shared/data/real-sensors]
        [--synth /tmp/u-synth ...] [--fit 6] [--span 4] [--half] [--measured-only]

``--half``: the rule on every second row and column (span and tile halved; each pixel takes
its 2x2 cell's switch), as the measured-support branch chooses its windows from radius
``HALF_RADIUS``: a quarter of the pixels. ``--measured-only``: only on frames whose default
takes the measured-support branch (``dn.noise_profile(depth, K).branch``: every real frame,
the synthetic kinect_v1 and realsense_d4xx columns; gaussian, kinect_v2 and tof take the
i.i.d. box-fit and are left as they are).

Prints, for the real frames, the mean over folders of the plane interiors, rims and the crease
bands (all, within 3 px of the line, 3-10 px) before and after, and per folder; for each
synthetic folder the mean error against the exact normals per sensor model (the clean column
left out: the rule is for the noisy branches).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

import depthnormals as dn
from depthnormals.camera import backproject

ROOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "real-sensors"
#: Directions of the candidate pixels (times ``span``).
DIRECTIONS = ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1))


def _shift(a: np.ndarray, dv: int, du: int) -> np.ndarray:
    """``out[v, u] = a[v + dv, u + du]``, NaN outside."""
    out = np.full_like(a, np.nan)
    h, w = a.shape[:2]
    src = (slice(max(dv, 0), h + min(dv, 0)), slice(max(du, 0), w + min(du, 0)))
    dst = (slice(max(-dv, 0), h + min(-dv, 0)), slice(max(-du, 0), w + min(-du, 0)))
    out[dst] = a[src]
    return out


def _mean3(a: np.ndarray) -> np.ndarray:
    """Mean over each pixel's 3x3 of the finite rows of ``a`` (H, W, C); NaN where none."""
    ok = np.isfinite(a).all(-1)
    p = np.pad(np.where(ok[..., None], a, 0.0), ((1, 1), (1, 1), (0, 0)))
    c = np.pad(ok.astype(np.float64), 1)
    h, w = a.shape[:2]
    s = sum(p[i:i + h, j:j + w] for i in range(3) for j in range(3))
    n = sum(c[i:i + h, j:j + w] for i in range(3) for j in range(3))
    with np.errstate(invalid="ignore", divide="ignore"):
        return s / n[..., None]


def _tile_lower_median(a: np.ndarray, tile: int) -> np.ndarray:
    """Per ``tile`` x ``tile`` block the lower median of the finite values of ``a``, spread over
    the block's pixels (the frame's where a block has none)."""
    h, w = a.shape
    th, tw = -(-h // tile), -(-w // tile)
    p = np.full((th * tile, tw * tile), np.nan)
    p[:h, :w] = a
    blocks = np.sort(p.reshape(th, tile, tw, tile).transpose(0, 2, 1, 3).reshape(th, tw, -1), -1)
    count = np.isfinite(blocks).sum(-1)
    idx = np.maximum((count - 1) // 2, 0)
    med = np.take_along_axis(blocks, idx[..., None], -1)[..., 0]
    fin = np.sort(a[np.isfinite(a)])
    glob = fin[(fin.size - 1) // 2] if fin.size else np.nan
    med = np.where(count > 0, med, glob)
    return np.repeat(np.repeat(med, tile, 0), tile, 1)[:h, :w]


def refine(depth: np.ndarray, K, normals: np.ndarray, *, span: int = 4, angle: float = 20.0,
           fit: float = 6.0, jump: float = 0.02, tile: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """The rule of the module docstring on ``normals`` (H, W, 3) of ``depth`` (metres).

    Returns the refined normals (float32) and the mask of the pixels that changed face.
    """
    X = backproject(depth, K)
    n = np.asarray(normals, np.float64)
    ok = np.isfinite(X[..., 2]) & np.isfinite(n).all(-1)
    n = np.where(ok[..., None], n, np.nan)
    X = np.where(ok[..., None], X, np.nan)
    z = X[..., 2]
    smooth = ok.copy()
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            with np.errstate(invalid="ignore"):
                smooth &= ~(np.abs(_shift(z, dv, du) - z) > jump * z)
    c = _mean3(X)
    outer = _mean3(np.einsum("...i,...j->...ij", X, X).reshape(*X.shape[:2], 9))
    cov = outer.reshape(*X.shape[:2], 3, 3) - np.einsum("...i,...j->...ij", c, c)

    def msd(nq: np.ndarray, cq: np.ndarray) -> np.ndarray:
        d = np.einsum("...i,...i", nq, c - cq)
        return np.einsum("...i,...ij,...j", nq, cov, nq) + d * d

    cos_min = np.cos(np.radians(angle))
    same = msd(n, c)
    own = same.copy()
    other = np.full(same.shape, np.inf)
    best = n.copy()
    for dv, du in DIRECTIONS:
        nq, cq = _shift(n, dv * span, du * span), _shift(c, dv * span, du * span)
        m = msd(nq, cq)
        with np.errstate(invalid="ignore"):
            differ = np.einsum("...i,...i", nq, n) < cos_min
            fin = np.isfinite(m)
            same = np.where(fin & ~differ & (m < same), m, same)
            take = fin & differ & (m < other)
        other = np.where(take, m, other)
        best = np.where(take[..., None], nq, best)
    scale = _tile_lower_median(np.where(smooth, own, np.nan), tile)
    with np.errstate(invalid="ignore"):
        switch = smooth & (other < same) & (other < fit * scale)
    out = np.where(switch[..., None], best, n)
    return out.astype(np.float32), switch


def refine_half(depth: np.ndarray, K, normals: np.ndarray, *, span: int = 4, **kw
                ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`refine` on every second row and column (intrinsics halved, ``span // 2`` cells,
    16-cell tiles); each pixel takes its 2x2 cell's switch and new normal."""
    from depthnormals.camera import Intrinsics, as_intrinsics

    cam = as_intrinsics(K)
    half = Intrinsics(cam.fx / 2.0, cam.fy / 2.0, cam.cx / 2.0, cam.cy / 2.0)
    n2, s2 = refine(np.ascontiguousarray(depth[::2, ::2]), half,
                    np.ascontiguousarray(np.asarray(normals)[::2, ::2]),
                    span=max(1, span // 2), tile=16, **kw)
    h, w = depth.shape
    switch = np.repeat(np.repeat(s2, 2, 0), 2, 1)[:h, :w]
    cells = np.repeat(np.repeat(n2, 2, 0), 2, 1)[:h, :w]
    out = np.where(switch[..., None], cells, np.asarray(normals, np.float32))
    return out.astype(np.float32), switch


def _apply(depth: np.ndarray, K, normals: np.ndarray, *, half: bool = False,
           measured_only: bool = False, **kw) -> tuple[np.ndarray, np.ndarray]:
    """The rule as the options ask (module doc); unchanged normals where it does not run."""
    if measured_only and dn.noise_profile(depth, K).branch != "measured-support":
        return np.asarray(normals, np.float32), np.zeros(depth.shape, bool)
    return (refine_half if half else refine)(depth, K, normals, **kw)


def real_table(root: Path, **kw) -> dict:
    """folder -> (before, after): means over the folder's frames of interior, rim, crease band,
    its near (< 3 px) and far parts (degrees)."""
    from depthnormals.datasets import open as open_dataset
    from depthnormals.evaluate import (
        crease_band,
        plane_reference,
        score_creases,
        score_planes,
        sensor_threshold,
    )

    rows: dict[str, list] = {}
    for f in open_dataset(root):
        ref = plane_reference(f.depth, f.K, threshold=sensor_threshold(f.meta))
        band = crease_band(f.depth, f.K, ref)
        depth = np.asarray(f.depth, np.float32)
        n0 = dn.estimate_normals(depth, f.K)
        n1, _ = _apply(depth, f.K, n0, **kw)
        pair = []
        for n in (n0, n1):
            p, c = score_planes(n, ref), score_creases(n, band)
            pair.append([p["interior_mean"], p["rim_mean"], c["mean"], c["near_mean"], c["far_mean"]])
        rows.setdefault(str(f.group).split("/")[0], []).append(pair)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # folders without a crease
        return {g: np.nanmean(np.array(v, np.float64), axis=0) for g, v in rows.items()}


def synth_table(root: Path, **kw) -> dict:
    """variant -> (before, after, share of pixels switched) mean error against the exact normals."""
    from depthnormals.datasets.synthetic import read_synthetic

    acc: dict[str, np.ndarray] = {}
    for f in read_synthetic(root):
        variant = f.meta.get("variant", f.group.rsplit("/", 1)[-1])
        if variant == "clean":
            continue
        depth = np.asarray(f.depth, np.float32)
        n0 = dn.estimate_normals(depth, f.K)
        n1, switch = _apply(depth, f.K, n0, **kw)
        keep = np.ones(depth.shape, bool) if f.mask is None else f.mask
        e0, e1 = dn.angular_error(n0, f.normals), dn.angular_error(n1, f.normals)
        ok = keep & np.isfinite(e0) & np.isfinite(e1)
        a = acc.setdefault(variant, np.zeros(4))
        a += [e0[ok].sum(), e1[ok].sum(), (switch & ok).sum(), ok.sum()]
    return {v: (a[0] / a[3], a[1] / a[3], a[2] / a[3]) for v, a in acc.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", default=str(ROOT), help="real-sensor folder ('' to skip)")
    ap.add_argument("--synth", type=Path, nargs="*", default=[], help="synthetic folders")
    ap.add_argument("--fit", type=float, default=6.0)
    ap.add_argument("--span", type=int, default=4)
    ap.add_argument("--half", action="store_true", help="on every second row and column")
    ap.add_argument("--measured-only", action="store_true",
                    help="only on frames of the measured-support branch")
    a = ap.parse_args(argv)
    if a.real and not Path(a.real).is_dir():
        ap.error(f"--real {a.real}: no such folder (pass --real '' to leave the real frames out)")
    for s in a.synth:
        if not s.is_dir():
            ap.error(f"--synth {s}: no such folder")
    kw = {"fit": a.fit, "span": a.span, "half": a.half, "measured_only": a.measured_only}
    if a.real:
        table = real_table(Path(a.real), **kw)
        names = ("interior", "rim", "crease", "crease < 3 px", "crease 3-10 px")
        print("real frames, mean over folders (deg): before -> after")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nanmean(np.array(list(table.values())), axis=0)
        for k, name in enumerate(names):
            print(f"  {name:16s} {mean[0][k]:6.2f} -> {mean[1][k]:6.2f}")
        print("per folder (interior / rim / crease): before -> after")
        for g, (b, r) in table.items():
            print(f"  {g:34s} " + " / ".join(f"{x:.2f}" for x in b[:3]) + "  ->  "
                  + " / ".join(f"{x:.2f}" for x in r[:3]))
    for s in a.synth:
        print(f"\n{s}: mean error against the exact normals (deg), before -> after, pixels switched")
        for v, (e0, e1, share) in sorted(synth_table(s, **kw).items()):
            print(f"  {v:15s} {e0:6.3f} -> {e1:6.3f} ({100 * (e1 / e0 - 1):+5.1f} %), {100 * share:.2f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
