"""Figure of a plane reference (matplotlib, imported lazily): the planes over the depth."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ._creases import CreaseBand
from ._figures import _save
from ._planes import PlaneReference

__all__ = ["plane_colours", "plot_planes"]


def plane_colours(n: int) -> np.ndarray:
    """``n`` distinct RGB colours in [0, 1] (golden-ratio hues, full saturation)."""
    import colorsys

    return np.array([colorsys.hsv_to_rgb((0.61803398875 * k) % 1.0, 0.85, 0.95)
                     for k in range(n)]).reshape(-1, 3)


def planes_overlay(depth: np.ndarray, ref: PlaneReference) -> np.ndarray:
    """RGB image (H, W, 3) in [0, 1]: the depth in grey, each plane's interior in its colour,
    its rim in the same colour lightened, no-depth pixels black."""
    z = np.asarray(depth, np.float64)
    ok = np.isfinite(z) & (z > 0)
    grey = np.zeros(z.shape)
    if ok.any():
        lo, hi = np.percentile(z[ok], [1, 99])
        grey[ok] = 0.25 + 0.6 * np.clip((z[ok] - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
    img = np.repeat(grey[..., None], 3, axis=2)
    cols = plane_colours(ref.n_planes)
    on = ref.labels >= 0
    c = cols[ref.labels[on]] if ref.n_planes else np.zeros((0, 3))
    shade = grey[on][:, None]
    inner = ref.interior[on][:, None]
    img[on] = np.where(inner, 0.75 * c + 0.25 * shade, 0.35 * c + 0.65)
    return img


#: Colour of the crease bands in the planes panel.
BAND_RGB = (0.1, 0.1, 0.1)


def plot_planes(path: str | Path, depth: np.ndarray, ref: PlaneReference, *, title: str = "",
                errors: Mapping[str, np.ndarray] | None = None, vmax: float = 20.0,
                dpi: int = 100, band: CreaseBand | None = None) -> None:
    """The plane reference of one frame, written as PNG atomically.

    Panels, each titled: (i) depth (metres) with its colour bar; (ii) the planes over the
    grey depth, interiors in the plane's colour, rims lightened, each plane numbered at its
    interior's centre with its pixel count, and the crease bands of ``band`` (if given) in
    near-black; (iii ...) one angular-error map per method in ``errors`` (degrees, 0 -
    ``vmax``), on the reference pixels only (and the bands').
    """
    from matplotlib.figure import Figure

    errors = dict(errors or {})
    n = 2 + len(errors)
    h, w = ref.labels.shape
    fig = Figure(figsize=(4.2 * min(n, 4), 4.2 * h / w * ((n + 3) // 4) + 0.6))
    cols = min(n, 4)
    rows = (n + 3) // 4
    ax = fig.add_subplot(rows, cols, 1)
    z = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan)
    im = ax.imshow(z, cmap="viridis")
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02, label="m")
    ax.set_title("depth (m)")
    ax = fig.add_subplot(rows, cols, 2)
    overlay = planes_overlay(depth, ref)
    scored = ref.labels >= 0
    on_band = band.mask if band is not None else np.zeros_like(scored)
    banded = bool(on_band.any())
    if banded:
        overlay[on_band] = 0.6 * np.asarray(BAND_RGB) + 0.4 * overlay[on_band]
        scored = scored | on_band
    ax.imshow(overlay)
    for info in ref.planes:
        v, u = np.nonzero((ref.labels == info.label) & ref.interior)
        if v.size:
            ax.text(float(np.median(u)), float(np.median(v)), str(info.label), color="black",
                    ha="center", va="center", fontsize=8,
                    bbox={"facecolor": "white", "alpha": 0.7, "pad": 1, "linewidth": 0})
    ax.set_title(f"{ref.n_planes} planes: interior (solid), rim (light)"
                 + ("\ncrease bands (dark)" if banded else ""))
    for i, (label, err) in enumerate(errors.items()):
        ax = fig.add_subplot(rows, cols, 3 + i)
        e = np.where(scored, err, np.nan)
        im = ax.imshow(e, cmap="magma", vmin=0.0, vmax=vmax)
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02, label="deg")
        ax.set_title(f"{label}: error on planes" + ("\nand crease bands" if banded else ""))
    for a in fig.axes:
        if a.images and a.get_label() != "<colorbar>":
            a.set_xticks([])
            a.set_yticks([])
    if title:
        fig.suptitle(title)
    _save(fig, Path(path), dpi)
