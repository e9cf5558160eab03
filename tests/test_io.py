"""PNG codec, depth / intrinsics readers, normal writers, atomic writes."""

from __future__ import annotations

import json
import os
import struct
import zlib

import numpy as np
import pytest

import depthnormals as dn
from depthnormals._png import decode_png, encode_png
from depthnormals.io import (
    atomic_write,
    read_depth,
    read_intrinsics,
    read_normals,
    write_normals,
    write_png,
)

RNG = np.random.default_rng(7)


def _chunk(ctype, body):
    return struct.pack(">I", len(body)) + ctype + body + struct.pack(">I", zlib.crc32(ctype + body))


def _paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def png_with_filters(img, filters):
    """Encode ``img`` (uint8/uint16, 2-D or 3-D) with the given filter type per row (cycled)."""
    a = np.asarray(img)
    depth = 16 if a.dtype == np.uint16 else 8
    ch = 1 if a.ndim == 2 else a.shape[2]
    ctype = {1: 0, 2: 4, 3: 2, 4: 6}[ch]
    h, w = a.shape[:2]
    rows = np.ascontiguousarray(a.astype(">u2") if depth == 16 else a).view(np.uint8).reshape(h, -1)
    rows = rows.astype(int)
    bpp = ch * depth // 8
    raw = bytearray()
    for y in range(h):
        f = filters[y % len(filters)]
        raw.append(f)
        for x in range(rows.shape[1]):
            a_ = rows[y, x - bpp] if x >= bpp else 0
            b_ = rows[y - 1, x] if y > 0 else 0
            c_ = rows[y - 1, x - bpp] if (y > 0 and x >= bpp) else 0
            pred = [0, a_, b_, (a_ + b_) // 2, _paeth(a_, b_, c_)][f]
            raw.append((rows[y, x] - pred) % 256)
    ihdr = struct.pack(">IIBBBBB", w, h, depth, ctype, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", zlib.compress(bytes(raw)))
            + _chunk(b"IEND", b""))


def _random_image(dtype, ch, shape=(7, 9)):
    hi = 256 if dtype == np.uint8 else 65536
    size = shape if ch == 1 else (*shape, ch)
    return RNG.integers(0, hi, size=size).astype(dtype)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("ch", [1, 2, 3, 4])
def test_png_round_trip(dtype, ch):
    img = _random_image(dtype, ch)
    out = decode_png(encode_png(img))
    assert out.dtype == dtype
    np.testing.assert_array_equal(out, img)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("ch", [1, 3, 4])
@pytest.mark.parametrize("filters", [[0], [1], [2], [3], [4], [0, 1, 2, 3, 4], [4, 3, 2, 1]])
def test_png_decodes_every_filter_type(dtype, ch, filters):
    img = _random_image(dtype, ch, (6, 5))
    np.testing.assert_array_equal(decode_png(png_with_filters(img, filters)), img)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("ch", [1, 3, 4])
def test_png_cross_check_with_opencv(tmp_path, dtype, ch):
    """libpng (through OpenCV) picks its own filters per row; decoding must agree."""
    cv2 = pytest.importorskip("cv2")
    # smooth content makes libpng use the predicting filters
    v, u = np.mgrid[0:40, 0:50]
    base = (u * 37 + v * 11 + (u * v) % 7).astype(np.int64)
    hi = 255 if dtype == np.uint8 else 65535
    img = np.stack([(base * (k + 1)) % hi for k in range(ch)], axis=-1).astype(dtype)
    img = img[..., 0] if ch == 1 else img
    bgr = img if ch == 1 else img[..., [2, 1, 0, 3][:ch]]
    ok, buf = cv2.imencode(".png", bgr)
    assert ok
    np.testing.assert_array_equal(decode_png(buf.tobytes()), img)
    # and OpenCV reads what we write
    path = tmp_path / "x.png"
    write_png(path, img)
    back = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    back = back if ch == 1 else back[..., [2, 1, 0, 3][:ch]]
    np.testing.assert_array_equal(back, img)


def test_png_encode_errors():
    with pytest.raises(TypeError, match="uint8 or uint16"):
        encode_png(np.zeros((2, 2), np.float32))
    with pytest.raises(ValueError, match="shape"):
        encode_png(np.zeros((2, 2, 5), np.uint8))
    with pytest.raises(ValueError, match="empty"):
        encode_png(np.zeros((0, 3), np.uint8))


def test_png_corrupt_and_truncated():
    data = encode_png(_random_image(np.uint16, 3, (20, 30)))
    with pytest.raises(ValueError, match="not a PNG"):
        decode_png(b"GIF89a" + data[6:])
    with pytest.raises(ValueError, match="not a PNG"):
        decode_png(b"")
    idat = data.index(b"IDAT")
    for cut in (20, 40, idat + 10, idat + 100, len(data) - 40):
        with pytest.raises(ValueError):
            decode_png(data[:cut])
    # a flipped byte in the compressed stream
    bad = bytearray(data)
    bad[idat + 30] ^= 0xFF
    with pytest.raises(ValueError):
        decode_png(bytes(bad))
    # an unknown row filter
    good = png_with_filters(_random_image(np.uint8, 1, (3, 4)), [0])
    i = good.index(b"IDAT")
    n = struct.unpack(">I", good[i - 4:i])[0]
    raw = bytearray(zlib.decompress(good[i + 4:i + 4 + n]))
    raw[0] = 7
    forged = good[:i - 4] + _chunk(b"IDAT", zlib.compress(bytes(raw))) + _chunk(b"IEND", b"")
    with pytest.raises(ValueError, match="filter"):
        decode_png(forged)
    # unsupported bit depth / interlace
    ihdr = struct.pack(">IIBBBBB", 4, 3, 4, 0, 0, 0, 0)
    with pytest.raises(ValueError, match="unsupported"):
        decode_png(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + good[i - 4:])
    ihdr = struct.pack(">IIBBBBB", 4, 3, 8, 0, 0, 0, 1)
    with pytest.raises(ValueError, match="interlaced"):
        decode_png(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + good[i - 4:])


# --- depth --------------------------------------------------------------------------------

def test_read_depth_npy(tmp_path):
    z = RNG.uniform(0.5, 3.0, (5, 6)).astype(np.float32)
    np.save(tmp_path / "d.npy", z)
    got = read_depth(tmp_path / "d.npy")
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, z)
    np.save(tmp_path / "i.npy", np.full((3, 3), 1500, np.uint16))
    with pytest.raises(TypeError, match="depth_scale"):
        read_depth(tmp_path / "i.npy")
    np.testing.assert_allclose(read_depth(tmp_path / "i.npy", depth_scale=0.001), 1.5, rtol=1e-7)


