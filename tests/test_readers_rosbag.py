"""``depthnormals.datasets.read_rosbag``: depth images of ROS 1 bags (the RealSense Viewer's
layout) and ROS 2 bags, written here with the ``rosbags`` library from the real D435 frame of
``tests/data/realsense_d435`` (the librealsense recording itself read identically to that
frame: docs/datasets.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.datasets import detect_format, read_rosbag

pytest.importorskip("rosbags")
from rosbags.typesys import Stores, get_typestore

DATA = Path(__file__).resolve().parent / "data"
D435 = DATA / "realsense_d435"
INFO = json.loads((D435 / "intrinsics.json").read_text())
K = (INFO["fx"], INFO["fy"], INFO["cx"], INFO["cy"])
LENS = (0.08, -0.15, 0.001, -0.0005, 0.05)  # a plumb_bob lens for the undistortion cases


def stored() -> np.ndarray:
    from depthnormals._png import read_png

    return read_png(D435 / "depth.png")  # uint16 millimetres


class Bag:
    """A bag written message by message (ROS 1 ``.bag`` or ROS 2 folder)."""

    def __init__(self, path: Path, ros: int, mcap: bool = False):
        self.ros = ros
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
        if ros == 1:
            from rosbags.rosbag1 import Writer

            self.w = Writer(path)
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer

            self.w = Writer(path, version=9,
                            storage_plugin=StoragePlugin.MCAP if mcap else StoragePlugin.SQLITE3)
        self.conns: dict = {}
        self.t = 0

    def __enter__(self):
        self.w.open()
        return self

    def __exit__(self, *exc):
        self.w.close()

    def _header(self):
        T = self.ts.types
        stamp = T["builtin_interfaces/msg/Time"](sec=1, nanosec=self.t)
        if self.ros == 1:
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="depth")
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id="depth")

    def write(self, topic: str, msg) -> None:
        kind = msg.__msgtype__
        if topic not in self.conns:
            self.conns[topic] = self.w.add_connection(topic, kind, typestore=self.ts)
        data = self.ts.serialize_ros1(msg, kind) if self.ros == 1 else self.ts.serialize_cdr(msg, kind)
        self.t += 1000
        self.w.write(self.conns[topic], self.t, data)

    def image(self, topic: str, arr: np.ndarray, encoding: str, *, big: bool = False, pad: int = 0):
        a = arr.astype(arr.dtype.newbyteorder(">" if big else "<"))
        rows = a.view(np.uint8).reshape(a.shape[0], -1)
        rows = np.concatenate([rows, np.full((rows.shape[0], pad), 7, np.uint8)], axis=1)
        msg = self.ts.types["sensor_msgs/msg/Image"](
            header=self._header(), height=a.shape[0], width=a.shape[1], encoding=encoding,
            is_bigendian=int(big), step=rows.shape[1], data=rows.reshape(-1))
        self.write(topic, msg)

    def camera(self, topic: str, shape, cam=K, dist=(0.0,) * 5, model="plumb_bob", binning=0):
        T = self.ts.types
        fx, fy, cx, cy = cam
        kk = np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], float)
        fields = {"D": np.array(dist, float), "K": kk, "R": np.eye(3).reshape(-1),
                  "P": np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], float)}
        if self.ros == 2:
            fields = {k.lower(): v for k, v in fields.items()}
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                    do_rectify=False)
        self.write(topic, T["sensor_msgs/msg/CameraInfo"](
            header=self._header(), height=shape[0], width=shape[1], distortion_model=model,
            binning_x=binning, binning_y=binning, roi=roi, **fields))

    def compressed(self, topic: str, png: bytes, fmt: str, header: bytes | None):
        data = np.frombuffer((header or b"") + png, np.uint8)
        self.write(topic, self.ts.types["sensor_msgs/msg/CompressedImage"](
            header=self._header(), format=fmt, data=data))

    def float32(self, topic: str, value: float):
        self.write(topic, self.ts.types["std_msgs/msg/Float32"](data=value))


def realsense_bag(path: Path, units: float = 0.001, frames: int = 2) -> np.ndarray:
    """A bag in the RealSense Viewer's layout (device_0 / sensor_0 / Depth_0) holding the D435
    frame ``frames`` times (the second one shifted by 1 mm); returns the stored frame."""
    d = stored()
    with Bag(path, 1) as b:
        b.camera("/device_0/sensor_0/Depth_0/info/camera_info", d.shape, model="Brown Conrady")
        b.camera("/device_0/sensor_1/Color_0/info/camera_info", d.shape, cam=(600, 600, 320, 240))
        b.float32("/device_0/sensor_0/option/Depth Units/value", units)
        b.float32("/device_0/sensor_1/option/Depth Units/value", 0.5)  # another sensor's
        for i in range(frames):
            b.image("/device_0/sensor_0/Depth_0/image/data", np.where(d > 0, d + i, 0), "mono16")
        b.image("/device_0/sensor_1/Color_0/image/data", np.zeros((4, 6, 3), np.uint8), "rgb8")
    return d


def test_a_realsense_recording(tmp_path):
    bag = tmp_path / "d435.bag"
    d = realsense_bag(bag)
    assert detect_format(bag) == "rosbag"
    frames = list(dn.datasets.open(bag))
    assert [f.name for f in frames] == ["000000", "000001"]
    f = frames[0]
    assert f.group == "device_0/sensor_0/Depth_0/image/data"
    assert f.meta["camera_info"] == "/device_0/sensor_0/Depth_0/info/camera_info"
    assert f.meta["depth_scale"] == pytest.approx(0.001) and f.meta["undistorted"] is None
    np.testing.assert_allclose(f.K, dn.Intrinsics(*K).matrix)
    np.testing.assert_array_equal(f.depth, (d.astype(np.float64) * np.float32(0.001)).astype(np.float32))
    assert f.depth.dtype == np.float32 and (f.depth[d == 0] == 0).all()
    assert np.allclose(frames[1].depth[d > 0] - f.depth[d > 0], 0.001, atol=1e-6)
    # the same frame as the fixture folder, and the same normals
    (g,) = list(dn.datasets.open(D435))
    np.testing.assert_allclose(f.depth, g.depth, rtol=1e-6)


def test_the_depth_units_of_its_own_sensor(tmp_path):
    bag = tmp_path / "hr.bag"
    d = realsense_bag(bag, units=0.0001, frames=1)
    (f,) = list(read_rosbag(bag))
    assert f.meta["depth_scale"] == pytest.approx(0.0001)
    assert np.allclose(f.depth, d * 0.0001, rtol=1e-6)
    (f,) = list(read_rosbag(bag, depth_scale=0.002))
    assert np.allclose(f.depth, d * 0.002, rtol=1e-6)


def stored_metres() -> np.ndarray:
    """The 32FC1 image of the ROS 2 bag: the frame in metres, NaN where it has no depth."""
    d = stored()
    m = d.astype(np.float32) * np.float32(0.001)
    m[d == 0] = np.nan
    return m


def ros2_bag(path: Path, mcap: bool = False) -> np.ndarray:
    d = stored()
    m = stored_metres()
    with Bag(path, 2, mcap) as b:
        b.camera("/camera/depth/camera_info", d.shape, dist=LENS)
        b.image("/camera/depth/image_raw", d, "16UC1")
        b.image("/camera/depth/image_rect_raw", d, "16UC1", big=True, pad=6)
        b.image("/camera/aligned_depth_to_color/image_raw", m, "32FC1")
        b.camera("/camera/aligned_depth_to_color/camera_info", d.shape)
        b.image("/camera/color/image_raw", np.zeros((4, 6, 3), np.uint8), "rgb8")
    return d


def test_a_ros2_bag_with_a_lens(tmp_path):
    bag = tmp_path / "ros2"
    d = ros2_bag(bag)
    assert detect_format(bag) == "rosbag"
    frames = {f.meta["topic"]: f for f in dn.datasets.open(bag)}
    assert sorted(frames) == ["/camera/aligned_depth_to_color/image_raw", "/camera/depth/image_raw",
                              "/camera/depth/image_rect_raw"]
    metres = (d.astype(np.float64) * 0.001).astype(np.float32)
    # image_raw: distorted, undone with its camera's plumb_bob lens
    raw = frames["/camera/depth/image_raw"]
    assert raw.meta["undistorted"] == list(LENS)
    np.testing.assert_array_equal(raw.depth, np.nan_to_num(dn.undistort_depth(metres, K, LENS)))
    # image_rect_raw (big-endian, padded rows): rectified already, read as stored
    rect = frames["/camera/depth/image_rect_raw"]
    assert rect.meta["undistorted"] is None
    np.testing.assert_array_equal(rect.depth, metres)
    # 32FC1 is metres; NaN reads as invalid (0)
    aligned = frames["/camera/aligned_depth_to_color/image_raw"]
    assert aligned.meta["depth_scale"] == 1.0 and aligned.meta["encoding"] == "32FC1"
    np.testing.assert_array_equal(aligned.depth, np.nan_to_num(stored_metres()))
    # undistort=False, and one topic
    (f,) = list(read_rosbag(bag, topic="/camera/depth/image_raw", undistort=False))
    np.testing.assert_array_equal(f.depth, metres)


def test_a_ros2_mcap_bag_and_its_mcap_file_alone(tmp_path, capsys):
    """MCAP storage (ROS 2's default since Iron): the bag folder, and its ``.mcap`` file given
    on its own (detected by its magic), read the same frames as the sqlite3 bag; the command
    line takes the file as a dataset."""
    from depthnormals.cli import main

    ros2_bag(tmp_path / "db3")
    ros2_bag(tmp_path / "mcap", mcap=True)
    (file,) = (tmp_path / "mcap").glob("*.mcap")
    assert detect_format(file) == detect_format(tmp_path / "mcap") == "rosbag"
    ref = list(read_rosbag(tmp_path / "db3"))
    for src in (tmp_path / "mcap", file):
        got = list(dn.datasets.open(src))
        assert [f.meta["topic"] for f in got] == [f.meta["topic"] for f in ref]
        for a, b in zip(got, ref, strict=True):
            np.testing.assert_array_equal(a.depth, b.depth)
            np.testing.assert_array_equal(a.K, b.K)
            assert a.meta["undistorted"] == b.meta["undistorted"]
    other = tmp_path / "x.mcap"
    other.write_bytes(b"not an mcap file")
    assert not dn.datasets.rosbag.is_rosbag(other)
    out = tmp_path / "out"
    assert main(["estimate", str(file), "-o", str(out), "-q"]) == 0
    assert len(list(out.rglob("*.npy"))) == 3


def test_errors_name_the_bag_and_what_is_missing(tmp_path):
    d = stored()
    bag = tmp_path / "nocam.bag"
    with Bag(bag, 1) as b:
        b.image("/depth/image", d, "16UC1")
        b.image("/color/image", np.zeros((4, 6, 3), np.uint8), "rgb8")
    with pytest.raises(ValueError, match=r"no CameraInfo.*intrinsics="):
        list(read_rosbag(bag))
    (f,) = list(read_rosbag(bag, intrinsics=K))
    np.testing.assert_allclose(f.K, dn.Intrinsics(*K).matrix)
    with pytest.raises(ValueError, match=r"'/color/image' is not a depth topic.*/depth/image"):
        list(read_rosbag(bag, topic="/color/image"))
    nodepth = tmp_path / "nodepth.bag"
    with Bag(nodepth, 1) as b:
        b.image("/color/image", np.zeros((4, 6, 3), np.uint8), "rgb8")
    with pytest.raises(ValueError, match=r"no depth topic.*/color/image"):
        list(read_rosbag(nodepth))
    fisheye = tmp_path / "fisheye.bag"
    with Bag(fisheye, 1) as b:
        b.camera("/cam/camera_info", d.shape, dist=(0.1, 0.01, 0.0, 0.0), model="equidistant")
        b.image("/cam/image_raw", d, "16UC1")
    with pytest.raises(ValueError, match=r"equidistant.*undistort=False"):
        list(read_rosbag(fisheye))
    assert len(list(read_rosbag(fisheye, undistort=False))) == 1
    with pytest.raises(FileNotFoundError):
        list(read_rosbag(tmp_path / "absent.bag"))
    with pytest.raises(ValueError, match="depth_scale"):
        list(read_rosbag(fisheye, depth_scale=0.0))
    # a camera of another size, binned, or uncalibrated (K all 0): never a silently wrong K
    for name, kw, match in (("size", {"shape": (240, 320)}, r"640 x 480 images.*320 x 240"),
                            ("binned", {"binning": 2}, "binned"),
                            ("zero", {"cam": (0.0, 0.0, 0.0, 0.0)}, "uncalibrated")):
        bag = tmp_path / f"{name}.bag"
        with Bag(bag, 1) as b:
            b.camera("/cam/camera_info", **{"shape": d.shape, **kw})
            b.image("/cam/image_rect", d, "16UC1")
        with pytest.raises(ValueError, match=match):
            list(read_rosbag(bag))
        assert len(list(read_rosbag(bag, intrinsics=K))) == 1
    (tmp_path / "x.bag").write_bytes(b"not a bag")
    assert not dn.datasets.rosbag.is_rosbag(tmp_path / "x.bag")


def test_cli_estimates_every_frame_of_a_bag(tmp_path):
    from depthnormals.cli import main

    bag = tmp_path / "d435.bag"
    realsense_bag(bag)
    out = tmp_path / "out"
    assert main(["estimate", str(bag), "-o", str(out), "-q"]) == 0
    written = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.npy"))
    assert written == ["device_0/sensor_0/Depth_0/image/data/000000.npy",
                       "device_0/sensor_0/Depth_0/image/data/000001.npy"]
    f = next(iter(read_rosbag(bag)))
    np.testing.assert_array_equal(np.load(out / written[0]), dn.estimate_normals(f.depth, f.K))


def test_compressed_depth_topics(tmp_path):
    """``compressed_depth_image_transport``'s PNG format: a 12-byte header (format, two
    quantisation parameters) then a 16-bit PNG of millimetres, or for 32FC1 of the quantised
    inverse depth ``v`` (``z = A / (v - B)``); old recordings without the header too."""
    import struct

    from depthnormals._png import encode_png

    d = stored()
    qa, qb = 100.0 * 101.0, 100.0  # the transport's quantisation (depth_quantization 100)
    z = d.astype(np.float64) * 0.001
    with np.errstate(divide="ignore"):
        inv = np.where(d > 0, np.round(qa / z + qb), 0).astype(np.uint16)
    head = struct.pack("<iff", 0, qa, qb)
    bag = tmp_path / "c.bag"
    with Bag(bag, 1) as b:
        b.camera("/camera/depth/camera_info", d.shape)
        b.compressed("/camera/depth/image_raw/compressedDepth", encode_png(d), "16UC1; compressedDepth", head)
        b.compressed("/camera/depth/image_rect_raw/compressedDepth", encode_png(d), "16UC1; compressedDepth",
                     None)
        b.compressed("/camera/depth_registered/image_raw/compressedDepth", encode_png(inv),
                     "32FC1; compressedDepth png", head)
        b.compressed("/camera/color/image_raw/compressed", b"\xff\xd8jpeg", "jpeg", None)
        b.compressed("/camera/depth/image_raw/compressedDepth_rvl", b"rvl", "16UC1; compressedDepth rvl",
                     head)
    frames = {}
    for t in ("/camera/depth/image_raw/compressedDepth", "/camera/depth/image_rect_raw/compressedDepth",
              "/camera/depth_registered/image_raw/compressedDepth"):
        frames.update({f.meta["topic"]: f for f in read_rosbag(bag, topic=t)})
    metres = (d.astype(np.float64) * 0.001).astype(np.float32)
    np.testing.assert_array_equal(frames["/camera/depth/image_raw/compressedDepth"].depth, metres)
    np.testing.assert_array_equal(frames["/camera/depth/image_rect_raw/compressedDepth"].depth, metres)
    f32 = frames["/camera/depth_registered/image_raw/compressedDepth"]
    assert f32.meta["encoding"] == "32FC1" and (f32.depth[d == 0] == 0).all()
    # the inverse-depth quantisation: 1 step of v is z^2 / A (0.4 mm at 2 m)
    ok = d > 0
    assert np.abs(f32.depth[ok] - metres[ok]).max() < 0.5 * (metres[ok].max() ** 2) / qa + 1e-6
    # every topic of the bag: the rvl one refuses, naming its codec; the jpeg is no depth topic
    with pytest.raises(ValueError, match="rvl"):
        list(read_rosbag(bag))
    with pytest.raises(ValueError, match="not a depth topic"):
        list(read_rosbag(bag, topic="/camera/color/image_raw/compressed"))


def test_without_rosbags_the_error_names_the_extra(tmp_path, monkeypatch):
    import sys

    bag = tmp_path / "d435.bag"
    realsense_bag(bag, frames=1)
    assert detect_format(bag) == "rosbag"  # the header alone, no rosbags needed
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)  # import fails as if absent
    with pytest.raises(ImportError, match=r"ROS bags needs rosbags: pip install 'depthnormals\[ros\]'"):
        list(read_rosbag(bag))


def test_a_damaged_bag_is_a_clear_error(tmp_path, capsys):
    from depthnormals.cli import main

    good = tmp_path / "d435.bag"
    realsense_bag(good, frames=2)
    data = good.read_bytes()
    bad = tmp_path / "cut.bag"
    bad.write_bytes(data[:len(data) // 2])  # the index and the second half gone
    with pytest.raises(ValueError, match=r"cut\.bag: not a readable ROS bag"):
        list(read_rosbag(bad))
    assert main(["estimate", str(bad), "-o", str(tmp_path / "out"), "-q"]) != 0
    err = capsys.readouterr().err
    assert "not a readable ROS bag" in err and "Traceback" not in err
