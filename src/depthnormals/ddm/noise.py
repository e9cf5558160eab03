"""Depth noise in pixel footprints: the level that picks the support of the noise-aware 3F2N+.

Ours, not the paper's (the 3F2N+ paper estimates no noise).

On a plane, inverse depth ``w = 1 / z`` is exactly linear in the pixel coordinates
(NOTES section 2, 3F2N), so its second difference ``w(u - 1) - 2 w(u) + w(u + 1)`` is zero;
with independent depth noise of standard deviation ``sigma_z`` it has standard deviation
``sqrt(6) sigma_z / z^2`` (to first order). Measured in pixel footprints ``z / f`` the noise
is ``sigma = sigma_z f / z``, so every second difference gives the sample

    x = |w(u - 1) - 2 w(u) + w(u + 1)| f z / sqrt(6)

with ``E|x| = sigma sqrt(2 / pi)`` for Gaussian noise and median ``0.6745 sigma``. The
estimate is the median of ``x`` over horizontal and vertical triples of valid pixels divided
by 0.6745 (the MAD rule): depth jumps and creases are a minority of the triples and do not
move a median; curved surfaces add ``z / (f R)`` footprints (``R`` the radius of curvature),
negligible at sensor scales.

**Quantised depth.** Structured-light sensors (Kinect v1, Xtion, PrimeSense) quantise
disparity: depth comes in plateaus a few pixels wide separated by steps that grow with
``z^2``. Inside a plateau every second difference is exactly zero, so the median above reads
0 on such frames. The same pass therefore also looks for plateaus: along a sampled row (and
column), where the depth changes over ``2 QUANT_SPAN`` pixels by a small amount (a sloped
surface, not an edge), a clean or noisy surface changes between every two neighbours, a
quantised one mostly does not. When the share of exact zeros among those neighbour
differences is at least :data:`QUANT_SHARE`, the depth is quantised with a step ``Delta``
(the median non-zero neighbour difference, footprints), and its rounding noise
``Delta / sqrt(12)`` (the standard deviation of a uniform rounding error) is added in
quadrature to the second-difference level. The result is the i.i.d. noise equivalent of the
two, in one unit (footprints ``z / f``), never 0 on quantised sensor depth.

**Depth on a grid.** Depth stored in integer units (millimetre PNGs of renders or of low-noise
sensors) may show no plateaus on its slopes (most neighbours differ) and still read 0 by the
median (its flat parts hold equal values). The plateau search therefore also checks whether
its non-zero neighbour differences are multiples of the least one (:func:`grid_quantum`); if
so, that quantum's rounding noise enters the level like the plateaus' step, where it is not
small beside the second-difference level (:func:`quant_step_of`).

Ours (docs/3f2n-plus.md, "The noise model of real sensors"); nothing in the 3F2N+ paper
estimates noise.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from ..kernels.depth import prepare

__all__ = ["GRID_SHARE", "GRID_TOL", "QUANT_SHARE", "QUANT_SPAN", "TILE", "NoiseSamples",
           "estimate_noise", "estimate_noise_map", "grid_quantum", "noise_levels", "noise_pass",
           "noise_tiles", "quant_step_of"]

_MAD = 0.6744897501960817  # median of |N(0, 1)|
_SQRT6 = 6.0 ** 0.5
_SQRT12 = 12.0 ** 0.5
#: Side of the square tiles of the per-region noise level (:func:`estimate_noise_map`).
TILE = 64
#: Inside a tile, every TILE_STRIDE-th row (and column, for vertical triples) is sampled:
#: ~340 triples in a full 64x64 tile (its median to ~7 %).
TILE_STRIDE = 12
#: A tile with fewer triples reads as NaN (the image's level is used there).
TILE_MIN = 100
#: Half-span (pixels) of the slope test of the plateau search: the depth at ``u +- QUANT_SPAN``
#: must differ, by less than ``QUANT_EDGE`` footprints per pixel (a surface, not an edge).
QUANT_SPAN = 4
#: The plateau search reads every QUANT_STRIDE-th row and column (~25k neighbour pairs on
#: 640x480).
QUANT_STRIDE = 24
#: Largest neighbour difference (footprints) counted as a quantisation step, not an edge.
QUANT_EDGE = 20.0
#: Share of exactly equal neighbours on sloped surfaces above which depth is quantised: 0 on
#: float renders and on noisy depth (every neighbour differs), 0.40-0.81 on the Kinect v1 /
#: Xtion frames of ``shared/data/real-sensors`` (docs/3f2n-plus.md).
QUANT_SHARE = 0.3
#: Depth on a grid (:func:`grid_quantum`): at least this share of the plateau search's
#: non-zero neighbour differences within GRID_TOL of a multiple of the least one (1.0 on
#: millimetre depth, 0.10-0.11 on float renders and on noisy float depth), from GRID_MIN of them.
GRID_SHARE = 0.9
GRID_TOL = 0.05
GRID_MIN = 50
#: A grid finer than this many footprints is no depth unit but float32's own spacing (a
#: render's nearly fronto-parallel wall: its values a few ulps apart, 1e-5 footprints), too
#: fine to matter: not counted (millimetres at 6 m and f = 525 px: 0.09).
GRID_FLOOR = 1e-3
#: The grid's rounding noise counts where it is at least 1 / GRID_DOMINANCE of the
#: second-difference level (:func:`quant_step_of`): on sensor depth stored in millimetres
#: (synthetic kinect_v2 and tof, iid 12-30x the rounding noise) it is left out.
GRID_DOMINANCE = 3.0


def noise_from_prepared(z: np.ndarray, fx: float, fy: float) -> float:
    """:func:`estimate_noise` on prepared depth (NaN at invalid pixels); NaN when no triple."""
    return noise_pass(z, fx, fy).sigma


@nb.njit(cache=True, error_model="numpy")
def _kth(a, n, k):
    """The ``k``-th smallest of ``a[:n]`` (reorders it): Hoare's selection."""
    lo = 0
    hi = n - 1
    while lo < hi:
        x = a[(lo + hi) // 2]
        i = lo
        j = hi
        while i <= j:
            while a[i] < x:
                i += 1
            while x < a[j]:
                j -= 1
            if i <= j:
                t = a[i]
                a[i] = a[j]
                a[j] = t
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return a[k]
    return a[k]


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _tile_samples(z, fx, fy, tile, stride, every, starts):
    """The samples ``x sqrt(6)`` (module doc) tile by tile (``tile x tile`` pixels, rows of
    tiles first): every ``stride``-th row (horizontal triples) and column of those rows
    (vertical triples). Writes them into ``every``, tile ``t``'s from ``starts[t]`` to
    ``starts[t + 1]``; returns their number."""
    h, w = z.shape
    tw = (w + tile - 1) // tile
    n = 0
    for t in range(starts.size - 1):
        i = t // tw
        j = t - i * tw
        starts[t] = n
        u0 = max(j * tile, 1)
        u1 = min((j + 1) * tile, w - 1)
        for v in range(max(i * tile + stride // 2, 1), min((i + 1) * tile, h - 1), stride):
            for u in range(u0, u1):
                b = np.float64(z[v, u])
                a = np.float64(z[v, u - 1])
                c = np.float64(z[v, u + 1])
                if a == a and b == b and c == c:
                    every[n] = abs(1.0 / a - 2.0 / b + 1.0 / c) * fx * b
                    n += 1
            for u in range(max(j * tile + stride // 2, 1), u1, stride):
                b = np.float64(z[v, u])
                a = np.float64(z[v - 1, u])
                c = np.float64(z[v + 1, u])
                if a == a and b == b and c == c:
                    every[n] = abs(1.0 / a - 2.0 / b + 1.0 / c) * fy * b
                    n += 1
    starts[starts.size - 1] = n
    return n


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _plateau_samples(z, fx, fy, stride, span, edge, out_steps, out_raw):
    """The plateau search of the module doc on every ``stride``-th row (neighbours along the
    row) and column (along the column): at each pixel ``u`` whose depths at ``u +- span``
    differ by less than ``edge`` footprints per pixel (and do differ), the neighbour
    difference ``z(u + 1) - z(u)``. Writes the non-zero ones (footprints ``|dz| f / z``,
    below ``edge``) into ``out_steps`` and the same in depth units (``|dz|``) into
    ``out_raw``; returns ``(tested, zero, steps)`` counts."""
    h, w = z.shape
    tested = 0
    zero = 0
    n = 0
    for pass_ in range(2):
        f = fx if pass_ == 0 else fy
        lines = h if pass_ == 0 else w
        length = w if pass_ == 0 else h
        for i in range(stride // 2, lines, stride):
            for j in range(span, length - span):
                if pass_ == 0:
                    a = np.float64(z[i, j - span])
                    b = np.float64(z[i, j + span])
                    c = np.float64(z[i, j])
                    d = np.float64(z[i, j + 1])
                else:
                    a = np.float64(z[j - span, i])
                    b = np.float64(z[j + span, i])
                    c = np.float64(z[j, i])
                    d = np.float64(z[j + 1, i])
                if not (a == a and b == b and c == c and d == d) or a == b:
                    continue
                if abs(b - a) * f / c >= 2.0 * span * edge:
                    continue
                step = abs(d - c) * f / c
                if step >= edge:
                    continue
                tested += 1
                if step == 0.0:
                    zero += 1
                elif n < out_steps.size:
                    out_steps[n] = step
                    out_raw[n] = abs(d - c)
                    n += 1
    return tested, zero, n


def quantisation_step(z: np.ndarray, fx: float, fy: float) -> tuple[float, float, float]:
    """The plateau search of the module doc on prepared depth: ``(share, step, grid)``, the
    share of exactly equal neighbours on sloped surfaces, the median non-zero step
    (footprints; 0 where ``share < QUANT_SHARE``: no plateaus) and the depth grid's quantum
    (footprints, :func:`grid_quantum`; 0 where the depth lies on no grid); ``share`` NaN where
    nothing was tested."""
    h, w = z.shape
    size = (h // QUANT_STRIDE + 1) * w + (w // QUANT_STRIDE + 1) * h
    steps = np.empty(size)
    raw = np.empty(size)
    tested, zero, n = _plateau_samples(z, float(fx), float(fy), QUANT_STRIDE, QUANT_SPAN,
                                       QUANT_EDGE, steps, raw)
    share, step = quantisation_from_counts(tested, zero, n,
                                           lambda: float(np.partition(steps[:n], n // 2)[n // 2]))
    return share, step, grid_quantum(steps[:n], raw[:n])


def grid_quantum(steps: np.ndarray, raw: np.ndarray) -> float:
    """The quantum of depth that lies on a grid (integer millimetres, a 16-bit PNG's units),
    in footprints: ``q f / z`` (upper median over the samples), ``q`` the least non-zero
    neighbour difference, where at least :data:`GRID_SHARE` of the differences ``raw`` (depth
    units; ``steps`` the same in footprints) are within :data:`GRID_TOL` of a multiple of
    ``q``, and the quantum is at least :data:`GRID_FLOOR`; else 0 (float renders, noisy
    depth: ~10 % are)."""
    n = raw.size
    q = float(raw.min()) if n else 0.0
    if n < GRID_MIN or not q > 0.0:
        return 0.0
    r = raw / q
    on = int(np.count_nonzero(np.abs(r - np.round(r)) < GRID_TOL))
    return grid_from_counts(n, q, on, lambda: float(np.partition(steps * (q / raw), n // 2)[n // 2]))


def grid_from_counts(n: int, q: float, on: int, quantum_median) -> float:
    """:func:`grid_quantum`'s verdict from its counts: ``n`` non-zero differences, the least
    ``q``, ``on`` of them on its grid; ``quantum_median()`` the upper median of ``q f / z``,
    asked for only on a grid. The one rule of the numba pass and of its torch port."""
    if n < GRID_MIN or not q > 0.0 or on < GRID_SHARE * n:
        return 0.0
    quantum = quantum_median()
    return quantum if quantum >= GRID_FLOOR else 0.0


def quant_step_of(iid: float, step: float, grid: float) -> float:
    """The step whose rounding noise enters the level: the plateaus' ``step`` where there are
    plateaus; else the grid's quantum ``grid`` where its rounding noise ``grid / sqrt(12)``
    is at least a :data:`GRID_DOMINANCE` th of the second-difference level ``iid`` (depth on
    a grid whose rounding the second differences read as 0: most neighbours are equal); else
    0. The one rule of the numba pass and of its torch port."""
    if step > 0.0:
        return step
    if grid > 0.0 and iid < GRID_DOMINANCE * grid / _SQRT12:
        return grid
    return 0.0


def quantisation_from_counts(tested: int, zero: int, n_steps: int, step_median) -> tuple[float, float]:
    """The plateau search's verdict from its counts: ``(share, step)`` (:func:`quantisation_step`);
    ``step_median()`` gives the upper median of the ``n_steps`` non-zero steps, asked for only
    when the depth is quantised. The one rule of the numba pass and of its torch port."""
    if tested == 0:
        return float("nan"), 0.0
    share = zero / tested
    if share < QUANT_SHARE or n_steps == 0:
        return share, 0.0
    return share, step_median()


def iid_level(median: float, n: int) -> float:
    """The second-difference level (footprints) from the upper median of ``n`` samples
    ``|second difference| f z`` (the MAD rule of the module doc); NaN without a sample."""
    return median / (_MAD * _SQRT6) if n else float("nan")


def combined_level(iid: float, step: float) -> tuple[float, float]:
    """``(quant, sigma)``: the rounding noise ``step / sqrt(12)`` of quantised depth and the
    level every branch reads, ``iid`` and it in quadrature (``iid`` alone when not quantised)."""
    quant = step / _SQRT12
    return quant, (math.hypot(iid, quant) if quant > 0.0 else iid)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _tile_medians(every, starts, minimum, out):
    """Median of each tile's samples (reorders them); NaN below ``minimum`` samples."""
    for t in range(out.size):
        a = starts[t]
        m = starts[t + 1] - a
        out.flat[t] = _kth(every[a:a + m], m, m // 2) if m >= minimum else np.nan


def _median_nonneg(a: np.ndarray) -> float:
    """The upper median of non-negative samples ``a`` (numpy's selection on a copy), with the
    zeros counted first: on quantised depth most are exactly 0, where the selection is slow."""
    n = a.size
    k = n // 2
    pos = a[a > 0.0]
    k -= n - pos.size
    return float(np.partition(pos, k)[k]) if k >= 0 else 0.0


class NoiseSamples:
    """The samples of one pass over prepared depth (:func:`noise_pass`): the image's level
    now (``sigma``), every tile's on demand (:meth:`tiles`).

    ``iid``: the second-difference level (footprints); ``quant_share``: the plateau search's
    share of equal neighbours (:func:`quantisation_step`); ``grid``: the depth grid's quantum
    (0: none); ``quant_step``: the step whose rounding noise counts (:func:`quant_step_of`:
    the plateaus', else the grid's, else 0) and ``plateaus`` whether it is the plateaus';
    ``quant``: the rounding noise ``quant_step / sqrt(12)``; ``sigma``:
    ``sqrt(iid^2 + quant^2)``, the level every branch reads."""

    def __init__(self, every: np.ndarray, starts: np.ndarray, shape: tuple[int, int],
                 quant: tuple[float, float, float] = (float("nan"), 0.0, 0.0)):
        self._every = every
        self._starts = starts
        self._shape = shape
        n = every.size
        # numpy's selection (a copy: the tiles' samples stay in place)
        self.iid = iid_level(_median_nonneg(every), n) if n else float("nan")
        self.quant_share, plateau_step, self.grid = quant
        self.quant_step = quant_step_of(self.iid, plateau_step, self.grid)
        self.plateaus = plateau_step > 0.0
        self.quant, self.sigma = combined_level(self.iid, self.quant_step)

    def tiles(self) -> np.ndarray:
        """Every tile's level, footprints (tiles down, across), NaN below :data:`TILE_MIN`:
        its second-difference level and the image's rounding noise in quadrature."""
        out = np.empty(self._shape)
        _tile_medians(self._every, self._starts, TILE_MIN, out)
        out /= _MAD * _SQRT6
        return np.hypot(out, self.quant) if self.quant > 0.0 else out


def noise_pass(z: np.ndarray, fx: float, fy: float, *, tile: int = TILE) -> NoiseSamples:
    """One pass over prepared depth ``z`` (NaN invalid): rows ``tile k + 6 + 12 j`` and, on
    them, every 12th column (:data:`TILE_STRIDE`), ~29k triples on 640x480, kept by tile."""
    h, w = z.shape
    shape = ((h + tile - 1) // tile, (w + tile - 1) // tile)
    every = np.empty((h // TILE_STRIDE + shape[0] + 1) * (w + w // TILE_STRIDE + shape[1] + 1))
    starts = np.empty(shape[0] * shape[1] + 1, dtype=np.int64)
    n = _tile_samples(z, float(fx), float(fy), int(tile), TILE_STRIDE, every, starts)
    return NoiseSamples(every[:n], starts, shape, quantisation_step(z, fx, fy))


def noise_levels(z: np.ndarray, fx: float, fy: float, *,
                 tile: int = TILE) -> tuple[float, np.ndarray]:
    """The image's noise and every tile's (:func:`noise_pass`), footprints: ``(sigma,
    tiles)``, ``sigma`` the median of all the samples (NaN when there is none), ``tiles``
    (ceil(H / tile), ceil(W / tile)) float64, NaN where a tile has fewer than
    :data:`TILE_MIN` triples."""
    p = noise_pass(z, fx, fy, tile=tile)
    return p.sigma, p.tiles()


def noise_tiles(z: np.ndarray, fx: float, fy: float, *, tile: int = TILE) -> np.ndarray:
    """Per-tile noise of prepared depth ``z`` (:func:`noise_levels`' tiles)."""
    return noise_pass(z, fx, fy, tile=tile).tiles()


def estimate_noise_map(depth: Any, K: Any, *, tile: int = TILE,
                       depth_scale: float | None = None) -> np.ndarray:
    """Per-region depth noise in pixel footprints: :func:`estimate_noise` per square tile.

    Sensor noise is not one level: a Kinect's or a stereo camera's noise in footprints
    ``sigma_z f / z`` changes with depth, so near and far surfaces of one frame differ. The
    noise-aware 3F2N+ (``selection="auto"``) reads this map under noise: its plane tests
    use the tile's level, not the image's.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth (as :func:`estimate_noise`).
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels.
    tile : int >= 8, keyword-only, default 64
        Tile side in pixels.
    depth_scale : float, optional, keyword-only
        Metres per unit of integer depth.

    Returns
    -------
    sigma : ndarray, shape (H, W), float32
        Every pixel holds its tile's noise (footprints); a tile with fewer than
        :data:`TILE_MIN` valid triples (sampled on every 12th row and column) holds the
        image's level (the median of all the map's samples: :func:`estimate_noise` for the
        default tile), NaN if there is none.

    Examples
    --------
    >>> import numpy as np, depthnormals as dn
    >>> from depthnormals.analytic import tilted_plane
    >>> r = tilted_plane().render()
    >>> rng = np.random.default_rng(0)
    >>> s = np.where(np.arange(r.depth.shape[1]) < 320, 0.1, 0.4)  # left 0.1, right 0.4
    >>> noisy = r.depth + rng.normal(size=r.depth.shape) * s * r.depth / r.K.fx
    >>> m = dn.estimate_noise_map(noisy, r.K)
    >>> round(float(m[240, 100]), 1), round(float(m[240, 500]), 1)
    (0.1, 0.4)
    """
    if isinstance(tile, bool) or not isinstance(tile, (int, np.integer)) or tile < 8:
        raise ValueError(f"tile must be an integer >= 8; got {tile!r}")
    z, cam = prepare(depth, K, depth_scale)
    sigma, t = noise_levels(z, cam.fx, cam.fy, tile=int(tile))
    t = np.where(np.isfinite(t), t, sigma)
    h, w = z.shape
    return np.repeat(np.repeat(t, tile, axis=0), tile, axis=1)[:h, :w].astype(np.float32)


def estimate_noise(depth: Any, K: Any, *, depth_scale: float | None = None) -> float:
    """Standard deviation of the depth noise, in pixel footprints ``z / f``, from one image.

    The median absolute second difference of inverse depth (zero on every plane), scaled to
    footprints and divided by ``0.6745 sqrt(6)`` (the MAD rule for Gaussian noise), and the
    rounding noise of quantised depth in quadrature; see the module doc. Depth jumps and
    creases, a minority of the pixels, do not move the median. Samples every 12th row (and
    column, vertically): about 29k triples on 640x480 (the samples of
    :func:`estimate_noise_map`, read in the same pass).

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth. float32/float64; integers need ``depth_scale``. Invalid depth
        (0, negative, NaN, inf) is skipped.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Intrinsics in pixels.
    depth_scale : float, optional
        Metres per unit of integer depth (the result does not depend on it).

    Returns
    -------
    sigma : float
        Noise in footprints (``sigma_z f / z``): ~1e-4 or 0 on float32 renders, 0.1 for the
        Gaussian noise of the analytic benchmark, ~0.2-0.5 for a Kinect v2 at 1-4 m,
        0.6-1.6 on real Kinect v1 depth (quantised), never 0 on real sensor depth.
        NaN when no three consecutive valid pixels exist. Unit-free: the same for depth in
        metres or millimetres.

    Notes
    -----
    Ours, used by ``selection="auto"``, the default of
    :func:`depthnormals.discontinuity_discrimination` and so of every ``"<name>+"`` method:
    below 0.001 footprints it takes the plane hypotheses (clean depth), above it a box-fit
    (docs/3f2n-plus.md). Quantised depth (Kinect v1, Xtion, PrimeSense: disparity in 1/8 px
    steps) reads as its rounding noise ``step / sqrt(12)`` added in quadrature to the
    second-difference level (module doc): 0.6-1.6 footprints on the Kinect v1 frames of
    ``shared/data/real-sensors``, where the second differences alone read exactly 0.
    :func:`depthnormals.noise_profile` reports the parts separately, with the correlated
    part the second differences cannot see.

    Examples
    --------
    >>> import numpy as np, depthnormals as dn
    >>> from depthnormals.analytic import tilted_plane
    >>> r = tilted_plane().render()
    >>> rng = np.random.default_rng(0)
    >>> noisy = r.depth + rng.normal(size=r.depth.shape) * 0.2 * r.depth / r.K.fx
    >>> round(dn.estimate_noise(noisy, r.K), 1)
    0.2
    """
    z, cam = prepare(depth, K, depth_scale)
    return noise_from_prepared(z, cam.fx, cam.fy)
