"""Figures (matplotlib, imported lazily): the paper's Fig. 3 layout and threshold curves."""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io import normals_to_rgb8, write_bytes_atomic

__all__ = ["plot_fig3", "plot_threshold_curves", "require_matplotlib"]


def require_matplotlib() -> None:
    """Raise ImportError with the install hint when matplotlib is missing."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("figures need matplotlib: pip install 'depthnormals[plot]' "
                          "(or pass figures=0 / --figures 0)") from exc


def _save(fig: Any, path: Path, dpi: int) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    write_bytes_atomic(path, buf.getvalue())


def plot_fig3(path: str | Path, depth: np.ndarray, truth: np.ndarray, mask: np.ndarray,
              estimate: np.ndarray, estimate_label: str,
              errors: Mapping[str, np.ndarray], *, title: str = "", vmax: float = 20.0,
              crop: bool = True, dpi: int = 110) -> None:
    """One row in the paper's Fig. 3 layout, written as PNG atomically.

    Panels, each titled: (i) depth with a colour bar in the dataset's units (metres for metric
    data: the 3F2N scenes use their own), (ii) ground-truth normals,
    (iii) the estimate of ``estimate_label``, then one angular-error map per method on a
    shared colour scale [0, ``vmax``] degrees with its colour bar.
    Normals are drawn as RGB = (1 - n) / 2; pixels outside ``mask`` are black.

    Parameters
    ----------
    path : str or Path
        Output PNG.
    depth : ndarray (H, W)
    truth, estimate : ndarray (H, W, 3)
    mask : ndarray of bool (H, W)
        Scored pixels (the pictures show only these).
    estimate_label : str
    errors : mapping of label -> ndarray (H, W)
        Error maps in degrees, NaN where not scored.
    title : str
    vmax : float
        Top of the error colour scale (degrees).
    crop : bool, default True
        Crop every panel to the bounding box of ``mask`` (plus a 6 % margin).
    dpi : int
    """
    require_matplotlib()
    from matplotlib.figure import Figure

    if crop and np.any(mask):
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        pad = max(2, round(0.06 * max(mask.shape)))
        win = (slice(max(rows[0] - pad, 0), rows[-1] + pad + 1),
               slice(max(cols[0] - pad, 0), cols[-1] + pad + 1))
        depth, truth, mask, estimate = depth[win], truth[win], mask[win], estimate[win]
        errors = {k: v[win] for k, v in errors.items()}

    n = 3 + len(errors)
    h, w = depth.shape
    fig = Figure(figsize=(2.6 * n * w / max(h, w) + 0.8, 2.6 * h / max(h, w) + 0.7),
                 layout="constrained")
    axes = fig.subplots(1, n, squeeze=False)[0]
    z = np.where(mask, depth, np.nan)
    lo, hi = (np.nanpercentile(z, [1, 99]) if np.any(mask) else (0.0, 1.0))
    import matplotlib

    depth_image = axes[0].imshow(z, cmap=matplotlib.colormaps["viridis"].with_extremes(bad="black"),
                                 vmin=lo, vmax=hi, interpolation="nearest")
    axes[0].set_title("(i) depth", fontsize=8)
    zbar = fig.colorbar(depth_image, ax=axes[0], location="bottom", fraction=0.05, pad=0.03,
                        shrink=0.9)
    zbar.set_label("depth (dataset units; m for metric data)", fontsize=8)
    zbar.ax.tick_params(labelsize=7)
    shown = truth.copy()
    shown[~mask] = np.nan
    axes[1].imshow(normals_to_rgb8(shown), interpolation="nearest")
    axes[1].set_title("(ii) ground truth", fontsize=8)
    est = np.array(estimate, dtype=np.float32)
    est[~mask] = np.nan
    axes[2].imshow(normals_to_rgb8(est), interpolation="nearest")
    axes[2].set_title(f"(iii) {estimate_label}", fontsize=8)
    roman = ["iv", "v", "vi", "vii", "viii", "ix", "x", "xi", "xii", "xiii", "xiv", "xv"]
    cmap = matplotlib.colormaps["jet"].with_extremes(bad="black")
    image = None
    for i, (label, err) in enumerate(errors.items()):
        ax = axes[3 + i]
        image = ax.imshow(err, cmap=cmap, vmin=0.0, vmax=vmax, interpolation="nearest")
        num = roman[i] if i < len(roman) else str(4 + i)
        ax.set_title(f"({num}) error {label}\nmean {np.nanmean(err):.2f} deg", fontsize=8)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    if image is not None:
        bar = fig.colorbar(image, ax=list(axes[3:]), fraction=0.05, pad=0.02, shrink=0.9)
        bar.set_label("angular error (deg)", fontsize=8)
        bar.ax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    _save(fig, Path(path), dpi)


def plot_threshold_curves(path: str | Path, thresholds: Sequence[float],
                          curves: Mapping[str, Mapping[str, Sequence[float]]], *,
                          title: str = "", xmax: float = 30.0, dpi: int = 110) -> None:
    """Error-vs-threshold curves, one panel per group and one line per method (PNG, atomic).

    Parameters
    ----------
    path : str or Path
    thresholds : sequence of float
        Degrees.
    curves : mapping group -> (mapping label -> shares in [0, 1])
    title : str
    xmax : float
        Right end of the threshold axis (degrees).
    dpi : int
    """
    require_matplotlib()
    from matplotlib.figure import Figure

    groups = list(curves)
    cols = min(len(groups), 3)
    rows = -(-len(groups) // cols)
    fig = Figure(figsize=(5.6 * cols, 4.0 * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    t = np.asarray(thresholds)
    for ax, g in zip(axes, groups, strict=False):
        for i, (label, share) in enumerate(curves[g].items()):
            ax.plot(t, 100 * np.asarray(share, dtype=float), label=label, lw=1.3,
                    ls=("-", "--", ":", "-.")[(i // 10) % 4])
        for x in (11.25, 22.5, 30.0):
            ax.axvline(x, color="0.85", lw=0.8, zorder=0)
        ax.set_xlim(0, xmax)
        ax.set_ylim(0, 100)
        ax.set_xlabel("threshold t (deg)", fontsize=8)
        ax.set_ylabel("pixels with error < t (%)", fontsize=8)
        ax.set_title(g, fontsize=9)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    for ax in axes[len(groups):]:
        ax.set_visible(False)
    if title:
        fig.suptitle(title, fontsize=10)
    _save(fig, Path(path), dpi)
