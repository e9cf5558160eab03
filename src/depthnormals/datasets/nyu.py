"""Reader of the NYU Depth v2 labeled set (Silberman et al., ECCV 2012), ``nyu_depth_v2_labeled.mat``.

The file is MATLAB v7.3, i.e. HDF5. MATLAB stores arrays column-major, so h5py sees every
array with its axes reversed: ``depths`` (480 x 640 x 1449 in MATLAB) reads as (1449, 640, 480)
and one frame is ``depths[i].T``. Depth is in metres, in-painted (``rawDepths``: the raw
projected depth, 0 = no data).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Intrinsics
from ._common import depth_mask, h5py_module, resolve_intrinsics
from ._frame import Frame

__all__ = ["NYU_CROP", "NYU_INTRINSICS", "NYU_INTRINSICS_MATLAB", "is_nyu", "read_nyu"]

#: ``camera_params.m`` of the NYU toolbox (RGB camera, the depth maps are registered to it),
#: on MATLAB's 1-based pixel grid: ``rgb_plane2rgb_world.m`` uses ``meshgrid(1:640, 1:480)``.
NYU_INTRINSICS_MATLAB = (5.1885790117450188e02, 5.1946961112127485e02,
                         3.2558244941119034e02, 2.5373616633400465e02)
#: The same on our 0-based grid: principal point minus 1.
NYU_INTRINSICS = Intrinsics(NYU_INTRINSICS_MATLAB[0], NYU_INTRINSICS_MATLAB[1],
                            NYU_INTRINSICS_MATLAB[2] - 1.0, NYU_INTRINSICS_MATLAB[3] - 1.0)
#: The toolbox's valid region ``mask(45:471, 41:601)`` (1-based, inclusive) as 0-based slices
#: (rows, columns): 427 x 561 pixels, the usual evaluation crop.
NYU_CROP = (slice(44, 471), slice(40, 601))


def is_nyu(path: str | Path) -> bool:
    """True for an HDF5 (MATLAB v7.3) ``.mat`` file with a ``depths`` array."""
    p = Path(path)
    if not (p.is_file() and p.suffix.lower() == ".mat"):
        return False
    with p.open("rb") as fh:
        head = fh.read(520)
    # v7.3 .mat files carry a 512-byte MATLAB header before the HDF5 superblock
    if b"\x89HDF\r\n\x1a\n" not in head:
        return False
    with h5py_module().File(p, "r") as f:
        return "depths" in f


def read_nyu(path: str | Path, *, intrinsics: Any = None, raw: bool = False, crop: bool = False,
             indices: Any = None) -> Iterator[Frame]:
    """Yield the frames of ``nyu_depth_v2_labeled.mat``.

    Parameters
    ----------
    path : str or Path
        The labeled ``.mat`` file (HDF5, read with h5py).
    intrinsics : Intrinsics, (fx, fy, cx, cy), 3x3 array or path, optional
        Default :data:`NYU_INTRINSICS`: fx 518.857901, fy 519.469611, cx 324.582449,
        cy 252.736166 (the toolbox's principal point 325.582449, 253.736166 minus 1).
    raw : bool, default False
        False: ``depths`` (in-painted, dense); True: ``rawDepths`` (0 where the Kinect gave
        nothing).
    crop : bool, default False
        True: keep the toolbox's valid region :data:`NYU_CROP` (427 x 561) and shift the
        principal point by (40, 44).
    indices : iterable of int, optional
        0-based frame indices to read (default all 1449).

    Yields
    ------
    Frame
        ``depth`` float32 metres, ``normals`` None (the labeled set has none), ``mask``
        depth > 0, ``name`` the 0-based index as ``"%04d"``, ``group`` the file stem,
        ``meta["rgb"]`` the registered colour image (H, W, 3) uint8.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"NYU .mat file {p} does not exist")
    cam = NYU_INTRINSICS if intrinsics is None else resolve_intrinsics(intrinsics, {}, what=str(p))
    if crop:
        cam = Intrinsics(cam.fx, cam.fy, cam.cx - NYU_CROP[1].start, cam.cy - NYU_CROP[0].start)
    key = "rawDepths" if raw else "depths"
    with h5py_module().File(p, "r") as f:
        if key not in f:
            raise ValueError(f"{p}: no {key!r} array (keys: {sorted(f.keys())}); is this "
                             "nyu_depth_v2_labeled.mat?")
        depths = f[key]
        images = f["images"] if "images" in f else None
        if depths.ndim != 3:
            raise ValueError(f"{p}: {key} has shape {depths.shape}; expected (N, W, H)")
        picks = range(depths.shape[0]) if indices is None else [int(i) for i in indices]
        for i in picks:
            depth = np.ascontiguousarray(np.asarray(depths[i], dtype=np.float32).T)
            rgb = None if images is None else np.ascontiguousarray(np.asarray(images[i]).transpose(2, 1, 0))
            if crop:
                depth = np.ascontiguousarray(depth[NYU_CROP])
                rgb = None if rgb is None else np.ascontiguousarray(rgb[NYU_CROP])
            yield Frame(depth=depth, normals=None, K=cam.matrix, mask=depth_mask(depth), name=f"{i:04d}",
                        group=p.stem, meta={"format": "nyu", "key": key, "rgb": rgb, "crop": crop})
