"""8-bit pictures of depth, normals and angular errors, without matplotlib."""

from __future__ import annotations

import numpy as np

from .io import normals_to_rgb8

__all__ = ["colorize", "error_to_rgb8", "normals_to_rgb8", "panel"]

# anchor colours (RGB, 0-255) sampled from perceptually uniform maps
_MAPS = {
    "viridis": [(68, 1, 84), (72, 40, 120), (62, 74, 137), (49, 104, 142), (38, 130, 142),
                (31, 158, 137), (53, 183, 121), (109, 205, 89), (180, 222, 44), (253, 231, 37)],
    "inferno": [(0, 0, 4), (31, 12, 72), (85, 15, 109), (136, 34, 106), (186, 54, 85),
                (227, 89, 51), (249, 140, 10), (249, 201, 50), (252, 255, 164)],
}


def colorize(values: np.ndarray, *, vmin: float | None = None, vmax: float | None = None,
             cmap: str = "viridis") -> np.ndarray:
    """Map a 2-D array to RGB uint8 with a perceptual colour map; NaN becomes black.

    Parameters
    ----------
    values : ndarray, shape (H, W)
    vmin, vmax : float, optional
        Colour range; default the 1st and 99th percentiles of the finite values.
    cmap : {"viridis", "inferno"}
    """
    if cmap not in _MAPS:
        raise ValueError(f"unknown cmap {cmap!r}; valid: {', '.join(_MAPS)}")
    x = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(x)
    if vmin is None or vmax is None:
        lo, hi = (np.percentile(x[ok], [1, 99]) if ok.any() else (0.0, 1.0))
        vmin = lo if vmin is None else vmin
        vmax = hi if vmax is None else vmax
    span = vmax - vmin if vmax > vmin else 1.0
    t = np.clip((np.where(ok, x, vmin) - vmin) / span, 0.0, 1.0)
    anchors = np.asarray(_MAPS[cmap], dtype=np.float64)
    pos = np.linspace(0.0, 1.0, len(anchors))
    rgb = np.stack([np.interp(t, pos, anchors[:, c]) for c in range(3)], axis=-1)
    out = (rgb + 0.5).astype(np.uint8)
    out[~ok] = 0
    return out


def error_to_rgb8(error_deg: np.ndarray, *, vmax: float = 30.0) -> np.ndarray:
    """Angular error map (degrees) as RGB uint8, 0..vmax on the inferno map, NaN black."""
    return colorize(error_deg, vmin=0.0, vmax=vmax, cmap="inferno")


def panel(images: list[np.ndarray], *, gap: int = 4) -> np.ndarray:
    """Place RGB uint8 images of equal height side by side with white gaps."""
    if not images:
        raise ValueError("panel needs at least one image")
    h = images[0].shape[0]
    parts = []
    for i, img in enumerate(images):
        if img.shape[0] != h or img.ndim != 3 or img.shape[2] != 3:
            raise ValueError(f"image {i} has shape {img.shape}; all must be (H={h}, W, 3)")
        if i:
            parts.append(np.full((h, gap, 3), 255, np.uint8))
        parts.append(img.astype(np.uint8, copy=False))
    return np.concatenate(parts, axis=1)
