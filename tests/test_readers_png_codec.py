"""Our PNG codec (depthnormals._png) against Pillow and OpenCV, byte for byte on the pixels.

We keep our codec (measurement in docs/datasets.md): Pillow reads 16-bit RGB PNGs as 8-bit RGB
and cannot write them, and the 3F2N ground-truth normals are 16-bit RGB. These tests pin that
what we write, maintained libraries read identically, and what they write (with their row
filters), we read identically.
"""

from __future__ import annotations

import io
import struct
import zlib

import numpy as np
import pytest
from PIL import Image

from depthnormals._png import decode_png, encode_png

RNG = np.random.default_rng(7)
YY, XX = np.mgrid[0:37, 0:53]
GREY16 = (1000 + 37 * XX + 11 * YY + RNG.integers(0, 300, XX.shape)).astype(np.uint16)
GREY16[3:5, 7:11] = 0
GREY16[0, 0] = 65535
RGB16 = np.dstack([GREY16, (65535 - GREY16), RNG.integers(0, 65536, XX.shape)]).astype(np.uint16)
RGB8 = RNG.integers(0, 256, (37, 53, 3), dtype=np.uint8)
GREY8 = RNG.integers(0, 256, (37, 53), dtype=np.uint8)


@pytest.mark.parametrize("img", [GREY16, RGB8, GREY8], ids=["grey16", "rgb8", "grey8"])
def test_pillow_reads_what_we_write(img):
    assert np.array_equal(np.asarray(Image.open(io.BytesIO(encode_png(img)))), img)


@pytest.mark.parametrize("img", [GREY16, RGB8, GREY8], ids=["grey16", "rgb8", "grey8"])
@pytest.mark.parametrize("optimize", [False, True])
def test_we_read_what_pillow_writes(img, optimize):
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG", optimize=optimize)
    assert np.array_equal(decode_png(buf.getvalue()), img)


def _row_filters(data: bytes, rows: int) -> set[int]:
    pos, idat = 8, b""
    while pos < len(data):
        length, ctype = struct.unpack(">I4s", data[pos:pos + 8])
        idat += data[pos + 8:pos + 8 + length] if ctype == b"IDAT" else b""
        pos += 12 + length
    raw = zlib.decompress(idat)
    return set(raw[::len(raw) // rows])


def test_pillow_files_exercise_every_row_filter():
    buf = io.BytesIO()
    Image.fromarray(GREY16).save(buf, format="PNG", optimize=True)
    assert _row_filters(buf.getvalue(), GREY16.shape[0]) == {0, 1, 2, 3, 4}
    assert _row_filters(encode_png(GREY16), GREY16.shape[0]) == {0}  # ours writes filter 0 only


def test_pillow_cannot_do_16bit_rgb():
    """Why we keep our codec: Pillow 13 truncates 16-bit RGB to 8 bits and refuses to write it."""
    read = np.asarray(Image.open(io.BytesIO(encode_png(RGB16))))
    assert read.dtype == np.uint8
    with pytest.raises(TypeError):
        Image.fromarray(RGB16).save(io.BytesIO(), format="PNG")


def test_16bit_rgb_against_opencv():
    cv2 = pytest.importorskip("cv2")
    ok, data = cv2.imencode(".png", np.ascontiguousarray(RGB16[..., ::-1]))  # OpenCV is BGR
    assert ok and np.array_equal(decode_png(data.tobytes()), RGB16)
    back = cv2.imdecode(np.frombuffer(encode_png(RGB16), np.uint8), cv2.IMREAD_UNCHANGED)
    assert back.dtype == np.uint16 and np.array_equal(back[..., ::-1], RGB16)


def test_3f2n_normal_png_against_opencv(shared_data):
    cv2 = pytest.importorskip("cv2")
    data = (shared_data / "3f2n-torusknot" / "normal" / "000001.png").read_bytes()
    ours = decode_png(data)
    theirs = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)[..., ::-1]
    assert ours.dtype == np.uint16 and ours.shape == (480, 640, 3) and np.array_equal(ours, theirs)
