"""Reader of Apple's Hypersim renders (Roberts et al., ICCV 2021).

Layout (https://github.com/apple/ml-hypersim, README "Dataset format")::

    ai_001_001/images/scene_cam_00_geometry_hdf5/
        frame.0000.depth_meters.hdf5   # "dataset": (768, 1024) float16, Euclidean DISTANCE (m)
                                       # to the optical centre, not planar depth; NaN = no geometry
        frame.0000.normal_cam.hdf5     # "dataset": (768, 1024, 3) float16, camera-space normals
    metadata_camera_parameters.csv     # contrib/mikeroberts3000: per-scene M_cam_from_uv

Hypersim's camera frame: x right, y up, z backward (away from where the camera looks). A
pixel (column i, row j) of a W x H image sees the camera-space ray ``M_cam_from_uv @ (u, v, 1)``
with ``u = (2 i + 1) / W - 1`` and ``v = 1 - (2 j + 1) / H`` (contrib notebook 01). With
``F = diag(1, -1, -1)`` (Hypersim -> OpenCV) and ``A`` the pixel -> uv map, ``inv(F M A) = K R``
(RQ decomposition): ``K`` is the pinhole matrix of the virtual camera whose frame is ``R`` times
OpenCV's camera frame. For the usual scenes ``R = I``; for tilt-shift scenes R is a small
rotation and depth and normals are expressed in that rotated frame, the one in which K is a
plain pinhole (our interpretation; ``meta["R_virtual_from_cam"]`` records it). Scenes whose K
has skew (31 of 482 in the published CSV) cannot be expressed by fx, fy, cx, cy and are rejected.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Intrinsics
from ._common import face_camera, h5py_module
from ._frame import Frame

__all__ = ["HYPERSIM_DEFAULT_M_CAM_FROM_UV", "hypersim_camera", "is_hypersim", "read_hypersim"]

_W, _H = 1024, 768
#: M_cam_from_uv of a scene without tilt-shift: 60 degree horizontal field of view.
HYPERSIM_DEFAULT_M_CAM_FROM_UV = np.diag([np.tan(np.pi / 6), np.tan(np.pi / 6) * _H / _W, -1.0])
_HYPERSIM_TO_OPENCV = np.diag([1.0, -1.0, -1.0])
_SCENE = re.compile(r"ai_\d{3}_\d{3}")
_CSV_NAME = "metadata_camera_parameters.csv"


def _geometry_dirs(root: Path) -> list[Path]:
    if root.name.endswith("_geometry_hdf5"):
        return [root]
    found = sorted(root.glob("*_geometry_hdf5")) + sorted(root.glob("images/*_geometry_hdf5"))
    found += sorted(root.glob("*/images/*_geometry_hdf5"))
    return [d for d in found if d.is_dir() and any(d.glob("frame.*.depth_meters.hdf5"))]


def is_hypersim(path: str | Path) -> bool:
    """True for a scene folder, its ``images/`` folder, a ``*_geometry_hdf5`` folder or a folder
    of scenes holding ``frame.IIII.depth_meters.hdf5`` files."""
    p = Path(path)
    return p.is_dir() and bool(_geometry_dirs(p))


def hypersim_camera(M_cam_from_uv: Any, *, width: int = _W,
                    height: int = _H) -> tuple[Intrinsics, np.ndarray]:
    """Pinhole K (0-based) and rotation R (virtual frame from OpenCV camera frame) of a Hypersim camera.

    Parameters
    ----------
    M_cam_from_uv : array (3, 3)
        The scene's matrix from ``metadata_camera_parameters.csv``.
    width, height : int
        Image size in pixels.

    Returns
    -------
    K : Intrinsics
    R : ndarray (3, 3)
        Identity for scenes without tilt-shift.

    Raises
    ------
    ValueError
        If the camera has skew (not expressible by fx, fy, cx, cy).
    """
    M = np.asarray(M_cam_from_uv, dtype=np.float64).reshape(3, 3)
    A = np.array([[2.0 / width, 0.0, 1.0 / width - 1.0],
                  [0.0, -2.0 / height, 1.0 - 1.0 / height],
                  [0.0, 0.0, 1.0]])
    P = np.linalg.inv(_HYPERSIM_TO_OPENCV @ M @ A)
    Kq, R = _rq(P)
    D = np.diag(np.sign(np.diag(Kq)))
    Kq, R = Kq @ D, D @ R
    Kq = Kq / Kq[2, 2]
    if abs(Kq[0, 1]) > 1e-6 * Kq[0, 0]:
        raise ValueError(f"this Hypersim camera has skew {Kq[0, 1]:.4g} px; fx, fy, cx, cy cannot "
                         "describe it")
    if np.allclose(R, np.eye(3), atol=1e-12):
        R = np.eye(3)
    return Intrinsics(Kq[0, 0], Kq[1, 1], Kq[0, 2], Kq[1, 2]), R


def _rq(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P = K R with K upper triangular and R orthogonal (QR of the row-reversed transpose)."""
    q, r = np.linalg.qr(np.flipud(P).T)
    return np.flipud(r.T)[:, ::-1], np.flipud(q.T)


