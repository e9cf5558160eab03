"""Closed-form eigen-solver for 3x3 symmetric matrices (numba, no LAPACK per pixel)."""

from __future__ import annotations

import math

import numba as nb

__all__ = ["smallest_eigenvector", "smallest_eigenvector_newton", "sym3_adjugate_apply"]

_TWO_PI_3 = 2.0 * math.pi / 3.0


@nb.njit(cache=True, error_model="numpy", inline="always")
def _null_vector(a00, a01, a02, a11, a12, a22, lam):
    """The longest cross product of two rows of ``A - lam I`` and its squared length.

    Branch-free (selects), so loops calling it vectorise.
    """
    r00 = a00 - lam
    r11 = a11 - lam
    r22 = a22 - lam
    # rows: (r00, a01, a02), (a01, r11, a12), (a02, a12, r22)
    c0x = a01 * a12 - a02 * r11
    c0y = a02 * a01 - r00 * a12
    c0z = r00 * r11 - a01 * a01
    c1x = a01 * r22 - a02 * a12
    c1y = a02 * a02 - r00 * r22
    c1z = r00 * a12 - a01 * a02
    c2x = r11 * r22 - a12 * a12
    c2y = a12 * a02 - a01 * r22
    c2z = a01 * a12 - r11 * a02
    d0 = c0x * c0x + c0y * c0y + c0z * c0z
    d1 = c1x * c1x + c1y * c1y + c1z * c1z
    d2 = c2x * c2x + c2y * c2y + c2z * c2z
    b0 = d0 >= d1 and d0 >= d2
    b1 = (not b0) and d1 >= d2
    x = c0x if b0 else (c1x if b1 else c2x)
    y = c0y if b0 else (c1y if b1 else c2y)
    z = c0z if b0 else (c1z if b1 else c2z)
    d = d0 if b0 else (d1 if b1 else d2)
    return x, y, z, d


@nb.njit(cache=True, error_model="numpy", inline="always")
def sym3_adjugate_apply(m00, m01, m02, m11, m12, m22, s0, s1, s2):
    """``adj(M) s`` and ``det(M)`` for the symmetric matrix ``M = [[m00 m01 m02] ...]``:
    ``M^-1 s = adj(M) s / det(M)`` without a division (``(x, y, z, det)``). Branch-free, so
    loops calling it vectorise. The normal equations of FALS and of the box-fit's planes."""
    c00 = m11 * m22 - m12 * m12
    c01 = m02 * m12 - m01 * m22
    c02 = m01 * m12 - m02 * m11
    c11 = m00 * m22 - m02 * m02
    c12 = m01 * m02 - m00 * m12
    c22 = m00 * m11 - m01 * m01
    x = c00 * s0 + c01 * s1 + c02 * s2
    y = c01 * s0 + c11 * s1 + c12 * s2
    z = c02 * s0 + c12 * s1 + c22 * s2
    return x, y, z, m00 * c00 + m01 * c01 + m02 * c02


@nb.njit(cache=True, error_model="numpy", inline="always")
def smallest_eigenvector(a00, a01, a02, a11, a12, a22):
    """Unit eigenvector of the smallest eigenvalue of the symmetric matrix [[a00 a01 a02] ...].

    The eigenvalue comes from the trigonometric solution of the characteristic cubic; the
    vector is the longest cross product of two rows of ``A - lambda I``. Returns NaNs when
    the smallest eigenvalue is not simple (fewer than three non-collinear points).
    """
    m = max(abs(a00), abs(a01), abs(a02), abs(a11), abs(a12), abs(a22))
    if not (m > 0.0) or not math.isfinite(m):
        return math.nan, math.nan, math.nan
    a00 /= m
    a01 /= m
    a02 /= m
    a11 /= m
    a12 /= m
    a22 /= m
    q = (a00 + a11 + a22) / 3.0
    b00 = a00 - q
    b11 = a11 - q
    b22 = a22 - q
    p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0
    if not (p2 > 0.0):
        return math.nan, math.nan, math.nan
    p = math.sqrt(p2)
    det = (b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02)
           + a02 * (a01 * a12 - b11 * a02))
    r = det / (2.0 * p2 * p)
    if r < -1.0:
        r = -1.0
    elif r > 1.0:
        r = 1.0
    phi = math.acos(r) / 3.0
    lam = q + 2.0 * p * math.cos(phi + _TWO_PI_3)
    x, y, z, d = _null_vector(a00, a01, a02, a11, a12, a22, lam)
    # relative to the matrix scale (1 after division by m): rank <= 1 leaves d ~ rounding
    if not (d > 1e-24):
        return math.nan, math.nan, math.nan
    s = 1.0 / math.sqrt(d)
    return x * s, y * s, z * s


@nb.njit(cache=True, error_model="numpy", inline="always")
def smallest_eigenvector_newton(a00, a01, a02, a11, a12, a22):
    """As :func:`smallest_eigenvector` for a positive semi-definite matrix, without
    trigonometry or branches (so that loops calling it vectorise); returns (x, y, z, ok).

    The smallest eigenvalue is the smallest root of the characteristic cubic, reached by
    12 steps of Newton's method from 0: below the smallest root the cubic is increasing and concave, so
    the iterates rise monotonically to it (quadratically once close, which they are from the
    start when the smallest eigenvalue is well separated, as for a surface patch). ``ok`` is
    False when the iteration has not settled to rounding, when the eigenvalue is not simple
    or the input not finite: the caller then uses :func:`smallest_eigenvector`.
    """
    m = max(abs(a00), abs(a01), abs(a02), abs(a11), abs(a12), abs(a22))
    a00 /= m
    a01 /= m
    a02 /= m
    a11 /= m
    a12 /= m
    a22 /= m
    # f(l) = l^3 - c2 l^2 + c1 l - c0
    c2 = a00 + a11 + a22
    c1 = a00 * a11 - a01 * a01 + a00 * a22 - a02 * a02 + a11 * a22 - a12 * a12
    c0 = (a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02)
          + a02 * (a01 * a12 - a11 * a02))
    lam = 0.0
    step = 0.0
    for _ in range(12):
        f = ((lam - c2) * lam + c1) * lam - c0
        df = (3.0 * lam - 2.0 * c2) * lam + c1
        step = f / df
        lam -= step
    x, y, z, d = _null_vector(a00, a01, a02, a11, a12, a22, lam)
    s = 1.0 / math.sqrt(d)
    # settled: after the last step the error is ~ step^2 / gap (quadratic convergence) and
    # sqrt(d) ~ gap on this unit-scale matrix; d well above the rank <= 1 threshold of
    # smallest_eigenvector
    ok = (m > 0.0 and m < math.inf and step * step * s <= 1e-17 and d > 1e-12
          and lam == lam)  # s = 1 / sqrt(d)
    return x * s, y * s, z * s, ok
