"""Compact storage of one synthetic view (``depthnormals-synth`` format version 2).

One file per view, ``<scene>/views/0000.npz``: a zip archive (deflate level 1, fixed
timestamps, so the bytes depend on the arrays only) whose members are ``.npy`` arrays plus
``codec.json``, which says how each decodes. ``numpy.load`` opens it (the arrays as stored);
:func:`read_view` decodes it. Depth maps are stored as byte planes, one member each
(``clean.0.npy`` is the most significant); a plane that deflate does not shrink (the low
bits of noise) is stored uncompressed.

Members
-------
``normals``
    Octahedral encoding (Meyer et al. 2010; Cigolle et al. 2014), two uint16 per pixel,
    grid points ``q`` of the octahedral coordinates ``p = 2 q / 65535 - 1`` in [-1, 1]^2,
    each pixel's code chosen among the 4 grid points around it as the one closest in angle
    (the "precise" variant of Cigolle et al.). Measured maximum angular error 0.0025 deg
    over 2 million random unit vectors, decoded to float32 (tests/test_synth_ssn.py pins
    < 0.003 deg).
    Pixels without ground truth are (0, 0) and read back as NaN (``valid`` decides).
``valid``
    ``numpy.packbits`` along rows, (H, ceil(W / 8)) uint8.
``clean`` and every noisy variant, float32 planar depth in metres (0 = none)
    ``f32``: lossless. The float32 bit patterns as uint32 (for positive floats the integer
    order is the value order, so near values have near patterns), a predictor (``grad``:
    the residual of ``left + up - upleft``, for the clean depth; ``row``: of ``left``, for
    noisy depth, where the noise makes the 2-D predictor worse), wrapping integer
    arithmetic, then the bytes split into planes (most significant first) and deflated.
    ``int``: exact multiples ``k * step`` of a model's rounding step (kinect_v2: 1 mm) as
    uint16 ``k`` with predictor ``row``; decoded as ``float32(float64(k) * step)``, which
    gives back the float32 values bit for bit (checked when writing: a map that does not
    round-trip exactly is stored ``f32`` instead).

Only the normals are lossy; every depth map reads back bit-identical to format version 1.

References
----------
Meyer, Sümuth, Stamminger et al., "On floating-point normal vectors", EGSR 2010.
Cigolle, Donow, Evangelakos, Mara, McGuire, Meyer, "A survey of efficient representations for
independent unit vectors", JCGT 3(2), 2014.
"""

from __future__ import annotations

import io
import json
import zipfile
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numba as nb
import numpy as np

from .io import write_bytes_atomic

__all__ = ["decode_normals", "encode_normals", "read_view", "view_bytes", "write_view"]

#: deflate level: 1 measured 0.77 MB per view (2 noise models, 512 x 424), level 6 about 0.71 MB
#: at 2-3 times the compression time (docs/synthetic.md, "SSN-scale preset").
ZLIB_LEVEL = 1
#: the zip timestamp of every member (the earliest zip can store): files depend on data only.
_EPOCH = (1980, 1, 1, 0, 0, 0)
_CODEC = "codec.json"
_Q = 65535.0


def _sign(a: np.ndarray) -> np.ndarray:
    return np.where(a >= 0.0, 1.0, -1.0)


