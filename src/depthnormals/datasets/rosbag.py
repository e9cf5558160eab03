"""Reader of depth images recorded in ROS bags: ROS 1 ``.bag`` files (the RealSense Viewer's
recordings among them), ROS 2 bag folders and a ROS 2 bag's single ``.mcap`` file (the default
storage since ROS 2 Iron), through the ``rosbags`` library (``pip install 'depthnormals[ros]'``;
pure Python, no ROS installation).

A depth topic is one of ``sensor_msgs/Image`` whose messages are ``16UC1`` / ``mono16``
(millimetres, REP 118) or ``32FC1`` (metres), or of ``sensor_msgs/CompressedImage`` in
``compressed_depth_image_transport``'s PNG format (``format`` ``"16UC1; compressedDepth"``,
``"32FC1; compressedDepth png"``: a 12-byte header, the compression format and two
quantisation parameters ``A, B``, then a 16-bit PNG of the millimetres, or for ``32FC1`` of
the quantised inverse depth ``v``, ``z = A / (v - B)``, 0 = none; the ``rvl`` codec is refused);
its camera is the ``sensor_msgs/CameraInfo``
topic that shares the longest leading part of its name (``/camera/depth/image_rect_raw`` and
``/camera/depth/camera_info``; the RealSense layout ``/device_0/sensor_0/Depth_0/image/data``
and ``/device_0/sensor_0/Depth_0/info/camera_info``). A RealSense recording's ``Depth Units``
option of the same sensor gives the scale of its 16-bit depth (0.001 by default, 0.0001 on the
high-resolution presets). The camera's distortion is undone (:func:`depthnormals.undistort_depth`)
when it is OpenCV's model (``plumb_bob``, ``rational_polynomial``, RealSense's ``Brown
Conrady``) with a non-zero coefficient and the topic is not a rectified one (``rect`` in its
name): ROS's ``image_raw`` topics are distorted, ``image_rect`` ones are not.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import OPENCV_MODELS, Intrinsics, check_distortion, undistort_depth
from ._common import depth_mask, optional_module, resolve_intrinsics
from ._frame import Frame

__all__ = ["DEPTH_ENCODINGS", "is_rosbag", "read_rosbag"]

#: Image encodings read as depth, with the metres per stored unit of each (REP 118); a
#: RealSense recording's ``Depth Units`` option overrides the 16-bit ones' scale.
DEPTH_ENCODINGS = {"16UC1": 0.001, "mono16": 0.001, "32FC1": 1.0}
_ROS1_MAGIC = b"#ROSBAG V2.0\n"
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_PNG = b"\x89PNG\r\n\x1a\n"
_IMAGE = "sensor_msgs/msg/Image"
_COMPRESSED = "sensor_msgs/msg/CompressedImage"


def _anyreader() -> Any:
    return optional_module("rosbags.highlevel", "reading ROS bags", "ros").AnyReader


def is_rosbag(path: str | Path) -> bool:
    """True for a ROS 1 bag file (``#ROSBAG V2.0`` header), a ROS 2 bag folder
    (``metadata.yaml`` beside ``.db3`` / ``.mcap`` storage) or an ``.mcap`` file (its magic:
    a ROS 2 bag's storage on its own; ``rosbags`` opens it by that suffix)."""
    p = Path(path)
    if p.is_file():
        with p.open("rb") as fh:
            head = fh.read(len(_ROS1_MAGIC))
        return head == _ROS1_MAGIC or (p.suffix == ".mcap" and head.startswith(_MCAP_MAGIC))
    return (p.is_dir() and (p / "metadata.yaml").is_file()
            and any(q.suffix in (".db3", ".mcap") for q in p.iterdir()))


def _field(msg: Any, name: str) -> Any:
    """A message field by its ROS 1 (``K``) or ROS 2 (``k``) spelling."""
    for key in (name, name.lower(), name.upper()):
        if hasattr(msg, key):
            return getattr(msg, key)
    raise AttributeError(name)


def _segments(topic: str) -> list[str]:
    return [s for s in topic.split("/") if s]


def _shared(a: str, b: str) -> int:
    """How many leading name segments two topics share."""
    n = 0
    for x, y in zip(_segments(a), _segments(b), strict=False):
        if x != y:
            break
        n += 1
    return n


def _partner(topic: str, candidates: list[str]) -> str | None:
    """The candidate topic sharing most leading segments with ``topic`` (at least one), the
    first of equals in name order; None when none shares any."""
    best, score = None, 0
    for c in sorted(candidates):
        s = _shared(topic, c)
        if s > score:
            best, score = c, s
    return best


def _encoding(msg: Any) -> str | None:
    """The depth encoding of an Image or compressedDepth CompressedImage message, else the
    Image's encoding (None for another CompressedImage)."""
    if hasattr(msg, "encoding"):
        return str(msg.encoding)
    fmt = str(msg.format)
    if "compresseddepth" not in fmt.lower():
        return None
    return fmt.split(";")[0].strip()


def _compressed_depth(msg: Any, topic: str) -> np.ndarray:
    """The depth of a compressedDepth message: uint16 millimetres (``16UC1``) or float32
    metres (``32FC1``, NaN where none)."""
    from .._png import decode_png

    fmt = str(msg.format)
    if "rvl" in fmt.lower():
        raise ValueError(f"{topic}: compressedDepth with the rvl codec ({fmt!r}) is not read (PNG "
                         "only)")
    data = bytes(msg.data)
    at = 0 if data[:8] == _PNG else 12 if data[12:20] == _PNG else -1
    if at < 0:
        raise ValueError(f"{topic}: a compressedDepth message ({fmt!r}) without PNG data")
    img = decode_png(data[at:], name=f"{topic} compressedDepth PNG")
    if img.dtype != np.uint16 or img.ndim != 2:
        raise ValueError(f"{topic}: compressedDepth PNG of {img.dtype} {img.shape}; expected 16-bit "
                         "greyscale")
    if _encoding(msg) != "32FC1":
        return img
    if at == 0:
        raise ValueError(f"{topic}: 32FC1 compressedDepth without its quantisation header")
    qa, qb = np.frombuffer(data[4:12], dtype="<f4").astype(np.float64)
    v = img.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(v > 0, qa / (v - qb), np.nan)
    return z.astype(np.float32)


def _image(msg: Any, topic: str) -> np.ndarray:
    """A depth image message as a 2-D array of its stored type (native byte order)."""
    if not hasattr(msg, "encoding"):
        return _compressed_depth(msg, topic)
    enc = str(msg.encoding)
    dtype = np.dtype(np.float32 if enc == "32FC1" else np.uint16)
    dtype = dtype.newbyteorder(">" if msg.is_bigendian else "<")
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if step < w * dtype.itemsize or data.size < h * step:
        raise ValueError(f"{topic}: a {enc} image message of {w} x {h} with step {step} holds "
                         f"{data.size} bytes; expected {h * step}")
    rows = data[:h * step].reshape(h, step)[:, :w * dtype.itemsize]
    return np.ascontiguousarray(rows).view(dtype).reshape(h, w).astype(dtype.newbyteorder("="))


def _camera(msg: Any, where: str) -> tuple[Intrinsics, tuple[float, ...], str, tuple[int, int]]:
    """(K, distortion or (), model, (height, width) or (0, 0)) of a CameraInfo message; a
    binned or cropped camera (``binning_x/y`` over 1, an ROI offset) and a K without focal
    lengths (an uncalibrated camera_info) raise, naming ``where``."""
    k = np.asarray(_field(msg, "K"), dtype=np.float64).reshape(3, 3)
    roi = msg.roi
    if int(msg.binning_x) > 1 or int(msg.binning_y) > 1 or int(roi.x_offset) or int(roi.y_offset):
        raise ValueError(f"{where}: the camera is binned ({msg.binning_x} x {msg.binning_y}) or "
                         f"cropped (offset {roi.x_offset}, {roi.y_offset}); pass intrinsics= for "
                         "the images as stored")
    try:
        cam = Intrinsics(k[0, 0], k[1, 1], k[0, 2], k[1, 2])
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: K {k.reshape(-1).tolist()} is no camera ({exc}); an "
                         "uncalibrated camera_info? pass intrinsics=") from exc
    model = str(_field(msg, "distortion_model")).strip()
    d = np.asarray(_field(msg, "D"), dtype=np.float64).reshape(-1)
    dist = tuple(float(x) for x in d) if d.size and np.any(d != 0) else ()
    return cam, dist, model, (int(msg.height), int(msg.width))


def read_rosbag(path: str | Path, *, topic: str | None = None, intrinsics: Any = None,
                depth_scale: float | None = None, undistort: bool = True) -> Iterator[Frame]:
    """Yield the depth frames of a ROS bag (ROS 1 ``.bag`` file, ROS 2 bag folder or ``.mcap``).

    Parameters
    ----------
    path : str or Path
        The bag.
    topic : str, optional
        The depth topic to read; default every depth topic (module doc), in name order.
    intrinsics : Intrinsics, (fx, fy, cx, cy), 3x3 array or path, optional
        The camera, instead of the topic's ``CameraInfo`` (required where it has none).
    depth_scale : float, optional
        Metres per stored unit of 16-bit depth, instead of the recording's (RealSense
        ``Depth Units``) or REP 118's 0.001. ``32FC1`` depth is metres.
    undistort : bool, default True
        Undo the camera's distortion where the module doc says it applies; False reads every
        image as a pinhole one.

    Yields
    ------
    Frame
        Depth in metres (float32, 0 = invalid: 0, NaN, inf and negative stored values),
        ``normals=None``, K, ``mask`` = valid depth, ``name`` = the message's index in its
        topic (``"000000"``, ...), ``group`` = the topic, ``meta`` with the topic, the
        message's bag time (ns), encoding, scale, distortion model and the distortion undone
        (``"undistorted"``, None when none).

    Raises
    ------
    ImportError
        Without the ``rosbags`` package.
    ValueError
        No depth topic (or ``topic`` is not one), a depth topic without a camera and no
        ``intrinsics``, a distortion of another model than OpenCV's where it would apply, or a
        malformed image message.
    """
    from .._validate import check_positive

    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"ROS bag {p} does not exist")
    check_positive(depth_scale, "depth_scale", allow_none=True)
    reader_cls = _anyreader()
    try:
        yield from _read(reader_cls, p, topic, intrinsics, depth_scale, undistort)
    except Exception as exc:  # rosbags' own errors (a damaged or truncated bag) named as ours
        if not type(exc).__module__.startswith("rosbags"):
            raise
        raise ValueError(f"{p}: not a readable ROS bag ({type(exc).__name__}: {exc})") from exc


