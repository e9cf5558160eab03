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
    "write_bytes_atomic",
    "write_normals",
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
