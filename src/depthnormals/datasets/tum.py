"""Reader of TUM RGB-D sequences (Sturm et al., IROS 2012).

Layout (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats)::

    rgbd_dataset_freiburg1_xyz/
        depth.txt               # "timestamp filename" per line, '#' comments
        depth/<timestamp>.png   # 640 x 480, 16-bit, 5000 units per metre, 0 = no data
        rgb.txt, rgb/...        # colour, registered 1:1 to depth by the OpenNI driver
        associations.txt        # optional, associate.py output: "t_rgb rgb/... t_depth depth/..."
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..camera import Intrinsics
from ._common import depth_mask, read_depth_png, resolve_intrinsics
from ._frame import Frame

__all__ = ["TUM_INTRINSICS", "is_tum", "read_tum"]

#: Published calibrations of the colour cameras (the depth images are registered to them);
#: ``"ros"`` is the ROS/OpenNI default the TUM page gives for all sequences. Distortion of
#: fr1/fr2 is ignored (fr3 images are already undistorted).
TUM_INTRINSICS: dict[str, Intrinsics] = {
    "fr1": Intrinsics(517.3, 516.5, 318.6, 255.3),
    "fr2": Intrinsics(520.9, 521.0, 325.1, 249.7),
    "fr3": Intrinsics(535.4, 539.2, 320.1, 247.6),
    "ros": Intrinsics(525.0, 525.0, 319.5, 239.5),
}
TUM_DEPTH_FACTOR = 5000.0
_ASSOCIATION_FILES = ("associations.txt", "associate.txt", "rgbd.txt")
_SEQUENCE = re.compile(r"freiburg([123])")


def is_tum(path: str | Path) -> bool:
    """True for a folder with ``depth.txt`` or an association file, and a ``depth/`` folder."""
    p = Path(path)
    listed = (p / "depth.txt").is_file() or any((p / a).is_file() for a in _ASSOCIATION_FILES)
    return p.is_dir() and listed and (p / "depth").is_dir()


def _list_lines(path: Path) -> list[list[str]]:
    rows = []
    for line in path.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            rows.append(line.split())
    return rows


def _depth_entries(root: Path, associations: Path | None) -> list[tuple[str, str, str | None]]:
    """(timestamp, depth file, rgb file or None) in file order."""
    if associations is None:
        found = [root / a for a in _ASSOCIATION_FILES if (root / a).is_file()]
        associations = found[0] if found else None
    if associations is not None:
        out = []
        for row in _list_lines(associations):
            pairs = list(zip(row[0::2], row[1::2], strict=False))
            depth = [p for p in pairs if "depth" in p[1]]
            rgb = [p for p in pairs if "rgb" in p[1]]
            if len(pairs) < 2 or len(depth) != 1:
                raise ValueError(f"{associations}: expected 't_rgb rgb/... t_depth depth/...' lines; "
                                 f"got {' '.join(row)!r}")
            out.append((depth[0][0], depth[0][1], rgb[0][1] if rgb else None))
        return out
    listing = root / "depth.txt"
    if not listing.is_file():
        raise FileNotFoundError(f"{root}: neither depth.txt nor an association file "
                                f"({', '.join(_ASSOCIATION_FILES)}) found")
    out = []
    for row in _list_lines(listing):
        if len(row) < 2:
            raise ValueError(f"{listing}: expected 'timestamp filename' lines; got {' '.join(row)!r}")
        out.append((row[0], row[1], None))
    return out


def read_tum(path: str | Path, *, intrinsics: Any = None, depth_scale: float | None = None,
             associations: str | Path | None = None) -> Iterator[Frame]:
    """Yield the depth frames of a TUM RGB-D sequence folder.

    Parameters
    ----------
    path : str or Path
        Sequence folder (``depth.txt`` or ``associations.txt``, and ``depth/``).
    intrinsics : str, Intrinsics, (fx, fy, cx, cy), 3x3 array or path, optional
        ``"fr1"``, ``"fr2"``, ``"fr3"`` (published colour-camera calibrations, see
        :data:`TUM_INTRINSICS`), ``"ros"`` (525, 525, 319.5, 239.5), or any camera / file.
        Default: the preset named by the folder (``rgbd_dataset_freiburg<N>_...``); a folder
        without that name needs this argument.
    depth_scale : float, optional
        Metres per PNG unit; default ``1 / 5000`` as published.
    associations : str or Path, optional
        An association file (``associate.py`` output); default ``associations.txt``,
        ``associate.txt`` or ``rgbd.txt`` in the folder when present, else every frame of
        ``depth.txt``.

    Yields
    ------
    Frame
        ``depth`` float32 metres (0 where the sensor gave no data), ``normals`` None (TUM has
        no ground-truth normals), ``mask`` depth > 0, ``K`` 0-based, ``name`` the depth
        timestamp, ``group`` the folder name, ``meta`` ``{"format": "tum", "intrinsics":
        preset or "given", "rgb": colour file or None, "depth_file": path}``.
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"TUM sequence folder {root} does not exist")
    if intrinsics is None:
        m = _SEQUENCE.search(root.resolve().name)
        if m is None:
            raise ValueError(f"{root}: cannot tell the camera from the folder name (expected "
                             "rgbd_dataset_freiburg<1|2|3>_...); pass intrinsics='fr1', 'fr2', 'fr3', "
                             "'ros', (fx, fy, cx, cy) or an intrinsics file")
        preset = f"fr{m.group(1)}"
        cam = TUM_INTRINSICS[preset]
    else:
        preset = intrinsics if isinstance(intrinsics, str) and intrinsics in TUM_INTRINSICS else "given"
        cam = resolve_intrinsics(intrinsics, TUM_INTRINSICS, what=str(root))
    units = TUM_DEPTH_FACTOR if depth_scale is None else 1.0 / float(depth_scale)
    assoc = Path(associations) if associations is not None else None
    for stamp, rel, rgb in _depth_entries(root, assoc):
        file = root / rel
        if not file.is_file():
            raise FileNotFoundError(f"{root}: depth image {rel} listed but missing")
        depth = read_depth_png(file, units_per_metre=units)
        yield Frame(depth=depth, normals=None, K=cam.matrix, mask=depth_mask(depth), name=stamp,
                    group=root.name, meta={"format": "tum", "intrinsics": preset, "rgb": rgb,
                                           "depth_file": str(file)})
