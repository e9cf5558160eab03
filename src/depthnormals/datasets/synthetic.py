"""Reader of datasets written by :func:`depthnormals.synth.generate` (format "depthnormals-synth").

See docs/synthetic.md for the layout; both format versions are read (1: ``.npy`` files,
2: compact ``views/*.npz``, :mod:`depthnormals._compact`).
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from ..camera import Intrinsics
from ..io import read_npy
from ._frame import Frame

__all__ = ["is_synthetic", "read_synthetic"]

_FORMAT = "depthnormals-synth"
#: 1: one float32 ``.npy`` per array and view; 2: one compact ``views/0000.npz`` per view.
_VERSIONS = (1, 2)


def _load_view(sdir: Path, name: str, variants: Sequence[str],
               version: int) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]] | None:
    """(normals, valid, {variant: depth}) of view ``name``, or None if it is not written yet.

    Variants whose file is missing (version 1, interrupted run) are left out.
    """
    if version == 2:
        vfile = sdir / "views" / f"{name}.npz"
        if not vfile.is_file():
            return None
        from .._compact import read_view

        return read_view(vfile, variants)
    nfile = sdir / "normals" / f"{name}.npy"
    if not nfile.is_file():
        return None
    # (checked reads: a truncated or corrupt file is a ValueError naming it, not numpy's EOF)
    depths = {v: read_npy(sdir / v / f"{name}.npy") for v in variants
              if (sdir / v / f"{name}.npy").is_file()}
    return read_npy(nfile), read_npy(sdir / "valid" / f"{name}.npy"), depths


def _sidecar(path: Path) -> dict | None:
    f = path / "dataset.json"
    if not f.is_file():
        return None
    try:
        data = json.loads(f.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    return data if isinstance(data, dict) and data.get("format") == _FORMAT else None


def is_synthetic(path: str | Path) -> bool:
    """True for a dataset root (``dataset.json``) or a scene folder (``scene.json``) of ours."""
    p = Path(path)
    if _sidecar(p) is not None:
        return True
    return (p / "scene.json").is_file() and _sidecar(p.parent.parent) is not None


def read_synthetic(path: str | Path, *, variants: Sequence[str] | None = None) -> Iterator[Frame]:
    """Yield the frames of a synthetic dataset (root or one scene folder).

    Parameters
    ----------
    path : str or Path
        Dataset root (with ``dataset.json``) or a scene folder (``<root>/<kind>/<scene>``).
    variants : sequence of str, optional, keyword-only
        Variants to read (``"clean"`` and/or noise model names); default all.

    Yields
    ------
    Frame
        ``depth`` float32 (0 = no measurement), ``normals`` float32 (NaN = no surface),
        ``mask`` the ground-truth validity, ``K`` (3, 3), ``name`` ``"0000"``, ``group``
        ``"<kind>/<scene>/<variant>"``, ``meta`` with ``pose`` (camera-to-world 4x4),
        ``variant`` and the noise settings.

    Examples
    --------
    >>> import tempfile
    >>> from depthnormals.synth import generate
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     _ = generate(tmp, indoor=1, outdoor=0, views=1, size=(48, 64), noise=(),
    ...                  K=(36.5, 36.5, 31.5, 23.5), progress=False)
    ...     [f.group for f in read_synthetic(tmp)]
    ['indoor/living_room-00/clean']
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"dataset path {p} does not exist")
    meta = _sidecar(p)
    if meta is not None:
        root, scenes = p, list(meta["scenes"])
    elif (p / "scene.json").is_file() and _sidecar(p.parent.parent) is not None:
        root, meta = p.parent.parent, _sidecar(p.parent.parent)
        scenes = [f"{p.parent.name}/{p.name}"]
    else:
        raise ValueError(f"{p} is not a {_FORMAT} dataset root or scene folder")
    known = list(meta["variants"])
    chosen = known if variants is None else list(variants)
    for v in chosen:
        if v not in known:
            raise ValueError(f"variant {v!r} not in {p}; valid: {', '.join(known)}")
    noise = {n["model"]: n["settings"] for n in meta["settings"].get("noise", [])}
    version = meta.get("format_version", 1)
    if version not in _VERSIONS:
        raise ValueError(f"{root}: {_FORMAT} format version {version!r}; this depthnormals reads versions "
                         f"{', '.join(map(str, _VERSIONS))} (a newer depthnormals wrote it?)")
    for rel in scenes:
        sdir = root / rel
        info = json.loads((sdir / "scene.json").read_text())
        Kd = info["K"]
        K = Intrinsics(Kd["fx"], Kd["fy"], Kd["cx"], Kd["cy"]).matrix
        poses = np.asarray(info["poses"], dtype=np.float64)
        for view in range(poses.shape[0]):
            name = f"{view:04d}"
            loaded = _load_view(sdir, name, chosen, version)
            if loaded is None:
                continue  # not generated yet (interrupted run)
            normals, mask, depths = loaded
            for v, depth in depths.items():
                yield Frame(depth=depth, normals=normals, K=K, mask=mask, name=name,
                            group=f"{rel}/{v}",
                            meta={"format": _FORMAT, "variant": v, "pose": poses[view],
                                  "noise": noise.get(v), "scene": info.get("recipe", info["name"])})
