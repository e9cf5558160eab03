"""Validity-aware derivative stencils shared by the image-gradient estimators.

A derivative at pixel (v, u) along the step (a_v, a_u) is a separable filter: derivative
taps along the step, smoothing taps across it. Where a tap falls on an invalid pixel (NaN)
or outside the image, that row of the filter falls back to the central, then to a one-sided
1-pixel difference; a row with none is left out and the smoothing weights renormalised.
Only when no row yields a difference is the result NaN.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["KERNELS", "gradient_kernels", "roberts_gradient", "stencil_derivative"]

#: Gradient kernels of the 3F2N family, with their smoothing taps (``None``: no smoothing).
#: Correctly named: Scharr smooths with (3, 10, 3), Prewitt with (1, 1, 1).
KERNELS: dict[str, tuple[float, ...] | None] = {
    "fd": None,
    "sobel": (1.0, 2.0, 1.0),
    "scharr": (3.0, 10.0, 3.0),
    "prewitt": (1.0, 1.0, 1.0),
    "roberts": None,
}


def gradient_kernels(kernel: str, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Derivative and smoothing taps of a named kernel of odd ``size`` (3..11).

    The derivative taps are scaled so that they return the derivative per pixel of a
    linear function (``sum(i * d_i) == 1``) and the smoothing taps sum to 1: one-sided
    fallbacks and full stencils then agree in scale.

    - ``fd``: a least-squares slope over ``size`` taps in one row ((-1, 0, 1) for size 3).
    - ``sobel``/``scharr``/``prewitt`` of size 2m+1: smoothing ``s^(*m)``, derivative
      ``(-1, 0, 1) * s^(*(m-1))`` with ``s`` the family's 3-tap smoothing, the construction
      of the public 3F2N code (and of OpenCV's Sobel).
    """
    if not isinstance(size, (int, np.integer)) or isinstance(size, bool):
        raise TypeError(f"kernel_size must be an odd integer in 3..11; got {size!r}")
    if size not in (3, 5, 7, 9, 11):
        raise ValueError(f"kernel_size must be one of 3, 5, 7, 9, 11; got {size}")
    m = (size - 1) // 2
    smooth_base = KERNELS[kernel]
    if smooth_base is None:
        deriv = np.arange(-m, m + 1, dtype=np.float64)
        smooth = np.ones(1)
    else:
        s = np.asarray(smooth_base)
        smooth = np.ones(1)
        for _ in range(m):
            smooth = np.convolve(smooth, s)
        deriv = np.array([-1.0, 0.0, 1.0])
        for _ in range(m - 1):
            deriv = np.convolve(deriv, s)
    offsets = np.arange(-(deriv.size // 2), deriv.size // 2 + 1)
    deriv = deriv / np.sum(offsets * deriv)
    smooth = smooth / smooth.sum()
    return np.ascontiguousarray(deriv), np.ascontiguousarray(smooth)


@nb.njit(cache=True, error_model="numpy", inline="always")
def sample_or_nan(D, r, c, recip=False):
    """``D[r, c]`` (its reciprocal, in float64, with ``recip``), or NaN outside the image."""
    h, w = D.shape
    if r < 0 or r >= h or c < 0 or c >= w:
        return np.nan
    if recip:
        return 1.0 / np.float64(D[r, c])
    return np.float64(D[r, c])


@nb.njit(cache=True, error_model="numpy")
def stencil_derivative(D, v, u, a_v, a_u, deriv, smooth, recip=False):
    """Derivative of D (of 1 / D with ``recip``) at (v, u) along (a_v, a_u), smoothed across it.

    NaN-aware; float64 whatever the dtype of D.
    """
    md = deriv.size // 2
    ms = smooth.size // 2
    b_v = a_u
    b_u = a_v
    acc = 0.0
    wsum = 0.0
    for j in range(-ms, ms + 1):
        s = smooth[j + ms]
        if s == 0.0:
            continue
        pv = v + j * b_v
        pu = u + j * b_u
        g = 0.0
        full = True
        for i in range(-md, md + 1):
            d = deriv[i + md]
            if d == 0.0:
                continue
            val = sample_or_nan(D, pv + i * a_v, pu + i * a_u, recip)
            if not (val == val):
                full = False
                break
            g += d * val
        if not full:
            fwd = sample_or_nan(D, pv + a_v, pu + a_u, recip)
            bwd = sample_or_nan(D, pv - a_v, pu - a_u, recip)
            c = sample_or_nan(D, pv, pu, recip)
            if fwd == fwd and bwd == bwd:
                g = 0.5 * (fwd - bwd)
            elif c == c and fwd == fwd:
                g = fwd - c
            elif c == c and bwd == bwd:
                g = c - bwd
            else:
                continue
        acc += s * g
        wsum += s
    if wsum > 0.0:
        return acc / wsum
    return np.nan


@nb.njit(cache=True, error_model="numpy")
def roberts_gradient(D, v, u):
    """(d/du, d/dv) of D from the first fully valid 2x2 Roberts cross around (v, u).

    The two diagonal differences d1 = D(v+1, u+1) - D(v, u) and d2 = D(v+1, u) - D(v, u+1)
    are rotated back: d/du = (d1 - d2) / 2, d/dv = (d1 + d2) / 2.
    """
    for k in range(4):
        r0 = v - (k // 2)
        c0 = u - (k % 2)
        a = sample_or_nan(D, r0, c0)
        b = sample_or_nan(D, r0, c0 + 1)
        c = sample_or_nan(D, r0 + 1, c0)
        d = sample_or_nan(D, r0 + 1, c0 + 1)
        if a == a and b == b and c == c and d == d:
            d1 = d - a
            d2 = c - b
            return 0.5 * (d1 - d2), 0.5 * (d1 + d2)
    return math.nan, math.nan
