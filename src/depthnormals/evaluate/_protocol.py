"""The evaluation protocol: which pixels are scored, how errors count, where edges are."""

from __future__ import annotations

import numbers
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ..metrics import NormalMetrics, angular_error, summarize_errors

__all__ = [
    "HIST_BIN_DEG",
    "INVALID_POLICIES",
    "FrameScore",
    "Protocol",
    "discontinuity_mask",
    "score_frame",
    "scoring_mask",
]

#: How invalid (NaN) estimates count: ``"drop"`` leaves them out (coverage < 1 says how
#: many), ``"score90"`` scores them as 90-degree errors.
INVALID_POLICIES = ("drop", "score90")

#: Width (degrees) of the bins of the per-frame error histograms, from which pooled medians
#: and the error-vs-threshold curves are computed (pooled medians are exact to this width).
HIST_BIN_DEG = 0.01
_N_BINS = round(180.0 / HIST_BIN_DEG)


def _check_int(value: Any, name: str, *, minimum: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer >= {minimum}; got {type(value).__name__}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}; got {value}")
    return int(value)


def _check_real(value: Any, name: str, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number in ({lo}, {hi}); got {type(value).__name__}")
    value = float(value)
    if not (lo < value < hi):
        raise ValueError(f"{name} must lie in ({lo}, {hi}); got {value!r}")
    return value


@dataclass(frozen=True)
class Protocol:
    """How a frame is scored.

    Parameters
    ----------
    folded : bool, default True
        Fold errors above 90 degrees (``theta -> 180 - theta``): the sign-agnostic error of
        the 3F2N literature, whose ground truth has arbitrary orientation. False scores the
        signed angle in [0, 180] (both maps face the camera, so a flipped estimate is wrong).
    border : int, default 1
        Width in pixels of the image border left out of the score (the 3F2N protocol leaves
        out 1 pixel).
    invalid : {"drop", "score90"}, default "drop"
        NaN estimates on scored pixels are dropped (``coverage`` reports the share that got
        an estimate) or scored as 90-degree errors.
    edge_radius : int, default 2
        A pixel is "near a discontinuity" when a ground-truth edge lies within this many
        pixels (Chebyshev distance: a (2 r + 1)^2 square).
    edge_angle : float, default 10.0
        Degrees: two 4-neighbours whose ground-truth normals differ by more (sign-agnostic)
        form a normal edge (a crease).
    depth_jump : float, default 0.05
        Two 4-neighbours whose depths differ by more than this fraction of the nearer depth
        form a depth edge (an occlusion). A pixel next to one without ground truth (the
        silhouette against background or sky) is an edge too.
    """

    folded: bool = True
    border: int = 1
    invalid: str = "drop"
    edge_radius: int = 2
    edge_angle: float = 10.0
    depth_jump: float = 0.05

    def __post_init__(self) -> None:
        if not isinstance(self.folded, (bool, np.bool_)):
            raise TypeError(f"folded must be True or False; got {self.folded!r}")
        object.__setattr__(self, "folded", bool(self.folded))
        object.__setattr__(self, "border", _check_int(self.border, "border"))
        object.__setattr__(self, "edge_radius", _check_int(self.edge_radius, "edge_radius"))
        if not isinstance(self.invalid, str):
            raise TypeError(f"invalid must be one of {INVALID_POLICIES}; got {self.invalid!r}")
        if self.invalid not in INVALID_POLICIES:
            raise ValueError(f"unknown invalid policy {self.invalid!r}; valid choices: "
                             f"{', '.join(INVALID_POLICIES)}")
        object.__setattr__(self, "edge_angle", _check_real(self.edge_angle, "edge_angle", 0, 90))
        object.__setattr__(self, "depth_jump", _check_real(self.depth_jump, "depth_jump", 0, 1e9))

    def as_dict(self) -> dict[str, Any]:
        """The protocol as a plain, JSON-ready dict."""
        return asdict(self)


def _truth_valid(truth: np.ndarray) -> np.ndarray:
    t = truth.astype(np.float64, copy=False)
    norm2 = np.einsum("...i,...i->...", t, t)
    return np.isfinite(norm2) & (norm2 > 0)


def scoring_mask(truth: np.ndarray, mask: np.ndarray | None, *, border: int) -> np.ndarray:
    """Pixels that are scored: ground truth valid, inside ``mask``, off the border.

    Parameters
    ----------
    truth : ndarray, shape (H, W, 3)
        Ground-truth normals (NaN or zero vectors are invalid).
    mask : ndarray of bool, shape (H, W), optional
        The dataset's own validity mask.
    border : int
        Border width (pixels) left out on each side.

    Returns
    -------
    ndarray of bool, shape (H, W)

    Raises
    ------
    ValueError
        A border that leaves no pixel of the image (a run would score nothing and print "-").
    """
    ok = _truth_valid(np.asarray(truth))
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != ok.shape:
            raise ValueError(f"mask has shape {m.shape}; it must match the normals' {ok.shape}")
        if m.dtype != bool:
            raise TypeError(f"mask must be a boolean array; got dtype {m.dtype}")
        ok = ok & m
    b = _check_int(border, "border")
    h, w = ok.shape[:2]
    if 2 * b >= min(h, w):
        raise ValueError(f"a border of {b} px leaves no pixel of a {w}x{h} image to score; "
                         f"use a border below {(min(h, w) + 1) // 2}")
    if b:
        ok[:b] = False
        ok[-b:] = False
        ok[:, :b] = False
        ok[:, -b:] = False
    return ok


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Square (Chebyshev) dilation by ``radius`` pixels, separable: rows then columns."""
    if radius == 0:
        return mask.copy()
    h, w = mask.shape
    pad = np.pad(mask, radius)
    rows = np.zeros((h + 2 * radius, w), bool)
    for d in range(2 * radius + 1):
        rows |= pad[:, d:d + w]
    out = np.zeros((h, w), bool)
    for d in range(2 * radius + 1):
        out |= rows[d:d + h]
    return out


def discontinuity_mask(truth: Any, depth: Any, valid: Any, *, radius: int = 2,
                       edge_angle: float = 10.0, depth_jump: float = 0.05) -> np.ndarray:
    """Pixels within ``radius`` pixels of a ground-truth normal edge or depth edge.

    An edge lies between two 4-neighbours when (a) both are valid and their ground-truth
    normals differ by more than ``edge_angle`` degrees (sign-agnostic: a crease), or (b) both
    are valid and their depths differ by more than ``depth_jump`` times the nearer depth (an
    occlusion), or (c) exactly one of them is valid (a silhouette against background). Both
    pixels of such a pair are edge pixels; the result is their square dilation.

    Parameters
    ----------
    truth : array_like, shape (H, W, 3)
        Ground-truth normals.
    depth : array_like, shape (H, W)
        Depth of the frame (planar z).
    valid : array_like of bool, shape (H, W)
        Pixels with ground truth (e.g. ``Frame.mask``).
    radius : int, default 2
        Dilation radius in pixels (Chebyshev).
    edge_angle : float, default 10.0
        Crease threshold in degrees.
    depth_jump : float, default 0.05
        Relative depth jump threshold.

    Returns
    -------
    near : ndarray of bool, shape (H, W)

    Examples
    --------
    >>> import numpy as np
    >>> n = np.zeros((5, 8, 3)); n[..., 2] = -1
    >>> z = np.ones((5, 8)); z[:, 4:] = 2.0
    >>> discontinuity_mask(n, z, np.ones((5, 8), bool), radius=1)[0].astype(int).tolist()
    [0, 0, 1, 1, 1, 1, 0, 0]
    """
    t = np.asarray(truth, dtype=np.float64)
    z = np.asarray(depth, dtype=np.float64)
    v = np.asarray(valid)
    if t.ndim != 3 or t.shape[-1] != 3:
        raise ValueError(f"truth must have shape (H, W, 3); got {t.shape}")
    if z.shape != t.shape[:2] or v.shape != t.shape[:2]:
        raise ValueError(f"depth {z.shape} and valid {v.shape} must match the normals' "
                         f"{t.shape[:2]}")
    if v.dtype != bool:
        raise TypeError(f"valid must be a boolean array; got dtype {v.dtype}")
    radius = _check_int(radius, "radius")
    cos_t = np.cos(np.radians(_check_real(edge_angle, "edge_angle", 0, 90)))
    jump = _check_real(depth_jump, "depth_jump", 0, 1e9)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = t / np.linalg.norm(t, axis=-1, keepdims=True)
    edge = np.zeros(v.shape, bool)
    for axis in (0, 1):
        a = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        b = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        both = v[a] & v[b]
        with np.errstate(invalid="ignore"):
            crease = np.abs(np.einsum("...i,...i->...", t[a], t[b])) < cos_t
            step = np.abs(z[a] - z[b]) > jump * np.minimum(z[a], z[b])
        pair = (both & (crease | step)) | (v[a] ^ v[b])
        edge[a] |= pair
        edge[b] |= pair
    return _dilate(edge, radius) & v


@dataclass(frozen=True)
class FrameScore:
    """Scores of one estimate on one frame.

    Attributes
    ----------
    metrics : NormalMetrics
        Over the scored pixels (see :class:`Protocol`); ``count`` errors went in.
    scored : int
        Pixels scored (ground truth valid, inside mask and off the border).
    covered : int
        Scored pixels with a finite estimate (``coverage = covered / scored``).
    near_mean, smooth_mean : float
        Mean error within ``edge_radius`` of a discontinuity / elsewhere (NaN if none).
    near_count, smooth_count : int
        How many errors each mean is over.
    hist : ndarray of int64, shape (18000,)
        Histogram of the errors in bins of :data:`HIST_BIN_DEG` degrees over [0, 180].
    error : ndarray, shape (H, W)
        The error map (degrees) on scored pixels, NaN elsewhere (90 where an invalid
        estimate was scored as 90).
    """

    metrics: NormalMetrics
    scored: int
    covered: int
    near_mean: float
    smooth_mean: float
    near_count: int
    smooth_count: int
    hist: np.ndarray
    error: np.ndarray


def histogram(errors: np.ndarray) -> np.ndarray:
    """Counts of finite errors (degrees) in bins of :data:`HIST_BIN_DEG` over [0, 180]."""
    idx = np.clip((np.asarray(errors, np.float64) / HIST_BIN_DEG).astype(np.int64), 0, _N_BINS - 1)
    return np.bincount(idx.ravel(), minlength=_N_BINS).astype(np.int64)


def score_frame(estimate: Any, truth: Any, *, mask: Any = None, near: Any = None,
                protocol: Protocol | None = None) -> FrameScore:
    """Score one normal map against ground truth under a protocol.

    With ``invalid="drop"`` the metrics equal
    ``normal_metrics(estimate, truth, mask=scoring_mask(truth, mask, border=...),
    folded=...)`` exactly.

    Parameters
    ----------
    estimate, truth : array_like, shape (H, W, 3)
        Estimated and ground-truth normals.
    mask : array_like of bool, shape (H, W), optional
        The dataset's validity mask (ground truth must also be finite to be scored).
    near : array_like of bool, shape (H, W), optional
        Pixels near a discontinuity (see :func:`discontinuity_mask`); without it every
        scored pixel counts as smooth.
    protocol : Protocol, optional
        Default ``Protocol()``.

    Returns
    -------
    FrameScore
    """
    p = Protocol() if protocol is None else protocol
    if not isinstance(p, Protocol):
        raise TypeError(f"protocol must be a Protocol; got {type(p).__name__}")
    err = angular_error(estimate, truth, folded=p.folded)
    scored = scoring_mask(np.asarray(truth), mask, border=p.border)
    finite = np.isfinite(err) & scored
    n_scored, n_covered = int(scored.sum()), int(finite.sum())
    if p.invalid == "score90":
        err = np.where(finite, err, 90.0)
        used = scored
    else:
        used = finite
    err[~used] = np.nan
    values = err[used]
    metrics = summarize_errors(values, n_scored)
    if p.invalid == "score90":
        cov = n_covered / n_scored if n_scored else 0.0
        metrics = replace(metrics, coverage=float(cov))
    if near is None:
        near_m = np.zeros(err.shape, bool)
    else:
        near_m = np.asarray(near)
        if near_m.shape != err.shape or near_m.dtype != bool:
            raise ValueError(f"near must be a boolean array of shape {err.shape}")
    e_near = err[used & near_m]
    e_smooth = err[used & ~near_m]
    nan = float("nan")
    return FrameScore(
        metrics=metrics, scored=n_scored, covered=n_covered,
        near_mean=float(e_near.mean()) if e_near.size else nan,
        smooth_mean=float(e_smooth.mean()) if e_smooth.size else nan,
        near_count=int(e_near.size), smooth_count=int(e_smooth.size),
        hist=histogram(values), error=err,
    )
