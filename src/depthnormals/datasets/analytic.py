"""The analytic scenes as a dataset: exact normals, clean and with Gaussian noise.

Used by ``depthnormals ablate --analytic`` and the accuracy benchmarks, so that every table on
"the analytic scenes" is measured on the same frames.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from .._validate import check_real
from ..analytic import make_scene
from ._frame import Frame

__all__ = ["EDGE_SCENES", "analytic_frames"]

#: The analytic scenes with creases and occlusions (the planes scene has neither).
EDGE_SCENES = ("box-on-floor", "stairs", "sphere-before-wall")


def analytic_frames(noise: float = 0.1, seed: int = 0, *,
                    scenes: Sequence[str] = EDGE_SCENES) -> Iterator[Frame]:
    """Each analytic scene rendered at its default size, clean and with Gaussian noise.

    Parameters
    ----------
    noise : float, default 0.1
        Standard deviation of the added noise in pixel footprints ``z / fx`` (the paper's
        clean -> noisy gap is about 0.1).
    seed : int, default 0
        Seed of the noise (the same seed for every scene).
    scenes : sequence of str, keyword-only
        Names for :func:`depthnormals.analytic.make_scene`.

    Returns
    -------
    iterator of Frame
        Group ``"<scene>/clean"`` then ``"<scene>/noise<noise>"``, name ``"0"``; the exact
        normals and mask; ``meta["clean_depth"]`` holds the noise-free depth (for edge bands
        computed on the clean geometry).

    Raises
    ------
    ValueError
        A negative or non-finite ``noise`` (at the call, before any frame is rendered).
    """
    noise = check_real(noise, "noise", minimum=0.0, hint="sigma in units of z/f")  # at the call
    return _frames(noise, seed, scenes)


def _frames(noise: float, seed: int, scenes: Sequence[str]) -> Iterator[Frame]:
    for name in scenes:
        r = make_scene(name).render()
        K = r.K.matrix
        mask = r.depth > 0
        for level in (0.0, noise):
            d = r.depth.copy()
            if level:
                rng = np.random.default_rng(seed)
                d[mask] += rng.normal(size=int(mask.sum())) * level * d[mask] / r.K.fx
            group = f"{name}/{'clean' if not level else f'noise{level:g}'}"
            yield Frame(d, r.normals.astype(np.float32), K, mask.copy(), "0", group,
                        {"clean_depth": r.depth})
