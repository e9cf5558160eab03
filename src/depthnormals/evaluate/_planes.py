"""The plane reference: scoring normals on real depth that has no ground truth.

Real sensor frames (Kinect, Xtion, densified LiDAR) come without ground-truth normals, but
nearly all of them show large planes: floors, walls, table tops, a road. On a real plane the
true normal is the plane's normal everywhere, so a plane fitted to many thousands of points is
a reference far more accurate than any local estimate. :func:`plane_reference` finds those
planes (RANSAC, then connected regions and least-squares refits); :func:`score_planes` scores
an estimate on their interiors and rims. The protocol is in docs/evaluation.md, section "Real
sensors without ground truth: the plane reference".

This is our protocol (not from the 3F2N paper).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validate import check_int, check_positive, check_real
from ..camera import backproject
from ..metrics import angular_error
from ._planes_kernels import (
    chessboard_inside,
    chessboard_to,
    label_8connected,
    plane_inliers,
    plane_ratio,
)

__all__ = ["PlaneInfo", "PlaneReference", "plane_reference", "score_planes", "sensor_threshold"]

#: Inlier threshold ``max(THRESHOLD_FLOOR_M, THRESHOLD_Z2_PER_M * z^2)`` in metres (point to
#: plane distance). Kinect v1 quantises disparity to 1/8 px; with f ~ 580 px and baseline
#: 7.5 cm one step is ``z^2 / (8 * 580 * 0.075) = 0.00287 z^2`` m (1.1 cm at 2 m, 4.6 cm at
#: 4 m), so a point of a staircase lies within half a step, ``0.0014 z^2``, of the plane
#: through the steps. The z^2 coefficient is 3.5 half steps (1.2 full steps): the staircase
#: plus the sensor's random noise (about ``0.0012-0.0019 z^2`` m, Khoshelham and Elberink
#: 2012) fits inside. The floor, 1 cm, holds near-range noise and surface texture.
THRESHOLD_FLOOR_M = 0.01
THRESHOLD_Z2_PER_M = 0.005
#: A plane is kept when the RMS of ``residual / threshold(z)`` over its region is at most
#: this. Points spread uniformly across the band give 1/sqrt(3) = 0.58 (a curved surface
#: filling the band); the planes kept on the real frames give 0.10 - 0.51 (after the
#: reassignment, within KEEP_SLACK).
MAX_RMS_RATIO = 0.45
#: Planes down to this share of the image (768 px at 640 x 480) are extracted as
#: *competitors*: they are no references, but they take back the pixels of their surface that
#: lie inside a larger plane's threshold band (a box side standing on the floor: at 3 m the
#: floor's band climbs about 10 px up the side). At most COMPETITORS_PER_PLANE * max_planes
#: planes are extracted.
COMPETITOR_FRACTION = 0.0025
COMPETITORS_PER_PLANE = 4
#: Extraction stops after this many rejected planes in a row.
MAX_FAILURES = 5
#: A region that fails the residual tests is grown again within this share of the threshold
#: (two parallel surfaces closer than the threshold fail as one; the tighter band holds one).
SPLIT_FACTOR = 0.5
#: Runs of a consensus reference agree on a pixel when their planes there are this close.
CONSENSUS_DEG = 2.0
#: Hypotheses (the most inliers first) whose largest connected region is compared.
TOP_HYPOTHESES = 8
#: Rounds of reassignment and refits after the extraction.
REASSIGN_ROUNDS = 3
#: Two planes at more than this angle both fitting a pixel within their thresholds: the pixel
#: is on their crease and is no reference (nearly coplanar planes, e.g. one floor split in two
#: regions, share their pixels without a gap).
AMBIGUOUS_DEG = 10.0
#: The threshold for LiDAR depth, whose noise does not grow with z^2: 5 cm everywhere, 2.5
#: times the 2 cm range accuracy of a Velodyne HDL-64E (the densified KITTI frames add
#: interpolation between scan lines). :func:`sensor_threshold` picks it for a sensor text
#: that mentions LiDAR.
LIDAR_THRESHOLD = (0.05, 0.0)
#: A plane is kept when the quadratic trend of its ``residual / threshold`` (a least-squares
#: quadric in the plane's own coordinates) has an RMS of at most MAX_BEND_RATIO and at most
#: MAX_BEND_SHARE of the residual RMS (the second test only where that RMS exceeds 0.05).
#: Noise and quantisation steps have little trend across a region (measured on the planes
#: kept on the real frames of ``../shared/data/real-sensors``: trend RMS <= 0.29, <= 0.70 of
#: the residual RMS); a cap of a sphere is nearly all trend (0.18 - 0.58, 0.99 of the
#: residual RMS).
MAX_BEND_RATIO = 0.25
MAX_BEND_SHARE = 0.7
#: Hysteresis: a plane found under the limits above is kept after the reassignment while its
#: RMS and trend stay within this multiple of them (a Kinect floor sits at the limits, 0.45 /
#: 0.25, and would otherwise come and go with the seed).
KEEP_SLACK = 1.2
#: The trend is fitted to at most this many points of a region.
BEND_POINTS = 20000


@dataclass(frozen=True)
class PlaneInfo:
    """One reference plane: ``normal . X + offset = 0`` on the plane (camera frame, metres).

    Attributes
    ----------
    label : int
        Its value in :attr:`PlaneReference.labels`.
    normal : tuple of 3 float
        Unit normal facing the camera (``normal . X < 0`` on the plane), OpenCV frame.
    offset : float
        Distance from the camera centre to the plane (> 0).
    n_pixels, n_interior, n_rim : int
        Pixels of its region; those >= ``interior_px`` inside it; those 1 .. ``interior_px-1``.
    rms_m : float
        RMS point-to-plane distance over the region (metres).
    rms_ratio : float
        RMS of distance / inlier threshold (the rejection test, :data:`MAX_RMS_RATIO`).
    bend_ratio : float
        RMS of the quadratic trend of distance / threshold (the curvature test,
        :data:`MAX_BEND_RATIO`).
    median_depth : float
        Median depth of the region (metres).
    incidence_deg : float
        Angle between the normal and the viewing ray to the region's centroid (0 = seen head on).
    """

    label: int
    normal: tuple[float, float, float]
    offset: float
    n_pixels: int
    n_interior: int
    n_rim: int
    rms_m: float
    rms_ratio: float
    bend_ratio: float
    median_depth: float
    incidence_deg: float


@dataclass(frozen=True)
class PlaneReference:
    """Planes found in one depth frame, the reference of :func:`score_planes`.

    Attributes
    ----------
    labels : ndarray (H, W), int32
        Plane index per pixel, ``-1`` where there is none.
    normals : ndarray (P, 3), float64
        Unit plane normals facing the camera (OpenCV frame).
    offsets : ndarray (P,), float64
        Camera-to-plane distances: ``normals[k] . X + offsets[k] = 0`` on plane ``k``.
    distance : ndarray (H, W), int32
        Chessboard distance to the outside of the pixel's region (1 on its boundary, 0 off
        every region; the image border counts as outside).
    interior : ndarray (H, W), bool
        ``distance >= interior_px``.
    rim : ndarray (H, W), bool
        ``1 <= distance < interior_px``.
    planes : tuple of PlaneInfo
        Per-plane details, in label order.
    settings : dict
        The parameters that produced it (thresholds, seed, sizes).
    """

    labels: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    distance: np.ndarray
    interior: np.ndarray
    rim: np.ndarray
    planes: tuple[PlaneInfo, ...]
    settings: dict = field(default_factory=dict)

    @property
    def n_planes(self) -> int:
        """Number of reference planes."""
        return len(self.planes)

    def normal_map(self) -> np.ndarray:
        """Reference normal per pixel (H, W, 3) float64, NaN off every plane."""
        out = np.full((*self.labels.shape, 3), np.nan)
        on = self.labels >= 0
        out[on] = self.normals[self.labels[on]]
        return out


def sensor_threshold(meta: dict) -> tuple[float, float]:
    """The ``threshold`` of :func:`plane_reference` for a frame, from its ``meta``.

    ``meta["plane_threshold"]`` when given (a real sensor folder's ``intrinsics.json`` may
    carry it), :data:`LIDAR_THRESHOLD` when ``meta["sensor"]`` mentions LiDAR, else the
    structured-light default ``(THRESHOLD_FLOOR_M, THRESHOLD_Z2_PER_M)``.

    Examples
    --------
    >>> sensor_threshold({"sensor": "Velodyne HDL-64E LiDAR"}), sensor_threshold({})
    ((0.05, 0.0), (0.01, 0.005))
    """
    given = meta.get("plane_threshold")
    if given is not None:
        a, b = (float(t) for t in given)
        return a, b
    if "lidar" in str(meta.get("sensor", "")).lower():
        return LIDAR_THRESHOLD
    return THRESHOLD_FLOOR_M, THRESHOLD_Z2_PER_M


def _threshold(z: np.ndarray, floor_m: float, z2_per_m: float) -> np.ndarray:
    return np.maximum(floor_m, z2_per_m * z * z)


def _fit_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Total least squares plane through (N, 3) points, the normal facing the camera."""
    c = points.mean(axis=0)
    d = points - c
    _, vecs = np.linalg.eigh(d.T @ d)
    n = vecs[:, 0]
    if n @ c > 0:
        n = -n
    return n, float(-(n @ c))


