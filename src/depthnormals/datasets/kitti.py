"""Reader of the KITTI depth completion / prediction benchmark (Uhrig et al., 3DV 2017).

Layouts (devkit of https://www.cvlibs.net/datasets/kitti/eval_depth.php)::

    <split>/2011_09_26_drive_0002_sync/proj_depth/groundtruth/image_02/0000000005.png
    <split>/2011_09_26_drive_0002_sync/proj_depth/velodyne_raw/image_02/0000000005.png
    2011_09_26/calib_cam_to_cam.txt            # from the raw data; P_rect_02 / P_rect_03

    depth_selection/val_selection_cropped/
        groundtruth_depth/<drive>_groundtruth_depth_<frame>_image_02.png
        intrinsics/<drive>_image_<frame>_image_02.txt      # 9 numbers, K row-major

Depth PNGs: 16-bit, ``depth = value / 256`` metres, 0 = no measurement (sparse).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Intrinsics
from ._common import depth_mask, read_depth_png, resolve_intrinsics
from ._frame import Frame

__all__ = ["is_kitti", "read_kitti", "read_kitti_calib"]

KITTI_DEPTH_FACTOR = 256.0
_KINDS = ("groundtruth", "velodyne_raw")


def is_kitti(path: str | Path) -> bool:
    """True for a drive folder with ``proj_depth/``, an ``image_0[23]`` folder under it, or a
    ``val_selection_cropped``-style folder (``groundtruth_depth/`` and ``intrinsics/``)."""
    p = Path(path)
    if (p / "proj_depth").is_dir():
        return True
    if p.name in ("image_02", "image_03") and p.parent.parent.name == "proj_depth":
        return True
    return (p / "groundtruth_depth").is_dir() and (p / "intrinsics").is_dir()


def read_kitti_calib(path: str | Path, *, camera: int = 2) -> Intrinsics:
    """K of rectified camera ``camera`` from a raw-data ``calib_cam_to_cam.txt`` (``P_rect_0N``)."""
    p = Path(path)
    key = f"P_rect_{camera:02d}:"
    for line in p.read_text().splitlines():
        if line.startswith(key):
            P = np.array([float(x) for x in line[len(key):].split()]).reshape(3, 4)
            return Intrinsics.from_matrix(P[:, :3])
    raise ValueError(f"{p}: no {key} line (is this a KITTI calib_cam_to_cam.txt?)")


def _find_calib(start: Path, date: str) -> Path | None:
    for folder in [start, *start.parents]:
        for cand in (folder / "calib_cam_to_cam.txt", folder / date / "calib_cam_to_cam.txt"):
            if cand.is_file():
                return cand
    return None


def _drive_frames(root: Path, kind: str) -> list[tuple[Path, int]]:
    if root.name in ("image_02", "image_03"):
        folders = [root]
    else:
        folders = [root / "proj_depth" / kind / c for c in ("image_02", "image_03")]
    return [(png, int(folder.name[-1])) for folder in folders if folder.is_dir()
            for png in sorted(folder.glob("*.png"))]


def read_kitti(path: str | Path, *, intrinsics: Any = None, depth_scale: float | None = None,
               calib: str | Path | None = None, kind: str = "groundtruth") -> Iterator[Frame]:
    """Yield the depth maps of a KITTI depth drive folder or a ``val_selection_cropped`` folder.

    Parameters
    ----------
    path : str or Path
        ``<drive>_sync`` folder (with ``proj_depth/``), one of its ``image_02``/``image_03``
        folders, or a folder with ``groundtruth_depth/`` and ``intrinsics/``.
    intrinsics : Intrinsics, (fx, fy, cx, cy), 3x3 array or path, optional
        One camera for every frame; overrides the calibration files.
    depth_scale : float, optional
        Metres per PNG unit; default ``1 / 256`` as published.
    calib : str or Path, optional
        ``calib_cam_to_cam.txt``; default: searched in the drive folder and its parents, also
        as ``<date>/calib_cam_to_cam.txt`` (the raw-data layout). K is ``P_rect_02[:, :3]``
        (``P_rect_03`` for ``image_03``), taken as 0-based.
    kind : {"groundtruth", "velodyne_raw"}
        Which depth of a drive folder (ignored for ``val_selection_cropped``, which reads
        ``groundtruth_depth``).

    Yields
    ------
    Frame
        ``depth`` float32 metres (0 = no measurement), ``normals`` None, ``mask`` depth > 0
        (sparse: about 16 % of the pixels for ``groundtruth``, 4 % for ``velodyne_raw``),
        ``name`` ``"<frame>_image_0N"``, ``group`` the drive name.
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"KITTI folder {root} does not exist")
    if kind not in _KINDS:
        raise ValueError(f"kind must be one of {_KINDS}; got {kind!r}")
    units = KITTI_DEPTH_FACTOR if depth_scale is None else 1.0 / float(depth_scale)
    given = None if intrinsics is None else resolve_intrinsics(intrinsics, {}, what=str(root))
    if (root / "groundtruth_depth").is_dir():
        files = sorted((root / "groundtruth_depth").glob("*.png"))
        for file in files:
            kfile = root / "intrinsics" / (file.stem.replace("groundtruth_depth", "image") + ".txt")
            if given is not None:
                cam = given
            elif kfile.is_file():
                cam = Intrinsics.from_matrix(np.loadtxt(kfile, dtype=np.float64).reshape(3, 3))
            else:
                raise FileNotFoundError(f"{kfile} is missing for {file.name}; pass intrinsics=...")
            depth = read_depth_png(file, units_per_metre=units)
            drive = file.stem.split("_groundtruth_depth_")[0]
            frame = file.stem.split("_groundtruth_depth_")[-1]
            yield Frame(depth=depth, normals=None, K=cam.matrix, mask=depth_mask(depth), name=frame,
                        group=drive, meta={"format": "kitti", "depth_file": str(file)})
        return
    drive_dir = root.parents[2] if root.name in ("image_02", "image_03") else root
    frames = _drive_frames(root, kind)
    if not frames:
        raise ValueError(f"{root}: no depth PNGs under proj_depth/{kind}/image_0[23]/")
    cams: dict[int, Intrinsics] = {}
    for file, camera in frames:
        if given is not None:
            cam = given
        else:
            if camera not in cams:
                cfile = Path(calib) if calib is not None else _find_calib(drive_dir, drive_dir.name[:10])
                if cfile is None:
                    raise FileNotFoundError(
                        f"{drive_dir}: calib_cam_to_cam.txt not found in the folder or its parents "
                        f"(nor as {drive_dir.name[:10]}/calib_cam_to_cam.txt); pass calib= or intrinsics=")
                cams[camera] = read_kitti_calib(cfile, camera=camera)
            cam = cams[camera]
        depth = read_depth_png(file, units_per_metre=units)
        yield Frame(depth=depth, normals=None, K=cam.matrix, mask=depth_mask(depth),
                    name=f"{file.stem}_image_0{camera}", group=drive_dir.name,
                    meta={"format": "kitti", "kind": kind, "depth_file": str(file)})
