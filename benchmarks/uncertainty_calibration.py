"""Calibration of the expected-error map (``estimate_normals(..., return_uncertainty=True)``).

For every column of data with a reference normal, the pixels where both the estimate and the
reference are finite are binned by deciles of the predicted error; per bin the mean observed
angular error is printed beside the mean prediction (the reliability table), with the Spearman
rank correlation of prediction and error over all pixels. A bin passes when the observed mean
is within 25 % of the predicted one, or within 0.5 deg where both are below 2 deg.

Columns:

- ``analytic``: the scenes of :mod:`depthnormals.analytic` with Gaussian depth noise of 0.1
  footprints (``z (1 + 0.1 n / fx)``);
- ``synth/<variant>``: a synthetic benchmark folder (``--synth``, made by ``depthnormals synth
  /tmp/u-synth --indoor 2 --outdoor 2 --views 2 --seed 0 --noise
  gaussian,kinect_v1,kinect_v2,tof,realsense_d4xx --scenes procedural``), one column per sensor
  model (and ``clean``); with several folders, each column pools all their frames (sets of
  other seeds: the benchmark at a larger scale);
- ``real/<folder>``: the real frames of ``../shared/data/real-sensors`` against their plane
  references (``plane_reference`` with ``sensor_threshold``; interiors and rims), and ``real``
  over all of them;
- with ``--planes``, each synthetic sensor column split as the real frames are scored:
  ``synth-planes/<variant>`` the pixels of the plane reference found on the noisy depth
  (interiors and rims, the structured-light threshold) and ``synth-off/<variant>`` the rest,
  both against the exact normals (no target: a diagnosis of where the map misses, the real
  frames having no reference off their planes), and ``synth-asreal/<variant>`` the same
  pixels against the reference's own normals, as the real frames are scored (no target: how
  far that scoring reads the same map otherwise; near a crease the reference, fitted to the
  same depth, can take the same wrong face as the estimate), with per sensor model, on the
  reference's interiors and rims, the share of pixels whose reference normal is over
  :data:`WRONG_DEG` deg from the exact one, whose estimate is over it from the exact one or
  from the reference, and whose estimate and reference are off the same way (the reference
  over :data:`WRONG_DEG` deg off, the estimate within :data:`SAME_DEG` deg of it: an error
  the real frames' scoring cannot see);
- with ``--by-crease``, each synthetic sensor column split by the exact geometry of its view
  (:func:`geometry_labels` on the clean depth and the exact normals): ``synth-crease/<variant>``
  the pixels within :data:`CREASE_PX` px of a crease (adjacent exact normals over
  :data:`CREASE_DEG` deg apart where the clean depth is continuous), ``synth-jump/<variant>``
  those within :data:`JUMP_PX` px of a depth jump (a relative step over :data:`JUMP_REL`), and
  ``synth-rest/<variant>`` the others (a diagnosis: a column whose deciles pass may pass by
  the mix of pixels the map reads too low and too high, and a set of other scenes mixes them
  otherwise);
- with ``--thin``, each synthetic sensor column split by the faces narrower than the
  estimator resolves (:func:`thin_labels` on the exact normals): ``synth-thin/<variant>`` the
  pixels within :data:`THIN_PX` px of a face at most 5 px across (a riser, a board's edge, a
  leg), ``synth-resolved/<variant>`` the others (a diagnosis: no window holds such a face,
  and no depth-only map can place it; the targets are read on the whole column);
- with ``--min-fraction F``, the real references keep planes down to ``F`` of the image
  (``plane_reference``'s ``min_fraction``, default 0.01): 0.0025 adds faces such as a table's
  front or a box's side, which the default leaves out (a diagnosis: the targets are read on
  the default references);
- with ``--creases``, ``real+creases/<folder>`` and ``real+creases``: the same pixels and the
  bands by the planes' creases (:func:`depthnormals.evaluate.crease_band`: within 10 px of the
  line where two reference planes over 30 deg apart meet, each pixel against the face it sees
  by geometry), which the plane references leave out and where a crease placed a few pixels
  off errs by the whole angle between the faces (a diagnosis: the targets are read on the
  plane references); and per distance from the crease line (0-1, 1-2, 2-3, 3-4, 4-6, 6-8,
  8-10 px) the band's pixels, mean observed and predicted error and the share observed over 45
  deg, for the real frames pooled and (with ``--synth``) each noisy sensor column, whose band
  is found on the plane reference of its noisy depth and scored against the exact normals.

    python benchmarks/uncertainty_calibration.py [--method 3f2n+] [--synth /tmp/u-synth ...]
        [--real ../shared/data/real-sensors] [--planes] [--by-crease] [--thin] [--min-fraction F]
        [--creases] [--json OUT]
        [--figure PNG] [--bootstrap N] [--leave-one-out] [--frames N] [--surface R] [--speed]

``--bootstrap N``: each column's frames resampled N times with replacement; per decile bin the
5-95 % range of observed / predicted and the share of resamples in which it passes, and the
share in which every bin passes (how far a column of a few frames reads its objects rather
than the map).

``--leave-one-out``: each column binned again without each of its frames in turn: the bins
that pass per frame left out, and the frames without which every bin passes (a failing decile
that hangs on one frame's objects).

``--frames N``: for each column with a failing bin, the N frames that carry most of the excess
in its failing bins (observed minus predicted, signed as each bin fails), with their share of it
and their own observed / predicted there: where the leave-one-out finds no single frame, which
scenes the miss is made of.

``--surface R``: on the real frames' plane interiors, per quartile of the prediction, the
mean predicted and observed error beside the angle between the reference's normal and the
plane of the same plane's own points within R px (:func:`surface_floor`): the large-scale
shape of the measured surface. Where that angle is as large as the observed error, the
error the plane reference scores is the depth's own deformation, which no estimate of the
depth, and so no map of the estimator's error, removes.

``--speed``: instead, the single-thread time of ``method`` with and without the map on every
real frame and one frame per synthetic variant (median of 7, interleaved per frame), and the
ratio.
"""

