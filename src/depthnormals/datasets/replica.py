"""Reader of Replica renders in the layout published with NICE-SLAM (Zhu et al., CVPR 2022).

The Replica dataset itself (Straub et al. 2019) ships meshes, not images. The renders most
papers use are the sequences distributed by the iMAP/NICE-SLAM authors
(``scripts/download_replica.sh`` of https://github.com/cvg/nice-slam)::

    room0/results/frame000000.jpg    # colour
    room0/results/depth000000.png    # 16-bit, 6553.5 units per metre (configs/Replica/replica.yaml)
    room0/traj.txt                   # one camera-to-world 4 x 4 per line (row-major, OpenCV axes)

Camera (configs/Replica/replica.yaml): 1200 x 680, fx = fy = 600, cx = 599.5, cy = 339.5
(the image centre on the 0-based grid). No ground-truth normals are distributed.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Intrinsics
from ._common import depth_mask, read_depth_png, resolve_intrinsics
from ._frame import Frame

__all__ = ["REPLICA_INTRINSICS", "is_replica", "read_replica"]

REPLICA_INTRINSICS = Intrinsics(600.0, 600.0, 599.5, 339.5)
REPLICA_DEPTH_FACTOR = 6553.5


def is_replica(path: str | Path) -> bool:
    """True for a folder with ``results/depth*.png``."""
    p = Path(path)
    return (p / "results").is_dir() and any((p / "results").glob("depth*.png"))


def read_replica(path: str | Path, *, intrinsics: Any = None,
                 depth_scale: float | None = None) -> Iterator[Frame]:
    """Yield the depth frames of a NICE-SLAM-style Replica sequence.

    Parameters
    ----------
    path : str or Path
        Sequence folder (``results/depth%06d.png``, optional ``traj.txt``).
    intrinsics : Intrinsics, (fx, fy, cx, cy), 3x3 array or path, optional
        Default :data:`REPLICA_INTRINSICS` (600, 600, 599.5, 339.5).
    depth_scale : float, optional
        Metres per PNG unit; default ``1 / 6553.5``.

    Yields
    ------
    Frame
        ``depth`` float32 metres, ``normals`` None, ``mask`` depth > 0, ``name`` the frame
        number (``"000000"``), ``group`` the folder name, ``meta["pose"]`` the camera-to-world
        matrix of ``traj.txt`` when present.
    """
    root = Path(path)
    if not is_replica(root):
        raise ValueError(f"{root} is not a Replica render folder (needs results/depth*.png)")
    cam = REPLICA_INTRINSICS if intrinsics is None else resolve_intrinsics(intrinsics, {}, what=str(root))
    units = REPLICA_DEPTH_FACTOR if depth_scale is None else 1.0 / float(depth_scale)
    files = sorted((root / "results").glob("depth*.png"))
    poses = None
    if (root / "traj.txt").is_file():
        poses = np.loadtxt(root / "traj.txt", dtype=np.float64, ndmin=2).reshape(-1, 4, 4)
        if len(poses) < len(files):
            raise ValueError(f"{root / 'traj.txt'} has {len(poses)} poses for {len(files)} depth images")
    for i, file in enumerate(files):
        depth = read_depth_png(file, units_per_metre=units)
        meta: dict[str, Any] = {"format": "replica", "depth_file": str(file)}
        if poses is not None:
            meta["pose"] = poses[i]
        yield Frame(depth=depth, normals=None, K=cam.matrix, mask=depth_mask(depth),
                    name=file.stem.removeprefix("depth"), group=root.name, meta=meta)