def _largest_component(mask: np.ndarray) -> np.ndarray:
    labels = np.empty(mask.shape, np.int32)
    sizes = label_8connected(mask, labels)
    if sizes.size == 0:
        return np.zeros_like(mask)
    return labels == int(np.argmax(sizes))


def _dilate(mask: np.ndarray, r: int) -> np.ndarray:
    """Chessboard dilation by ``r`` px."""
    dist = np.empty(mask.shape, np.int32)
    chessboard_to(mask, dist)
    return dist <= r


def _inliers(pts: np.ndarray, thr: np.ndarray, allowed: np.ndarray, plane: np.ndarray
             ) -> np.ndarray:
    out = np.empty(allowed.shape, bool)
    plane_inliers(pts, thr, allowed, np.ascontiguousarray(plane, np.float64), out)
    return out


def _ratio(pts: np.ndarray, thr: np.ndarray, plane: np.ndarray) -> np.ndarray:
    out = np.empty(thr.shape)
    plane_ratio(pts, thr, np.ascontiguousarray(plane, np.float64), out)
    return out


def _hypotheses(pts: np.ndarray, remaining: np.ndarray, rng: np.random.Generator,
                n_hyp: int, radius: int) -> np.ndarray:
    """Planes (n, 4) through a remaining seed pixel and two remaining pixels near it.

    The partners lie ``radius/3 .. radius`` px from the seed (chessboard), so the three points
    usually sit on one surface and are far enough apart for the quantisation steps not to
    dominate their plane.
    """
    h, w = remaining.shape
    idx = np.flatnonzero(remaining)
    seeds = idx[rng.integers(0, idx.size, n_hyp)]
    sv, su = np.divmod(seeds, w)
    lo = max(1, radius // 3)
    mag = rng.integers(lo, radius + 1, (n_hyp, 2, 2)) * rng.choice([-1, 1], (n_hyp, 2, 2))
    pv = np.clip(sv[:, None] + mag[:, :, 0], 0, h - 1)
    pu = np.clip(su[:, None] + mag[:, :, 1], 0, w - 1)
    ok = remaining[pv, pu].all(axis=1)
    p0 = pts.reshape(-1, 3)[seeds]
    p1 = pts[pv[:, 0], pu[:, 0]]
    p2 = pts[pv[:, 1], pu[:, 1]]
    n = np.cross(p1 - p0, p2 - p0)
    norm = np.linalg.norm(n, axis=1)
    ok &= norm > 1e-12
    n = n[ok] / norm[ok, None]
    return np.concatenate([n, -np.einsum("ij,ij->i", n, p0[ok])[:, None]], axis=1)


def _best_hypothesis(pts: np.ndarray, thr: np.ndarray, remaining: np.ndarray, hyps: np.ndarray,
                     pick: np.ndarray) -> np.ndarray:
    """The hypothesis whose largest connected inlier region is largest, among the
    TOP_HYPOTHESES with the most inliers in the sampled pixels ``pick``.

    The inlier count alone favours planes that slice through many surfaces (a grazing plane
    through the floor and the furniture tops); the connected region is what is kept.
    """
    resid = np.abs(pts.reshape(-1, 3)[pick] @ hyps[:, :3].T + hyps[:, 3])
    counts = (resid <= thr.reshape(-1)[pick][:, None]).sum(axis=0)
    top = np.argsort(-counts, kind="stable")[:TOP_HYPOTHESES]
    sizes = []
    for k in top:
        sizes.append(int(_largest_component(_inliers(pts, thr, remaining, hyps[k])).sum()))
    return hyps[top[int(np.argmax(sizes))]]


@dataclass(frozen=True)
class _Params:
    floor_m: float
    z2_per_m: float
    min_pixels: int
    min_competitor: int
    max_rms_ratio: float
    max_bend_ratio: float
    n_hyp: int
    n_sample: int
    radius: int
    refits: int
    max_planes: int
    interior_px: int


def _grow(pts: np.ndarray, thr: np.ndarray, allowed: np.ndarray, plane: np.ndarray,
          refits: int) -> tuple[np.ndarray, np.ndarray]:
    """Largest connected inlier region of ``plane`` among ``allowed``, refitted ``refits`` times."""
    plane = np.asarray(plane, np.float64)
    region = np.zeros(allowed.shape, bool)
    for _ in range(refits):
        region = _largest_component(_inliers(pts, thr, allowed, plane))
        if region.sum() < 3:
            break
        n, d = _fit_plane(pts[region])
        plane = np.append(n, d)
    return region, plane


def _extract(pts: np.ndarray, thr: np.ndarray, valid: np.ndarray, p: _Params,
             rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    """Planes one after another, each removed from the remaining pixels when found."""
    remaining = valid.copy()
    found: list[tuple[np.ndarray, np.ndarray]] = []
    failures = 0
    while (len(found) < COMPETITORS_PER_PLANE * p.max_planes and failures < MAX_FAILURES
           and remaining.sum() >= p.min_competitor):
        hyps = _hypotheses(pts, remaining, rng, p.n_hyp, p.radius)
        if len(hyps) == 0:
            failures += 1
            continue
        idx = np.flatnonzero(remaining)
        pick = idx[rng.choice(idx.size, min(p.n_sample, idx.size), replace=False)]
        best = _best_hypothesis(pts, thr, remaining, hyps, pick)
        region, plane = _grow(pts, thr, remaining, best, p.refits)
        if region.sum() >= p.min_competitor and not _flat(pts, thr, region, plane, p):
            # two parallel surfaces closer than the threshold (two desk tops, a rug on the
            # floor) fail as one: try the tighter band, which holds one of them
            split, split_plane = _grow(pts, SPLIT_FACTOR * thr, remaining, plane, p.refits)
            if split.sum() >= p.min_competitor and _flat(pts, thr, split, split_plane, p):
                region, plane = split, split_plane
        remaining &= ~region
        if region.sum() < p.min_competitor or not _flat(pts, thr, region, plane, p):
            failures += 1
            continue
        failures = 0
        found.append((region, plane))
    return found


def _rms_ratio(pts: np.ndarray, thr: np.ndarray, region: np.ndarray, plane: np.ndarray) -> float:
    if not region.any():
        return float("inf")
    r = (pts[region] @ plane[:3] + plane[3]) / thr[region]
    return float(np.sqrt(np.mean(r * r)))


def _flat(pts: np.ndarray, thr: np.ndarray, region: np.ndarray, plane: np.ndarray,
          p: _Params, slack: float = 1.0) -> bool:
    """The residual tests: RMS within the band, no quadratic trend (curved surface); the two
    limits times ``slack`` (:data:`KEEP_SLACK` once a plane was found)."""
    rms = _rms_ratio(pts, thr, region, plane)
    if rms > slack * p.max_rms_ratio:
        return False
    bend = _bend_ratio(pts, thr, region, plane)
    return bend <= slack * p.max_bend_ratio and (rms <= 0.05 or bend <= MAX_BEND_SHARE * rms)


def _bend_ratio(pts: np.ndarray, thr: np.ndarray, region: np.ndarray, plane: np.ndarray) -> float:
    """RMS of the quadratic trend of ``residual / threshold`` over the region.

    The residuals are fitted by ``a + b x + c y + d x^2 + e x y + f y^2`` (``x, y``: in-plane
    coordinates of the points, normalised to unit RMS); the RMS of the fit minus its mean.
    Over at most BEND_POINTS points (every k-th in raster order): a trend needs no more.
    """
    q = pts[region]
    if q.shape[0] < 12:
        return float("inf")
    step = -(-q.shape[0] // BEND_POINTS)
    q = q[::step]
    n = plane[:3]
    r = (q @ n + plane[3]) / thr[region][::step]
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    c = q - q.mean(axis=0)
    x, y = c @ e1, c @ e2
    x = x / (np.sqrt(np.mean(x * x)) or 1.0)
    y = y / (np.sqrt(np.mean(y * y)) or 1.0)
    A = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)
    coef = np.linalg.lstsq(A.T @ A, A.T @ r, rcond=None)[0]  # normal equations: 6 x 6
    fit = A @ coef
    fit -= fit.mean()
    return float(np.sqrt(np.mean(fit * fit)))


def _reassign(pts: np.ndarray, thr: np.ndarray, valid: np.ndarray,
              found: list[tuple[np.ndarray, np.ndarray]], p: _Params
              ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Labels (H, W) and refitted planes: each pixel near a region goes to the plane it fits
    best, crease pixels that fit two planes go to none.

    A plane extracted first also takes the band of a neighbouring plane that lies within its
    threshold (a wall's foot in the floor's band). For REASSIGN_ROUNDS rounds: every valid
    pixel within ``p.radius`` px of a region and inside that plane's threshold is a candidate
    of the plane; it joins the candidate plane of the smallest ``residual / threshold``, unless
    a second candidate plane, at more than AMBIGUOUS_DEG to the first, fits it within its
    threshold too (the pixel lies on the crease of the two: its reference is ambiguous); each
    plane keeps its largest connected part and is refitted to it.
    """
    h, w = valid.shape
    regions = [r for r, _ in found]
    planes = [pl for _, pl in found]
    labels = np.full((h, w), -1, np.int32)
    for _ in range(REASSIGN_ROUNDS):
        best = np.full((h, w), np.inf)
        second = np.full((h, w), np.inf)
        labels = np.full((h, w), -1, np.int32)
        second_label = np.full((h, w), -1, np.int32)
        for k, (region, plane) in enumerate(zip(regions, planes, strict=True)):
            ratio = _ratio(pts, thr, plane)
            cand = valid & _dilate(region, p.radius) & (ratio <= 1.0)
            better = cand & (ratio < best)
            demoted = better & (labels >= 0)
            second[demoted] = best[demoted]
            second_label[demoted] = labels[demoted]
            runner = cand & ~better & (ratio < second)
            second[runner] = ratio[runner]
            second_label[runner] = k
            best[better] = ratio[better]
            labels[better] = k
        normals = np.array([pl[:3] for pl in planes])
        both = (labels >= 0) & (second_label >= 0)
        cosang = np.einsum("ij,ij->i", normals[labels[both]], normals[second_label[both]])
        crease = np.zeros((h, w), bool)
        crease[both] = cosang < np.cos(np.radians(AMBIGUOUS_DEG))
        labels[crease] = -1
        out = np.full((h, w), -1, np.int32)
        for k in range(len(planes)):
            part = _largest_component(labels == k)
            out[part] = k
            regions[k] = part
            if part.sum() >= 3:
                n, d = _fit_plane(pts[part])
                planes[k] = np.append(n, d)
        labels = out
    return labels, planes


def _check_params(threshold: Any, min_fraction: float, max_rms_ratio: float, hypotheses: int,
                  max_planes: int, interior_px: int, shape: tuple[int, int]) -> _Params:
    try:
        floor_m, z2 = (float(t) for t in threshold)
    except (TypeError, ValueError):
        raise TypeError("threshold must be a pair (floor_m, z2_per_m): the inlier distance "
                        f"max(floor_m, z2_per_m * z**2) in metres; got {threshold!r}") from None
    check_positive(floor_m, "threshold[0] (floor_m)")
    check_real(z2, "threshold[1] (z2_per_m)", minimum=0.0)
    frac = check_real(min_fraction, "min_fraction", minimum=1e-6, maximum=1.0)
    h, w = shape
    min_pixels = max(50, round(frac * h * w))
    return _Params(floor_m=floor_m, z2_per_m=z2, min_pixels=min_pixels,
                   min_competitor=min(min_pixels, max(30, round(COMPETITOR_FRACTION * h * w))),
                   max_rms_ratio=check_positive(max_rms_ratio, "max_rms_ratio"),
                   max_bend_ratio=MAX_BEND_RATIO,
                   n_hyp=check_int(hypotheses, "hypotheses", minimum=1, maximum=100_000),
                   n_sample=4000, radius=max(4, round(0.06 * min(h, w))), refits=3,
                   max_planes=check_int(max_planes, "max_planes", minimum=1, maximum=1000),
                   interior_px=check_int(interior_px, "interior_px", minimum=1, maximum=1000))


def plane_reference(depth: Any, K: Any, *, depth_scale: float | None = None, seed: int = 0,
                    threshold: tuple[float, float] = (THRESHOLD_FLOOR_M, THRESHOLD_Z2_PER_M),
                    min_fraction: float = 0.01, max_rms_ratio: float = MAX_RMS_RATIO,
                    hypotheses: int = 256, max_planes: int = 20,
                    interior_px: int = 5, consensus: int = 3) -> PlaneReference:
    """Find the large planes of a depth frame: the reference normals of a real sensor frame.

    Per plane, on the back-projected points of the pixels not yet taken:

    1. RANSAC: ``hypotheses`` planes through a random seed pixel and two pixels 1/3 to 1 times
       ``0.06 min(H, W)`` px from it; of the :data:`TOP_HYPOTHESES` with the most inliers
       among 4000 random points, the one with the largest connected inlier region wins. A
       point is an inlier within ``max(floor_m, z2_per_m * z^2)`` metres of the plane
       (the sensor's noise and disparity steps grow with ``z^2``: :data:`THRESHOLD_Z2_PER_M`).
    2. Its largest 8-connected image region of inlier pixels, refitted by total least squares
       (PCA of the region's points), three times.
    3. Kept if the region holds at least :data:`COMPETITOR_FRACTION` of the image (768 px at
       640 x 480), the RMS of residual / threshold is at most ``max_rms_ratio`` and the
       residuals have no quadratic trend (:data:`MAX_BEND_RATIO`: a curved surface); its
       pixels leave the pool either way. Extraction stops after five rejections in a row, at
       ``4 max_planes`` planes, or when fewer pixels than that minimum remain.

    Then three rounds of reassignment: each valid pixel within the sampling radius of a region
    and inside that plane's threshold goes to the plane it fits best (relative to the
    threshold), so a plane found first does not keep the band of its neighbour that lies
    within its threshold; a pixel that two planes more than 10 deg apart both fit is on their
    crease and goes to none; each plane keeps its largest connected part and is refitted. The
    references are the planes whose region holds at least ``min_fraction`` of the image (3072
    px at 640 x 480) and passes the residual tests again; the smaller ones served as
    competitors only.

    Parameters
    ----------
    depth : array_like (H, W)
        Planar depth, metres (integer depth with ``depth_scale``); 0 / NaN = invalid.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Camera intrinsics, 0-based pixel centres.
    depth_scale : float, optional
        Metres per unit for integer depth.
    seed : int, default 0
        Seed of the random sampling: the result is deterministic for a given seed.
    threshold : (float, float), default (0.01, 0.005)
        ``(floor_m, z2_per_m)`` of the inlier distance ``max(floor_m, z2_per_m z^2)``, metres.
        The default holds Kinect v1 disparity steps (half a step is ``0.0014 z^2``) with their
        noise; for a sensor whose noise does not grow with ``z^2`` (LiDAR) pass e.g.
        ``(0.03, 0.0)``.
    min_fraction : float, default 0.01
        Smallest region kept, as a share of the image's pixels (at least 50 px).
    max_rms_ratio : float, default 0.45
        Largest RMS of residual / threshold over a kept region (:data:`MAX_RMS_RATIO`).
    hypotheses : int, default 256
        RANSAC hypotheses per plane.
    max_planes : int, default 20
        Planes extracted: at most four times this (competitors included).
    interior_px : int, default 5
        Pixels at chessboard distance >= this from the region's outside are its interior,
        closer ones its rim.
    consensus : int, default 3
        Run the search with seeds ``seed .. seed + consensus - 1`` and keep the pixels of the
        first run where at least ``consensus // 2`` of the other runs have a plane within
        :data:`CONSENSUS_DEG` of the first run's (with three: the first run and one more
        agree); each plane keeps its largest connected part, at least ``min_fraction`` of
        the image; the planes are the first run's. On the real frames of
        ``../shared/data/real-sensors`` this halves how much a score moves with the seed
        (FALS, window 11, interior mean: 0.5 deg on average and 1.3 deg at most between
        seeds, against 1.0 and 3.3 deg for one run), at three times the cost;
        ``consensus=1`` is the single run.

    Returns
    -------
    PlaneReference
        Labels, normals (facing the camera), offsets, interior and rim masks, per-plane info.

    Examples
    --------
    >>> from depthnormals.analytic import tilted_plane
    >>> r = tilted_plane((0.0, 0.0, -1.0), 2.0).render(shape=(60, 80))
    >>> ref = plane_reference(r.depth, r.K)
    >>> ref.n_planes, round(float(ref.normals[0, 2]), 6), round(float(ref.offsets[0]), 6)
    (1, -1.0, 2.0)
    """
    pts = backproject(depth, K, depth_scale=depth_scale)
    valid = np.isfinite(pts[..., 2])
    p = _check_params(threshold, min_fraction, max_rms_ratio, hypotheses, max_planes,
                      interior_px, valid.shape)
    seed = check_int(seed, "seed", minimum=0, maximum=2**63 - 1)
    consensus = check_int(consensus, "consensus", minimum=1, maximum=100)
    thr = _threshold(np.where(valid, pts[..., 2], 0.0), p.floor_m, p.z2_per_m)
    labels, planes = _single_reference(pts, thr, valid, p, seed)
    if consensus > 1:
        votes = np.zeros(labels.shape, np.int32)
        for extra in range(1, consensus):
            other, other_planes = _single_reference(pts, thr, valid, p, seed + extra)
            votes += _agree(labels, planes, other, other_planes) >= 0
        labels = np.where(votes >= consensus // 2, labels, -1).astype(np.int32)
        labels, planes = _keep_large(labels, planes, p.min_pixels)
    return _assemble(pts, thr, labels, planes, p, seed, consensus)


def _single_reference(pts: np.ndarray, thr: np.ndarray, valid: np.ndarray, p: _Params,
                      seed: int) -> tuple[np.ndarray, list[tuple[np.ndarray, float]]]:
    """Labels and planes of one RANSAC run: extraction, reassignment, the final tests."""
    rng = np.random.default_rng(seed)
    found = _extract(pts, thr, valid, p, rng) if valid.sum() >= p.min_pixels else []
    labels, fitted = (_reassign(pts, thr, valid, found, p) if found
                      else (np.full(valid.shape, -1, np.int32), []))
    planes, keep = [], []
    for k, plane in enumerate(fitted):
        region = labels == k
        if region.sum() >= p.min_pixels and _flat(pts, thr, region, plane, p, KEEP_SLACK):
            planes.append((plane[:3], float(plane[3])))
            keep.append(k)
    # relabel the survivors 0..P-1 in order
    remap = np.full(len(found) + 1, -1, np.int32)
    remap[keep] = np.arange(len(keep), dtype=np.int32)
    return remap[labels], planes


def _agree(labels: np.ndarray, planes: list[tuple[np.ndarray, float]], other: np.ndarray,
           other_planes: list[tuple[np.ndarray, float]]) -> np.ndarray:
    """``labels`` where ``other`` also has a plane within CONSENSUS_DEG of it, else -1."""
    out = np.full(labels.shape, -1, np.int32)
    if not planes or not other_planes:
        return out
    n1 = np.array([n for n, _ in planes])
    n2 = np.array([n for n, _ in other_planes])
    both = (labels >= 0) & (other >= 0)
    cosang = np.einsum("ij,ij->i", n1[labels[both]], n2[other[both]])
    ok = np.zeros(labels.shape, bool)
    ok[both] = cosang >= np.cos(np.radians(CONSENSUS_DEG))
    out[ok] = labels[ok]
    return out


def _keep_large(labels: np.ndarray, planes: list[tuple[np.ndarray, float]], min_pixels: int
                ) -> tuple[np.ndarray, list[tuple[np.ndarray, float]]]:
    """Each plane's largest connected part; planes below ``min_pixels`` dropped, relabelled."""
    out = np.full(labels.shape, -1, np.int32)
    kept = []
    for k, plane in enumerate(planes):
        part = _largest_component(labels == k)
        if part.sum() >= min_pixels:
            out[part] = len(kept)
            kept.append(plane)
    return out, kept


def _assemble(pts: np.ndarray, thr: np.ndarray, labels: np.ndarray,
              planes: list[tuple[np.ndarray, float]], p: _Params, seed: int,
              consensus: int) -> PlaneReference:
    dist = np.empty(labels.shape, np.int32)
    chessboard_inside(np.ascontiguousarray(labels, np.int32), dist)
    interior = dist >= p.interior_px
    rim = (dist >= 1) & ~interior
    normals = np.array([n for n, _ in planes], np.float64).reshape(-1, 3)
    offsets = np.array([d for _, d in planes], np.float64)
    infos = []
    for k, (n, d) in enumerate(planes):
        region = labels == k
        q = pts[region]
        r = q @ n + d
        c = q.mean(axis=0)
        inc = np.degrees(np.arccos(np.clip(-(n @ c) / np.linalg.norm(c), -1.0, 1.0)))
        infos.append(PlaneInfo(
            label=k, normal=tuple(float(x) for x in n), offset=float(d),
            n_pixels=int(region.sum()), n_interior=int((interior & region).sum()),
            n_rim=int((rim & region).sum()), rms_m=float(np.sqrt(np.mean(r * r))),
            rms_ratio=float(np.sqrt(np.mean((r / thr[region]) ** 2))),
            bend_ratio=_bend_ratio(pts, thr, region, np.append(n, d)),
            median_depth=float(np.median(q[:, 2])), incidence_deg=float(inc)))
    settings = {"threshold": [p.floor_m, p.z2_per_m], "min_pixels": p.min_pixels,
                "min_competitor_pixels": p.min_competitor,
                "max_rms_ratio": p.max_rms_ratio, "hypotheses": p.n_hyp,
                "sample_points": p.n_sample, "radius_px": p.radius, "refits": p.refits,
                "max_planes": p.max_planes, "interior_px": p.interior_px, "seed": seed,
                "consensus": consensus}
    return PlaneReference(labels=labels, normals=normals, offsets=offsets, distance=dist,
                          interior=interior, rim=rim, planes=tuple(infos), settings=settings)


def _stats(err: np.ndarray, sel: np.ndarray) -> tuple[float, float, int, int]:
    """(mean, median, scored, reference) of the finite errors in ``sel``."""
    e = err[sel]
    n_ref = int(e.size)
    e = e[np.isfinite(e)]
    if e.size == 0:
        return float("nan"), float("nan"), 0, n_ref
    return float(e.mean()), float(np.median(e)), int(e.size), n_ref


def _share(num: int, den: int) -> float:
    return num / den if den else float("nan")


def score_planes(normals: Any, ref: PlaneReference, *, folded: bool = False) -> dict[str, Any]:
    """Angular error of a normal map on the planes of a :class:`PlaneReference`.

    The error is ``depthnormals.angular_error`` (degrees, ``atan2(|n x g|, n . g)`` on
    renormalised vectors) against the plane's normal, on the plane interiors (chessboard
    distance >= ``interior_px`` from the region's outside, 5 by default) and rims (1 to
    ``interior_px - 1`` px inside). A NaN (or zero) estimate is not scored but lowers the
    coverage.

    Parameters
    ----------
    normals : array_like (H, W, 3)
        The estimate, OpenCV camera frame.
    ref : PlaneReference
        From :func:`plane_reference` on the same frame.
    folded : bool, default False
        Fold errors over 90 deg (``180 - theta``) for estimates of arbitrary orientation. The
        reference faces the camera, so the default scores orientation too.

    Returns
    -------
    dict
        ``interior_mean``, ``interior_median``, ``rim_mean``, ``rim_median`` (degrees, NaN
        when nothing is scored), ``coverage`` (share of reference pixels, interior and rim,
        with a finite estimate), ``interior_coverage``, ``rim_coverage``, ``n_interior``,
        ``n_rim`` (reference pixels), ``scored_interior``, ``scored_rim``, ``n_planes`` and
        ``planes``: one dict per plane with the same keys (``label`` added, no ``planes``).

    Examples
    --------
    >>> from depthnormals.analytic import tilted_plane
    >>> r = tilted_plane((0.0, 0.0, -1.0), 2.0).render(shape=(60, 80))
    >>> ref = plane_reference(r.depth, r.K)
    >>> s = score_planes(r.normals, ref)
    >>> round(s["interior_mean"], 6), s["coverage"], s["n_interior"], s["n_rim"]
    (0.0, 1.0, 3744, 1056)
    """
    if not isinstance(ref, PlaneReference):
        raise TypeError(f"ref must be a PlaneReference (from plane_reference); got "
                        f"{type(ref).__name__}")
    err = angular_error(normals, ref.normal_map(), folded=folded)
    if err.shape != ref.labels.shape:
        raise ValueError(f"normals have shape {err.shape} but the reference {ref.labels.shape}")
    out = _score_masks(err, ref.interior, ref.rim)
    out["n_planes"] = ref.n_planes
    planes = []
    for k in range(ref.n_planes):
        region = ref.labels == k
        entry = {"label": k}
        entry.update(_score_masks(err, ref.interior & region, ref.rim & region))
        planes.append(entry)
    out["planes"] = planes
    return out


def _score_masks(err: np.ndarray, interior: np.ndarray, rim: np.ndarray) -> dict[str, Any]:
    i_mean, i_med, i_scored, i_ref = _stats(err, interior)
    r_mean, r_med, r_scored, r_ref = _stats(err, rim)
    return {"interior_mean": i_mean, "interior_median": i_med, "rim_mean": r_mean,
            "rim_median": r_med, "coverage": _share(i_scored + r_scored, i_ref + r_ref),
            "interior_coverage": _share(i_scored, i_ref), "rim_coverage": _share(r_scored, r_ref),
            "n_interior": i_ref, "n_rim": r_ref, "scored_interior": i_scored,
            "scored_rim": r_scored}