def _scene_matrix(csv_file: Path, scene: str) -> tuple[np.ndarray, int, int]:
    with csv_file.open(newline="") as fh:
        for row in csv.DictReader(fh):
            if row.get("scene_name") == scene:
                M = np.array([[float(row[f"M_cam_from_uv_{i}{j}"]) for j in range(3)] for i in range(3)])
                width = int(float(row["settings_output_img_width"]))
                return M, width, int(float(row["settings_output_img_height"]))
    raise ValueError(f"{csv_file}: no row for scene {scene!r}")


def _find_csv(start: Path) -> Path | None:
    for folder in [start, *start.parents]:
        if (folder / _CSV_NAME).is_file():
            return folder / _CSV_NAME
    return None


def _read_h5(path: Path) -> np.ndarray:
    with h5py_module().File(path, "r") as f:
        if "dataset" not in f:
            raise ValueError(f"{path}: no 'dataset' array (keys: {sorted(f.keys())})")
        return np.asarray(f["dataset"][...], dtype=np.float32)


def read_hypersim(path: str | Path, *, camera_parameters: str | Path | None = None,
                  bump: bool = False) -> Iterator[Frame]:
    """Yield the frames of Hypersim scenes with planar depth and normals in our convention.

    Parameters
    ----------
    path : str or Path
        A scene folder (``ai_001_001``), its ``images/`` folder, one
        ``scene_cam_XX_geometry_hdf5`` folder, or a folder of scenes.
    camera_parameters : str or Path, optional
        ``metadata_camera_parameters.csv``; default: searched in ``path`` and its parents.
        Without it (or for a folder whose scene name is unknown), the default 60 degree camera
        (fx = fy = 886.81, cx = 511.5, cy = 383.5) is used and ``meta["intrinsics"]`` says so.
    bump : bool, default False
        Read ``normal_bump_cam`` (with bump mapping) instead of ``normal_cam``.

    Yields
    ------
    Frame
        ``depth`` float32 planar depth in metres (``distance / |K^-1 (u, v, 1)|``), NaN where
        Hypersim has no geometry; ``normals`` Hypersim's camera-space normals mapped by
        ``(x, -y, -z)`` (then ``R``), unit length, facing the camera, or None when the file
        is absent; ``mask`` finite depth and normal; ``group`` ``"<scene>/<cam_XX>"``.
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"Hypersim folder {root} does not exist")
    dirs = _geometry_dirs(root)
    if not dirs:
        raise ValueError(f"{root}: no */frame.IIII.depth_meters.hdf5 found")
    csv_file = Path(camera_parameters) if camera_parameters is not None else _find_csv(root.resolve())
    kind = "normal_bump_cam" if bump else "normal_cam"
    for gdir in dirs:
        scene_match = [p.name for p in [gdir, *gdir.resolve().parents] if _SCENE.fullmatch(p.name)]
        scene = scene_match[0] if scene_match else gdir.parent.name
        cam_name = gdir.name.removeprefix("scene_").removesuffix("_geometry_hdf5")
        if csv_file is not None and scene_match:
            M, width, height = _scene_matrix(csv_file, scene)
            source = f"{csv_file.name}:{scene}"
        else:
            M, width, height = HYPERSIM_DEFAULT_M_CAM_FROM_UV, _W, _H
            source = "default (60 deg horizontal field of view)"
        K, R = hypersim_camera(M, width=width, height=height)
        u = (np.arange(width, dtype=np.float64)[None, :] - K.cx) / K.fx
        v = (np.arange(height, dtype=np.float64)[:, None] - K.cy) / K.fy
        ray_length = np.sqrt(u * u + v * v + 1.0)
        for dfile in sorted(gdir.glob("frame.*.depth_meters.hdf5")):
            frame_id = dfile.name.split(".")[1]
            distance = _read_h5(dfile)
            if distance.shape != (height, width):
                raise ValueError(f"{dfile}: shape {distance.shape}; expected ({height}, {width})")
            depth = (distance.astype(np.float64) / ray_length).astype(np.float32)
            valid = np.isfinite(depth) & (depth > 0)
            nfile = gdir / f"frame.{frame_id}.{kind}.hdf5"
            normals = None
            if nfile.is_file():
                n_h = _read_h5(nfile).astype(np.float64)
                if n_h.shape != (height, width, 3):
                    raise ValueError(f"{nfile}: shape {n_h.shape}; expected ({height}, {width}, 3)")
                n_cv = n_h @ (R @ _HYPERSIM_TO_OPENCV).T
                normals = face_camera(n_cv, depth, K, valid)
                valid = valid & np.all(np.isfinite(normals), axis=-1)
            yield Frame(depth=depth, normals=normals, K=K.matrix, mask=valid, name=frame_id,
                        group=f"{scene}/{cam_name}",
                        meta={"format": "hypersim", "intrinsics": source, "R_virtual_from_cam": R,
                              "depth_file": str(dfile)})
