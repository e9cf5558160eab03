"""Depth noise in pixel footprints: the level that picks the support of the noise-aware 3F2N+.

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
negligible at sensor scales. This is our reading (issue 13); nothing in the 3F2N+ paper
estimates noise.
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from ..kernels.depth import prepare

__all__ = ["estimate_noise", "noise_samples"]

_MAD = 0.6744897501960817  # median of |N(0, 1)|
_SQRT6 = 6.0 ** 0.5
#: Rows sampled: every STRIDE-th row (and every STRIDE-th column for the vertical triples);
#: ~29k samples on 640x480, a median to ~1 %.
STRIDE = 12


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _samples(z, fx, fy, stride, out):
    """Write the samples ``x sqrt(6)`` (module doc) of rows ``v % stride == 1`` into ``out``
    (horizontal triples, then the vertical triples of every ``stride``-th column); return
    their number."""
    h, w = z.shape
    m = 0
    for v in range(1, h - 1, stride):
        for u in range(1, w - 1):
            a = np.float64(z[v, u - 1])
            b = np.float64(z[v, u])
            c = np.float64(z[v, u + 1])
            if a == a and b == b and c == c:
                out[m] = abs(1.0 / a - 2.0 / b + 1.0 / c) * fx * b
                m += 1
        for u in range(1, w - 1, stride):
            a = np.float64(z[v - 1, u])
            b = np.float64(z[v, u])
            c = np.float64(z[v + 1, u])
            if a == a and b == b and c == c:
                out[m] = abs(1.0 / a - 2.0 / b + 1.0 / c) * fy * b
                m += 1
    return m


def noise_samples(z: np.ndarray, fx: float, fy: float, *, stride: int = STRIDE) -> np.ndarray:
    """The samples ``x sqrt(6)`` (see the module doc) of prepared depth ``z`` (NaN invalid):
    1-D float64, horizontal triples on every ``stride``-th row, vertical triples on every
    ``stride``-th column of those rows."""
    h, w = z.shape
    out = np.empty((h // stride + 1) * (w + w // stride + 2))
    m = _samples(z, float(fx), float(fy), int(stride), out)
    return out[:m]


def noise_from_prepared(z: np.ndarray, fx: float, fy: float) -> float:
    """:func:`estimate_noise` on prepared depth (NaN at invalid pixels); NaN when no triple."""
    h, w = z.shape
    out = np.empty((h // STRIDE + 1) * (w + w // STRIDE + 2))
    m = _samples(z, float(fx), float(fy), STRIDE, out)
    if m == 0:
        return float("nan")
    # numpy's median (the same order statistics as numba's, without its 1.5 s first compile)
    return float(np.median(out[:m])) / (_MAD * _SQRT6)


def estimate_noise(depth: Any, K: Any, *, depth_scale: float | None = None) -> float:
    """Standard deviation of the depth noise, in pixel footprints ``z / f``, from one image.

    The median absolute second difference of inverse depth (zero on every plane), scaled to
    footprints and divided by ``0.6745 sqrt(6)`` (the MAD rule for Gaussian noise); see the
    module doc. Depth jumps and creases, a minority of the pixels, do not move the median.
    Samples every 12th row (and column, vertically): about 29k triples on 640x480.

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
        Noise in footprints (``sigma_z f / z``): ~1e-4 on float32 renders, 0.1 for the
        Gaussian noise of the analytic benchmark, ~0.2-0.5 for a Kinect v2 at 1-4 m.
        NaN when no three consecutive valid pixels exist. Unit-free: the same for depth in
        metres or millimetres.

    Notes
    -----
    Ours (issue 13), used by ``selection="auto"``, the default of
    :func:`depthnormals.discontinuity_discrimination` and so of every ``"<name>+"`` method:
    below 0.03 footprints the depth counts as clean (docs/3f2n-plus.md). Quantised depth (e.g. 1 mm steps)
    reads as its rounding noise where it exceeds the sensor's.

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