from __future__ import annotations

import argparse
import json
import sys
from functools import partial
from pathlib import Path

import numpy as np

import depthnormals as dn

ROOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "real-sensors"
#: A decile bin passes when |observed - predicted| <= REL_TOL predicted, or <= ABS_TOL deg where
#: both are below ABS_BELOW deg.
REL_TOL, ABS_TOL, ABS_BELOW = 0.25, 0.5, 2.0
BINS = 10
#: The columns the calibration targets hold for (every bin passes, Spearman at least this): the
#: issue's "on the real frames" read on the real frames pooled (``real``); each folder
#: (``real/<folder>``, a few frames of one sensor) is read against the same numbers as the
#: stricter reading, its verdict marked "per folder" (docs/benchmarks.md, section 17). Every
#: noise model of the generator is a sensor column; Gaussian since session 33 (docs/benchmarks.md
#: 24: its top decile had read 0.72-0.75 of the map before the clean-jump weighting).
TARGETS = {"synth/gaussian": 0.6, "synth/kinect_v1": 0.6, "synth/kinect_v2": 0.6, "synth/tof": 0.6,
           "synth/realsense_d4xx": 0.6, "real": 0.5, "real/": 0.5}


def target(name: str) -> float | None:
    """The Spearman target of a column (None: no target; a key ending in ``/`` covers every
    column below it)."""
    return next((t for k, t in TARGETS.items() if name == k or (k.endswith("/") and
                                                                 name.startswith(k))), None)


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman's rank correlation (average ranks for ties), numpy only."""
    def ranks(x):
        order = np.argsort(x, kind="stable")
        xs = x[order]
        r = np.empty(x.size)
        r[order] = np.arange(x.size, dtype=np.float64)
        # average the ranks of ties
        _, first, counts = np.unique(xs, return_index=True, return_counts=True)
        if np.any(counts > 1):
            avg = first + (counts - 1) / 2.0
            r[order] = np.repeat(avg, counts)
        return r

    if a.size < 3:
        return float("nan")
    ra, rb = ranks(a), ranks(b)
    ra -= ra.mean()
    rb -= rb.mean()
    den = np.sqrt((ra * ra).sum() * (rb * rb).sum())
    return float((ra * rb).sum() / den) if den > 0 else float("nan")


def passes(pred, obs):
    """Whether a bin of mean prediction ``pred`` and mean observation ``obs`` passes (module
    doc); scalars or arrays of bins alike."""
    diff = np.abs(np.asarray(obs) - pred)
    return (diff <= REL_TOL * pred) | ((pred < ABS_BELOW) & (obs < ABS_BELOW) & (diff <= ABS_TOL))


def reliability(pred: np.ndarray, obs: np.ndarray, bins: int = BINS) -> list[dict]:
    """Pixels binned by deciles of ``pred``: per bin its mean prediction and observation."""
    order = np.argsort(pred, kind="stable")
    out = []
    for part in np.array_split(order, bins):
        if part.size == 0:
            continue
        p, o = float(pred[part].mean()), float(obs[part].mean())
        out.append({"n": int(part.size), "predicted": p, "observed": o,
                    "pass": bool(passes(p, o))})
    return out


