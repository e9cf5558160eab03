"""Dataset readers. :func:`open` recognises a folder's format and yields :class:`Frame` s."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from ._frame import Frame
from .threef2n import is_3f2n_scene, read_3f2n

__all__ = ["Frame", "open", "read_3f2n"]


def open(path: str | Path) -> Iterator[Frame]:  # noqa: A001 - the documented public name
    """Yield the frames of any dataset folder this library reads.

    Recognised: a 3F2N scene folder (``params.txt`` + ``depth/*.bin``), or a folder of such
    scenes (e.g. ``Easy/``, or the dataset root with ``Easy/Medium/Hard``).

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
    if is_3f2n_scene(root):
        yield from read_3f2n(root)
        return
    scenes = sorted(p.parent for p in root.glob("**/params.txt") if is_3f2n_scene(p.parent))
    if scenes:
        for scene in scenes:
            rel = scene.relative_to(root).as_posix()
            for frame in read_3f2n(scene):
                frame.group = rel
                yield frame
        return
    raise ValueError(
        f"{root}: no known dataset layout found; tried: 3F2N scene (params.txt + depth/*.bin), "
        "folder of 3F2N scenes"
    )
