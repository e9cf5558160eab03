"""Reading depth and intrinsics, writing normals; every write is atomic.

Normal maps as 16-bit PNG (``write_normals(..., ".png")``): channels (R, G, B) = (nx, ny, nz)
encoded as ``round((n + 1) / 2 * 65535)``; invalid (NaN) pixels are written (0, 0, 0), which
no unit vector encodes (it would decode to (-1, -1, -1)). :func:`read_normals` inverts this,
renormalises, and gives NaN for (0, 0, 0).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ._png import encode_png, read_png
from ._validate import check_depth, check_normals
from .camera import Intrinsics, as_intrinsics

__all__ = [
    "atomic_write",
    "normals_to_rgb8",
    "read_depth",
    "read_intrinsics",
    "read_normals",
    "to_open3d",
    "write_bytes_atomic",
    "write_normals",
    "write_ply",
    "write_png",
]

DEPTH_SUFFIXES = (".npy", ".png", ".tif", ".tiff", ".bin")


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "wb") -> Iterator[Any]:
    """Open a temporary file beside ``path``; on success it replaces ``path`` atomically.

    On any exception the temporary file is removed and ``path`` is left as it was, so a
    crash never leaves a half-written file under the final name.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(f"output folder {parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent)
    try:
        # mkstemp creates 0600; give the file the permissions a plain open() would have
        os.chmod(tmp, 0o666 & ~_umask())
        with os.fdopen(fd, mode) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_write(path) as fh:
        fh.write(data)


def write_png(path: str | Path, img: np.ndarray) -> None:
    """Write a uint8/uint16 image as PNG, atomically."""
    write_bytes_atomic(path, encode_png(img))


def read_depth(path: str | Path, *, depth_scale: float | None = None,
               shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a depth map.

    Parameters
    ----------
    path : str or Path
        ``.npy`` (float or integer array), ``.png`` (16-bit grey; needs ``depth_scale``),
        ``.tif``/``.tiff`` (float32, needs the ``tifffile`` package: ``pip install
        depthnormals[io]``) or ``.bin`` (3F2N format: raw little-endian float32).
    depth_scale : float, optional
        Metres per unit, required for integer data (e.g. 0.001 for millimetre PNGs).
    shape : (H, W), optional
        Size of a ``.bin`` file; default 480 x 640 as in the 3F2N dataset.

    Returns
    -------
    depth : ndarray, shape (H, W), float32 or float64
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"depth file {path} does not exist")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        arr = np.load(path, allow_pickle=False)
    elif suffix == ".png":
        arr = read_png(path)
        if arr.ndim != 2:
            raise ValueError(f"{path}: a depth PNG must be single-channel; got shape {arr.shape}")
    elif suffix in (".tif", ".tiff"):
        try:
            import tifffile
        except ImportError as exc:
            raise ImportError("reading TIFF depth needs tifffile: pip install 'depthnormals[io]'") from exc
        arr = tifffile.imread(path)
        if arr.ndim == 3 and arr.shape[-1] == 1:
            arr = arr[..., 0]
    elif suffix == ".bin":
        h, w = shape if shape is not None else (480, 640)
        arr = np.fromfile(path, dtype="<f4")
        if arr.size != h * w:
            raise ValueError(f"{path} holds {arr.size} float32 values; expected {h} x {w} = {h * w} "
                             "(pass shape=(H, W))")
        arr = arr.reshape(h, w)
    else:
        raise ValueError(f"{path}: unknown depth format {suffix!r}; use one of {', '.join(DEPTH_SUFFIXES)}")
    return check_depth(arr, depth_scale=depth_scale, name=f"depth in {path.name}")


def read_intrinsics(path: str | Path) -> Intrinsics:
    """Read camera intrinsics.

    Accepts JSON or YAML with ``fx, fy, cx, cy`` (0-based) or ``K`` (3x3, nested or flat),
    optionally under a ``camera`` or ``intrinsics`` key, and 3F2N ``params.txt``
    (``fx fy cx cy N`` on MATLAB's 1-based grid: converted to 0-based by subtracting 1).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"intrinsics file {path} does not exist")
    suffix = path.suffix.lower()
    text = path.read_text()
    if suffix == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno} column "
                             f"{exc.colno}); {_INTRINSICS_EXAMPLE}") from exc
    elif suffix in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError as exc:
            raise ImportError("reading YAML needs PyYAML: pip install 'depthnormals[io]'") from exc
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f"{path}: not valid YAML ({exc}); {_INTRINSICS_EXAMPLE}") from exc
    elif suffix == ".txt":
        values = text.split()
        try:
            fx, fy, cx, cy = (float(x) for x in values[:4])
        except ValueError as exc:
            raise ValueError(f"{path}: expected 'fx fy cx cy [N]' (3F2N params.txt)") from exc
        return Intrinsics(fx, fy, cx - 1.0, cy - 1.0)
    else:
        raise ValueError(f"{path}: intrinsics must be .json, .yaml/.yml or 3F2N params.txt")
    if isinstance(data, dict):
        for key in ("camera", "intrinsics"):
            if isinstance(data.get(key), dict):
                data = data[key]
        try:
            if "K" in data:
                return as_intrinsics(np.asarray(data["K"], dtype=np.float64).reshape(3, 3))
            if all(k in data for k in ("fx", "fy", "cx", "cy")):
                return as_intrinsics(data)
        except (ValueError, TypeError) as exc:
            raise type(exc)(f"{path}: {exc}; {_INTRINSICS_EXAMPLE}") from exc
    raise ValueError(f"{path}: needs keys fx, fy, cx, cy or K (3x3); {_INTRINSICS_EXAMPLE}")


_INTRINSICS_EXAMPLE = ('a valid file looks like {"fx": 525.0, "fy": 525.0, "cx": 319.5, '
                       '"cy": 239.5} (pixels, 0-based principal point) or {"K": [[525.0, 0, '
                       '319.5], [0, 525.0, 239.5], [0, 0, 1]]}')


def normals_to_rgb8(normals: np.ndarray) -> np.ndarray:
    """8-bit colour picture of a normal map: RGB = (1 - n) / 2 * 255, black where invalid.

    The ``(1 - n) / 2`` mapping (of the 3F2N papers) shows a camera-facing wall light blue.
    """
    n = check_normals(normals)
    ok = np.all(np.isfinite(n), axis=-1)
    rgb = np.clip((1.0 - np.nan_to_num(n)) * 0.5 * 255.0 + 0.5, 0, 255).astype(np.uint8)
    rgb[~ok] = 0
    return rgb


def write_normals(path: str | Path, normals: np.ndarray) -> None:
    """Write a normal map: ``.npy`` (float32), ``.png`` (16-bit, see module doc); atomic.

    A name ending in ``.vis.png`` writes the 8-bit picture of :func:`normals_to_rgb8` instead.
    """
    path = Path(path)
    n = check_normals(normals)
    name = path.name.lower()
    if name.endswith(".npy"):
        with atomic_write(path) as fh:
            np.save(fh, n.astype(np.float32))
    elif name.endswith(".vis.png"):
        write_png(path, normals_to_rgb8(n))
    elif name.endswith(".png"):
        ok = np.all(np.isfinite(n), axis=-1)
        enc = np.clip(np.round((np.nan_to_num(n) + 1.0) * 0.5 * 65535.0), 0, 65535).astype(np.uint16)
        enc[~ok] = 0
        write_png(path, enc)
    else:
        raise ValueError(f"{path}: normals are written as .npy, .png (16-bit) or .vis.png (8-bit picture)")


def read_normals(path: str | Path) -> np.ndarray:
    """Read normals written by :func:`write_normals` (.npy or 16-bit .png) as float32."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
        return check_normals(np.load(path, allow_pickle=False)).astype(np.float32)
    img = read_png(path)
    if img.dtype != np.uint16 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"{path}: expected a 16-bit RGB normal PNG; got {img.dtype} {img.shape}")
    n = img.astype(np.float64) / 65535.0 * 2.0 - 1.0
    bad = np.all(img == 0, axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[bad] = np.nan
    return n.astype(np.float32)


# --- point clouds -------------------------------------------------------------------------

_PLY_FIELDS = (("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"))
_PLY_COLOURS = (("red", "u1"), ("green", "u1"), ("blue", "u1"))


def _cloud(depth: Any, K: Any, normals: Any, colors: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Points (float64), normals and colours of the valid pixels (finite depth > 0 and finite normal)."""
    from .camera import backproject

    z = check_depth(depth)
    n = check_normals(normals, shape=z.shape)
    points = backproject(z, K)
    valid = np.all(np.isfinite(points), axis=-1) & np.all(np.isfinite(n), axis=-1)
    rgb = None
    if colors is not None:
        rgb = np.asarray(colors)
        if rgb.dtype != np.uint8:
            raise TypeError(f"colors must be uint8 (H, W, 3); got dtype {rgb.dtype}")
        if rgb.shape != (*z.shape, 3):
            raise ValueError(f"colors must have shape {(*z.shape, 3)} like depth; got {rgb.shape}")
        rgb = rgb[valid]
    return points[valid], np.asarray(n[valid]), rgb


def write_ply(path: str | Path, depth: Any, K: Any, normals: Any, *, colors: Any = None) -> int:
    """Write the valid pixels as a binary little-endian PLY point cloud, atomically.

    Parameters
    ----------
    path : str or Path
        Output ``.ply`` file; replaced atomically (a crash leaves the old file or none).
    depth : array (H, W), float32 or float64
        Planar depth in metres (integer depth: scale it first); invalid pixels are skipped.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Camera intrinsics, 0-based pixel centres.
    normals : array (H, W, 3)
        Normals in the OpenCV camera frame (e.g. from :func:`depthnormals.estimate_normals`);
        pixels with a NaN normal are skipped.
    colors : array (H, W, 3) uint8, optional
        Per-pixel RGB, written as ``uchar red green blue``.

    Returns
    -------
    int
        The number of points written.

    Notes
    -----
    One ``vertex`` element with ``float x y z nx ny nz`` (float32: the points of
    :func:`depthnormals.backproject` rounded to float32, the normals as given rounded to
    float32), then ``uchar red green blue`` when ``colors`` is given, in row-major pixel order.
    Camera frame: OpenCV (x right, y down, z forward), metres. Open3D, plyfile and MeshLab read it.

    Examples
    --------
    >>> import tempfile, os
    >>> import numpy as np
    >>> depth = np.full((4, 5), 2.0)
    >>> n = np.zeros((4, 5, 3), np.float32); n[..., 2] = -1
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     write_ply(os.path.join(tmp, "wall.ply"), depth, (100, 100, 2, 1.5), n)
    20
    """
    points, n, rgb = _cloud(depth, K, normals, colors)
    fields = _PLY_FIELDS + (_PLY_COLOURS if rgb is not None else ())
    records = np.empty(len(points), dtype=list(fields))
    for i, axis in enumerate("xyz"):
        records[axis] = points[:, i]
        records["n" + axis] = n[:, i]
    if rgb is not None:
        for i, name in enumerate(("red", "green", "blue")):
            records[name] = rgb[:, i]
    types = {"<f4": "float", "u1": "uchar"}
    header = "".join([
        "ply\n", "format binary_little_endian 1.0\n",
        "comment depthnormals point cloud, OpenCV camera frame\n",
        f"element vertex {len(records)}\n",
        *(f"property {types[t]} {name}\n" for name, t in fields),
        "end_header\n",
    ]).encode("ascii")
    with atomic_write(path) as fh:
        fh.write(header)
        fh.write(records.tobytes())
    return len(records)


def to_open3d(depth: Any, K: Any, normals: Any, *, colors: Any = None) -> Any:
    """The valid pixels as an ``open3d.geometry.PointCloud`` with normals (and colours).

    Parameters
    ----------
    depth, K, normals, colors
        As in :func:`write_ply`.

    Returns
    -------
    open3d.geometry.PointCloud
        ``points`` from :func:`depthnormals.backproject` (float64), ``normals`` as given,
        ``colors`` scaled to [0, 1]; OpenCV camera frame, row-major pixel order. Needs the
        ``open3d`` extra (``pip install 'depthnormals[open3d]'``, which installs ``open3d-cpu``).

    Notes
    -----
    Open3D 0.20 bundles TBB 2021.5. Once it is loaded, numba's first parallel kernel warns
    (``NumbaWarning``) that this TBB is too old and picks another threading layer; results
    are unaffected. Our tests therefore use Open3D in a subprocess.
    """
    try:
        import open3d as o3d
    except ImportError as exc:
        raise ImportError("to_open3d needs Open3D: pip install 'depthnormals[open3d]' "
                          "(or the open3d / open3d-cpu wheel)") from exc
    points, n, rgb = _cloud(depth, K, normals, colors)
    cloud = o3d.geometry.PointCloud()
    cloud.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64))
    cloud.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(n, dtype=np.float64))
    if rgb is not None:
        cloud.colors = o3d.utility.Vector3dVector(rgb.astype(np.float64) / 255.0)
    return cloud
