"""Dataset readers. :func:`open` recognises a folder's format and yields :class:`Frame` s."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ._frame import Frame
from .hypersim import is_hypersim, read_hypersim
from .kitti import is_kitti, read_kitti
from .nyu import is_nyu, read_nyu
from .realsensors import is_realsensors, read_realsensors
from .replica import REPLICA_INTRINSICS, is_replica, read_replica
from .rosbag import is_rosbag, read_rosbag
from .scannet import is_scannet, read_scannet
from .ssn import is_ssn, read_ssn
from .synthetic import is_synthetic, read_synthetic
from .threef2n import is_3f2n_scene, read_3f2n
from .tum import TUM_INTRINSICS, is_tum, read_tum

__all__ = [
    "FORMATS",
    "REPLICA_INTRINSICS",
    "TUM_INTRINSICS",
    "Frame",
    "detect_format",
    "open",
    "read_3f2n",
    "read_hypersim",
    "read_kitti",
    "read_nyu",
    "read_realsensors",
    "read_replica",
    "read_rosbag",
    "read_scannet",
    "read_ssn",
    "read_synthetic",
    "read_tum",
]

#: format name -> (test, reader, options that :func:`open` passes on)
_READERS: dict[str, tuple[Any, Any, tuple[str, ...]]] = {
    "synthetic": (is_synthetic, read_synthetic, ()),
    "ssn": (is_ssn, read_ssn, ()),
    "3f2n": (None, None, ()),
    "tum": (is_tum, read_tum, ("intrinsics", "depth_scale")),
    "scannet": (is_scannet, read_scannet, ("intrinsics", "depth_scale")),
    "kitti": (is_kitti, read_kitti, ("intrinsics", "depth_scale")),
    "nyu": (is_nyu, read_nyu, ("intrinsics",)),
    "hypersim": (is_hypersim, read_hypersim, ()),
    "replica": (is_replica, read_replica, ("intrinsics", "depth_scale")),
    "rosbag": (is_rosbag, read_rosbag, ("intrinsics", "depth_scale")),
    "realsensors": (is_realsensors, read_realsensors, ("intrinsics", "depth_scale")),
}
#: The format names :func:`open` accepts as ``format=``, in detection order.
FORMATS = tuple(_READERS)


def _png_size(path: Path) -> tuple[int, int] | None:
    """(H, W) from a PNG header, or None."""
    with path.open("rb") as fh:
        head = fh.read(24)
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n":
        return None
    return int.from_bytes(head[20:24], "big"), int.from_bytes(head[16:20], "big")


def _read_3f2n_sized(scene: Path) -> Iterator[Frame]:
    """3F2N scene with the image size taken from its first normal PNG (default 480 x 640)."""
    pngs = sorted((scene / "normal").glob("*.png")) if (scene / "normal").is_dir() else []
    size = _png_size(pngs[0]) if pngs else None
    yield from read_3f2n(scene, shape=size or (480, 640))


def _is_3f2n(root: Path) -> bool:
    return is_3f2n_scene(root) or any(is_3f2n_scene(p.parent) for p in root.glob("**/params.txt"))


def _read_3f2n_tree(root: Path) -> Iterator[Frame]:
    if is_3f2n_scene(root):
        yield from _read_3f2n_sized(root)
        return
    scenes = sorted(p.parent for p in root.glob("**/params.txt") if is_3f2n_scene(p.parent))
    for scene in scenes:
        rel = scene.relative_to(root).as_posix()
        for frame in _read_3f2n_sized(scene):
            frame.group = rel
            yield frame


def detect_format(path: str | Path) -> str:
    """The name of the layout found at ``path`` (one of :data:`FORMATS`).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If no known layout is found; the message lists the layouts tried.
    """
    root = Path(path)
    if not root.exists():
        raise FileNotFoundError(f"dataset path {root} does not exist")
    for name, (test, _, _) in _READERS.items():
        if name == "3f2n":
            if root.is_dir() and _is_3f2n(root):
                return name
        elif test(root):
            return name
    raise ValueError(
        f"{root}: no known dataset layout found; tried: depthnormals-synth (dataset.json), "
        "SSN (<root>/indoor|outdoor/<scene>/standard_exr/*.exr), 3F2N scene (params.txt + "
        "depth/*.bin) or a folder of them, TUM RGB-D (depth.txt or associations.txt + depth/), "
        "ScanNet export (depth/*.png + intrinsic/intrinsic_depth.txt), KITTI depth (proj_depth/ "
        "or groundtruth_depth/ + intrinsics/), NYU Depth v2 labeled .mat (HDF5 with 'depths'), "
        "Hypersim (*_geometry_hdf5/frame.IIII.depth_meters.hdf5), Replica renders as NICE-SLAM "
        "publishes them (results/depth*.png), ROS bags (a ROS 1 .bag file, a ROS 2 bag "
        "folder or its .mcap file, with depth images), real sensor folders (intrinsics.json + depth "
        "images, or a folder of them); pass format= to force one"
    )


def open(path: str | Path, *, format: str | None = None, intrinsics: Any = None,
         depth_scale: float | None = None) -> Iterator[Frame]:
    """Yield the frames of any dataset this library reads.

    Parameters
    ----------
    path : str or Path
        A dataset folder (or, for NYU, the ``.mat`` file).
    format : str, optional
        One of :data:`FORMATS`; default: detected from the layout.
    intrinsics : str, Intrinsics, (fx, fy, cx, cy), 3x3 array or path, optional
        Camera (or preset name, e.g. ``"fr1"`` for TUM) for the formats that take one (TUM,
        ScanNet, KITTI, NYU, Replica, real sensor folders); an error for the others, whose
        files carry their camera.
    depth_scale : float, optional
        Metres per PNG unit for TUM, ScanNet, KITTI, Replica and real sensor folders
        (defaults: 1/5000, 1/1000, 1/256, 1/6553.5, ``intrinsics.json``).

    Each format's own reader (``read_tum``, ``read_kitti``, ...) takes further options.
    Recognised, in this order:

    - our synthetic format (``dataset.json`` with format ``depthnormals-synth``, or one of its
      scene folders), groups ``"<kind>/<scene>/<variant>"``;
    - the SSN layout (``<root>/{indoor|outdoor}/<scene>/standard_exr/*.exr``, any level),
      groups ``"<kind>/<scene>/standard"``; needs the OpenEXR package;
    - a 3F2N scene folder (``params.txt`` + ``depth/*.bin``; image size from the normal
      PNGs), or a folder of such scenes (e.g. ``Easy/``, or the root with
      ``Easy/Medium/Hard``), groups the scene folder relative to ``path``;
    - TUM RGB-D, ScanNet export, KITTI depth, NYU Depth v2 labeled ``.mat``, Hypersim and
      Replica renders (NICE-SLAM layout):
      see docs/datasets.md and each reader. Their frames carry ``normals=None`` when the
      dataset has no ground-truth normals (all but Hypersim);
    - a ROS bag (a ROS 1 ``.bag`` file, the RealSense Viewer's recordings among them, a
      ROS 2 bag folder or a ROS 2 ``.mcap`` file) with depth images: :func:`read_rosbag`
      (needs the ``rosbags`` package), groups the depth topics;
    - last, a real sensor folder (``intrinsics.json`` + depth images at the top or in
      ``depth/``, or a folder of them: :func:`read_realsensors`), groups the folder names.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If no known layout is found; the message lists the layouts tried.

    Examples
    --------
    >>> import tempfile
    >>> from depthnormals.synth import generate
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     _ = generate(tmp, indoor=1, outdoor=0, views=1, size=(48, 64), noise=(),
    ...                  K=(36.5, 36.5, 31.5, 23.5), progress=False)
    ...     [(f.group, f.depth.shape) for f in open(tmp)]
    [('indoor/living_room-00/clean', (48, 64))]
    """
    root = Path(path)
    if format is None:
        format = detect_format(root)
    elif format not in _READERS:
        raise ValueError(f"unknown dataset format {format!r}; use one of {', '.join(FORMATS)}")
    elif not root.exists():
        raise FileNotFoundError(f"dataset path {root} does not exist")
    _, reader, takes = _READERS[format]
    options = {"intrinsics": intrinsics, "depth_scale": depth_scale}
    given = {k: v for k, v in options.items() if v is not None}
    refused = sorted(set(given) - set(takes))
    if refused:
        raise TypeError(f"format {format!r} does not take {', '.join(refused)} (its files carry it); "
                        f"it takes {', '.join(takes) or 'no options here'}")
    if format == "3f2n":
        yield from _read_3f2n_tree(root)
        return
    yield from reader(root, **given)
