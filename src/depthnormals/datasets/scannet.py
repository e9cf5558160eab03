"""Reader of ScanNet frames exported by its SensReader (Dai et al., CVPR 2017).

Layout (``SensReader/python/reader.py --export_depth_images --export_intrinsics``)::

    scene0000_00/
        depth/<i>.png                    # 16-bit, millimetres, 0 = no data (640 x 480)
        intrinsic/intrinsic_depth.txt    # 4 x 4, K in the upper-left 3 x 3
        pose/<i>.txt                     # 4 x 4 camera-to-world (optional)
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Intrinsics
from ._common import depth_mask, read_depth_png, resolve_intrinsics
from ._frame import Frame

__all__ = ["is_scannet", "read_scannet", "read_scannet_intrinsics"]

SCANNET_DEPTH_FACTOR = 1000.0


def is_scannet(path: str | Path) -> bool:
    """True for a folder with ``depth/*.png`` and ``intrinsic/intrinsic_depth.txt``."""
    p = Path(path)
    return (p / "intrinsic" / "intrinsic_depth.txt").is_file() and any((p / "depth").glob("*.png"))


def read_scannet_intrinsics(path: str | Path) -> Intrinsics:
    """K from a ScanNet ``intrinsic_depth.txt`` (4 x 4 matrix, K in the upper-left 3 x 3)."""
    p = Path(path)
    try:
        lines = [line for line in p.read_text().splitlines() if line.strip()]
        M = np.array([[float(x) for x in line.split()] for line in lines])
    except ValueError as exc:
        raise ValueError(f"{p}: expected a 4 x 4 matrix of numbers") from exc
    if M.shape != (4, 4):
        raise ValueError(f"{p}: expected a 4 x 4 matrix; got shape {M.shape}")
    return Intrinsics.from_matrix(M[:3, :3])


def _frame_key(p: Path) -> tuple[int, str]:
    return (int(p.stem), p.stem) if p.stem.isdigit() else (1 << 62, p.stem)


def read_scannet(path: str | Path, *, intrinsics: Any = None,
                 depth_scale: float | None = None) -> Iterator[Frame]:
    """Yield the depth frames of an exported ScanNet scene folder.

    Parameters
    ----------
    path : str or Path
        Scene folder with ``depth/<i>.png`` and ``intrinsic/intrinsic_depth.txt``.
    intrinsics : Intrinsics, (fx, fy, cx, cy), 3x3 array or path, optional
        Overrides ``intrinsic/intrinsic_depth.txt``.
    depth_scale : float, optional
        Metres per PNG unit; default 0.001 (millimetres) as exported.

    Yields
    ------
    Frame
        ``depth`` float32 metres (0 = no data), ``normals`` None, ``mask`` depth > 0, ``K``
        as in the file (taken as 0-based: ScanNet's own back-projection uses it with 0-based
        pixel indices), ``name`` the frame number, ``group`` the folder name, ``meta`` with
        ``"pose"`` (4 x 4 camera-to-world) when ``pose/<i>.txt`` exists.
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"ScanNet scene folder {root} does not exist")
    if intrinsics is None:
        kfile = root / "intrinsic" / "intrinsic_depth.txt"
        if not kfile.is_file():
            raise FileNotFoundError(f"{kfile} is missing; pass intrinsics=...")
        cam = read_scannet_intrinsics(kfile)
    else:
        cam = resolve_intrinsics(intrinsics, {}, what=str(root))
    units = SCANNET_DEPTH_FACTOR if depth_scale is None else 1.0 / float(depth_scale)
    files = sorted((root / "depth").glob("*.png"), key=_frame_key)
    if not files:
        raise ValueError(f"{root / 'depth'} holds no .png depth images")
    for file in files:
        depth = read_depth_png(file, units_per_metre=units)
        meta: dict[str, Any] = {"format": "scannet", "depth_file": str(file)}
        pose = root / "pose" / f"{file.stem}.txt"
        if pose.is_file():
            meta["pose"] = np.loadtxt(pose, dtype=np.float64).reshape(4, 4)
        yield Frame(depth=depth, normals=None, K=cam.matrix, mask=depth_mask(depth), name=file.stem,
                    group=root.name, meta=meta)
