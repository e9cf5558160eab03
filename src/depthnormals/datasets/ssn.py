"""Reader of the SSN dataset layout of the 3F2N+ paper (OpenEXR frames).

Layout (NOTES.md section 5): ``<root>/{indoor|outdoor}/<scene>/standard_exr/%04d.exr``, each
EXR with channel ``Z`` (planar depth, metres) and ``R, G, B`` (the normal). Any folder named
``*_exr`` inside a scene is read as a variant (``standard_exr`` -> ``"standard"``).

Reading EXR needs the ``OpenEXR`` package (``pip install 'depthnormals[synth]'``), imported
only when a file is read.

What the files do not say, and what we assume (both are options): the normal is stored in
the OpenCV camera frame with components in [-1, 1] (``normal_frame="opengl"`` converts from
x right, y up, z backward); background pixels have a non-finite, non-positive or huge
(> ``max_depth``) Z. Normals are renormalised and turned to face the camera.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import as_intrinsics
from ._frame import Frame

__all__ = ["is_ssn", "read_exr_channels", "read_ssn"]

_KINDS = ("indoor", "outdoor")
#: Kinect v2 default (image centre); pass K for measured values.
_SSN_K = (365.5, 365.5, 255.5, 211.5)


def _exr_dirs(scene: Path) -> list[Path]:
    return sorted(d for d in scene.iterdir()
                  if d.is_dir() and d.name.endswith("_exr") and any(d.glob("*.exr")))


def _scenes(root: Path) -> list[tuple[str, Path]]:
    """(group prefix, scene folder) pairs under ``root`` in the SSN layout."""
    if root.name.endswith("_exr") and any(root.glob("*.exr")):
        return [(f"{root.parent.parent.name}/{root.parent.name}", root.parent)]
    if _exr_dirs(root):
        return [(f"{root.parent.name}/{root.name}", root)]
    out = []
    kinds = [root / k for k in _KINDS if (root / k).is_dir()]
    if root.name in _KINDS:
        kinds = [root]
    for kdir in kinds:
        for scene in sorted(p for p in kdir.iterdir() if p.is_dir()):
            if _exr_dirs(scene):
                out.append((f"{kdir.name}/{scene.name}", scene))
    return out


def is_ssn(path: str | Path) -> bool:
    """True if ``path`` is an SSN root, kind folder, scene folder or ``*_exr`` folder."""
    p = Path(path)
    return p.is_dir() and bool(_scenes(p))


def read_exr_channels(path: str | Path) -> dict[str, np.ndarray]:
    """Read every channel of an EXR file as float32 (H, W) arrays, keyed by channel name."""
    try:
        import OpenEXR
    except ImportError as exc:
        raise ImportError("reading EXR files needs the OpenEXR package: "
                          "pip install 'depthnormals[synth]' (or pip install OpenEXR)") from exc
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EXR file {path} does not exist")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            chans = {name: np.asarray(ch.pixels, dtype=np.float32) for name, ch in f.channels().items()}
    except Exception as exc:  # OpenEXR raises RuntimeError/OSError on corrupt files
        raise ValueError(f"{path}: cannot read EXR ({type(exc).__name__}: {exc})") from exc
    return chans


def read_ssn(path: str | Path, *, K: Any = _SSN_K, normal_frame: str = "opencv",
             max_depth: float = 1e4) -> Iterator[Frame]:
    """Yield the frames of an SSN dataset folder (root, kind, scene or ``*_exr`` folder).

    Parameters
    ----------
    path : str or Path
        Any level of the SSN layout.
    K : intrinsics, keyword-only
        Camera; default Kinect v2 with the principal point at the image centre.
    normal_frame : {"opencv", "opengl"}, keyword-only
        Frame of the stored normals (see the module notes).
    max_depth : float, keyword-only
        Z above this is background.

    Yields
    ------
    Frame
        ``group`` ``"<kind>/<scene>/<variant>"`` (e.g. ``"indoor/office/standard"``),
        ``name`` the file stem, float32 depth (0 on background), camera-facing normals.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"dataset path {p} does not exist")
    if normal_frame not in ("opencv", "opengl"):
        raise ValueError(f"normal_frame must be 'opencv' or 'opengl'; got {normal_frame!r}")
    cam = as_intrinsics(K)
    scenes = _scenes(p) if p.is_dir() else []
    if not scenes:
        raise ValueError(f"{p} is not in the SSN layout (<root>/indoor|outdoor/<scene>/standard_exr/*.exr)")
    for prefix, scene in scenes:
        for d in _exr_dirs(scene):
            variant = d.name[: -len("_exr")]
            for f in sorted(d.glob("*.exr")):
                ch = read_exr_channels(f)
                missing = [c for c in ("Z", "R", "G", "B") if c not in ch]
                if missing:
                    raise ValueError(f"{f}: channels {missing} missing; SSN frames have Z, R, G, B "
                                     f"(found {sorted(ch)})")
                z = ch["Z"]
                n = np.stack([ch["R"], ch["G"], ch["B"]], axis=-1).astype(np.float64)
                if normal_frame == "opengl":
                    n[..., 1:] *= -1.0
                h, w = z.shape
                valid = np.isfinite(z) & (z > 0) & (z < max_depth)
                norm = np.linalg.norm(n, axis=-1)
                valid &= np.isfinite(norm) & (norm > 0.5)
                with np.errstate(invalid="ignore", divide="ignore"):
                    n = n / norm[..., None]
                u = (np.arange(w) - cam.cx) / cam.fx
                v = (np.arange(h) - cam.cy) / cam.fy
                flip = (n[..., 0] * u[None, :] + n[..., 1] * v[:, None] + n[..., 2]) > 0
                n[flip] *= -1.0
                n[~valid] = np.nan
                depth = np.where(valid, z, 0.0).astype(np.float32)
                yield Frame(depth=depth, normals=n.astype(np.float32), K=cam.matrix, mask=valid,
                            name=f.stem, group=f"{prefix}/{variant}",
                            meta={"format": "ssn", "file": str(f), "normal_frame": normal_frame})