def _read(reader_cls: Any, p: Path, topic: str | None, intrinsics: Any,
          depth_scale: float | None, undistort: bool) -> Iterator[Frame]:
    with reader_cls([p]) as reader:
        conns = reader.connections
        images = sorted({c.topic for c in conns if c.msgtype in (_IMAGE, _COMPRESSED)})
        infos = sorted({c.topic for c in conns if c.msgtype == "sensor_msgs/msg/CameraInfo"})
        units = [c for c in conns if c.topic.endswith("/option/Depth Units/value")]
        firsts = {t: _one(reader, conns, t) for t in images}
        depth_topics = [t for t in images
                        if firsts[t] is not None and _encoding(firsts[t]) in DEPTH_ENCODINGS]
        if topic is not None:
            if topic not in depth_topics:
                raise ValueError(f"{p}: {topic!r} is not a depth topic of this bag (16UC1, mono16 "
                                 f"or 32FC1 images, or compressedDepth); its depth topics: "
                                 f"{', '.join(depth_topics) or 'none'}")
            depth_topics = [topic]
        if not depth_topics:
            raise ValueError(f"{p}: no depth topic (sensor_msgs/Image of 16UC1, mono16 or 32FC1, "
                             f"or a compressedDepth CompressedImage); its image topics: "
                             f"{', '.join(images) or 'none'}")
        for t in depth_topics:
            yield from _topic_frames(reader, conns, p, t, infos, units, intrinsics, depth_scale,
                                     undistort)