def test_read_depth_png(tmp_path):
    mm = RNG.integers(0, 65536, (5, 6)).astype(np.uint16)
    write_png(tmp_path / "d.png", mm)
    got = read_depth(tmp_path / "d.png", depth_scale=0.001)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, mm * 0.001, rtol=1e-6)
    with pytest.raises(TypeError, match="depth_scale"):
        read_depth(tmp_path / "d.png")
    write_png(tmp_path / "rgb.png", np.zeros((2, 2, 3), np.uint16))
    with pytest.raises(ValueError, match="single-channel"):
        read_depth(tmp_path / "rgb.png", depth_scale=0.001)


def test_read_depth_tif(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    z = RNG.uniform(0.5, 3.0, (5, 6)).astype(np.float32)
    z[1, 1] = np.nan
    tifffile.imwrite(tmp_path / "d.tif", z)
    np.testing.assert_array_equal(read_depth(tmp_path / "d.tif"), z)


def test_read_depth_bin(tmp_path):
    z = RNG.uniform(0.5, 3.0, (4, 5)).astype("<f4")
    z.tofile(tmp_path / "d.bin")
    np.testing.assert_array_equal(read_depth(tmp_path / "d.bin", shape=(4, 5)), z)
    with pytest.raises(ValueError, match="shape"):
        read_depth(tmp_path / "d.bin")  # default 480 x 640


def test_read_depth_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_depth(tmp_path / "missing.npy")
    (tmp_path / "d.jpg").write_bytes(b"x")
    with pytest.raises(ValueError, match="unknown depth format"):
        read_depth(tmp_path / "d.jpg")


# --- intrinsics ---------------------------------------------------------------------------

def test_read_intrinsics_json_and_yaml(tmp_path):
    want = dn.Intrinsics(525.0, 520.0, 319.5, 239.5)
    (tmp_path / "a.json").write_text(json.dumps({"fx": 525, "fy": 520, "cx": 319.5, "cy": 239.5}))
    assert read_intrinsics(tmp_path / "a.json") == want
    (tmp_path / "b.json").write_text(json.dumps({"camera": {"K": want.matrix.tolist()}}))
    assert read_intrinsics(tmp_path / "b.json") == want
    (tmp_path / "c.json").write_text(json.dumps({"K": want.matrix.ravel().tolist()}))
    assert read_intrinsics(tmp_path / "c.json") == want
    pytest.importorskip("yaml")
    (tmp_path / "d.yaml").write_text("intrinsics:\n  fx: 525\n  fy: 520\n  cx: 319.5\n  cy: 239.5\n")
    assert read_intrinsics(tmp_path / "d.yaml") == want
    (tmp_path / "e.json").write_text(json.dumps({"f": 1}))
    with pytest.raises(ValueError, match="fx, fy, cx, cy"):
        read_intrinsics(tmp_path / "e.json")
    (tmp_path / "f.json").write_text(json.dumps({"fx": -1, "fy": 1, "cx": 0, "cy": 0}))
    with pytest.raises(ValueError, match="focal"):
        read_intrinsics(tmp_path / "f.json")


def test_read_intrinsics_params_txt_is_one_based(tmp_path):
    (tmp_path / "params.txt").write_text("1400 1380 350 200 2500")
    assert read_intrinsics(tmp_path / "params.txt") == dn.Intrinsics(1400, 1380, 349, 199)
    (tmp_path / "bad.txt").write_text("1400 x")
    with pytest.raises(ValueError, match="fx fy cx cy"):
        read_intrinsics(tmp_path / "bad.txt")
    with pytest.raises(FileNotFoundError):
        read_intrinsics(tmp_path / "none.json")


def test_intrinsics_inline(tmp_path, monkeypatch):
    """``fx,fy,cx,cy`` where no file has that name is the camera itself; a file of that name
    wins; anything else still says the file does not exist, and names the inline form."""
    monkeypatch.chdir(tmp_path)
    assert read_intrinsics("525,520,319.5,239.5") == dn.Intrinsics(525.0, 520.0, 319.5, 239.5)
    assert read_intrinsics(" 525, 520 ,319.5,239.5") == dn.Intrinsics(525.0, 520.0, 319.5, 239.5)
    with pytest.raises(ValueError, match="focal"):
        read_intrinsics("-525,520,319.5,239.5")
    for text in ("525,520,319.5", "525,520,319.5,239.5,1", "fx,fy,cx,cy", "cam.json"):
        with pytest.raises(FileNotFoundError, match="inline as fx,fy,cx,cy"):
            read_intrinsics(text)
    (tmp_path / "1,2,3,4").write_text("not a camera")  # a file of that name is read as one
    with pytest.raises(ValueError, match="1,2,3,4"):
        read_intrinsics("1,2,3,4")


# --- normals ------------------------------------------------------------------------------

def _normals():
    n = RNG.normal(size=(6, 7, 3))
    n[..., 2] = -np.abs(n[..., 2])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[2, 3] = np.nan
    n[0, 0] = (0.0, 0.0, -1.0)
    return n.astype(np.float32)


def test_normals_npy_round_trip_is_exact(tmp_path):
    n = _normals()
    write_normals(tmp_path / "n.npy", n)
    got = read_normals(tmp_path / "n.npy")
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, n)


