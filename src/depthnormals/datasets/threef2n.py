"""Reader of the 3F2N dataset (Fan et al., RA-L 2021) scene folders."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .._png import read_png
from ..camera import Intrinsics
from ._frame import Frame

__all__ = ["is_3f2n_scene", "read_3f2n"]

_BACKGROUND_DEPTH = 1.0


def is_3f2n_scene(path: str | Path) -> bool:
    """True if ``path`` looks like a 3F2N scene folder (depth/*.bin and params.txt)."""
    p = Path(path)
    return (p / "params.txt").is_file() and (p / "depth").is_dir() and any((p / "depth").glob("*.bin"))


def read_3f2n(path: str | Path, *, corrected_intrinsics: bool = False,
              shape: tuple[int, int] = (480, 640)) -> Iterator[Frame]:
    """Yield the frames of a 3F2N dataset scene folder.

    Parameters
    ----------
    path : str or Path
        Scene folder with ``depth/%06d.bin`` (little-endian float32, row-major, background
        exactly 1.0), ``normal/%06d.png`` (16-bit RGB, ``n = value / 65535 * 2 - 1``) and
        ``params.txt`` (``fx fy cx cy N``, cx, cy on MATLAB's 1-based grid).
    corrected_intrinsics : bool, default False
        False: principal point ``(cx - 1, cy - 1)``, which reproduces the published
        numbers. True: ``(cx - 0.5, H - cy - 0.5)``, which matches the rendered geometry of
        most scenes (see NOTES.md section 5).
    shape : (H, W), default (480, 640)
        Image size of the ``.bin`` files.

    Yields
    ------
    Frame
        ``depth`` float32 (background kept at 1.0, as in the files), ``normals`` renormalised
        and turned to face the camera, NaN on the background, ``mask`` True on the object,
        ``K`` 0-based, ``name`` the file stem, ``group`` the folder name.
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"3F2N scene folder {root} does not exist")
    if not is_3f2n_scene(root):
        raise ValueError(f"{root} is not a 3F2N scene folder (needs params.txt and depth/*.bin)")
    values = (root / "params.txt").read_text().split()
    try:
        fx, fy, cx, cy = (float(x) for x in values[:4])
    except ValueError as exc:
        raise ValueError(f"{root / 'params.txt'}: expected 'fx fy cx cy N'") from exc
    h, w = shape
    if corrected_intrinsics:
        cam = Intrinsics(fx, fy, cx - 0.5, h - cy - 0.5)
    else:
        cam = Intrinsics(fx, fy, cx - 1.0, cy - 1.0)
    for depth_file in sorted((root / "depth").glob("*.bin")):
        raw = np.fromfile(depth_file, dtype="<f4")
        if raw.size != h * w:
            raise ValueError(f"{depth_file} holds {raw.size} values; expected {h} x {w}")
        depth = raw.reshape(h, w).astype(np.float32)
        normal_file = root / "normal" / f"{depth_file.stem}.png"
        if not normal_file.is_file():
            raise FileNotFoundError(f"ground truth {normal_file} is missing for {depth_file.name}")
        img = read_png(normal_file)
        if img.dtype != np.uint16 or img.shape != (h, w, 3):
            raise ValueError(f"{normal_file}: expected 16-bit RGB {h}x{w}; got {img.dtype} {img.shape}")
        background = np.all(img == 65535, axis=-1) | (depth == _BACKGROUND_DEPTH)
        n = img.astype(np.float64) / 65535.0 * 2.0 - 1.0
        norm = np.linalg.norm(n, axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            n = n / norm
        valid = ~background & np.isfinite(depth) & (depth > 0) & (norm[..., 0] > 0)
        u = np.arange(w)[None, :]
        v = np.arange(h)[:, None]
        point = np.stack([(u - cam.cx) * depth / cam.fx, (v - cam.cy) * depth / cam.fy,
                          depth.astype(np.float64)], axis=-1)
        flip = np.einsum("...i,...i->...", n, point) > 0
        n[flip] *= -1.0
        n[~valid] = np.nan
        yield Frame(depth=depth, normals=n.astype(np.float32), K=cam.matrix, mask=valid,
                    name=depth_file.stem, group=root.name,
                    meta={"format": "3f2n", "corrected_intrinsics": corrected_intrinsics})
