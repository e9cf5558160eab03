"""Angular error between normal maps, and the metrics of the surface-normal literature."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ._validate import check_normals

__all__ = ["THRESHOLDS", "NormalMetrics", "angular_error", "normal_metrics"]

#: Thresholds (degrees) of the "share of pixels under t" metrics.
THRESHOLDS = (5.0, 11.25, 22.5, 30.0)


def _unit(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = n.astype(np.float64, copy=False)
    norm = np.sqrt(np.einsum("...i,...i->...", n, n))
    ok = np.isfinite(norm) & (norm > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return n / norm[..., None], ok


def angular_error(estimate: Any, truth: Any, *, folded: bool = False) -> np.ndarray:
    """Per-pixel angle between two normal maps, in degrees.

    Both maps are renormalised, then ``theta = atan2(|n x g|, n . g)`` (accurate near 0 and
    180 degrees, unlike ``acos``).

    Parameters
    ----------
    estimate, truth : array_like, shape (H, W, 3)
        Normal maps; any length, NaN or zero vectors mark invalid pixels.
    folded : bool, default False
        Map theta > 90 to 180 - theta (sign-agnostic error, as in the 3F2N literature whose
        ground truth has arbitrary orientation).

    Returns
    -------
    error : ndarray, shape (H, W), float64
        Degrees in [0, 180] (or [0, 90] folded); NaN where either normal is invalid.

    Examples
    --------
    >>> import numpy as np
    >>> angular_error(np.array([[[0, 0, -1.0]]]), np.array([[[0, 1.0, -1.0]]])).round(6).tolist()
    [[45.0]]
    """
    n = check_normals(estimate, name="estimate")
    g = check_normals(truth, name="truth", shape=n.shape[:2])
    n, okn = _unit(n)
    g, okg = _unit(g)
    cross = np.cross(n, g)
    err = np.degrees(np.arctan2(np.sqrt(np.einsum("...i,...i->...", cross, cross)),
                                np.einsum("...i,...i->...", n, g)))
    if folded:
        err = np.where(err > 90.0, 180.0 - err, err)
    err[~(okn & okg)] = np.nan
    return err


@dataclass(frozen=True)
class NormalMetrics:
    """Summary of angular errors over a set of pixels (degrees; shares in [0, 1]).

    ``coverage`` is the share of ground-truth-valid pixels (inside the mask) that got a
    finite estimate; every other metric is over those pixels only (NaN estimates dropped).
    """

    mean: float
    median: float
    rmse: float
    a5: float
    a11_25: float
    a22_5: float
    a30: float
    coverage: float
    count: int

    def as_dict(self) -> dict[str, float]:
        """The metrics as a plain dict."""
        return asdict(self)


def summarize_errors(errors: np.ndarray, n_truth: int) -> NormalMetrics:
    """Metrics of a 1-D array of finite errors (degrees) out of ``n_truth`` scored pixels."""
    e = np.asarray(errors, dtype=np.float64).ravel()
    if e.size == 0:
        nan = float("nan")
        return NormalMetrics(nan, nan, nan, nan, nan, nan, nan, 0.0, 0)
    shares = [float(np.mean(e < t)) for t in THRESHOLDS]
    return NormalMetrics(
        mean=float(e.mean()), median=float(np.median(e)), rmse=float(np.sqrt(np.mean(e * e))),
        a5=shares[0], a11_25=shares[1], a22_5=shares[2], a30=shares[3],
        coverage=float(e.size / n_truth) if n_truth else 0.0, count=int(e.size),
    )


def normal_metrics(estimate: Any, truth: Any, *, mask: Any = None,
                   folded: bool = False) -> NormalMetrics:
    """Mean, median, RMSE, shares under 5 / 11.25 / 22.5 / 30 degrees and coverage.

    Parameters
    ----------
    estimate, truth : array_like, shape (H, W, 3)
        Estimated and ground-truth normals (NaN or zero vectors are invalid).
    mask : array_like of bool, shape (H, W), optional
        Pixels to score (e.g. ground truth valid minus a border). Pixels whose ground truth
        is invalid are never scored.
    folded : bool, default False
        Fold errors above 90 degrees (see :func:`angular_error`).

    Returns
    -------
    NormalMetrics
        Pooled over the scored pixels; ``coverage`` = scored pixels with a finite estimate /
        scored pixels with valid ground truth.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.zeros((2, 2, 3)); g[..., 2] = -1
    >>> m = normal_metrics(g, g)
    >>> (m.mean, m.coverage)
    (0.0, 1.0)
    """
    err = angular_error(estimate, truth, folded=folded)
    _, okg = _unit(np.asarray(truth))
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != err.shape:
            raise ValueError(f"mask has shape {m.shape}; it must match the normals' {err.shape}")
        if m.dtype != bool:
            raise TypeError(f"mask must be a boolean array; got dtype {m.dtype}")
        okg = okg & m
    return summarize_errors(err[okg & np.isfinite(err)], int(okg.sum()))
