"""Dataset readers. :func:`open` recognises a folder's format and yields :class:`Frame` s."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from ._frame import Frame
from .ssn import is_ssn, read_ssn
from .synthetic import is_synthetic, read_synthetic
from .threef2n import is_3f2n_scene, read_3f2n

__all__ = ["Frame", "open", "read_3f2n", "read_ssn", "read_synthetic"]


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


def open(path: str | Path) -> Iterator[Frame]:
    """Yield the frames of any dataset folder this library reads.

    Recognised, in this order:

    - our synthetic format (``dataset.json`` with format ``depthnormals-synth``, or one of its
      scene folders), groups ``"<kind>/<scene>/<variant>"``;
    - the SSN layout (``<root>/{indoor|outdoor}/<scene>/standard_exr/*.exr``, any level),
      groups ``"<kind>/<scene>/standard"``; needs the OpenEXR package;
    - a 3F2N scene folder (``params.txt`` + ``depth/*.bin``; image size from the normal
      PNGs), or a folder of such scenes (e.g. ``Easy/``, or the root with
      ``Easy/Medium/Hard``), groups the scene folder relative to ``path``.

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
    if not root.exists():
        raise FileNotFoundError(f"dataset path {root} does not exist")
    if is_synthetic(root):
        yield from read_synthetic(root)
        return
    if is_ssn(root):
        yield from read_ssn(root)
        return
    if is_3f2n_scene(root):
        yield from _read_3f2n_sized(root)
        return
    scenes = sorted(p.parent for p in root.glob("**/params.txt") if is_3f2n_scene(p.parent))
    if scenes:
        for scene in scenes:
            rel = scene.relative_to(root).as_posix()
            for frame in _read_3f2n_sized(scene):
                frame.group = rel
                yield frame
        return
    raise ValueError(
        f"{root}: no known dataset layout found; tried: depthnormals-synth (dataset.json), "
        "SSN (<root>/indoor|outdoor/<scene>/standard_exr/*.exr), 3F2N scene (params.txt + "
        "depth/*.bin), folder of 3F2N scenes"
    )