class _Frames:
    """Each frame's predictions sorted, with running sums of them and of their observations:
    any selection of the frames (repeats allowed) is binned by deciles of its pooled
    prediction without pooling it (:meth:`bins`)."""

    def __init__(self, pred: list[np.ndarray], obs: list[np.ndarray]) -> None:
        order = [np.argsort(p, kind="stable") for p in pred]
        self.ps = [p[o] for p, o in zip(pred, order, strict=True)]
        self.cp = [np.concatenate(([0.0], np.cumsum(p))) for p in self.ps]
        self.co = [np.concatenate(([0.0], np.cumsum(o[k]))) for o, k in zip(obs, order, strict=True)]

    def edges(self, pick, bins: int = BINS):
        """The inner decile edges of the frames ``pick``' pooled prediction (at its rank
        quantiles, as :func:`reliability` splits), or None with fewer pixels than bins."""
        allp = np.concatenate([self.ps[j] for j in pick])
        n = allp.size
        if n < bins:
            return None
        ranks = [n * k // bins for k in range(1, bins)]
        return np.partition(allp, ranks)[ranks]

    def frame_sums(self, j: int, edges: np.ndarray) -> tuple:
        """Frame ``j``'s summed prediction, summed observation and pixels per bin of
        ``edges``."""
        cut = np.concatenate(([0], np.searchsorted(self.ps[j], edges, side="left"),
                              [self.ps[j].size]))
        return np.diff(self.cp[j][cut]), np.diff(self.co[j][cut]), np.diff(cut)

    def bins(self, pick, bins: int = BINS):
        """``(mean predicted, mean observed, pixels)`` per decile bin of the frames ``pick``
        (repeats allowed), or None with fewer pixels than bins."""
        edges = self.edges(pick, bins)
        if edges is None:
            return None
        sp = np.zeros(bins)
        so = np.zeros(bins)
        cnt = np.zeros(bins)
        for j in pick:
            a, b, c = self.frame_sums(j, edges)
            sp += a
            so += b
            cnt += c
        with np.errstate(invalid="ignore", divide="ignore"):
            return sp / cnt, so / cnt, cnt


def bootstrap_bins(pred: list[np.ndarray], obs: list[np.ndarray], reps: int, seed: int,
                   bins: int = BINS) -> dict:
    """The decile table's spread over the frames: ``reps`` resamples of the frames (with
    replacement, as many as there are), each binned as :func:`reliability` bins (edges at the
    resample's rank quantiles); per bin the 5th and 95th percentiles of observed / predicted
    and the share of resamples it passes in, and the share in which every bin passes. A
    column of a few frames is binned over a few objects: one narrow face or shelf moves a
    decile by half (docs/benchmarks.md section 17)."""
    frames = _Frames(pred, obs)
    rng = np.random.default_rng(seed)
    ratios = np.full((reps, bins), np.nan)
    passed = np.zeros((reps, bins), dtype=bool)
    for i in range(reps):
        got = frames.bins(rng.integers(0, len(pred), len(pred)), bins)
        if got is None:
            continue
        mp, mo, cnt = got
        ratios[i] = mo / mp
        passed[i] = passes(mp, mo) & (cnt > 0)
    return {"reps": reps, "ratio_p5": np.nanpercentile(ratios, 5, axis=0).tolist(),
            "ratio_p95": np.nanpercentile(ratios, 95, axis=0).tolist(),
            "bin_pass_share": passed.mean(axis=0).tolist(),
            "all_pass_share": float(passed.all(axis=1).mean())}


def leave_one_out(pred: list[np.ndarray], obs: list[np.ndarray], names: list[str],
                  bins: int = BINS) -> dict:
    """The decile table without each frame in turn: per frame left out, the bins that pass
    and the ratio observed / predicted of every bin; and the frames without which every bin
    passes (where a column's failing decile hangs on one frame's objects, such as one narrow
    face the depth cannot resolve: docs/benchmarks.md section 17, "Session 21")."""
    frames = _Frames(pred, obs)
    rows = []
    for i, name in enumerate(names):
        got = frames.bins([j for j in range(len(pred)) if j != i], bins)
        if got is None:
            continue
        mp, mo, cnt = got
        ok = passes(mp, mo) & (cnt > 0)
        rows.append({"left_out": name, "bins_passed": int(ok.sum()),
                     "ratios": (mo / mp).tolist()})
    return {"frames": rows,
            "every_bin_passes_without": [r["left_out"] for r in rows if r["bins_passed"] == bins]}


def excess_frames(pred: list[np.ndarray], obs: list[np.ndarray], names: list[str],
                  top: int, bins: int = BINS) -> dict:
    """Which frames carry a column's failing decile bins, where no one frame does alone
    (:func:`leave_one_out`): per frame, the excess it adds to the failing bins (observed minus
    predicted, degree-pixels, signed as each bin fails: under-prediction positive where the
    bin reads high, over-prediction where it reads low), its share of their total and its own
    observed / predicted there; the ``top`` frames of most excess. Empty where every bin
    passes."""
    frames = _Frames(pred, obs)
    edges = frames.edges(range(len(pred)), bins)
    if edges is None:
        return {"bins": [], "frames": []}
    per = np.array([frames.frame_sums(j, edges) for j in range(len(pred))], dtype=np.float64)
    tp, to, cnt = per.sum(axis=0)  # (the pooled table, as _Frames.bins adds it up)
    with np.errstate(invalid="ignore", divide="ignore"):
        mp, mo = tp / cnt, to / cnt
    fail = ~(passes(mp, mo) & (cnt > 0))
    if not fail.any():
        return {"bins": [], "frames": []}
    sign = np.where(mo > mp, 1.0, -1.0)[fail]
    rows = []
    for (sp, so, n), name in zip(per[:, :, fail], names, strict=True):
        rows.append({"frame": name, "excess": float((sign * (so - sp)).sum()),
                     "pixels": int(n.sum()),
                     "ratio": float(so.sum() / sp.sum()) if sp.sum() > 0 else float("nan")})
    total = sum(r["excess"] for r in rows)
    for r in rows:
        r["share"] = r["excess"] / total if total else float("nan")
    rows.sort(key=lambda r: -r["excess"])
    return {"bins": [int(i) + 1 for i in np.nonzero(fail)[0]], "frames": rows[:top]}


#: ``--by-crease``: a crease is a change of the exact normal over ``CREASE_DEG`` between
#: adjacent pixels where the clean depth is continuous (relative step at most ``JUMP_REL``);
#: pixels within ``CREASE_PX`` px (the chessboard distance) of one, or ``JUMP_PX`` of a jump.
CREASE_DEG, CREASE_PX, JUMP_REL, JUMP_PX = 15.0, 8, 0.03, 4


def geometry_labels(clean: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Per pixel of a synthetic view (the clean depth (H, W) and the exact normals (H, W, 3)):
    1 within :data:`JUMP_PX` px of a depth jump (adjacent clean depths a relative step over
    :data:`JUMP_REL` apart, or one of them invalid), else 2 within :data:`CREASE_PX` px of a
    crease (adjacent exact normals over :data:`CREASE_DEG` deg apart, the depth continuous
    between them), else 0 (int8 (H, W))."""
    from depthnormals.evaluate._creases import _reach  # the crease bands' chessboard distance

    z = np.where(np.isfinite(clean) & (clean > 0), clean, np.nan).astype(np.float64)
    g = np.asarray(normals, dtype=np.float64)
    jump = np.zeros(z.shape, dtype=bool)
    crease = np.zeros(z.shape, dtype=bool)
    cos = np.cos(np.radians(CREASE_DEG))
    for a, b, za, zb, sl, sr in ((g[:, 1:], g[:, :-1], z[:, 1:], z[:, :-1],
                                  (slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                                 (g[1:], g[:-1], z[1:], z[:-1],
                                  (slice(1, None), slice(None)), (slice(None, -1), slice(None)))):
        with np.errstate(invalid="ignore"):
            step = ~(np.abs(za - zb) <= JUMP_REL * np.fmin(za, zb))  # NaN: a jump
            bend = ~step & ~((a * b).sum(-1) >= cos)
        for side in (sl, sr):  # both pixels of the pair
            jump[side] |= step
            crease[side] |= bend
    out = np.where(_reach(crease, CREASE_PX) <= CREASE_PX, 2, 0).astype(np.int8)
    out[_reach(jump, JUMP_PX) <= JUMP_PX] = 1
    return out


#: ``--thin``: a pixel whose exact normal is over ``THIN_DEG`` from the exact normals ``k`` px
#: before and ``k`` px after it along a row or a column, for a ``k`` of ``THIN_SPANS``, lies on
#: a face at most ``2 max(THIN_SPANS) - 1`` px across; the pixels within ``THIN_PX`` px of one
#: (the chessboard distance) make the column's thin part.
THIN_DEG, THIN_SPANS, THIN_PX = 30.0, (2, 3), 3


def thin_labels(normals: np.ndarray) -> np.ndarray:
    """Per pixel of a synthetic view (its exact normals (H, W, 3), NaN where no surface): True
    within :data:`THIN_PX` px of a pixel on a face narrower than about 5 px (its normal over
    :data:`THIN_DEG` deg from the normals :data:`THIN_SPANS` px away on both sides along a row
    or a column; no surface there counts as another face, the image's border as none) (bool
    (H, W))."""
    from depthnormals.evaluate._creases import _reach  # the crease bands' chessboard distance

    g = np.asarray(normals, dtype=np.float64)
    h, w = g.shape[:2]
    cos = np.cos(np.radians(THIN_DEG))
    thin = np.zeros((h, w), dtype=bool)
    for k in THIN_SPANS:
        for axis in (0, 1):
            n = g.shape[axis]
            if n <= 2 * k:
                continue
            a = np.take(g, range(k, n), axis=axis)  # the pixel, k after the first
            b = np.take(g, range(n - k), axis=axis)  # the pixel k before it
            with np.errstate(invalid="ignore"):
                other = ~((a * b).sum(-1) >= cos)  # NaN: no surface, another face
            before = np.zeros((h, w), dtype=bool)
            after = np.zeros((h, w), dtype=bool)
            if axis == 0:
                before[k:] = other
                after[:-k] = other
            else:
                before[:, k:] = other
                after[:, :-k] = other
            thin |= before & after
    thin &= np.isfinite(g).all(-1)
    return _reach(thin, THIN_PX) <= THIN_PX


#: Distance bins (px from the crease line) of the crease-band profile (``--creases``).
BAND_EDGES = (0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0 + 1e-9)


class BandProfile:
    """Per distance bin from the crease line: pixels, summed observed and predicted error and
    the pixels observed over 45 deg (the other face, in effect)."""

    def __init__(self) -> None:
        self.sums = np.zeros((len(BAND_EDGES) - 1, 4))

    def add(self, unc: np.ndarray, err: np.ndarray, distance: np.ndarray) -> None:
        ok = np.isfinite(unc) & np.isfinite(err) & np.isfinite(distance)
        k = np.searchsorted(BAND_EDGES, distance[ok], side="right") - 1
        e, u = err[ok].astype(np.float64), unc[ok].astype(np.float64)
        for col, w in enumerate((np.ones_like(e), e, u, (e > 45.0).astype(np.float64))):
            self.sums[:, col] += np.bincount(k, weights=w, minlength=len(BAND_EDGES) - 1)[:len(self.sums)]

    def rows(self) -> list[dict]:
        out = []
        for i, (n, o, p, wrong) in enumerate(self.sums):
            lo, hi = BAND_EDGES[i], min(BAND_EDGES[i + 1], 10.0)
            out.append({"from_px": lo, "to_px": hi, "pixels": int(n),
                        "observed": o / n if n else float("nan"),
                        "predicted": p / n if n else float("nan"),
                        "over_45": wrong / n if n else float("nan")})
        return out


#: ``--planes``: a normal over ``WRONG_DEG`` from another took the other face, in effect; an
#: estimate within ``SAME_DEG`` of a reference that did took the same one.
WRONG_DEG, SAME_DEG = 30.0, 10.0


class ReferenceAgreement:
    """Per part of a plane reference (interiors, rims): pixels, and those whose reference is
    over :data:`WRONG_DEG` deg from the exact normal, whose estimate is over it from the exact
    normal and from the reference, and whose estimate and reference are off the same way."""

    PARTS = ("interior", "rim")

    def __init__(self) -> None:
        self.counts = np.zeros((len(self.PARTS), 5), dtype=np.int64)

    def add(self, err_exact: np.ndarray, err_ref: np.ndarray, ref_exact: np.ndarray,
            parts: tuple[np.ndarray, np.ndarray]) -> None:
        ok = np.isfinite(err_exact) & np.isfinite(err_ref) & np.isfinite(ref_exact)
        ref_off = ref_exact > WRONG_DEG
        for i, part in enumerate(parts):
            m = ok & part
            self.counts[i] += (int(m.sum()), int((m & ref_off).sum()),
                               int((m & (err_exact > WRONG_DEG)).sum()),
                               int((m & (err_ref > WRONG_DEG)).sum()),
                               int((m & ref_off & (err_ref <= SAME_DEG)).sum()))

    def rows(self) -> dict:
        out = {}
        for part, (n, *k) in zip(self.PARTS, self.counts.tolist(), strict=True):
            share = [x / n if n else float("nan") for x in k]
            out[part] = {"pixels": n, "reference_off": share[0], "estimate_off_exact": share[1],
                         "estimate_off_reference": share[2], "off_the_same_way": share[3]}
        return out


class Column:
    """The (prediction, observation) pairs of one column."""

    def __init__(self) -> None:
        self.pred: list[np.ndarray] = []
        self.obs: list[np.ndarray] = []
        self.names: list[str] = []

    def add(self, unc: np.ndarray, err: np.ndarray, mask: np.ndarray | None = None,
            name: str | None = None) -> None:
        ok = np.isfinite(unc) & np.isfinite(err)
        if mask is not None:
            ok &= mask
        self.pred.append(unc[ok].astype(np.float64))
        self.obs.append(err[ok].astype(np.float64))
        self.names.append(name if name is not None else f"frame {len(self.names)}")

    def summary(self, bootstrap: int = 0, seed: int = 0, loo: bool = False,
                excess: int = 0) -> dict:
        p = np.concatenate(self.pred) if self.pred else np.empty(0)
        o = np.concatenate(self.obs) if self.obs else np.empty(0)
        table = reliability(p, o) if p.size >= BINS else []
        out = {"pixels": int(p.size), "frames": len(self.pred), "spearman": spearman(p, o),
               "mean_predicted": float(p.mean()) if p.size else float("nan"),
               "mean_observed": float(o.mean()) if o.size else float("nan"),
               "bins_passed": sum(b["pass"] for b in table), "bins": table}
        if bootstrap and table and len(self.pred) > 1:
            out["bootstrap"] = bootstrap_bins(self.pred, self.obs, bootstrap, seed)
        if loo and table and len(self.pred) > 1:
            out["leave_one_out"] = leave_one_out(self.pred, self.obs, self.names)
        if excess and table and out["bins_passed"] < len(table):
            out["excess_frames"] = excess_frames(self.pred, self.obs, self.names, excess)
        return out


def analytic_columns(method: str, noise: float, seed: int) -> dict[str, Column]:
    from depthnormals.analytic import make_scene, scene_names

    col = Column()
    rng = np.random.default_rng(seed)
    for name in scene_names():
        r = make_scene(name).render()
        fx = dn.as_intrinsics(r.K).fx
        d = r.depth * (1.0 + noise * rng.standard_normal(r.depth.shape) / fx)
        n, u = dn.estimate_normals(d.astype(np.float32), r.K, method=method, return_uncertainty=True)
        col.add(u, dn.angular_error(n, r.normals))
    return {"analytic": col}


def synth_columns(root: Path | list[Path], method: str, planes: bool = False, seed: int = 0,
                  profiles: dict[str, BandProfile] | None = None,
                  by_crease: bool = False, thin: bool = False,
                  agreement: dict[str, ReferenceAgreement] | None = None) -> dict[str, Column]:
    """One column per sensor model of the synthetic folder ``root`` (several: their frames
    pooled, each named by its folder); with ``planes`` also
    its pixels on and off the plane reference of the noisy depth (module doc); with
    ``profiles`` (a dict), the crease-band profile of each noisy model, the band found on the
    noisy depth's plane reference and scored against the exact normals; with ``by_crease``,
    its pixels by a crease, by a jump and the rest (:func:`geometry_labels` on the view's
    clean depth, which a set holds before its noisy variants; a view without one raises); with
    ``thin``, its pixels by a face narrower than about 5 px and the others (:func:`thin_labels`
    on the exact normals); with ``planes`` and ``agreement`` (a dict), the plane reference
    against the exact normals and the estimate per noisy model (:class:`ReferenceAgreement`)."""
    from depthnormals.datasets.synthetic import read_synthetic
    from depthnormals.evaluate import crease_band, plane_reference, sensor_threshold

    roots = [root] if isinstance(root, Path) else list(root)
    cols: dict[str, Column] = {}
    labels: tuple = (None, None)  # the view (folder, scene, name) and its geometry_labels
    for folder, f in ((r, f) for r in roots for f in read_synthetic(r)):
        variant = f.meta.get("variant", f.group.rsplit("/", 1)[-1])
        view = (folder, f.group.rsplit("/", 1)[0], f.name)
        if by_crease and variant == "clean":
            labels = (view, geometry_labels(f.depth, f.normals))
        n, u = dn.estimate_normals(f.depth, f.K, method=method, return_uncertainty=True)
        err = dn.angular_error(n, f.normals)
        name = f"{f.group}/{f.name}" if len(roots) == 1 else f"{folder.name}/{f.group}/{f.name}"
        cols.setdefault(f"synth/{variant}", Column()).add(u, err, f.mask, name=name)
        valid = np.ones(u.shape, dtype=bool) if f.mask is None else f.mask
        if (planes or profiles is not None) and variant != "clean":
            ref = plane_reference(f.depth, f.K, seed=seed, threshold=sensor_threshold({}))
        if profiles is not None and variant != "clean":
            band = crease_band(f.depth, f.K, ref)
            profiles.setdefault(f"synth/{variant}", BandProfile()).add(
                u, err, np.where(band.mask & valid, band.distance, np.nan))
        if planes and variant != "clean":
            on = ref.interior | ref.rim
            cols.setdefault(f"synth-planes/{variant}", Column()).add(u, err, valid & on)
            cols.setdefault(f"synth-off/{variant}", Column()).add(u, err, valid & ~on)
            g = ref.normal_map().astype(np.float32)
            err_ref = dn.angular_error(n, g)
            cols.setdefault(f"synth-asreal/{variant}", Column()).add(u, err_ref, valid & on,
                                                                     name=name)
            if agreement is not None:
                agreement.setdefault(f"synth/{variant}", ReferenceAgreement()).add(
                    err, err_ref, dn.angular_error(g, f.normals),
                    (valid & ref.interior, valid & ref.rim))
        if by_crease and variant != "clean":
            if labels[0] != view:
                raise ValueError(f"--by-crease: {folder}/{f.group}/{f.name} has no clean "
                                 "variant before it (the exact geometry's depth)")
            for kind, code in (("synth-crease", 2), ("synth-jump", 1), ("synth-rest", 0)):
                cols.setdefault(f"{kind}/{variant}", Column()).add(
                    u, err, valid & (labels[1] == code), name=name)
        if thin and variant != "clean":
            near = thin_labels(f.normals)
            for kind, part in (("synth-thin", near), ("synth-resolved", ~near)):
                cols.setdefault(f"{kind}/{variant}", Column()).add(u, err, valid & part,
                                                                   name=name)
    return cols


def surface_floor(depth: np.ndarray, K: np.ndarray, ref, radius: int) -> np.ndarray:
    """``--surface``: per pixel of a plane's interior, the angle (deg) between the reference's
    normal and the total-least-squares plane of that plane's own points within ``radius`` px
    (a (2 radius + 1)^2 window, at least half of it the plane's): the large-scale shape of the
    measured surface, whose random error over thousands of points is negligible. Where it
    reads as much as the estimate errs, the error the plane reference scores is the depth's
    own deformation (the sensor's systematic error), which no estimator of the depth can
    remove. NaN elsewhere."""
    import cv2

    from depthnormals.camera import backproject

    X = backproject(depth, K)
    Xz = np.nan_to_num(X)
    g = ref.normal_map().astype(np.float64)
    k = (2 * radius + 1, 2 * radius + 1)

    def box(a):
        return cv2.boxFilter(a, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)

    out = np.full(depth.shape, np.nan)
    for label in np.unique(ref.labels[ref.labels >= 0]):
        v = ((ref.labels == label) & np.isfinite(X[..., 2])).astype(np.float64)
        cnt = box(v)
        m = ref.interior & (ref.labels == label) & (cnt > 0.5 * k[0] * k[1])
        if not m.any():
            continue
        idx = np.nonzero(m)
        c = cnt[idx]
        mu = np.stack([box(Xz[..., i] * v)[idx] / c for i in range(3)], -1)
        cov = np.empty((c.size, 3, 3))
        for i in range(3):
            for j in range(i, 3):
                cov[:, i, j] = cov[:, j, i] = (box(Xz[..., i] * Xz[..., j] * v)[idx] / c
                                               - mu[:, i] * mu[:, j])
        n = np.linalg.eigh(cov)[1][:, :, 0]
        cos = np.abs(np.einsum("ij,ij->i", n, g[idx]))
        out[idx] = np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))
    return out


def real_columns(root: Path, method: str, seed: int, min_fraction: float | None = None,
                 creases: bool = False, profiles: dict[str, BandProfile] | None = None,
                 surface: int = 0, floors: dict[str, list] | None = None) -> dict[str, Column]:
    """The real frames' columns (pooled and per folder), scored on their plane references;
    with ``surface`` (a radius) and ``floors`` (a dict), also each column's interior pixels'
    prediction, observation and :func:`surface_floor`, into ``floors[column]``."""
    from depthnormals.datasets import open as open_dataset
    from depthnormals.evaluate import crease_band, plane_reference, sensor_threshold

    cols: dict[str, Column] = {"real": Column()}
    if creases:
        cols["real+creases"] = Column()
    more = {} if min_fraction is None else {"min_fraction": min_fraction}
    for f in open_dataset(root):
        ref = plane_reference(f.depth, f.K, seed=seed, threshold=sensor_threshold(f.meta),
                              **more)
        n, u = dn.estimate_normals(f.depth, f.K, method=method, return_uncertainty=True)
        g = ref.normal_map()
        err = dn.angular_error(n, g.astype(np.float32))
        mask = ref.interior | ref.rim
        group = str(f.group).split("/")[0]
        name = f"{f.group}/{f.name}"
        cols.setdefault(f"real/{group}", Column()).add(u, err, mask, name=name)
        cols["real"].add(u, err, mask, name=name)
        if surface and floors is not None:
            fl = surface_floor(f.depth, f.K, ref, surface)
            ok = np.isfinite(fl) & np.isfinite(u) & np.isfinite(err)
            for key in (f"real/{group}", "real"):
                floors.setdefault(key, []).append((u[ok], err[ok], fl[ok]))
        if creases:
            band = crease_band(f.depth, f.K, ref)
            g[band.mask] = band.normals[band.mask]
            err = dn.angular_error(n, g.astype(np.float32))
            mask = mask | band.mask
            cols.setdefault(f"real+creases/{group}", Column()).add(u, err, mask)
            cols["real+creases"].add(u, err, mask)
            if profiles is not None:
                profiles.setdefault("real", BandProfile()).add(u, err, band.distance)
    return cols


def speed(method: str, synth: Path | None, real: str, repeats: int = 25) -> None:
    """Print the time of ``method`` with and without ``return_uncertainty`` per frame: the
    least of ``repeats`` interleaved runs (the run least disturbed on a shared machine) and
    the ratio of the medians."""
    import time

    from depthnormals.datasets import open as open_dataset
    from depthnormals.datasets.synthetic import read_synthetic

    dn.set_num_threads(1)
    frames = []
    if real:
        frames += [(f"real/{f.group}", f.depth, f.K) for f in open_dataset(real)]
    seen: set = set()
    for f in read_synthetic(synth) if synth is not None else ():
        v = f.group.rsplit("/", 1)[-1]
        if v not in seen:
            seen.add(v)
            frames.append((f"synth/{v}", f.depth, f.K))
    total = [0.0, 0.0]
    vga: list[float] = []  # the ratios of the 640x480 frames (the size)
    for name, d, K in frames:
        fns = (partial(dn.estimate_normals, d, K, method=method),
               partial(dn.estimate_normals, d, K, method=method, return_uncertainty=True))
        ts: list[list[float]] = [[], []]
        for fn in fns:
            fn()
        for _ in range(repeats):
            for j, fn in enumerate(fns):
                t = time.perf_counter()
                fn()
                ts[j].append(time.perf_counter() - t)
        a, b = (float(np.min(t)) for t in ts)
        ma, mb = (float(np.median(t)) for t in ts)
        total[0] += a
        total[1] += b
        if d.shape == (480, 640):
            vga.append(b / a)
        print(f"{name:42s} {d.shape[1]}x{d.shape[0]}  {a * 1e3:7.2f} ms  with the map "
              f"{b * 1e3:7.2f} ms  x{b / a:.2f} (medians x{mb / ma:.2f})")
    if frames:
        print(f"all frames: x{total[1] / total[0]:.2f}")
    if vga:
        print(f"640x480 frames: x{min(vga):.2f}-x{max(vga):.2f} (median x{np.median(vga):.2f}, "
              f"{sum(round(r, 2) <= 1.3 for r in vga)} of {len(vga)} at or under x1.30)")


SYNTH_KINDS = ("synth", "synth-planes", "synth-off", "synth-asreal", "synth-crease", "synth-jump",
               "synth-rest", "synth-thin", "synth-resolved")


def _order(name: str) -> tuple:
    """Columns in print order: analytic, then per sensor model all, on and off planes, by a
    crease, by a jump and the rest, by a thin face and the rest (:data:`SYNTH_KINDS`)."""
    kind, _, variant = name.partition("/")
    return (kind != "analytic", variant, SYNTH_KINDS.index(kind) if kind.startswith("synth")
            else 0)


def _print(name: str, s: dict) -> None:
    print(f"\n{name}: {s['pixels']} px, Spearman {s['spearman']:.3f}, mean predicted "
          f"{s['mean_predicted']:.3f} deg, observed {s['mean_observed']:.3f} deg, "
          f"bins passed {s['bins_passed']}/{len(s['bins'])}")
    bs = s.get("bootstrap")
    print("  bin  predicted  observed  ratio  pass" + (
        f"  ratio 5-95 % ({bs['reps']} resamples of {s['frames']} frames), passes" if bs else ""))
    for i, b in enumerate(s["bins"]):
        ratio = b["observed"] / b["predicted"] if b["predicted"] > 0 else float("nan")
        more = (f"  {bs['ratio_p5'][i]:5.2f}-{bs['ratio_p95'][i]:5.2f}  "
                f"{100 * bs['bin_pass_share'][i]:3.0f} %" if bs else "")
        print(f"  {i + 1:3d}  {b['predicted']:9.3f}  {b['observed']:8.3f}  {ratio:5.2f}  "
              f"{'yes' if b['pass'] else 'NO ':3s}{more}")
    if bs:
        print(f"  every bin passes in {100 * bs['all_pass_share']:.0f} % of the resamples")
    lo = s.get("leave_one_out")
    if lo and lo["frames"]:
        got = [r["bins_passed"] for r in lo["frames"]]
        without = lo["every_bin_passes_without"]
        more = ""
        if s["bins_passed"] < len(s["bins"]):  # which frames the failing bins hang on
            more = "; every bin passes without " + (", ".join(without) if without
                                                     else "none of them alone")
        print(f"  leaving one of {s['frames']} frames out: {min(got)}-{max(got)} bins pass{more}")
    ex = s.get("excess_frames")
    if ex and ex["frames"]:
        print(f"  the frames that carry failing bin{'s' if len(ex['bins']) > 1 else ''} "
              f"{', '.join(map(str, ex['bins']))} (share of their excess, observed / predicted "
              "there, pixels):")
        for r in ex["frames"]:
            print(f"    {r['frame']:48s} {100 * r['share']:5.1f} %  {r['ratio']:5.2f}  {r['pixels']}")


def _figure(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [k for k, v in results.items()
             if v["bins"] and not k.startswith(("synth-planes/", "synth-off/", "synth-asreal/"))]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5))
    top = 0.0
    for k in names:
        p = [b["predicted"] for b in results[k]["bins"]]
        o = [b["observed"] for b in results[k]["bins"]]
        ax.loglog(p, o, "o-", ms=3, label=k)
        top = max(top, max(p), max(o))
    lo = 1e-3
    ax.plot([lo, top], [lo, top], "k--", lw=0.8)
    ax.set_xlabel("mean predicted error per decile (deg)")
    ax.set_ylabel("mean observed error (deg)")
    ax.set_title("reliability")
    ax.legend(fontsize=7)
    bx.barh(names, [results[k]["spearman"] for k in names])
    bx.axvline(0.6, color="k", ls="--", lw=0.8)
    bx.axvline(0.5, color="grey", ls=":", lw=0.8)
    bx.set_xlabel("Spearman rank correlation")
    fig.tight_layout()
    from depthnormals.io import atomic_write

    with atomic_write(path) as fh:
        fig.savefig(fh, dpi=120, format="png")
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="3f2n+")
    ap.add_argument("--noise", type=float, default=0.1, help="analytic scenes' noise (footprints)")
    ap.add_argument("--synth", type=Path, nargs="+", default=None,
                    help="synthetic benchmark folder (several: one column per sensor model over "
                         "all their frames)")
    ap.add_argument("--real", default=str(ROOT), help="real-sensor folder ('' to skip)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--figure", type=Path, default=None)
    ap.add_argument("--speed", action="store_true", help="time with and without the map instead")
    ap.add_argument("--planes", action="store_true",
                    help="also score the synthetic columns on and off their plane reference, and on it "
                         "against the reference's normals as the real frames are scored")
    ap.add_argument("--by-crease", action="store_true",
                    help="also score each synthetic column's pixels by a crease, by a jump and "
                         "the rest (the exact geometry of the view)")
    ap.add_argument("--thin", action="store_true",
                    help="also score each synthetic column's pixels within 3 px of a face "
                         "narrower than about 5 px and the others (the exact normals)")
    ap.add_argument("--min-fraction", type=float, default=None,
                    help="the real plane references' smallest plane, a share of the image "
                         "(plane_reference's default 0.01; smaller: faces the default leaves out)")
    ap.add_argument("--creases", action="store_true",
                    help="also score the real frames with the bands by their planes' creases "
                         "(crease_band: the face each pixel sees, by geometry)")
    ap.add_argument("--bootstrap", type=int, default=0, metavar="N",
                    help="also resample each column's frames N times (with replacement): the "
                         "decile ratios' 5-95 %% range and how often each bin passes")
    ap.add_argument("--leave-one-out", action="store_true",
                    help="also bin each column without each of its frames in turn: which frame "
                         "a failing decile hangs on")
    ap.add_argument("--surface", type=int, default=0, metavar="R",
                    help="also print, per quartile of the prediction on the real frames' "
                         "interiors, how far the plane of each plane's own points within R px "
                         "lies from its reference (surface_floor: the depth's own deformation)")
    ap.add_argument("--frames", type=int, default=0, metavar="N",
                    help="for each column with a failing bin, the N frames that carry most of "
                         "its excess there")
    a = ap.parse_args(argv)
    if a.real and not Path(a.real).is_dir():  # never a silently shorter table
        ap.error(f"--real {a.real}: no such folder (pass --real '' to leave the real frames out)")
    for d in a.synth or ():
        if not d.is_dir():
            ap.error(f"--synth {d}: no such folder")
    if a.min_fraction is not None and not 1e-6 <= a.min_fraction <= 1.0:  # before any column
        ap.error(f"--min-fraction {a.min_fraction}: must be in [1e-06, 1] (plane_reference's "
                 "min_fraction, a share of the image)")
    if not 0 <= a.bootstrap <= 100_000:
        ap.error(f"--bootstrap {a.bootstrap}: must be in [0, 100000] (0: no resampling)")
    if a.frames < 0:
        ap.error(f"--frames {a.frames}: must be >= 0 (0: none listed)")
    if a.speed:
        speed(a.method, a.synth[0] if a.synth else None, a.real)
        return 0
    cols = analytic_columns(a.method, a.noise, a.seed)
    profiles: dict[str, BandProfile] | None = {} if a.creases else None
    agreement: dict[str, ReferenceAgreement] = {}
    if a.synth is not None:
        cols.update(synth_columns(a.synth, a.method, a.planes, a.seed, profiles, a.by_crease,
                                  a.thin, agreement))
        cols = dict(sorted(cols.items(), key=lambda kv: _order(kv[0])))
    floors: dict[str, list] = {}
    if a.real:
        cols.update(real_columns(Path(a.real), a.method, a.seed, a.min_fraction, a.creases,
                                 profiles, a.surface, floors))
    results = {k: c.summary(a.bootstrap, a.seed, a.leave_one_out, a.frames)
               for k, c in cols.items()}
    for k, s in results.items():
        _print(k, s)
    bands = {k: p.rows() for k, p in (profiles or {}).items()}
    if bands:
        print("\ncrease bands by distance from the line (px): pixels, observed / predicted deg, "
              "share observed over 45 deg")
        for k, rows in bands.items():
            print(f"  {k:24s} " + "  ".join(
                f"{r['from_px']:g}-{r['to_px']:g}: {r['pixels']} {r['observed']:.1f}/"
                f"{r['predicted']:.1f} {100 * r['over_45']:.0f}%" for r in rows))
    refs = {k: r.rows() for k, r in agreement.items()}
    if refs:
        print(f"\nplane references of the noisy depth (--planes): pixels, share whose reference is "
              f"over {WRONG_DEG:g} deg from the exact normal, whose estimate is over it from the "
              f"exact normal / from the reference, and whose estimate lies within {SAME_DEG:g} "
              "deg of a reference that is (off the same way)")
        for k, parts in refs.items():
            print(f"  {k:24s} " + "  ".join(
                f"{part}: {r['pixels']} {100 * r['reference_off']:.2f}% "
                f"{100 * r['estimate_off_exact']:.2f}% / {100 * r['estimate_off_reference']:.2f}% "
                f"same {100 * r['off_the_same_way']:.2f}%" for part, r in parts.items()))
    if floors:
        print(f"\nthe depth's own deformation (--surface {a.surface}): per quartile of the "
              "prediction on the plane interiors, mean predicted / observed / the angle of the "
              f"{2 * a.surface + 1}-px own-plane fit to the reference (deg), pixels")
        for k, parts in floors.items():
            u, o, fl = (np.concatenate(x) for x in zip(*parts, strict=True))
            q = np.quantile(u, [0.0, 0.25, 0.5, 0.75, 1.0])
            cells = []
            for i in range(4):
                b = (u >= q[i]) & (u <= q[i + 1])
                cells.append(f"{u[b].mean():.2f} / {o[b].mean():.2f} / {fl[b].mean():.2f}")
            print(f"  {k:32s} " + "   ".join(cells) + f"   ({u.size} px)")
    print("\nsummary: column, Spearman, bins passed, target (every bin; Spearman)")
    for k, s in results.items():
        t = target(k)
        why = ([f"bins {s['bins_passed']}/{len(s['bins'])}"]
               if s["bins_passed"] < len(s["bins"]) else [])
        why += [f"Spearman < {t}"] if t is not None and not s["spearman"] >= t else []
        stricter = " per folder" if k.startswith("real/") else ""
        verdict = "" if t is None else (f"  pass{stricter}" if not why else
                                        f"  FAIL{stricter}: {', '.join(why)}")
        print(f"  {k:40s} {s['spearman']:6.3f}  {s['bins_passed']}/{len(s['bins'])}{verdict}")
    if a.json is not None:
        from depthnormals.io import write_bytes_atomic

        write_bytes_atomic(a.json, json.dumps({"method": a.method, "noise": a.noise,
                                               "seed": a.seed,
                                               "synth": [str(d) for d in a.synth or ()],
                                               "real": str(a.real), "columns": results,
                                               "crease_profiles": bands,
                                               "plane_references": refs},
                                              indent=1).encode())
    if a.figure is not None:
        _figure(results, a.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
