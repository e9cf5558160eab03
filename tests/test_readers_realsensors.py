"""The real sensor folder reader (``datasets.read_realsensors``, format ``realsensors``):
pinned depths of every frame of ``../shared/data/real-sensors`` (cross-checked against
OpenCV's decoder), NYU raw disparity endianness, the SUN RGB-D bit rotation, skipped colour
images, ``(H, W, 1)`` arrays, invalid codes, the PGM reader and layout detection."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from depthnormals._png import encode_png
from depthnormals.datasets import detect_format, open, read_realsensors
from depthnormals.datasets.realsensors import (
    decode_nyu_disparity,
    decode_sunrgbd,
    encoding_of,
    read_pgm,
)

# Provenance: computed with this reader (2026-11-25) on ../shared/data/real-sensors and
# checked in test_pins_match_opencv against cv2.imread (an independent decoder): linear
# files raw * depth_scale, NYU_depth.pgm byte-swapped then 351.3 / (1092.5 - raw), SUN
# rotated. Columns: (group, name) -> (metres at the centre pixel (H//2, W//2), valid pixels,
# median valid depth in metres).
PINS = {
    ("kitti_road_lidar_sne_roadseg", "depth_u16"): (0.0, 246475, 10.670000076293945),  # 65535
    ("nyu_raw_kinect1_open3d", "NYU_depth"): (3.0415585041046143, 285001, 3.267906904220581),
    ("nyu_registered_kinect1_slambook", "1"): (2.7990000247955322, 209236, 2.9149999618530273),
    ("nyu_registered_kinect1_slambook", "2"): (0.0, 212954, 2.7769999504089355),
    ("nyu_registered_kinect1_slambook", "3"): (0.0, 223149, 2.7130000591278076),
    ("nyu_registered_kinect1_slambook", "4"): (3.0420000553131104, 216331, 3.190000057220459),
    ("nyu_registered_kinect1_slambook", "5"): (0.0, 220173, 2.88700008392334),
    ("sunrgbd_open3d", "SUN_depth"): (0.0, 251188, 2.7230000495910645),
    ("tum_fr2_kinect1_slambook", "1_depth"): (1.6052000522613525, 204859, 1.5019999742507935),
    ("tum_fr2_kinect1_slambook", "2_depth"): (1.7247999906539917, 201565, 1.5784000158309937),
    ("tum_kinect1_open3d", "TUM_depth"): (2.184000015258789, 248250, 2.4149999618530273),
}


@pytest.fixture(scope="module")
def real_root(shared_data) -> Path:
    root = shared_data / "real-sensors"
    if not root.is_dir():
        pytest.skip(f"{root} is absent")
    return root


@pytest.fixture(scope="module")
def real_frames(real_root):
    return {(f.group, f.name): f for f in open(real_root)}


def test_detected_and_every_frame_read_once(real_root, real_frames):
    assert detect_format(real_root) == "realsensors"
    for folder in real_root.iterdir():
        if folder.is_dir():
            assert detect_format(folder) == "realsensors"
    assert set(real_frames) == set(PINS)  # NYU_depth_mm_derived.png not read: no duplicate


@pytest.mark.parametrize("key", sorted(PINS))
def test_pinned_depths(real_frames, key):
    f = real_frames[key]
    centre, valid, median = PINS[key]
    h, w = f.depth.shape
    assert f.depth.dtype == np.float32 and f.normals is None
    assert float(f.depth[h // 2, w // 2]) == centre
    assert int(f.mask.sum()) == valid
    assert float(np.median(f.depth[f.mask])) == median


def test_pins_match_opencv(real_frames):
    cv2 = pytest.importorskip("cv2")
    for (group, _), f in real_frames.items():
        raw = cv2.imread(f.meta["depth_file"], cv2.IMREAD_UNCHANGED)
        if f.meta["encoding"] == "nyu_raw_disparity":
            raw = raw.byteswap()  # cv2 reads the PGM big-endian, as its header says
            z = np.where(raw < 2047, 351.3 / (1092.5 - raw.astype(np.float64)), 0.0)
        else:
            if f.meta["encoding"] == "sunrgbd_rotated":
                raw = ((raw >> 3) | (raw << 13)).astype(np.uint16)
            z = np.where(raw < 65535, raw * f.meta["depth_scale"], 0.0)
        assert np.allclose(f.depth, z, rtol=1e-6, atol=0), group


def test_nyu_endianness(real_root):
    f = next(open(real_root / "nyu_raw_kinect1_open3d"))
    assert f.meta["encoding"] == "nyu_raw_disparity"
    assert 1.0 < float(np.median(f.depth[f.mask])) < 5.0
    raw_le = read_pgm(real_root / "nyu_raw_kinect1_open3d" / "NYU_depth.pgm", byteorder="<")
    raw_be = read_pgm(real_root / "nyu_raw_kinect1_open3d" / "NYU_depth.pgm")
    assert raw_le.max() == 2047 and raw_le.min() > 800  # 11-bit disparity
    assert raw_be.max() > 60000  # the header's (wrong) byte order: not 11-bit disparity
    wrong = decode_nyu_disparity(raw_be)
    assert (wrong > 0).mean() < 0.05  # 2.8 % of the pixels would get any depth at all
    # the derived mm PNG beside it agrees with the conversion (it is not read as a frame)
    from depthnormals._png import read_png

    mm = read_png(real_root / "nyu_raw_kinect1_open3d" / "NYU_depth_mm_derived.png")
    both = (mm > 0) & f.mask
    assert np.abs(mm[both] / 1000.0 - f.depth[both]).max() < 0.0006


def test_registered_nyu_pgm_is_big_endian_mm(real_root):
    f = next(open(real_root / "nyu_registered_kinect1_slambook"))
    assert f.name == "1" and f.meta["encoding"] == "linear"
    assert 1.0 < float(np.median(f.depth[f.mask])) < 5.0


def test_sunrgbd_rotation_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    mm = rng.integers(1, 8000, (12, 16)).astype(np.uint16)
    mm[0, 0] = 0
    stored = ((mm << 3) | (mm >> 13)).astype(np.uint16)  # SUN RGB-D's writer: rotate left by 3
    assert np.array_equal(decode_sunrgbd(stored), mm)
    (tmp_path / "depth.png").write_bytes(encode_png(stored))
    (tmp_path / "intrinsics.json").write_text(json.dumps(
        {"fx": 20.0, "fy": 20.0, "cx": 7.5, "cy": 5.5, "depth_scale": 0.001,
         "raw_format": "uint16 PNG with SUN3D bit rotation: mm = (v >> 3) | (v << 13)"}))
    (f,) = read_realsensors(tmp_path)
    assert f.meta["encoding"] == "sunrgbd_rotated"
    assert np.array_equal(f.depth, (mm * 0.001).astype(np.float32))
    assert not f.mask[0, 0]


def _folder(tmp_path: Path, info: dict) -> Path:
    (tmp_path / "intrinsics.json").write_text(json.dumps(
        {"fx": 20.0, "fy": 21.0, "cx": 7.5, "cy": 5.5, **info}))
    return tmp_path


def test_skips_colour_and_reads_npy_hw1(tmp_path):
    root = _folder(tmp_path, {"depth_scale": 0.0002, "invalid_value": [0, 4095]})
    (root / "rgb.png").write_bytes(encode_png(np.zeros((12, 16, 3), np.uint8)))
    (root / "mask.png").write_bytes(encode_png(np.zeros((12, 16), np.uint8)))
    raw = np.full((12, 16, 1), 10000, np.uint16)
    raw[1, 1] = 4095
    raw[2, 2] = 65535
    np.save(root / "b.npy", raw)
    np.save(root / "a.npy", np.full((12, 16), 1.25, np.float32))  # float: metres
    frames = list(open(root))
    assert [f.name for f in frames] == ["a", "b"]
    assert frames[0].depth[0, 0] == np.float32(1.25)
    b = frames[1]
    assert b.depth.shape == (12, 16) and b.depth[0, 0] == np.float32(2.0)
    assert b.depth[1, 1] == 0 and b.depth[2, 2] == 0 and b.mask.sum() == 12 * 16 - 2
    assert np.allclose(b.K, [[20, 0, 7.5], [0, 21, 5.5], [0, 0, 1]])


def test_depth_subfolder_scale_and_intrinsics_override(tmp_path):
    root = _folder(tmp_path, {"depth_scale": 0.001, "invalid_value": 0,
                              "alt": {"fx": 30.0, "fy": 30.0, "cx": 8.0, "cy": 6.0}})
    (root / "depth").mkdir()
    for i in (10, 2):
        (root / "depth" / f"{i}.png").write_bytes(encode_png(np.full((12, 16), 500 * i, np.uint16)))
    (root / "rgb.png").write_bytes(encode_png(np.zeros((12, 16, 3), np.uint8)))
    frames = list(open(root))
    assert [f.name for f in frames] == ["2", "10"]  # numeric order
    assert frames[0].depth[0, 0] == np.float32(1.0)
    (f,) = [f for f in open(root, depth_scale=0.002) if f.name == "2"]
    assert f.depth[0, 0] == np.float32(2.0)
    f = next(open(root, intrinsics="alt"))
    assert f.K[0, 0] == 30.0 and f.meta["intrinsics"] == "given"


def test_pgm_reader(tmp_path):
    img = np.arange(12, dtype=np.uint16).reshape(3, 4) * 1000
    (tmp_path / "be.pgm").write_bytes(b"P5\n# comment\n4 3\n65535\n" + img.astype(">u2").tobytes())
    assert np.array_equal(read_pgm(tmp_path / "be.pgm"), img)
    (tmp_path / "le.pgm").write_bytes(b"P5 4 3 65535\n" + img.astype("<u2").tobytes())
    assert np.array_equal(read_pgm(tmp_path / "le.pgm", byteorder="<"), img)
    (tmp_path / "a.pgm").write_text("P2\n4 3\n65535\n" + " ".join(map(str, img.ravel())))
    assert np.array_equal(read_pgm(tmp_path / "a.pgm"), img)
    (tmp_path / "bad.pgm").write_bytes(b"P6 4 3 255\n" + bytes(36))
    with pytest.raises(ValueError, match="not a PGM"):
        read_pgm(tmp_path / "bad.pgm")
    with pytest.raises(ValueError, match="byteorder"):
        read_pgm(tmp_path / "be.pgm", byteorder="big")


def test_encoding_keys():
    assert encoding_of({}) == "linear"
    assert encoding_of({"encoding": "nyu_raw_disparity"}) == "nyu_raw_disparity"
    assert encoding_of({"raw_format": "NYU_depth.pgm: LITTLE-endian ..."}) == "nyu_raw_disparity"
    assert encoding_of({"raw_format": "SUN3D bit rotation"}) == "sunrgbd_rotated"
    with pytest.raises(ValueError, match="encoding"):
        encoding_of({"encoding": "mm"})


def test_nyu_encoding_key_reads_only_pgm(tmp_path):
    root = _folder(tmp_path, {"encoding": "nyu_raw_disparity", "depth_scale": 0.001})
    disp = np.full((3, 4), 985, np.uint16)
    disp[0, 0] = 2047
    (root / "raw.pgm").write_bytes(b"P5\n4 3\n65535\n" + disp.astype("<u2").tobytes())
    (root / "raw_mm_derived.png").write_bytes(encode_png(np.full((3, 4), 3268, np.uint16)))
    (f,) = open(root)
    assert f.name == "raw" and f.depth[0, 0] == 0
    assert f.depth[1, 1] == pytest.approx(351.3 / (1092.5 - 985), rel=1e-6)


def test_not_a_real_sensor_folder(tmp_path):
    (tmp_path / "intrinsics.json").write_text(json.dumps({"fx": 1.0}))
    np.save(tmp_path / "d.npy", np.ones((3, 4)))
    with pytest.raises(ValueError, match="no known dataset layout"):
        detect_format(tmp_path)
    with pytest.raises(ValueError, match=r"intrinsics\.json"):
        list(read_realsensors(tmp_path))
