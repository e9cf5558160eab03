"""8-bit pictures of depth, normals and angular errors, without matplotlib."""

from __future__ import annotations

import numpy as np

from .io import normals_to_rgb8

__all__ = ["colorbar", "colorize", "error_to_rgb8", "normals_to_rgb8", "panel", "text_mask",
           "titled_panel"]

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


# A 5 x 7 pixel font (rows top to bottom, bit 4 = leftmost column) for titles and tick labels;
# upper-case letters are drawn in lower case, characters it lacks as a box.
_FONT = {
    " ": (0, 0, 0, 0, 0, 0, 0),
    "0": (14, 17, 19, 21, 25, 17, 14), "1": (4, 12, 4, 4, 4, 4, 14),
    "2": (14, 17, 1, 2, 4, 8, 31), "3": (31, 2, 4, 2, 1, 17, 14),
    "4": (2, 6, 10, 18, 31, 2, 2), "5": (31, 16, 30, 1, 1, 17, 14),
    "6": (6, 8, 16, 30, 17, 17, 14), "7": (31, 1, 2, 4, 8, 8, 8),
    "8": (14, 17, 17, 14, 17, 17, 14), "9": (14, 17, 17, 15, 1, 2, 12),
    "a": (0, 0, 14, 1, 15, 17, 15), "b": (16, 16, 22, 25, 17, 17, 30),
    "c": (0, 0, 14, 16, 16, 17, 14), "d": (1, 1, 13, 19, 17, 17, 15),
    "e": (0, 0, 14, 17, 31, 16, 14), "f": (6, 9, 8, 28, 8, 8, 8),
    "g": (0, 15, 17, 17, 15, 1, 14), "h": (16, 16, 22, 25, 17, 17, 17),
    "i": (4, 0, 12, 4, 4, 4, 14), "j": (2, 0, 6, 2, 2, 18, 12),
    "k": (16, 16, 18, 20, 24, 20, 18), "l": (12, 4, 4, 4, 4, 4, 14),
    "m": (0, 0, 26, 21, 21, 17, 17), "n": (0, 0, 22, 25, 17, 17, 17),
    "o": (0, 0, 14, 17, 17, 17, 14), "p": (0, 0, 30, 17, 30, 16, 16),
    "q": (0, 0, 13, 19, 15, 1, 1), "r": (0, 0, 22, 25, 16, 16, 16),
    "s": (0, 0, 14, 16, 14, 1, 30), "t": (8, 8, 28, 8, 8, 9, 6),
    "u": (0, 0, 17, 17, 17, 19, 13), "v": (0, 0, 17, 17, 17, 10, 4),
    "w": (0, 0, 17, 17, 21, 21, 10), "x": (0, 0, 17, 10, 4, 10, 17),
    "y": (0, 0, 17, 17, 15, 1, 14), "z": (0, 0, 31, 2, 4, 8, 31),
    "(": (2, 4, 8, 8, 8, 4, 2), ")": (8, 4, 2, 2, 2, 4, 8),
    "[": (14, 8, 8, 8, 8, 8, 14), "]": (14, 2, 2, 2, 2, 2, 14),
    ".": (0, 0, 0, 0, 0, 12, 12), ",": (0, 0, 0, 0, 12, 4, 8),
    ":": (0, 12, 12, 0, 12, 12, 0), "-": (0, 0, 0, 31, 0, 0, 0),
    "+": (0, 4, 4, 31, 4, 4, 0), "=": (0, 0, 31, 0, 31, 0, 0),
    "/": (0, 1, 2, 4, 8, 16, 0), "|": (4, 4, 4, 4, 4, 4, 4),
    "_": (0, 0, 0, 0, 0, 0, 31), "<": (2, 4, 8, 16, 8, 4, 2),
    ">": (8, 4, 2, 1, 2, 4, 8), "%": (24, 25, 2, 4, 8, 19, 3),
}
_BOX = (31, 17, 17, 17, 17, 17, 31)


def text_mask(text: str, *, scale: int = 1) -> np.ndarray:
    """Boolean mask (7 s, 6 s len(text) - s) of ``text`` in a 5 x 7 pixel font, ``s = scale``."""
    if not text:
        return np.zeros((7 * scale, 0), dtype=bool)
    cols = []
    for ch in text.lower():
        rows = _FONT.get(ch, _BOX)
        glyph = np.array([[(r >> (4 - c)) & 1 for c in range(5)] for r in rows], dtype=bool)
        cols.extend([glyph, np.zeros((7, 1), dtype=bool)])
    mask = np.concatenate(cols[:-1], axis=1)
    return np.kron(mask, np.ones((scale, scale), dtype=bool)).astype(bool)