def test_normals_png_round_trip(tmp_path):
    n = _normals()
    write_normals(tmp_path / "n.png", n)
    raw = decode_png((tmp_path / "n.png").read_bytes())
    assert raw.dtype == np.uint16 and raw.shape == (6, 7, 3)
    np.testing.assert_array_equal(raw[0, 0], [32768, 32768, 0])  # round((n + 1) / 2 * 65535)
    np.testing.assert_array_equal(raw[2, 3], [0, 0, 0])           # NaN
    got = read_normals(tmp_path / "n.png")
    assert got.dtype == np.float32
    ok = np.isfinite(n).all(axis=-1)
    assert np.array_equal(np.isnan(got).all(axis=-1), ~ok)
    np.testing.assert_allclose(got[ok], n[ok], atol=2.5e-5)  # 16-bit quantisation
    assert np.nanmax(dn.angular_error(got, n)) < 3e-3


def test_normals_vis_png(tmp_path):
    n = _normals()
    write_normals(tmp_path / "n.vis.png", n)
    rgb = decode_png((tmp_path / "n.vis.png").read_bytes())
    assert rgb.dtype == np.uint8 and rgb.shape == (6, 7, 3)
    np.testing.assert_array_equal(rgb[0, 0], [128, 128, 255])  # (1 - n) / 2 * 255
    np.testing.assert_array_equal(rgb[2, 3], [0, 0, 0])


def test_write_normals_errors(tmp_path):
    with pytest.raises(ValueError, match=r"\.npy, \.png"):
        write_normals(tmp_path / "n.txt", _normals())
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        write_normals(tmp_path / "n.npy", np.zeros((3, 3)))
    with pytest.raises(FileNotFoundError):
        write_normals(tmp_path / "no" / "n.npy", _normals())
    assert os.listdir(tmp_path) == []


# --- atomic writes ------------------------------------------------------------------------

def test_atomic_write_failure_keeps_previous_file(tmp_path):
    path = tmp_path / "out.bin"
    path.write_bytes(b"previous")
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_write(path) as fh:
            fh.write(b"partial data")
            raise RuntimeError("boom")
    assert path.read_bytes() == b"previous"
    assert os.listdir(tmp_path) == ["out.bin"]
    with atomic_write(path) as fh:
        fh.write(b"new")
    assert path.read_bytes() == b"new"
    assert os.listdir(tmp_path) == ["out.bin"]


def test_write_normals_failure_mid_write(tmp_path, monkeypatch):
    path = tmp_path / "n.npy"
    n = _normals()
    write_normals(path, n)
    before = path.read_bytes()

    def boom(fd):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(OSError, match="disk full"):
        write_normals(path, np.zeros((2, 2, 3), np.float32))
    with pytest.raises(OSError, match="disk full"):
        write_normals(tmp_path / "m.png", n)
    assert path.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["n.npy"]
