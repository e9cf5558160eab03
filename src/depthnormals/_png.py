"""A small, dependency-free PNG codec for 8- and 16-bit grey, grey+alpha, RGB and RGBA.

Writing uses filter type 0 and zlib; reading handles all five filter types (compiled).
Interlaced PNGs and bit depths below 8 are rejected with a clear error.

Kept rather than replaced by Pillow or imageio (measured, see docs/datasets.md "PNG codec"):
Pillow 13 reads 16-bit RGB PNGs (the 3F2N ground-truth normals, our 16-bit normal maps) as
8-bit RGB and cannot write them, and imageio's PNG plugin is Pillow. On 640 x 480 16-bit
grey, reading is as fast as Pillow and OpenCV (about 13 ms each) and writing 4x faster than
Pillow (70 vs 295 ms; files 1.5x larger: no row filters). tests/test_readers_png_codec.py
pins it against Pillow (all five row filters) and OpenCV (16-bit RGB).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numba as nb
import numpy as np

__all__ = ["decode_png", "encode_png", "read_png"]

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}


@nb.njit(cache=True, error_model="numpy")
def _unfilter(raw, h, stride, bpp):
    out = np.empty((h, stride), dtype=np.uint8)
    pos = 0
    for y in range(h):
        ftype = raw[pos]
        pos += 1
        for x in range(stride):
            cur = np.int32(raw[pos + x])
            a = np.int32(out[y, x - bpp]) if x >= bpp else 0
            b = np.int32(out[y - 1, x]) if y > 0 else 0
            c = np.int32(out[y - 1, x - bpp]) if (y > 0 and x >= bpp) else 0
            if ftype == 0:
                val = cur
            elif ftype == 1:
                val = cur + a
            elif ftype == 2:
                val = cur + b
            elif ftype == 3:
                val = cur + (a + b) // 2
            elif ftype == 4:
                p = a + b - c
                pa = abs(p - a)
                pb = abs(p - b)
                pc = abs(p - c)
                if pa <= pb and pa <= pc:
                    pred = a
                elif pb <= pc:
                    pred = b
                else:
                    pred = c
                val = cur + pred
            else:
                return out, False
            out[y, x] = val & 0xFF
        pos += stride
    return out, True


def decode_png(data: bytes, *, name: str = "PNG data") -> np.ndarray:
    """Decode PNG bytes to an array (H, W) or (H, W, C) of uint8 or uint16 (palette -> RGB)."""
    if data[:8] != _SIGNATURE:
        raise ValueError(f"{name} is not a PNG file (bad signature)")
    pos = 8
    ihdr = None
    palette = None
    idat = []
    while pos + 8 <= len(data):
        length, ctype = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        if len(body) != length:
            raise ValueError(f"{name} is truncated (chunk {ctype!r})")
        pos += 12 + length
        if ctype == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif ctype == b"PLTE":
            palette = np.frombuffer(body, dtype=np.uint8).reshape(-1, 3)
        elif ctype == b"IDAT":
            idat.append(body)
        elif ctype == b"IEND":
            break
    if ihdr is None or not idat:
        raise ValueError(f"{name} has no IHDR or no image data")
    w, h, depth, ctype_, _, _, interlace = ihdr
    if interlace:
        raise ValueError(f"{name} is interlaced (Adam7); re-save it without interlacing")
    if ctype_ not in _CHANNELS or depth not in (8, 16) or (ctype_ == 3 and depth != 8):
        raise ValueError(f"{name}: unsupported PNG (colour type {ctype_}, bit depth {depth}); "
                         "8- or 16-bit grey/RGB/RGBA or 8-bit palette are supported")
    ch = _CHANNELS[ctype_]
    bpp = ch * depth // 8
    stride = w * bpp
    try:
        raw = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8)
    except zlib.error as exc:
        raise ValueError(f"{name} has corrupt image data: {exc}") from exc
    if raw.size != h * (stride + 1):
        raise ValueError(f"{name} has {raw.size} bytes of pixel data; expected {h * (stride + 1)}")
    rows, ok = _unfilter(raw, h, stride, bpp)
    if not ok:
        raise ValueError(f"{name} uses an unknown row filter")
    img = rows.view(">u2").astype(np.uint16) if depth == 16 else rows
    img = img.reshape(h, w, ch)
    if ctype_ == 3:
        if palette is None:
            raise ValueError(f"{name} is a palette PNG without a palette")
        img = palette[img[..., 0]]
        ch = 3
    return img[..., 0] if ch == 1 else img


def read_png(path: str | Path) -> np.ndarray:
    """Read a PNG file (see :func:`decode_png`)."""
    return decode_png(Path(path).read_bytes(), name=str(path))


def _chunk(ctype: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + ctype + body + struct.pack(">I", zlib.crc32(ctype + body))


def encode_png(img: np.ndarray, *, level: int = 6) -> bytes:
    """Encode a uint8/uint16 array (H, W), (H, W, 1), (H, W, 2/3/4) as PNG bytes."""
    a = np.asarray(img)
    if a.dtype not in (np.uint8, np.uint16):
        raise TypeError(f"PNG pixels must be uint8 or uint16; got {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 2:
        ctype, ch = 0, 1
    elif a.ndim == 3 and a.shape[2] in (2, 3, 4):
        ch = a.shape[2]
        ctype = {2: 4, 3: 2, 4: 6}[ch]
    else:
        raise ValueError(f"PNG image must be (H, W) or (H, W, 1..4); got shape {a.shape}")
    h, w = a.shape[:2]
    if h == 0 or w == 0:
        raise ValueError("cannot write an empty PNG")
    depth = 16 if a.dtype == np.uint16 else 8
    rows = np.ascontiguousarray(a.astype(">u2") if depth == 16 else a).view(np.uint8).reshape(h, -1)
    raw = np.hstack([np.zeros((h, 1), np.uint8), rows]).tobytes()
    ihdr = struct.pack(">IIBBBBB", w, h, depth, ctype, 0, 0, 0)
    return (_SIGNATURE + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", zlib.compress(raw, level))
            + _chunk(b"IEND", b""))
