"""Reader of real sensor depth folders: depth images beside an ``intrinsics.json``.

The layout of ``../shared/data/real-sensors/*`` (frames from Kinect v1, Xtion, densified
LiDAR; no ground-truth normals)::

    <folder>/
        intrinsics.json        # fx, fy, cx, cy, depth_scale, invalid_value, raw_format / encoding
        *.png | *.pgm | *.npy  # depth frames, at the top ...
        depth/*.png|pgm|npy    # ... or in depth/ (then only those are read)
        rgb.png, ...           # colour images: skipped

A folder of such folders is read too, one group per sub-folder. Depth encodings
(:data:`ENCODINGS`): ``linear`` (``metres = value * depth_scale``), ``nyu_raw_disparity``
(Kinect v1 11-bit disparity of the NYU Depth v2 raw frames, stored little-endian behind a PGM
header that says big-endian: ``metres = 351.3 / (1092.5 - raw)``, 2047 = none) and
``sunrgbd_rotated`` (SUN RGB-D's PNGs, the millimetres rotated left by three bits:
``mm = (v >> 3) | (v << 13)`` in 16 bits). docs/datasets.md, section "Real sensor folders".
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .._png import read_png
from ..camera import Intrinsics, lens_distortion, undistort_depth
from ..io import read_npy, read_pgm
from ._common import depth_mask, resolve_intrinsics
from ._frame import Frame

__all__ = ["ENCODINGS", "decode_nyu_disparity", "decode_sunrgbd", "encoding_of", "is_realsensors",
           "read_pgm", "read_realsensors"]

#: Depth encodings of :func:`read_realsensors` (``"encoding"`` in ``intrinsics.json``).
ENCODINGS = ("linear", "nyu_raw_disparity", "sunrgbd_rotated")
#: File suffixes read as depth.
DEPTH_SUFFIXES = (".png", ".pgm", ".npy")
#: NYU Depth v2 toolbox (``depth_rel2depth_abs``): metres = NYU_A / (NYU_B - disparity).
NYU_A = 351.3
NYU_B = 1092.5
#: The disparity code of a pixel without a return (11 bits all set).
NYU_INVALID = 2047
_JSON = "intrinsics.json"


def _read_json(folder: Path) -> dict:
    try:
        info = json.loads((folder / _JSON).read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{folder / _JSON}: not a readable JSON object ({exc})") from exc
    if not isinstance(info, dict):
        raise ValueError(f"{folder / _JSON}: expected a JSON object; got {type(info).__name__}")
    return info


def _depth_files(folder: Path) -> list[Path]:
    """Depth candidates: ``depth/`` when it holds any, else the folder itself (sorted)."""
    sub = folder / "depth"
    where = sub if sub.is_dir() and any(_candidates(sub)) else folder
    return sorted(_candidates(where), key=_frame_key)


def _candidates(folder: Path) -> Iterator[Path]:
    return (p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in DEPTH_SUFFIXES)


def _frame_key(p: Path) -> tuple[int, str]:
    return (int(p.stem), p.name) if p.stem.isdigit() else (1 << 62, p.name)


def _is_folder(p: Path) -> bool:
    if not (p / _JSON).is_file():
        return False
    try:
        info = json.loads((p / _JSON).read_text())
    except (OSError, ValueError):
        return False
    return (isinstance(info, dict) and all(k in info for k in ("fx", "fy", "cx", "cy"))
            and bool(_depth_files(p)))


def is_realsensors(path: str | Path) -> bool:
    """True for a folder with ``intrinsics.json`` (fx, fy, cx, cy) and depth images (at the top
    or in ``depth/``), or a folder of such folders."""
    p = Path(path)
    if not p.is_dir():
        return False
    return _is_folder(p) or any(_is_folder(c) for c in p.iterdir() if c.is_dir())


def encoding_of(info: dict) -> str:
    """The depth encoding an ``intrinsics.json`` declares.

    ``"encoding"`` when present (one of :data:`ENCODINGS`); else from the free-text
    ``"raw_format"``: ``nyu_raw_disparity`` when it names ``NYU_depth.pgm`` or raw disparity,
    ``sunrgbd_rotated`` when it speaks of a bit rotation / shift; else ``linear``.
    """
    enc = info.get("encoding")
    if enc is not None:
        if enc not in ENCODINGS:
            raise ValueError(f"intrinsics.json: unknown encoding {enc!r}; use one of "
                             f"{', '.join(ENCODINGS)}")
        return str(enc)
    text = str(info.get("raw_format", "")).lower()
    if "nyu_depth.pgm" in text or "raw kinect disparity" in text:
        return "nyu_raw_disparity"
    if "rotation" in text or "rotated" in text or "circularly shifted" in text:
        return "sunrgbd_rotated"
    return "linear"


def decode_nyu_disparity(raw: np.ndarray) -> np.ndarray:
    """Metres (float32) from NYU Depth v2 raw Kinect disparity: ``351.3 / (1092.5 - raw)``.

    2047 (no return) and codes at or above 1092.5 (no finite depth) give 0.

    Examples
    --------
    >>> decode_nyu_disparity(np.array([985, 2047], np.uint16)).astype(float).round(4).tolist()
    [3.2679, 0.0]
    """
    d = np.asarray(raw).astype(np.float64)
    ok = (d < NYU_INVALID) & (d < NYU_B)
    z = np.zeros(d.shape)
    z[ok] = NYU_A / (NYU_B - d[ok])
    return z.astype(np.float32)


def decode_sunrgbd(raw: np.ndarray) -> np.ndarray:
    """Millimetres (uint16) from a SUN RGB-D depth PNG: ``(v >> 3) | (v << 13)`` in 16 bits.

    Examples
    --------
    >>> decode_sunrgbd(np.array([2000 << 3], np.uint16)).tolist()
    [2000]
    """
    v = np.asarray(raw).astype(np.uint16)
    return ((v >> np.uint16(3)) | (v << np.uint16(13))).astype(np.uint16)


def _png_kind(path: Path) -> tuple[int, int] | None:
    """(bit depth, colour type) from a PNG header, or None when it is not a PNG."""
    with path.open("rb") as fh:
        head = fh.read(26)
    if len(head) < 26 or head[:8] != b"\x89PNG\r\n\x1a\n":
        return None
    return head[24], head[25]


def _load_raw(path: Path, encoding: str) -> np.ndarray | None:
    """The stored samples of a depth file, or None when the file is not depth (colour, 8-bit)."""
    suffix = path.suffix.lower()
    if suffix == ".png":
        kind = _png_kind(path)
        if kind is None or kind != (16, 0):  # depth is 16-bit greyscale
            return None
        return read_png(path)
    if suffix == ".pgm":
        arr = read_pgm(path, byteorder="<" if encoding == "nyu_raw_disparity" else ">")
        return arr if arr.dtype == np.uint16 else None
    arr = read_npy(path)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim != 2 or arr.dtype.kind not in "iuf":
        return None
    return arr


def _invalid_codes(info: dict) -> list[float]:
    codes = info.get("invalid_value", [])
    codes = codes if isinstance(codes, list) else [codes]
    return [float(c) for c in codes]


def _to_metres(raw: np.ndarray, encoding: str, scale: float, invalid: list[float]) -> np.ndarray:
    """Metres (float32, 0 = invalid) from the stored samples."""
    if encoding == "nyu_raw_disparity":
        return decode_nyu_disparity(raw)
    if raw.dtype.kind == "f":  # float files hold metres
        z = raw.astype(np.float32)
        return np.where(np.isfinite(z) & (z > 0), z, np.float32(0.0)).astype(np.float32)
    bad = raw == 0
    if raw.dtype.kind == "u":
        bad |= raw == np.iinfo(raw.dtype).max  # saturated code
    for c in invalid:
        bad |= raw == c
    if encoding == "sunrgbd_rotated":
        raw = decode_sunrgbd(raw)
    z = (raw.astype(np.float64) * scale).astype(np.float32)
    z[bad | (z < 0)] = 0.0
    return z


def _distortion_of(info: dict, folder: Path) -> tuple[float, ...]:
    """The ``distortion`` of an ``intrinsics.json`` (OpenCV's order), () when absent or all 0."""
    try:
        return lens_distortion(info.get("distortion"))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{folder / _JSON}: {exc}") from exc


def _folder_frames(folder: Path, group: str, intrinsics: Any,
                   depth_scale: float | None, undistort: bool) -> Iterator[Frame]:
    info = _read_json(folder)
    dist = _distortion_of(info, folder) if undistort else ()
    encoding = encoding_of(info)
    presets = {k: Intrinsics(v["fx"], v["fy"], v["cx"], v["cy"]) for k, v in info.items()
               if isinstance(v, dict) and all(x in v for x in ("fx", "fy", "cx", "cy"))}
    cam = (resolve_intrinsics(intrinsics, presets, what=str(folder)) if intrinsics is not None
           else Intrinsics(info["fx"], info["fy"], info["cx"], info["cy"]))
    scale = float(depth_scale if depth_scale is not None else info.get("depth_scale", 0.001))
    invalid = _invalid_codes(info)
    for file in _depth_files(folder):
        if encoding == "nyu_raw_disparity" and file.suffix.lower() != ".pgm":
            continue  # the folder's other images are derived from the raw .pgm
        raw = _load_raw(file, encoding)
        if raw is None:
            continue
        depth = _to_metres(raw, encoding, scale, invalid)
        if dist:  # onto the pinhole grid (nearest: no blend across jumps); 0 where it leaves
            depth = np.nan_to_num(undistort_depth(depth, cam, dist), nan=0.0)
        meta = {"format": "realsensors", "depth_file": str(file), "encoding": encoding,
                "depth_scale": None if encoding == "nyu_raw_disparity" else scale,
                "sensor": str(info.get("sensor", "")),
                "intrinsics": "given" if intrinsics is not None else _JSON,
                "undistorted": list(dist) if dist else None}
        if "plane_threshold" in info:
            meta["plane_threshold"] = [float(t) for t in info["plane_threshold"]]
        yield Frame(depth=depth, normals=None, K=cam.matrix, mask=depth_mask(depth),
                    name=file.stem, group=group, meta=meta)


def read_realsensors(path: str | Path, *, intrinsics: Any = None,
                     depth_scale: float | None = None, undistort: bool = True) -> Iterator[Frame]:
    """Yield the frames of a real sensor folder (or of a folder of them).

    Parameters
    ----------
    path : str or Path
        A folder with ``intrinsics.json`` and depth images (``.png`` 16-bit grey, ``.pgm``
        16-bit, ``.npy``, at the top or in ``depth/``), or a folder of such folders.
    intrinsics : str, Intrinsics, (fx, fy, cx, cy), 3x3 array or path, optional
        Overrides the camera of ``intrinsics.json``; a string may also name one of its
        alternative cameras (an object with fx, fy, cx, cy, e.g.
        ``"alt_intrinsics_ros_default"``).
    depth_scale : float, optional
        Metres per stored unit of integer files; overrides ``intrinsics.json``'s
        ``depth_scale`` (default there: 0.001).
    undistort : bool, default True
        Where ``intrinsics.json`` gives the lens's ``distortion`` (OpenCV's order ``k1, k2, p1,
        p2[, k3[, k4, k5, k6[, s1, s2, s3, s4]]]``), resample each frame onto the pinhole grid
        of its camera (:func:`depthnormals.undistort_depth`; nearest pixel, 0 where the ray
        leaves the image); False keeps the stored grid (the estimators then read it as a
        pinhole image).

    Yields
    ------
    Frame
        Depth in metres (float32, 0 = invalid), ``normals=None``, K, ``mask`` = valid depth,
        ``name`` = file stem, ``group`` = the folder's name (its path relative to ``path``
        for a folder of folders), ``meta`` with the file, encoding, scale, sensor text and
        the distortion undone (``"undistorted"``, None when none).

    Notes
    -----
    Invalid stored values become 0: zero, the integer type's largest value (65535: a
    saturated code) and the ``invalid_value`` codes of ``intrinsics.json`` (a number or a
    list). Float ``.npy`` files hold metres (``depth_scale`` is for integer files). Files
    that are not depth (colour or 8-bit PNGs, 8-bit PGMs, non-2-D arrays) are skipped;
    ``(H, W, 1)`` arrays are squeezed. In a ``nyu_raw_disparity`` folder only the ``.pgm``
    files are read (``NYU_depth_mm_derived.png`` beside ``NYU_depth.pgm`` is the same frame).

    Examples
    --------
    >>> import json, tempfile
    >>> from pathlib import Path
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     _ = (Path(tmp) / "intrinsics.json").write_text(json.dumps(
    ...         {"fx": 50.0, "fy": 50.0, "cx": 15.5, "cy": 11.5, "depth_scale": 0.001}))
    ...     np.save(Path(tmp) / "d.npy", np.full((24, 32, 1), 1500, np.uint16))
    ...     [(f.name, f.depth.shape, float(f.depth[0, 0])) for f in read_realsensors(tmp)]
    [('d', (24, 32), 1.5)]
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"real sensor folder {root} does not exist")
    if _is_folder(root):
        yield from _folder_frames(root, root.name, intrinsics, depth_scale, undistort)
        return
    folders = sorted(c for c in root.iterdir() if c.is_dir() and _is_folder(c))
    if not folders:
        raise ValueError(f"{root}: no intrinsics.json with fx, fy, cx, cy beside depth images "
                         "(at the top or in depth/), here or in a sub-folder")
    for folder in folders:
        yield from _folder_frames(folder, folder.relative_to(root).as_posix(), intrinsics,
                                  depth_scale, undistort)
