"""The support of the noisy branch, measured on the depth itself (ours, not the paper's).

The box-fit (:mod:`depthnormals.ddm.boxfit`) fits least-squares planes of inverse depth over
square windows. How large a window must be depends on the noise, and real sensor noise is not
the independent per-pixel noise of the synthetic models: structured light correlates it over
its matching window, lens blur and multipath over a few pixels, and disparity quantisation
makes it a staircase. A window radius predicted from a per-pixel noise level is then far too
small (docs/3f2n-plus.md, "The noise model of real sensors").

So the radius is chosen from a measurement of what it is for, the error of the fitted normal:

1. For each candidate radius ``r`` in :data:`RADII`, windows of ``(2 r + 1)^2`` pixels are
   fitted on a grid of about :data:`SAMPLES` sample pixels (spacing at least
   ``2 (2 r + 1)``; windows from :data:`SPARSE_RADIUS` on read on every second row and
   column), each beside its right and
   lower neighbour window (adjacent, not overlapping). On one plane the two fits differ only
   by their errors: for independent isotropic errors, the mean angular error of one fit is
   ``0.753`` times the median angle between the two (:data:`PAIR_TO_ERROR`, Rayleigh
   statistics). Pairs straddling an edge or a crease are left out: only pairs whose larger
   residual variance is at most the median of all pairs count.
2. The measured error is never taken below the error that the depth's noise level predicts
   for a plane of independent noise (``sigma / sqrt(S_uu)`` radians per axis,
   :func:`predicted_error`): on quantised depth two small windows inside one plateau agree
   exactly and would read as noise-free.
3. The radius is the smallest whose error is at most :data:`TARGET_ERROR` degrees, or the one
   of least error when none reaches it.

The branch then runs the box-fit with that radius: the centred window where its residual
variance is within ``GATE`` times the measured plane residual at that radius, a larger
centred window (:data:`BIG_FACTOR` ``r``, fitted on every second row and column, a pixel
reading the nearest such window) first where it passes the same test, otherwise the window
of least residual among the nine that contain the pixel (one-sided at edges). The gates grow
with depth as the measured plane residual does (:func:`depth_exponent`). All of it runs over
running sums: the cost does not depend on the radius.

Last (session 16), a face narrower than the windows (a table's front edge, a kerb's riser, a
pole) loses every window: each holds more of the face beside it, and the least residual of
the nine is a window on that face, whose normal the narrow face then takes (up to 90 deg
off). Its depth shows it: a pixel whose depth lies more than :data:`DEVIATION` standard
deviations of the measured plane residual off the plane of the window it chose
(:func:`_deviation`) takes the least residual of the nine windows of
:data:`FALLBACK_RADIUS` that hold it instead (:func:`_fallback_rows`; noisier, but on its own
face). On the synthetic kinect_v1 frames of the calibration benchmark the mean error drops
12-20 %, on the realsense model 1-7 %, on the real frames' plane rims 10.51 -> 9.96 deg (mean
over folders; interiors 3.83 -> 3.76); it costs about 1.3 ms at 640x480 (a radius-2 box-fit
pass and the deviation of every pixel).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numba as nb
import numpy as np

from .._parallel import run_rows
from .boxfit import SHIFTS, box_fit_windows, solve_window
from .faceswitch import SPAN as SWITCH_SPAN
from .faceswitch import switch_faces
from .noise import TILE

__all__ = ["BIG_FACTOR", "EXCESS_FLOOR", "GATE", "LOCAL_KEEP", "LOCAL_MAX_RADIUS", "MAX_RADIUS",
           "PAIR_TO_ERROR", "RADII", "TARGET_ERROR", "SupportProfile", "choice_inputs",
           "choose_pixel", "depth_exponent", "local_excess", "predicted_error",
           "profile_from_pairs", "profiles_from_pair_tables", "sample_every", "sample_step",
           "support_profile", "support_select"]

#: Candidate window radii (windows of 3x3 to 33x33 pixels).
RADII = (1, 2, 3, 4, 6, 8, 11, 16)
#: Largest radius of any window the branch fits (the large centred one included).
MAX_RADIUS = 24
#: Target mean angular error (degrees) of a fitted normal on a plane: the radius is the
#: smallest that reaches it. At 2.5 deg (the i.i.d. rule's former target, 0.035 rad per axis)
#: KITTI's densified LiDAR stopped at radius 3 (2.2 / 6.0 deg interior / rim on its planes);
#: at 1 deg it takes 16 (0.7 / 2.1); on quantised and correlated Kinect depth no radius
#: reaches either, so the least error decides there (docs/3f2n-plus.md).
TARGET_ERROR = 1.0
#: Mean angular error of one fit per unit of the median angle between two independent fits
#: (Rayleigh: mean s sqrt(pi / 2) of one, median s sqrt(2) sqrt(2 ln 2) of the difference).
PAIR_TO_ERROR = math.sqrt(math.pi / 2.0) / (2.0 * math.sqrt(math.log(2.0)))
#: Radii whose predicted error (independent noise) is below this many degrees do not count
#: in :meth:`SupportProfile.excess`.
EXCESS_FLOOR = 1.0
#: A window is kept while its residual variance is within GATE times the median plane
#: residual measured at its radius.
GATE = 2.0
#: The large centred window has radius ``round(BIG_FACTOR r)`` (at most :data:`MAX_RADIUS`).
BIG_FACTOR = 2.0
#: Largest exponent of the residual's growth with depth (Kinect-like noise, ``sigma_z ~ z^2``,
#: gives ``sigma ~ z`` in footprints and a variance ~ ``z^2``).
MAX_EXPONENT = 2.0
#: From this radius on the branch runs on every second row and column (:func:`support_select`).
HALF_RADIUS = 6
#: A pixel whose depth lies more than this many standard deviations of the measured plane
#: residual (at its depth) off the plane of the window it chose takes the least residual of
#: the nine windows of radius :data:`FALLBACK_RADIUS` that hold it instead
#: (:func:`_fallback_rows`): its face is narrower than the windows (a table's edge, a kerb's
#: riser), and the chosen window fitted the face beside it. Five: one pixel in 1.7 million
#: of independent Gaussian noise (the plane residual is measured on the frame, so quantised
#: and correlated depth scale it alike). On the real frames (benchmarks/real_sensors.py) four
#: made SUN RGB-D's rims 1.5 deg worse, five improves every folder's rims; on the synthetic
#: kinect_v1 frames five takes 12-20 % off the mean error, four 14-22 %.
DEVIATION = 5.0
#: Radius of the windows a deviating pixel falls back to, on the grid of the choice (every
#: second row and column from :data:`HALF_RADIUS` on): 5x5 cells.
FALLBACK_RADIUS = 2
#: A sampled window needs this share of valid pixels.
MIN_VALID = 0.6
#: Fewest pairs for a radius to be measured.
MIN_PAIRS = 12
#: Sample windows per radius, about (the grid spacing is at least ``2 (2 r + 1)``): the
#: median angle of ~2 x 100 pairs is known to ~12 %.
SAMPLES = 100
#: From this radius on, a sampled window is fitted on every second row and column (a quarter
#: of its pixels): the measurement then costs about the same for every radius (~0.1 ms at
#: 640x480). Sensor noise correlated over two pixels or more loses nothing by it; on
#: independent noise the error read is up to 2x the full window's, but there the smaller,
#: fully read radii reach the target first.
SPARSE_RADIUS = 6
#: :func:`local_excess` reads the radii from 2 up to this one (windows up to 9x9): larger
#: windows span the scene's own structure (shelves, an auditorium's tiers), which the pairs'
#: angles then read as noise.
LOCAL_MAX_RADIUS = 4
#: :func:`local_excess` keeps the pairs whose residual variance, in units of their tile's
#: noise variance, is within this many times the median one (a pair across an edge or a
#: crease is far beyond; correlated noise reads 1-6 times its second-difference level, and
#: keeping only the better half, as :meth:`SupportProfile.excess` does, drops it where it is
#: strongest).
LOCAL_KEEP = 4.0


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _fit(z, v, u, r, fx, fy, cx, cy, every):
    """Least-squares plane of ``1 / z`` over the window of radius ``r`` centred at (v, u),
    read on every ``every``-th row and column: (residual variance in footprints^2, unit
    normal x, y, z); NaN without a fit."""
    h, w = z.shape
    n = 0.0
    su = 0.0
    sv = 0.0
    suu = 0.0
    suv = 0.0
    svv = 0.0
    sw = 0.0
    suw = 0.0
    svw = 0.0
    sww = 0.0
    for dv in range(-r, r + 1, every):
        a = v + dv
        if a < 0 or a >= h:
            continue
        for du in range(-r, r + 1, every):
            b = u + du
            if b < 0 or b >= w:
                continue
            zz = np.float64(z[a, b])
            if not (zz == zz):
                continue
            x = 1.0 / zz
            n += 1.0
            su += du
            sv += dv
            suu += du * du
            suv += du * dv
            svv += dv * dv
            sw += x
            suw += du * x
            svw += dv * x
            sww += x * x
    nan = np.nan
    if n < MIN_VALID * ((2 * r) // every + 1) ** 2:
        return nan, nan, nan, nan
    pa, pb, c, rss, ok = solve_window(n, su, sv, suu, suv, svv, sw, suw, svw, sww)
    if not ok or not (c > 0.0):
        return nan, nan, nan, nan
    nx = fx * pa
    ny = fy * pb
    nz = c - pa * (u - cx) - pb * (v - cy)
    s = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    return rss * fx * fx / ((n - 3.0) * c * c), nx * s, ny * s, nz * s


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _pairs(z, r, fx, fy, cx, cy, step, every, out):
    """Adjacent-window pairs of radius ``r`` on a grid of spacing ``step``: each row of
    ``out`` gets (angle between the two normals in degrees, the larger residual variance,
    the depth at the first window's centre, the index of the noise pass's tile holding that
    centre, rows of tiles first); returns the number of rows written."""
    h, w = z.shape
    tw = (w + TILE - 1) // TILE
    d = 2 * r + 1
    k = 0
    for v in range(r, h - r, step):
        for u in range(r, w - r, step):
            if not (z[v, u] == z[v, u]):
                continue
            s0, x0, y0, t0 = _fit(z, v, u, r, fx, fy, cx, cy, every)
            if not (s0 == s0):
                continue
            for o in range(2):
                vv = v + d * o
                uu = u + d * (1 - o)
                if vv >= h - r or uu >= w - r or k >= out.shape[0]:
                    continue
                s1, x1, y1, t1 = _fit(z, vv, uu, r, fx, fy, cx, cy, every)
                if not (s1 == s1):
                    continue
                dot = min(1.0, max(-1.0, x0 * x1 + y0 * y1 + t0 * t1))
                out[k, 0] = math.degrees(math.acos(dot))
                out[k, 1] = max(s0, s1)
                out[k, 2] = z[v, u]
                out[k, 3] = (v // TILE) * tw + u // TILE
                k += 1
    return k


def predicted_error(sigma: float, r: int, every: int = 1) -> float:
    """Mean angular error (degrees) of a plane fitted over a full ``(2 r + 1)^2`` window of
    independent noise ``sigma`` (footprints), read on every ``every``-th row and column,
    fronto-parallel: per-axis standard deviation ``sigma / sqrt(S_uu)`` radians
    (``S_uu = sum du^2`` over the window's pixels), times ``sqrt(pi / 2)``."""
    if not sigma > 0.0:
        return 0.0
    return math.degrees(math.sqrt(math.pi / 2.0) * sigma / math.sqrt(_window_suu(r, every)))


@functools.cache
def _window_suu(r: int, every: int) -> float:
    """``S_uu = sum du^2`` over a full ``(2 r + 1)^2`` window read on every ``every``-th row
    and column."""
    offsets = np.arange(-r, r + 1, every, dtype=np.float64)
    return offsets.size * float(np.sum(offsets * offsets))


@dataclass(frozen=True)
class SupportProfile:
    """What :func:`support_profile` measured: per candidate radius (:data:`RADII`, those
    measured), the mean angular error of a fitted normal (``error``, degrees, the larger of
    the measured and the predicted one) and the median plane residual variance
    (``residual``, footprints^2); the chosen ``radius``; how the plane residual grows with
    depth at that radius, ``residual ~ (z / depth) ** exponent`` (:func:`depth_exponent`);
    ``local``, the excess read pair by pair against the noise level of each pair's own tile
    (:func:`local_excess`; NaN where the tiles' levels were not given or too few pairs
    count)."""

    radii: tuple[int, ...]
    error: tuple[float, ...]
    residual: tuple[float, ...]
    radius: int
    depth: float = float("nan")
    exponent: float = 0.0
    measured: tuple[float, ...] = ()
    predicted: tuple[float, ...] = ()
    local: float = float("nan")

    def excess(self) -> float:
        """How far the measured fit errors exceed those the noise level predicts for
        independent noise: the largest ratio over the measured radii from 2 on whose
        predicted error is at least :data:`EXCESS_FLOOR` degrees (below it the scene's own
        curvature and clutter, not the noise, make the measured error); 1 where there is
        none. At most 1.1 for independent noise, 1.3-1.9 for the 0.5 px blur of the ``tof``
        model, 2.4-4 on the correlated sensor frames of ``shared/data/real-sensors``
        (docs/3f2n-plus.md)."""
        ratios = [m / p for r, m, p in zip(self.radii, self.measured, self.predicted, strict=True)
                  if r >= 2 and p >= EXCESS_FLOOR]
        return max(ratios) if ratios else 1.0

    def residual_at(self, r: int) -> float:
        """The median plane residual variance at a measured radius (the nearest one)."""
        i = min(range(len(self.radii)), key=lambda j: abs(self.radii[j] - r))
        return self.residual[i]


def depth_exponent(res: np.ndarray, z: np.ndarray) -> tuple[float, float]:
    """How plane residual variances ``res`` grow with the depth ``z`` of their windows:
    ``(z_ref, exponent)`` with ``res ~ (z / z_ref) ** exponent``, from the medians of the
    nearer and the farther half (``z_ref`` the median depth), clipped to
    ``[0, MAX_EXPONENT]``; exponent 0 where the two halves are too close in depth."""
    zm = float(np.median(z))
    near = z <= zm
    if near.all() or not near.any():
        return zm, 0.0
    zn, zf = float(np.median(z[near])), float(np.median(z[~near]))
    rn, rf = float(np.median(res[near])), float(np.median(res[~near]))
    if not (zf > 1.1 * zn and rn > 0.0 and rf > 0.0):
        return zm, 0.0
    return zm, min(MAX_EXPONENT, max(0.0, math.log(rf / rn) / math.log(zf / zn)))


def sample_step(h: int, w: int, r: int) -> int:
    """Spacing of the grid of sampled windows of radius ``r`` on an ``h x w`` image: about
    :data:`SAMPLES` windows, at least ``2 (2 r + 1)`` apart."""
    return max(2 * (2 * r + 1), int(math.sqrt(h * w / SAMPLES)))


def sample_every(r: int) -> int:
    """Sampled windows of radius ``r`` are read on every this-many rows and columns."""
    return 2 if r >= SPARSE_RADIUS else 1


def support_profile(z: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                    sigma: float, *, target: float = TARGET_ERROR,
                    tiles: np.ndarray | None = None) -> SupportProfile:
    """Measure the fitted normal's error per radius on prepared depth ``z`` (module doc) and
    choose the radius; ``sigma`` is the noise level (footprints, :func:`estimate_noise`).
    Radii are measured smallest first and the search stops at the first that reaches
    ``target``. ``tiles``: the noise pass's tile levels
    (:meth:`depthnormals.ddm.noise.NoiseSamples.tiles`), for the profile's ``local`` excess
    (NaN without them)."""
    h, w = z.shape

    def pairs(r: int) -> np.ndarray:
        step = sample_step(h, w, r)
        out = np.empty((2 * (h // step + 1) * (w // step + 1), 4))
        k = _pairs(z, r, float(fx), float(fy), float(cx), float(cy), step, sample_every(r), out)
        return out[:k]

    return profile_from_pairs(pairs, sigma, target=target, tiles=tiles)


def profile_from_pairs(pairs, sigma: float, *, target: float = TARGET_ERROR,
                       tiles: np.ndarray | None = None) -> SupportProfile:
    """The statistics of :func:`support_profile` from the adjacent-window pairs:
    ``pairs(r)`` gives, for a radius of :data:`RADII`, the rows (angle between the two
    normals in degrees, the larger residual variance, the depth at the first window's
    centre, the index of its tile), in any order; it is asked for radii smallest first, and
    no further than the search goes. ``tiles``: the tiles' levels, for ``local``."""
    read: list[np.ndarray] = []

    def stats(k: int) -> tuple:
        out = pairs(RADII[k])
        read.append(out)
        n, measured, resid, keep = _radius_stats(out[None], np.ones((1, out.shape[0]), dtype=bool))
        return n[0], measured[0], resid[0], out[keep[0]]

    prof = _choose_profile(stats, sigma, target)
    if tiles is None:
        return prof
    tables = [(rows, np.ones(rows.shape[0], dtype=bool)) for rows in read[:len(prof.radii)]]
    return replace(prof, local=local_excess(tables, tiles, sigma))


def profiles_from_pair_tables(tables: list[tuple[np.ndarray, np.ndarray]],
                              sigmas: list[float], *,
                              target: float = TARGET_ERROR,
                              tiles: np.ndarray | None = None) -> list[SupportProfile]:
    """:func:`profile_from_pairs` for a batch of frames at once: ``tables[k] = (rows (B, P, 4),
    ok (B, P))`` the pairs of radius ``RADII[k]`` of every frame (rows where ``ok``), ``sigmas``
    the frames' noise levels, ``tiles`` their tile levels (B, TY, TX). The medians of every
    frame and radius are computed together, the choices frame by frame: the same profiles as
    one call of :func:`profile_from_pairs` per frame (tested); the torch port computes the
    pairs on the device and hands them here, so both libraries take the same decisions."""
    per = [_radius_stats(rows, ok) for rows, ok in tables]

    def frame(f: int):
        return lambda k: (per[k][0][f], per[k][1][f], per[k][2][f], tables[k][0][f][per[k][3][f]])

    out = [_choose_profile(frame(f), sigma, target) for f, sigma in enumerate(sigmas)]
    if tiles is None:
        return out
    return [replace(p, local=local_excess([(rows[f], ok[f]) for rows, ok in tables[:len(p.radii)]],
                                          tiles[f], sigmas[f]))
            for f, p in enumerate(out)]


def local_excess(tables: list[tuple[np.ndarray, np.ndarray]], tiles: np.ndarray,
                 sigma: float) -> float:
    """:meth:`SupportProfile.excess` read pair by pair against the noise of each pair's own
    tile: per measured radius from 2 to :data:`LOCAL_MAX_RADIUS` (``tables[k] = (rows (P, 4),
    ok (P,))`` the pairs of ``RADII[k]``, :func:`_pairs`), the pairs whose residual variance
    in units of their tile's level squared (``tiles``, NaN: ``sigma``) is within
    :data:`LOCAL_KEEP` times the median one and whose predicted error (:func:`predicted_error`
    at their tile's level) is at least :data:`EXCESS_FLOOR` degrees;
    :data:`PAIR_TO_ERROR` times the median of their angle over that prediction; the largest
    over the radii with :data:`MIN_PAIRS` such pairs, NaN where none has.

    Why: the image-wide excess compares the median pair with the median tile. Where the
    noise grows steeply with depth (active stereo: ``sigma_z ~ z^2``, correlated over the
    matching window, so that second differences read it several times low in the far tiles)
    the far pairs have the largest residuals and drop out, and the far tiles' levels count
    once each: on a room seen by the realsense_d4xx model the image-wide excess reads 0.9-1.9
    while the box-fit errs 9.5-17 deg where the measured support errs 0.8-5.3
    (benchmarks/stereo_range.py; docs/3f2n-plus.md, "Correlated noise the image-wide excess
    misses"). Each pair read against its own tile's level reads 2.5-6.8 there, at most 1.7 for
    the tof model and 1.0 for independent noise."""
    lev = np.asarray(tiles, dtype=np.float64).ravel()
    lev = np.where(np.isfinite(lev), lev, sigma)
    best = float("nan")
    last = RADII.index(LOCAL_MAX_RADIUS)
    for k in range(1, min(len(tables), last + 1)):
        rows, ok = tables[k]
        rows = rows[ok]
        if rows.shape[0] < MIN_PAIRS:
            continue
        r = RADII[k]
        s = lev[rows[:, 3].astype(np.int64)]
        with np.errstate(divide="ignore", invalid="ignore"):
            res = rows[:, 1] / (s * s)
            pred = np.degrees(math.sqrt(math.pi / 2.0) * s / math.sqrt(_window_suu(r, sample_every(r))))
            fin = np.isfinite(res)
            if not fin.any():
                continue
            keep = fin & (res <= LOCAL_KEEP * np.median(res[fin])) & (pred >= EXCESS_FLOOR)
            if np.count_nonzero(keep) < MIN_PAIRS:
                continue
            ratio = PAIR_TO_ERROR * float(np.median(rows[keep, 0] / pred[keep]))
        best = ratio if not best >= ratio else best
    return best


def _radius_stats(rows: np.ndarray, ok: np.ndarray) -> tuple:
    """Per frame (rows (B, P, 4) of one radius, present where ``ok``): the number of pairs,
    the measured mean error of one fit (:data:`PAIR_TO_ERROR` times the median angle of the
    pairs whose larger residual is at most the median one: edges drop out), the median
    residual of those, and which they are (B, P). Compiled (:func:`_radius_stats_rows`): the
    tables hold a few hundred pairs, where numpy's per-call cost was most of the support
    profile's time (1.1 of 1.3 ms at 640x480, eight radii)."""
    n, ang, res, keep = _radius_stats_rows(np.asarray(rows), np.asarray(ok, dtype=np.bool_))
    return n, PAIR_TO_ERROR * ang, res, keep


@nb.njit(cache=True, error_model="numpy")
def _median_of(x, ok, buf):
    """``np.median`` of the entries of ``x`` (P,) where ``ok`` (NaN where there is none): the
    middle one of the sorted entries, or the mean of the two middle ones (``buf``: scratch of
    P; the others read as infinite, so that a NaN entry sorts after them, as numpy sorts)."""
    m = x.size
    k = 0
    for i in range(m):
        buf[i] = x[i] if ok[i] else np.inf
        k += 1 if ok[i] else 0
    if k == 0:
        return np.nan
    srt = buf[:m]
    srt.sort()  # in place, the scratch's (NaN last, after the infinities, as numpy sorts)
    lo = srt[(k - 1) // 2]
    hi = srt[min(k // 2, m - 1)]
    # (the sum in the dtype of x, as numpy's mean; halving it is exact in any float dtype)
    return hi if k % 2 == 1 else (lo + hi) / 2


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _radius_stats_rows(rows, ok):
    """:func:`_radius_stats` before the error's factor: per frame the number of pairs, the
    median angle and the median residual of the kept pairs, and the kept pairs."""
    b, m = ok.shape
    n = np.zeros(b, dtype=np.int64)
    ang = np.empty(b, dtype=rows.dtype)
    res = np.empty(b, dtype=rows.dtype)
    keep = np.zeros((b, m), dtype=np.bool_)
    buf = np.empty(max(m, 1), dtype=rows.dtype)
    for f in range(b):
        r = rows[f, :, 1]
        o = ok[f]
        c = 0
        for i in range(m):
            c += 1 if o[i] else 0
        n[f] = c
        med = _median_of(r, o, buf)
        for i in range(m):
            keep[f, i] = o[i] and r[i] <= med
        ang[f] = _median_of(rows[f, :, 0], keep[f], buf)
        res[f] = _median_of(r, keep[f], buf)
    return n, ang, res, keep


def _choose_profile(stats, sigma: float, target: float) -> SupportProfile:
    """The radius search of :func:`support_profile`: ``stats(k)`` gives, for radius
    ``RADII[k]``, ``(pairs, measured error, median residual, kept rows)``; radii are read
    smallest first, up to the first with too few pairs or whose error reaches ``target``."""
    radii, errors, residuals, kept, meas, pred = [], [], [], [], [], []
    for k, r in enumerate(RADII):
        n, measured, resid, rows = stats(k)
        if n < MIN_PAIRS:
            break
        radii.append(r)
        meas.append(float(measured))
        pred.append(predicted_error(sigma, r, sample_every(r)))
        errors.append(max(float(measured), predicted_error(sigma, r)))
        residuals.append(float(resid))
        kept.append(rows)
        if errors[-1] <= target:
            break
    if not radii:
        return SupportProfile((1,), (float("nan"),), (0.0,), 1, measured=(float("nan"),),
                              predicted=(0.0,))
    i = next((j for j, e in enumerate(errors) if e <= target), int(np.argmin(errors)))
    zref, gamma = depth_exponent(kept[i][:, 1], kept[i][:, 2])
    return SupportProfile(tuple(radii), tuple(errors), tuple(residuals), radii[i], zref, gamma,
                          tuple(meas), tuple(pred))


@nb.njit(cache=True, error_model="numpy", inline="always")
def _gate_growth(zq, izref, half):
    """``(z / zref)^(half / 2)`` in float32 (``izref = 1 / zref``, ``half`` 1..4), without a
    transcendental function: how the gates grow with depth."""
    t = np.float32(zq) * izref
    q = np.sqrt(t)
    return t * t if half == 4 else (t * q if half == 3 else (t if half == 2 else q))


@nb.njit(cache=True, error_model="numpy", inline="always")
def _deviation(zq, nx, ny, nz, wc, rcx, rcy, rx, ry, fx, unit):
    """How far the depth ``zq`` of the pixel on the ray ``(rx, ry, 1)`` lies off the plane of
    normal ``n`` through the point of inverse depth ``wc`` on the ray ``(rcx, rcy, 1)`` (the
    chosen window's fitted centre), in standard deviations: the plane's inverse depth on the
    pixel's ray is ``wc (n . ray) / (n . ray_c)``; the miss in footprints ``(1 / zq - w) fx / w``
    times ``sqrt(unit)`` (the inverse plane residual variance at that depth, footprints of this
    grid). 0 where any of it is undefined."""
    w = wc * (nx * rx + ny * ry + nz) / (nx * rcx + ny * rcy + nz)
    d = np.abs((np.float32(1.0) / zq - w) * np.float32(fx) / w) * np.sqrt(unit)
    return d if d < np.float32(np.inf) else np.float32(0.0)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _deviation_row(zrow, n3, gc, cr, rx, ry, fx, un, fac, best, out):
    """One row of :func:`_deviation` into ``out`` (0 where the depth is invalid or the pixel
    has no window, ``best`` inf): its own loop, branch-free, so it vectorises. ``n3`` the
    chosen normals' rows ``(x, y, z)``, ``cr`` their centres' rays ``(x, y)``."""
    gx, gy, gz = n3
    cxr, cyr = cr
    for u in range(out.size):
        zq = zrow[u]
        d = _deviation(zq, gx[u], gy[u], gz[u], gc[u], cxr[u], cyr[u], rx[u], ry, fx,
                       un / fac[u])
        out[u] = d if (zq == zq) & (best[u] < np.inf) else np.float32(0.0)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _least_window(score, v, u, shift, k0, best):
    """The least of ``best`` and the ``score`` of the windows ``SHIFTS[k0:]`` (centres
    ``shift`` apart) around (v, u) inside the image, the first of equal ones winning: (score,
    row, column), (v, u) where ``best`` stays."""
    h, w = score.shape
    bv = v
    bu = u
    for k in range(k0, SHIFTS.shape[0]):
        r = v + shift * SHIFTS[k, 0]
        c = u + shift * SHIFTS[k, 1]
        if 0 <= r < h and 0 <= c < w and score[r, c] < best:
            best = score[r, c]
            bv = r
            bu = c
    return best, bv, bu


@nb.njit(cache=True, error_model="numpy")
def choose_pixel(z, fits, big, shift, gates, cam, v, u):
    """The readable reference of :func:`_choose_least_rows` at one pixel (same arguments):
    its normal ``(x, y, z)`` (NaN where it has none) and its deviation (:func:`_deviation`,
    0 there). Tested to agree with the fast rows."""
    fit_n, score, cen = fits
    big_n, big_s, big_c = big
    gate0, big_gate0, zref, half, unit0 = gates
    fx, fy, cx, cy = cam
    h = z.shape[0]
    nan = np.float32(np.nan)
    zq = z[v, u]
    if not (zq == zq):
        return nan, nan, nan, np.float32(0.0)
    fac = _gate_growth(zq, np.float32(1.0 / zref), half) if half > 0 else np.float32(1.0)
    best = score[v, u]
    if best <= np.float32(gate0) * fac:
        best = np.float32(-1.0)
    best, bv, bu = _least_window(score, v, u, shift, 1, best)
    if not (best < np.inf):
        return nan, nan, nan, np.float32(0.0)
    if big_s.shape[0] == (h + 1) // 2 and big_s[v >> 1, u >> 1] <= np.float32(big_gate0) * fac:
        nx, ny, nz = big_n[0, v >> 1, u >> 1], big_n[1, v >> 1, u >> 1], big_n[2, v >> 1, u >> 1]
        wc = big_c[v >> 1, u >> 1]
        cv = np.float32(2 * (v >> 1))
        cu = np.float32(2 * (u >> 1))
    else:
        nx, ny, nz = fit_n[0, bv, bu], fit_n[1, bv, bu], fit_n[2, bv, bu]
        wc = cen[bv, bu]
        cv = np.float32(bv)
        cu = np.float32(bu)
    f32 = np.float32
    dev = _deviation(zq, nx, ny, nz, wc, f32((cu - cx) / fx), f32((cv - cy) / fy),
                     f32((u - cx) / fx), f32((v - cy) / fy), fx, f32(unit0) / fac)
    if nx * ((u - cx) / fx) + ny * ((v - cy) / fy) + nz > 0.0:
        return -nx, -ny, -nz, dev
    return nx, ny, nz, dev


@nb.njit(cache=True, error_model="numpy", inline="always")
def _planar_row(normals, v, out3):
    """Row ``v`` of ``normals`` (H, W, 3) C-contiguous into ``out3`` (3, W), read as one flat
    row (a constant stride of 3: the loop vectorises, 3.6x faster than 3-d indexing)."""
    w = normals.shape[1]
    r = normals[v].reshape(3 * w)
    x = out3[0]
    y = out3[1]
    t = out3[2]
    for u in range(w):
        x[u] = r[3 * u]
        y[u] = r[3 * u + 1]
        t[u] = r[3 * u + 2]


@nb.njit(cache=True, error_model="numpy", inline="always")
def _put_facing(out, v, u, x, y, t, ray, ok):
    """``out[v, u] = (x, y, t)`` turned toward the pixel's ray ``(ray_x, ray_y, 1)``, or NaN
    where not ``ok``."""
    nan = np.float32(np.nan)
    # no tie rule (kernels.orient.TIE_COS) needed: the normal is a plane of inverse depth
    # fitted here or on the cell beside, and ``n . ray`` is that plane's inverse depth at the
    # pixel (times its length), positive wherever the plane has a depth there
    sg = np.float32(-1.0) if x * ray[0] + y * ray[1] + t > 0.0 else np.float32(1.0)
    out[v, u, 0] = x * sg if ok else nan
    out[v, u, 1] = y * sg if ok else nan
    out[v, u, 2] = t * sg if ok else nan


@nb.njit(cache=True, error_model="numpy", inline="always")
def _least(a, out_best, out_k, k):
    """``out_best = min(out_best, a)`` elementwise, ``out_k = k`` where ``a`` is smaller
    (slices from 0, so the loop vectorises: an index ``u + du`` with a negative ``du`` kept
    it scalar, 16x slower)."""
    for i in range(a.size):
        x = a[i]
        b = out_best[i]
        take = x < b
        out_best[i] = x if take else b
        out_k[i] = k if take else out_k[i]


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _choose_least_rows(v0, v1, z, fits, big, shift, gates, cam, out, out_dev, out_rows):
    """Rows ``[v0, v1)`` of the window choice.

    ``fits = (normals (3, H, W), scores (H, W), centres (H, W))`` of the radius-``shift``
    windows (``centres``: the fitted ``1 / z`` at each window's centre); ``big`` the same of
    the large centred windows fitted on every second row and column (shape ``(ceil(H / 2),
    ceil(W / 2))``, pixel (v, u) reads ``(v // 2, u // 2)``, whose centre is ``(2 (v // 2),
    2 (u // 2))``; a (1, W) score row: none); ``gates = (gate, big_gate, zref,
    half_exponent, unit)`` (footprints^2, growing as ``(z / zref)^(half_exponent / 2)``,
    ``half_exponent`` an integer 0..4; ``unit`` the inverse plane residual variance at
    ``zref`` in footprints of this grid, growing alike); ``cam = (fx, fy, cx, cy)``. A pixel
    takes the large window where its score is within the big gate, else the centred window
    where its score is within the gate, else the least score of the nine windows that hold it
    (the centred one wins ties). Writes ``out`` (H, W, 3): unit normals turned toward the
    pixel's ray, NaN at invalid depth or without a fit; ``out_dev`` (H, W): how many standard
    deviations the pixel's depth lies off the chosen window's plane (:func:`_deviation`; 0
    where it has no normal); ``out_rows`` (H, 3, W): the same normals by row
    (:func:`_planar_row`, each row while it is at hand), for the uncertainty map; a (0, 3, W)
    array: none. Every loop runs along a row (vectorised); the choice is one small
    index a pixel."""
    fit_n, score, cen = fits
    big_n, big_s, big_c = big
    gate0, big_gate0, zref, half, unit0 = gates
    fx, fy, cx, cy = cam
    h, w = z.shape
    f32 = np.float32
    use_big = big_s.shape[0] == (h + 1) // 2
    g0 = f32(gate0)
    gb = f32(big_gate0)
    un = f32(unit0)
    izref = f32(1.0 / zref if zref > 0.0 else 0.0)
    best = np.empty(w, dtype=f32)
    fac = np.ones(w, dtype=f32)
    kk = np.zeros(w, dtype=np.int32)
    gx = np.empty(w, dtype=f32)
    gy = np.empty(w, dtype=f32)
    gz = np.empty(w, dtype=f32)
    gc = np.empty(w, dtype=f32)
    cxr = np.empty(w, dtype=f32)  # the chosen window centre's ray
    cyr = np.empty(w, dtype=f32)
    dvk = shift * SHIFTS[:, 0]
    duk = shift * SHIFTS[:, 1]
    rx = ((np.arange(w) - cx) / fx).astype(f32)
    bx = ((2 * (np.arange(w) >> 1) - cx) / fx).astype(f32)  # the large windows' centres
    for v in range(v0, v1):
        srow = score[v]
        zrow = z[v]
        if half > 0:
            for u in range(w):
                fac[u] = _gate_growth(zrow[u], izref, half)
        for u in range(w):
            x = srow[u]
            best[u] = f32(-1.0) if x <= g0 * fac[u] else x
            kk[u] = 0
        for k in range(1, SHIFTS.shape[0]):
            r = v + dvk[k]
            if r < 0 or r >= h:
                continue
            du = duk[k]
            lo = max(0, -du)
            hi = min(w, w - du)
            _least(score[r, lo + du:hi + du], best[lo:hi], kk[lo:hi], np.int32(k))
        vb = min(v >> 1, big_s.shape[0] - 1)
        for u in range(w):  # the chosen window's normal (a gather; k > 0 only inside)
            k = kk[u]
            r = v + dvk[k]
            c = u + duk[k]
            gx[u] = fit_n[0, r, c]
            gy[u] = fit_n[1, r, c]
            gz[u] = fit_n[2, r, c]
            gc[u] = cen[r, c]
            cxr[u] = rx[c]
            cyr[u] = f32((r - cy) / fy)
        if use_big:  # the large window where it is one plane within the gate
            bs_row = big_s[vb]
            byr = f32((2 * vb - cy) / fy)
            for u in range(w):
                take = bs_row[u >> 1] <= gb * fac[u]
                gx[u] = big_n[0, vb, u >> 1] if take else gx[u]
                gy[u] = big_n[1, vb, u >> 1] if take else gy[u]
                gz[u] = big_n[2, vb, u >> 1] if take else gz[u]
                gc[u] = big_c[vb, u >> 1] if take else gc[u]
                cxr[u] = bx[u] if take else cxr[u]
                cyr[u] = byr if take else cyr[u]
        ry = f32((v - cy) / fy)
        for u in range(w):  # facing the pixel's ray; NaN at invalid depth or without a fit
            _put_facing(out, v, u, gx[u], gy[u], gz[u], (rx[u], ry),
                        (zrow[u] == zrow[u]) & (best[u] < np.inf))
        if out_rows.shape[0] == h:
            _planar_row(out, v, out_rows[v])
        _deviation_row(zrow, (gx, gy, gz), gc, (cxr, cyr), rx, ry, fx, un, fac, best,
                       out_dev[v])


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _fallback_rows(v0, v1, z, dev, limit, small, rs, cam, out):
    """Rows ``[v0, v1)``: where ``dev`` exceeds ``limit``, ``out[v, u]`` becomes the normal of
    the least residual among the nine windows of radius ``rs`` (centres ``rs`` apart) that
    hold the pixel (the first of equal ones in :data:`SHIFTS` order), turned toward its ray;
    unchanged where none of them has a fit. ``small = (normals (3, H, W), scores (H, W))``:
    the centred windows of radius ``rs`` (:func:`depthnormals.ddm.boxfit.box_fit_windows`).
    Few pixels deviate: a per-pixel loop."""
    fit_n, score = small
    fx, fy, cx, cy = cam
    w = z.shape[1]
    for v in range(v0, v1):
        ry = np.float32((v - cy) / fy)
        for u in range(w):
            if not (dev[v, u] > limit):
                continue
            best, br, bc = _least_window(score, v, u, rs, 0, np.float32(np.inf))
            if best < np.inf:
                _put_facing(out, v, u, fit_n[0, br, bc], fit_n[1, br, bc], fit_n[2, br, bc],
                            (np.float32((u - cx) / fx), ry), True)


def choice_inputs(z: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                  profile: SupportProfile, *, radius: int | None = None,
                  score_scale: float = 1.0) -> tuple:
    """The arguments of the window choice after the rows (``fits, big, shift, gates, cam``):
    the box-fit passes over ``z`` at ``radius`` (default the profile's) and at the large
    radius on every second row and column, with their windows' fitted centres. ``score_scale``
    turns the residual variances of ``z``'s footprints into those of the profile (4 when ``z``
    is the full image read on every second row and column)."""
    r = profile.radius if radius is None else radius
    big = min(MAX_RADIUS, round(BIG_FACTOR * r))
    residual = profile.residual_at(profile.radius)
    gate = GATE * residual
    w = z.shape[1]
    n, sc, cen = box_fit_windows(z, fx, fy, cx, cy, r, centres=True)
    fits = (n, sc * np.float32(score_scale), cen) if score_scale != 1.0 else (n, sc, cen)
    if big > r:  # on every second row and column: a quarter of the cost
        zd = np.ascontiguousarray(z[::2, ::2])
        bn, bs, bc = box_fit_windows(zd, 0.5 * fx, 0.5 * fy, 0.5 * cx, 0.5 * cy, (big + 1) // 2,
                                     centres=True)
        bigs = (bn, bs * np.float32(4.0 * score_scale), bc)  # footprints of the profile
    else:
        bigs = (fits[0][:, :1], np.full((1, w), np.inf, dtype=np.float32), cen[:1])
    half = round(2.0 * profile.exponent) if profile.depth == profile.depth else 0
    # the deviation's unit: the plane residual in footprints of this grid, inverted
    unit = score_scale / residual if residual > 0.0 else 0.0
    gates = (float(gate), float(gate), float(profile.depth), half, float(unit))
    return fits, bigs, int(r), gates, (float(fx), float(fy), float(cx), float(cy))


def _choose(z: np.ndarray, zc: np.ndarray, args: tuple, out: np.ndarray, min_rows: int,
            keep: bool = False) -> tuple:
    """The window choice (:func:`_choose_least_rows`) of ``args`` (:func:`choice_inputs`) on
    the depth ``zc`` into ``out``, then the fallback of the pixels that deviate from their
    window's plane (:func:`_fallback_rows`, on the depth ``z``) past :data:`DEVIATION` where
    the choice's radius exceeds :data:`FALLBACK_RADIUS` (else none falls back). Returns the
    deviations (H, W; 0 where ``z`` is invalid, which ``zc`` may fill), the limit past which
    pixels fell back (inf: none can) and, with ``keep``, the normals of the choice before the
    fallback by row, (H, 3, W) (else None), written by the choice itself: a copy even where
    none fell back, since the face switch then changes ``out`` in place (session 39: where
    none fell back the map read the switched normals, elsewhere the choice's)."""
    h, w = z.shape
    dev = np.empty(z.shape, dtype=np.float32)
    rows = np.empty((h if keep else 0, 3, w), dtype=np.float32)
    run_rows(_choose_least_rows, h, zc, *args, out, dev, rows, min_rows=min_rows)
    if zc is not z:
        dev[np.isnan(z)] = 0.0
    limit = DEVIATION if args[2] > FALLBACK_RADIUS else np.inf
    falls = bool((dev > limit).any())
    before = rows if keep else None
    if falls:
        cam = args[4]
        small = box_fit_windows(z, *cam, FALLBACK_RADIUS)
        run_rows(_fallback_rows, z.shape[0], z, dev, np.float32(limit), small,
                 FALLBACK_RADIUS, cam, out, min_rows=min_rows)
    return dev, limit, before


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _upsample_rows(v0, v1, z, half, cam, out):
    """Rows ``[v0, v1)``: pixel (v, u) takes the normal of ``half`` at (v // 2, u // 2) (the
    choice made on every second row and column), turned toward its own ray; NaN where its
    depth is invalid or ``half`` has none."""
    fx, fy, cx, cy = cam
    w = z.shape[1]
    rx = ((np.arange(w) - cx) / fx).astype(np.float32)
    for v in range(v0, v1):
        hr = half[v >> 1]
        zrow = z[v]
        ry = np.float32((v - cy) / fy)
        for u in range(w):
            _put_facing(out, v, u, hr[u >> 1, 0], hr[u >> 1, 1], hr[u >> 1, 2], (rx[u], ry),
                        zrow[u] == zrow[u])


def support_select(z: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                   sigma: float, *, profile: SupportProfile | None = None,
                   out_scores: list | None = None) -> np.ndarray:
    """The noisy branch on prepared depth ``z`` (module doc): normals (H, W, 3) float32, NaN
    at invalid depth and where no window has a fit. ``sigma``: the noise level
    (footprints); ``profile``: the measured support when already known.

    From radius :data:`HALF_RADIUS` on, the windows and the choice run on every second row
    and column (windows of radius ``r / 2`` there: the same extent) and every pixel takes the
    choice of its 2x2 cell: a window of 13 pixels or more loses little by it, and the branch
    costs about a third. A pixel (a cell) whose depth lies more than :data:`DEVIATION`
    standard deviations off the plane of the window it chose takes a small window instead
    (:func:`_fallback_rows`). ``out_scores``: a list that receives, on the grid of the choice
    (every second row and column from :data:`HALF_RADIUS` on), the residual variances of the
    chosen radius's windows (footprints^2 of the profile), their shift, the normals chosen
    before the fallback by row ((H, 3, W)), the deviations, the limit past which pixels fell
    back (inf where the radius allows none), whether that grid is the half one, the normals
    on that grid after the fallback and the face switch (the output, but not yet turned
    toward each pixel's ray on the half grid) and the face switch's decisions
    (:func:`depthnormals.ddm.faceswitch.switch_faces`), for the uncertainty map
    (:mod:`depthnormals.ddm.uncertainty`); the normals do not change.

    Last on the grid of the choice, a cell by a crease takes the other face's normal where
    that face's plane explains its 3x3 clearly better
    (:mod:`depthnormals.ddm.faceswitch`)."""
    p = support_profile(z, fx, fy, cx, cy, sigma) if profile is None else profile
    h, w = z.shape
    out = np.empty((h, w, 3), dtype=np.float32)
    keep = out_scores is not None
    if p.radius < HALF_RADIUS:
        args = choice_inputs(z, fx, fy, cx, cy, p)
        dev, limit, before = _choose(z, z, args, out, 16, keep)
        out, _, decisions = switch_faces(z, out, fx, fy, cx, cy, span=SWITCH_SPAN,
                                         decisions=keep)
        if keep:
            out_scores.extend((args[0][1], args[2], before, dev, limit, False, out, decisions))
        return out
    zd = np.ascontiguousarray(z[::2, ::2])
    cam = (0.5 * fx, 0.5 * fy, 0.5 * cx, 0.5 * cy)
    args = choice_inputs(zd, *cam, p, radius=round(p.radius / 2), score_scale=4.0)
    # the choice reads depth only for the gates' growth and for validity: every cell chooses
    zfill = np.where(np.isnan(zd), zd.dtype.type(p.depth if p.depth == p.depth else 1.0), zd)
    half = np.empty((zd.shape[0], zd.shape[1], 3), dtype=np.float32)
    dev, limit, before = _choose(zd, zfill, args, half, 8, keep)
    half, _, decisions = switch_faces(zd, half, *cam, span=SWITCH_SPAN // 2, decisions=keep,
                                      min_rows=8)
    if keep:
        out_scores.extend((args[0][1], args[2], before, dev, limit, True, half, decisions))
    run_rows(_upsample_rows, h, z, half, (float(fx), float(fy), float(cx), float(cy)), out,
             min_rows=16)
    return out