def _stamp(canvas: np.ndarray, text: str, top: int, centre: float, scale: int) -> None:
    """Draw ``text`` in black on ``canvas`` (RGB), centred on column ``centre``, clipped."""
    mask = text_mask(text, scale=scale)
    w = mask.shape[1]
    left = round(centre - w / 2)
    left = min(max(left, 0), max(canvas.shape[1] - w, 0))
    mask = mask[: canvas.shape[0] - top, : canvas.shape[1] - left]
    canvas[top:top + mask.shape[0], left:left + mask.shape[1]][mask] = 0


def _scale_for(width: int) -> int:
    return 2 if width >= 400 else 1


def colorbar(width: int, *, vmin: float, vmax: float, cmap: str = "viridis", label: str = "",
             ticks: int = 3, scale: int | None = None) -> np.ndarray:
    """A horizontal colour bar (RGB uint8, white background) with tick values and a label.

    Parameters
    ----------
    width : int
        Width in pixels (the width of the picture it sits under).
    vmin, vmax : float
        The values at the left and right ends (as given to :func:`colorize`).
    cmap : {"viridis", "inferno"}
    label : str
        Written after the tick values, e.g. ``"depth (m)"``.
    ticks : int
        Number of tick values, evenly spaced from ``vmin`` to ``vmax``.
    scale : int, optional
        Font scale (default 2 for widths of 400 pixels and more, else 1).
    """
    s = _scale_for(width) if scale is None else scale
    bar_h, pad = 6 * s, 2 * s
    strip = colorize(np.tile(np.linspace(vmin, vmax, width), (bar_h, 1)), vmin=vmin,
                     vmax=vmax, cmap=cmap)
    text_h = 7 * s
    out = np.full((bar_h + 2 * pad + 2 * text_h + pad, width, 3), 255, np.uint8)
    out[pad:pad + bar_h] = strip
    top = pad + bar_h + pad
    values = np.linspace(vmin, vmax, max(ticks, 2))
    digits = 0 if abs(vmax - vmin) >= 10 else (1 if abs(vmax - vmin) >= 1 else 2)
    for i, v in enumerate(values):
        x = i * (width - 1) / (len(values) - 1)
        out[pad + bar_h:pad + bar_h + s, round(x)] = 0   # tick mark
        _stamp(out, f"{v:.{digits}f}", top, x, s)
    if label:
        _stamp(out, label, top + text_h + pad // 2, width / 2, s)
    return out


def titled_panel(images: list[np.ndarray], titles: list[str], *,
                 colorbars: list[dict | None] | None = None, gap: int = 4) -> np.ndarray:
    """Images side by side, each with a title above and optionally a colour bar below.

    Parameters
    ----------
    images : list of ndarray (H, W, 3) uint8
        Equal heights.
    titles : list of str
        One per image.
    colorbars : list of dict or None, optional
        One per image: keyword arguments of :func:`colorbar` (``vmin``, ``vmax``, ``cmap``,
        ``label``), or None for no bar under that image.
    gap : int
        White columns between images.
    """
    if len(titles) != len(images):
        raise ValueError(f"titled_panel needs one title per image; got {len(titles)} titles "
                         f"for {len(images)} images")
    bars = colorbars if colorbars is not None else [None] * len(images)
    if len(bars) != len(images):
        raise ValueError(f"titled_panel needs one colorbars entry (dict or None) per image; got "
                         f"{len(bars)} for {len(images)} images")
    body = panel(images, gap=gap)
    s = _scale_for(images[0].shape[1])
    title_h = 7 * s + 4 * s
    head = np.full((title_h, body.shape[1], 3), 255, np.uint8)
    feet = [colorbar(img.shape[1], scale=s, **b) if b else None for img, b in zip(images, bars, strict=True)]
    foot_h = max((f.shape[0] for f in feet if f is not None), default=0)
    foot = np.full((foot_h, body.shape[1], 3), 255, np.uint8)
    left = 0
    for img, title, f in zip(images, titles, feet, strict=True):
        w = img.shape[1]
        _stamp(head, title, 2 * s, left + w / 2, s)
        if f is not None:
            foot[:f.shape[0], left:left + w] = f
        left += w + gap
    return np.concatenate([head, body, foot], axis=0)
