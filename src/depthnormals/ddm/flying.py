"""How the depth's jumps are drawn: in one pixel, or through mixed ("flying") pixels.

A sensor that averages light or depth over a pixel's footprint (a time-of-flight camera, a
renderer that supersamples, a blurring filter) returns, where a surface occludes another, pixels
whose depth lies between the two: the mixed or flying pixels (Reynolds et al., "Capturing
Time-of-Flight data with confidence", CVPR 2011; Fankhauser et al., "Kinect v2 for mobile robot
navigation", ICAR 2015); so does a depth resampled by interpolation (registered to another
camera). A depth that samples one ray per pixel (a ray caster) steps from one surface to the
other between two neighbours. Which of the two a frame holds changes what a jump does to the
windows beside it: a mixed pixel is an outlier of the size of the jump in every window that
holds it, while a clean step leaves each side's windows a plane of their own that the window
shift finds.

:func:`mixed_share` reads it off the depth alone: among the one-pixel jumps along rows and
columns (five consecutive valid depths ``p0 .. p4`` where ``p1`` and ``p3`` differ by more than
:data:`JUMP_REL` of the nearer and each side is flat: ``|p0 - p1|`` and ``|p3 - p4|`` under
:data:`SIDE_FLAT` of that step), the share whose middle pixel ``p2`` lies inside the step (its
position ``(p2 - p1) / (p3 - p1)`` in :data:`INSIDE`). A slope steep enough to pass the relative
test is not flat on its sides and is not counted; a step without a mixed pixel is seen by the
two windows whose middle pixel lies on either side, each counting a half. Medians over the
synthetic benchmark's frames (procedural seed 5, 80 a model; 10th-90th percentiles): clean and
Gaussian renders 0.012 (0-0.11), Kinect v2 (3x3 supersampled pixels) 0.69 (0.53-0.97), time
of flight 0.73 (0.58-1.0), realsense 0.85 (0.45-0.97), Kinect v1 0.27 (0.02-0.87); the real
frames of ``shared/data/real-sensors`` 0.11-0.19 (TUM's Kinect v1), 0.45-0.75 (NYU and SUN
RGB-D, registered to the colour camera), 0.95 (KITTI's lidar, projected into the image).
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["INSIDE", "JUMP_REL", "MIN_JUMPS", "SIDE_FLAT", "mixed_share"]

#: A jump: the depths on either side of the middle pixel differ by more than this share of the
#: nearer (also the jumps of the uncertainty map's densities, which import it).
JUMP_REL = 0.03
#: Each side of a jump is flat: the next depth outward within this share of the step.
SIDE_FLAT = 0.25
#: The middle pixel is mixed where its position across the step lies in this open interval
#: (0: the near side's depth, 1: the far side's).
INSIDE = (0.15, 0.85)
#: Fewer counted jumps than this: :func:`mixed_share` returns NaN (no reading).
MIN_JUMPS = 20


@nb.njit(cache=True, error_model="numpy", inline="always")
def _count(p0, p1, p2, p3, p4, rel, flat, lo, hi, n, m):
    """Add the jumps of five rows of depths (one per position, elementwise) to the per-column
    counters ``n`` (counted) and ``m`` (mixed). A step without a mixed pixel is seen by two
    windows, the middle pixel on either side (``t`` about 0 and 1): each counts a half (the
    same read either way along the row). NaN fails every comparison: not counted. No branch:
    the loop vectorises."""
    f1 = np.float32(1.0)
    f0 = np.float32(0.0)
    half = np.float32(0.5)
    for i in range(p0.size):
        a = p1[i]
        b = p3[i]
        d = b - a
        s = abs(d)
        near = a if a < b else b
        side = flat * s
        ok = (s > rel * near) & (abs(p0[i] - a) < side) & (abs(b - p4[i]) < side)
        t = (p2[i] - a) / d
        mixed = ok & (t > lo) & (t < hi)
        n[i] += f1 if mixed else (half if ok & (t == t) else f0)
        m[i] += f1 if mixed else f0


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _mixed_counts(z, rel, flat, lo, hi):
    """(counted, mixed) jumps of ``z`` (H, W; NaN invalid) along rows and columns."""
    h, w = z.shape
    f32 = np.float32
    rel = f32(rel)
    flat = f32(flat)
    lo = f32(lo)
    hi = f32(hi)
    nr = np.zeros(max(w - 4, 0), dtype=f32)  # per column: exact integers below 2^24
    mr = np.zeros(max(w - 4, 0), dtype=f32)
    nc = np.zeros(w, dtype=f32)
    mc = np.zeros(w, dtype=f32)
    if w >= 5:
        for v in range(h):
            a = z[v]
            _count(a[0:w - 4], a[1:w - 3], a[2:w - 2], a[3:w - 1], a[4:w], rel, flat, lo, hi,
                   nr, mr)
    for v in range(h - 4):
        _count(z[v], z[v + 1], z[v + 2], z[v + 3], z[v + 4], rel, flat, lo, hi, nc, mc)
    return (np.sum(nr.astype(np.float64)) + np.sum(nc.astype(np.float64)),
            np.sum(mr.astype(np.float64)) + np.sum(mc.astype(np.float64)))


def mixed_share(z: np.ndarray) -> float:
    """The share of the depth's one-pixel jumps drawn through a mixed pixel (module doc).

    Parameters
    ----------
    z : ndarray, shape (H, W), float32
        Depth (any unit: the tests are relative), NaN where invalid (as
        :func:`depthnormals.kernels.depth.prepare` returns it).

    Returns
    -------
    float
        In [0, 1]; NaN where fewer than :data:`MIN_JUMPS` jumps were counted.
    """
    with np.errstate(over="ignore"):  # float64 depth past float32's range reads as inf: a jump
        z = np.ascontiguousarray(z, dtype=np.float32)
    if z.ndim != 2:
        raise ValueError(f"z must be a 2-D depth (H, W), got shape {z.shape}")
    n, m = _mixed_counts(z, JUMP_REL, SIDE_FLAT, INSIDE[0], INSIDE[1])
    return float(m / n) if n >= MIN_JUMPS else float("nan")