def _one(reader: Any, conns: list, topic: str) -> Any:
    """The first message of ``topic``, deserialised (None when it has none)."""
    for c, _, raw in reader.messages(connections=[c for c in conns if c.topic == topic]):
        return reader.deserialize(raw, c.msgtype)
    return None


def _topic_frames(reader: Any, conns: list, p: Path, topic: str, infos: list[str], units: list,
                  intrinsics: Any, depth_scale: float | None, undistort: bool) -> Iterator[Frame]:
    info_topic = _partner(topic, infos)
    dist: tuple[float, ...] = ()
    model = ""
    size = (0, 0)
    if intrinsics is not None:
        cam = resolve_intrinsics(intrinsics, {}, what=f"{p}:{topic}")
    elif info_topic is not None and (msg := _one(reader, conns, info_topic)) is not None:
        cam, dist, model, size = _camera(msg, f"{p}: {info_topic}")
    else:
        raise ValueError(f"{p}: depth topic {topic} has no CameraInfo topic beside it; pass "
                         "intrinsics=")
    rectified = "rect" in topic.lower()
    if dist and undistort and not rectified:
        if model.lower() not in OPENCV_MODELS:
            raise ValueError(f"{p}: {info_topic} gives a {model!r} distortion {list(dist)}, which "
                             "depthnormals.undistort_depth cannot undo (OpenCV's plumb_bob / "
                             "rational_polynomial only); pass undistort=False to read the images "
                             "as pinhole ones")
        try:
            dist = check_distortion(dist)
        except ValueError as exc:
            raise ValueError(f"{p}: {info_topic}: {exc}") from exc
    else:
        dist = ()
    unit_scale = None
    mine = [u for u in units if _shared(u.topic, topic) >= 2]  # the same device and sensor
    if mine:
        msg = _one(reader, conns, mine[0].topic)
        unit_scale = float(msg.data) if msg is not None and float(msg.data) > 0 else None
    n = 0
    for c, stamp, raw in reader.messages(connections=[c for c in conns if c.topic == topic]):
        msg = reader.deserialize(raw, c.msgtype)
        enc = _encoding(msg)
        if enc not in DEPTH_ENCODINGS:
            raise ValueError(f"{p}: message {n} of {topic} is {enc}, not depth (16UC1, mono16, 32FC1)")
        stored = _image(msg, topic)
        if size[0] and size[1] and stored.shape != size:
            raise ValueError(f"{p}: {topic} holds {stored.shape[1]} x {stored.shape[0]} images but "
                             f"its camera {info_topic} is {size[1]} x {size[0]}; pass intrinsics= "
                             "for the images as stored")
        scale = 1.0 if enc == "32FC1" else float(depth_scale or unit_scale or DEPTH_ENCODINGS[enc])
        z = stored.astype(np.float64) * scale
        z = np.where(np.isfinite(z) & (z > 0), z, 0.0).astype(np.float32)
        if dist:
            z = np.nan_to_num(undistort_depth(z, cam, dist), nan=0.0)
        meta = {"format": "rosbag", "bag": str(p), "topic": topic, "stamp_ns": int(stamp),
                "encoding": enc, "depth_scale": scale, "camera_info": info_topic,
                "distortion_model": model or None, "undistorted": list(dist) if dist else None}
        yield Frame(depth=z, normals=None, K=cam.matrix, mask=depth_mask(z), name=f"{n:06d}",
                    group=topic.strip("/"), meta=meta)
        n += 1