def _fold(x: np.ndarray, y: np.ndarray, lower: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The octahedron's lower half folded onto the square's corners (its own inverse)."""
    fx = np.where(lower, (1.0 - np.abs(y)) * _sign(x), x)
    fy = np.where(lower, (1.0 - np.abs(x)) * _sign(y), y)
    return fx, fy


def _oct_decode(q: np.ndarray) -> np.ndarray:
    p = q.astype(np.float64) * (2.0 / _Q) - 1.0
    x, y = p[..., 0], p[..., 1]
    z = 1.0 - np.abs(x) - np.abs(y)
    x, y = _fold(x, y, z < 0.0)
    n = np.stack([x, y, z], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


@nb.njit(cache=True, nogil=True)
def _fold1(x, y):  # pragma: no cover - compiled
    """:func:`_fold` of one point of the lower half."""
    sx = 1.0 if x >= 0.0 else -1.0
    sy = 1.0 if y >= 0.0 else -1.0
    return (1.0 - abs(y)) * sx, (1.0 - abs(x)) * sy


@nb.njit(cache=True, nogil=True)
def _oct_encode_kernel(n, out):  # pragma: no cover - compiled
    """Octahedral codes of directions: reads ``n`` (N, 3), writes ``out`` (N, 2) uint16.

    A row with a non-finite or zero component sum gets (0, 0); a row equal to the previous one
    gets its code (ground truth is one normal per triangle: runs of equal rows). Per vector:
    ``p = n / |n|_1``, the lower half folded, grid position ``g = (p + 1) / 2 * Q``; of the 4
    grid points around ``g``, the one whose decoded direction has the largest cosine with
    ``n`` (first in the order (0, 0), (0, 1), (1, 0), (1, 1) on ties).
    """
    for i in range(n.shape[0]):
        x, y, z = float(n[i, 0]), float(n[i, 1]), float(n[i, 2])
        if i > 0 and x == n[i - 1, 0] and y == n[i - 1, 1] and z == n[i - 1, 2]:
            out[i, 0] = out[i - 1, 0]
            out[i, 1] = out[i - 1, 1]
            continue
        s = abs(x) + abs(y) + abs(z)
        if not (np.isfinite(s) and s > 0.0):
            out[i, 0] = 0
            out[i, 1] = 0
            continue
        r = np.sqrt(x * x + y * y + z * z)
        x, y, z = x / r, y / r, z / r
        px, py = x * r / s, y * r / s
        if z < 0.0:
            px, py = _fold1(px, py)
        lx = min(max(np.floor((px + 1.0) * (_Q / 2.0)), 0.0), _Q - 1.0)
        ly = min(max(np.floor((py + 1.0) * (_Q / 2.0)), 0.0), _Q - 1.0)
        best = -2.0
        bx, by = lx, ly
        for dx in range(2):
            for dy in range(2):
                ux = (lx + dx) * (2.0 / _Q) - 1.0
                uy = (ly + dy) * (2.0 / _Q) - 1.0
                uz = 1.0 - abs(ux) - abs(uy)
                if uz < 0.0:
                    ux, uy = _fold1(ux, uy)
                c = (ux * x + uy * y + uz * z) / np.sqrt(ux * ux + uy * uy + uz * uz)
                if c > best:
                    best, bx, by = c, lx + dx, ly + dy
        out[i, 0] = np.uint16(bx)
        out[i, 1] = np.uint16(by)


def encode_normals(normals: np.ndarray) -> np.ndarray:
    """Normals (..., 3), float -> octahedral codes (..., 2) uint16; non-finite rows -> (0, 0).

    Each vector is normalised, then coded as the nearest of the 4 surrounding grid points in
    angle (:func:`_oct_encode_kernel`); maximum error 0.0025 deg (measured).
    """
    n = np.asarray(normals)
    if n.shape[-1:] != (3,) or n.dtype.kind != "f":
        raise ValueError(f"normals must be a float array of shape (..., 3); got {n.dtype} {n.shape}")
    flat = np.ascontiguousarray(n.reshape(-1, 3), dtype=np.float64)  # one compiled signature
    out = np.empty((flat.shape[0], 2), dtype=np.uint16)
    _oct_encode_kernel(flat, out)
    return out.reshape(*n.shape[:-1], 2)


def decode_normals(codes: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Octahedral codes (H, W, 2) -> float32 unit normals (H, W, 3), NaN where not ``valid``."""
    n = _oct_decode(np.asarray(codes))
    n[~np.asarray(valid, dtype=bool)] = np.nan
    return n.astype(np.float32)


def _predict(a: np.ndarray, predictor: str) -> np.ndarray:
    """Residuals of an integer (H, W) image under ``predictor`` (wrapping arithmetic)."""
    d = a.copy()
    d[:, 1:] -= a[:, :-1]
    if predictor == "grad":
        d[1:, :] -= d[:-1, :].copy()
    return d


def _unpredict(d: np.ndarray, predictor: str) -> np.ndarray:
    a = np.cumsum(d, axis=0, dtype=d.dtype) if predictor == "grad" else d
    return np.cumsum(a, axis=1, dtype=d.dtype)


def _planes(a: np.ndarray) -> np.ndarray:
    """Bytes of an integer image split into planes, most significant first: (itemsize, H*W)."""
    b = a.astype(a.dtype.newbyteorder(">")).view(np.uint8).reshape(-1, a.dtype.itemsize)
    return np.ascontiguousarray(b.T)


def _unplanes(p: np.ndarray, dtype: np.dtype, shape: tuple[int, int]) -> np.ndarray:
    be = np.dtype(dtype).newbyteorder(">")
    return np.ascontiguousarray(p.T).view(be).reshape(shape).astype(dtype)


def _encode_depth(z: np.ndarray, *, predictor: str, step: float | None) -> tuple[np.ndarray, dict]:
    z = np.ascontiguousarray(z, dtype=np.float32)
    if step is not None:
        k = np.rint(z.astype(np.float64) / step)
        if k.min() >= 0 and k.max() <= 65535:
            k = k.astype(np.uint16)
            if np.array_equal((k.astype(np.float64) * step).astype(np.float32).view(np.uint32),
                              z.view(np.uint32)):
                return _planes(_predict(k, "row")), {"codec": "int", "dtype": "uint16", "step": step,
                                                     "predictor": "row"}
    return _planes(_predict(z.view(np.uint32), predictor)), {"codec": "f32", "dtype": "uint32",
                                                            "predictor": predictor}


def _decode_depth(p: np.ndarray, info: Mapping, shape: tuple[int, int]) -> np.ndarray:
    if info["codec"] == "int":
        k = _unpredict(_unplanes(p, np.dtype(info["dtype"]), shape), info["predictor"])
        return (k.astype(np.float64) * float(info["step"])).astype(np.float32)
    if info["codec"] == "f32":
        return _unpredict(_unplanes(p, np.dtype(np.uint32), shape), info["predictor"]).view(np.float32)
    raise ValueError(f"unknown depth codec {info['codec']!r} (a newer depthnormals wrote this file?)")


def view_bytes(normals: np.ndarray, valid: np.ndarray, depths: Mapping[str, np.ndarray], *,
               steps: Mapping[str, float | None] | None = None) -> bytes:
    """Encode one view: the bytes of its ``.npz`` (deterministic for the same arrays).

    Parameters
    ----------
    normals : ndarray (H, W, 3)
        Ground-truth unit normals (NaN where none).
    valid : ndarray (H, W) bool
        Ground truth valid.
    depths : mapping str -> ndarray (H, W)
        ``"clean"`` (lossless, 2-D predictor) and one noisy depth map per model (lossless,
        row predictor, or exact integers where ``steps[name]`` gives the model's rounding).
    steps : mapping str -> float or None, optional, keyword-only
        Rounding step (metres) of each noisy variant, where its model rounds.

    Returns
    -------
    bytes
    """
    valid = np.asarray(valid, dtype=bool)
    if valid.ndim != 2 or np.shape(normals) != (*valid.shape, 3):
        raise ValueError(f"normals must be (H, W, 3) and valid (H, W); got {np.shape(normals)} and "
                         f"{valid.shape}")
    steps = dict(steps or {})
    members: dict[str, np.ndarray] = {"normals": encode_normals(normals),
                                      "valid": np.packbits(valid, axis=1)}
    codec: dict = {"format": "depthnormals-synth-view", "version": 2, "shape": list(valid.shape),
                   "members": {"normals": {"codec": "oct16"}, "valid": {"codec": "bits"}}}
    for name, z in depths.items():
        if np.shape(z) != valid.shape:
            raise ValueError(f"depth {name!r} has shape {np.shape(z)}; expected {valid.shape}")
        pred = "grad" if name == "clean" else "row"
        members[name], codec["members"][name] = _encode_depth(z, predictor=pred, step=steps.get(name))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        _put(zf, _CODEC, (json.dumps(codec, sort_keys=True) + "\n").encode())
        for name, arr in members.items():
            if name in depths:  # one member per byte plane; noise-only planes stored as they are
                for i, plane in enumerate(arr):
                    _put(zf, f"{name}.{i}.npy", _npy(plane), deflate=_compressible(plane))
            else:
                _put(zf, f"{name}.npy", _npy(arr))
    return buf.getvalue()


def _npy(arr: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, arr, allow_pickle=False)
    return out.getvalue()


def _compressible(plane: np.ndarray) -> bool:
    """Whether deflate gains over 5 % on the plane's first 16 KiB (low planes of noisy depth
    are noise: measured 217,164 bytes deflated of 217,088, at 30 % of the view's encoding time)."""
    head = plane[:16384].tobytes()
    return len(zlib.compress(head, ZLIB_LEVEL)) < 0.95 * len(head)


def _put(zf: zipfile.ZipFile, name: str, data: bytes, *, deflate: bool = True) -> None:
    kind = zipfile.ZIP_DEFLATED if deflate else zipfile.ZIP_STORED
    info = zipfile.ZipInfo(name, date_time=_EPOCH)
    info.compress_type = kind
    info.create_system = 3  # the same bytes on every platform
    info.external_attr = 0o644 << 16
    zf.writestr(info, data, compress_type=kind, compresslevel=ZLIB_LEVEL if deflate else None)


def write_view(path: str | Path, normals: np.ndarray, valid: np.ndarray, depths: Mapping[str, np.ndarray],
               *, steps: Mapping[str, float | None] | None = None) -> None:
    """:func:`view_bytes` written atomically to ``path``."""
    write_bytes_atomic(path, view_bytes(normals, valid, depths, steps=steps))


def read_view(path: str | Path,
              variants: Sequence[str]) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Decode a view file: ``(normals float32 (H, W, 3), valid bool (H, W), {variant: depth})``.

    Only the members asked for are decompressed. A file that is not a readable view (truncated,
    corrupt) raises ValueError naming it.
    """
    try:
        return _read_view(path, variants)
    except (zipfile.BadZipFile, zlib.error, KeyError, EOFError, OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is not a readable view file: {exc or type(exc).__name__}") from exc
    except ValueError as exc:
        if str(path) in str(exc):
            raise
        raise ValueError(f"{path} is not a readable view file: {exc}") from exc


def _read_view(path: str | Path,
               variants: Sequence[str]) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    with zipfile.ZipFile(path) as zf:
        codec = json.loads(zf.read(_CODEC))
        if codec.get("version") != 2:
            raise ValueError(f"{path}: view file version {codec.get('version')!r}; this depthnormals "
                             "reads version 2")
        h, w = codec["shape"]

        def member(name: str) -> np.ndarray:
            return np.load(io.BytesIO(zf.read(f"{name}.npy")), allow_pickle=False)

        for v in variants:
            if v not in codec["members"]:
                raise ValueError(f"{path} holds no {v!r}; it has {', '.join(codec['members'])}")
        valid = np.unpackbits(member("valid"), axis=1, count=w).astype(bool)
        normals = decode_normals(member("normals"), valid)
        depths = {}
        for v in variants:
            info = codec["members"][v]
            nplanes = np.dtype(info["dtype"]).itemsize
            planes = np.stack([member(f"{v}.{i}") for i in range(nplanes)])
            depths[v] = _decode_depth(planes, info, (h, w))
    return normals, valid, depths
