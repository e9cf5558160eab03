"""Helpers shared by the dataset readers: intrinsics arguments, 16-bit depth PNGs, orientation."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._png import read_png
from ..camera import Intrinsics, as_intrinsics
from ..io import read_intrinsics

__all__ = ["depth_mask", "face_camera", "h5py_module", "optional_module", "read_depth_png",
           "resolve_intrinsics"]


def optional_module(name: str, needed_for: str, extra: str) -> Any:
    """The module ``name`` of an optional dependency, imported on first use; without it an
    ImportError saying what needs it and which extra installs it."""
    import importlib

    try:
        return importlib.import_module(name)
    except ImportError as exc:
        raise ImportError(f"{needed_for} needs {name.split('.')[0]}: "
                          f"pip install 'depthnormals[{extra}]'") from exc


def h5py_module() -> Any:
    """h5py, imported on first use (NYU .mat and Hypersim files); a clear error without it."""
    return optional_module("h5py", "reading NYU .mat and Hypersim files", "io")


def resolve_intrinsics(intrinsics: Any, presets: Mapping[str, Intrinsics], *, what: str) -> Intrinsics:
    """An :class:`Intrinsics` from a preset name, a file, or anything :func:`as_intrinsics` takes.

    ``intrinsics`` may be a key of ``presets``, a path to a file :func:`depthnormals.io.read_intrinsics`
    reads (JSON/YAML/params.txt), an :class:`Intrinsics`, ``(fx, fy, cx, cy)`` or a 3x3 matrix.
    """
    if isinstance(intrinsics, str) and intrinsics in presets:
        return presets[intrinsics]
    if isinstance(intrinsics, (str, Path)):
        p = Path(intrinsics)
        if p.is_file():
            return read_intrinsics(p)
        raise ValueError(f"{what}: intrinsics {str(intrinsics)!r} is neither a preset "
                         f"({', '.join(sorted(presets)) or 'none'}) nor an existing file")
    return as_intrinsics(intrinsics)


def read_depth_png(path: Path, *, units_per_metre: float) -> np.ndarray:
    """A 16-bit single-channel depth PNG as float32 metres: ``value / units_per_metre`` (0 stays 0)."""
    raw = read_png(path)
    if raw.dtype != np.uint16 or raw.ndim != 2:
        raise ValueError(f"{path}: expected a 16-bit single-channel depth PNG; got {raw.dtype} "
                         f"with shape {raw.shape}")
    return (raw.astype(np.float64) / units_per_metre).astype(np.float32)


def depth_mask(depth: np.ndarray) -> np.ndarray:
    """True where depth is finite and > 0."""
    return np.isfinite(depth) & (depth > 0)


def face_camera(normals: np.ndarray, depth: np.ndarray, K: Intrinsics, valid: np.ndarray) -> np.ndarray:
    """Unit normals turned to face the camera (dot(n, X) < 0), NaN outside ``valid``; float32.

    ``normals`` (H, W, 3) in the OpenCV camera frame, any length; zero-length vectors are invalid.
    """
    n = np.asarray(normals, dtype=np.float64)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    ok = valid & np.all(np.isfinite(n), axis=-1) & (norm[..., 0] > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / norm
    h, w = depth.shape
    u = np.arange(w, dtype=np.float64)[None, :]
    v = np.arange(h, dtype=np.float64)[:, None]
    # the ray direction (u - cx) / fx, (v - cy) / fy, 1 has the sign of the point X when z > 0
    dot = n[..., 0] * (u - K.cx) / K.fx + n[..., 1] * (v - K.cy) / K.fy + n[..., 2]
    n[dot > 0] *= -1.0
    n[~ok] = np.nan
    return n.astype(np.float32)
