"""Every scene recipe by name: the procedural set, the asset-mesh set, or both.

:mod:`depthnormals.synth.scenes` holds the procedural recipes (10 indoor, 10 outdoor) and
:mod:`depthnormals.synth.asset_scenes` the recipes built from real asset meshes (7 indoor,
5 outdoor; they need ``pip install 'depthnormals[assets]'`` to build). This module names and
builds both; for a procedural name :func:`make_scene` is
:func:`depthnormals.synth.scenes.make_scene`, so procedural scenes keep their bytes.

Examples
--------
>>> from depthnormals.synth.catalog import scene_names
>>> scene_names("indoor", scenes="assets")[:2]
('furnished_living', 'robot_lab')
>>> len(scene_names(scenes="all"))
32
"""

from __future__ import annotations

import numpy as np

from . import scenes as _procedural
from .asset_scenes import ASSET_INDOOR, ASSET_OUTDOOR, asset_recipe
from .scenes import Scene

__all__ = ["SCENE_SETS", "make_scene", "recipe_of_folder", "scene_names"]

#: Scene sets: the procedural recipes, the asset-mesh recipes, or both (procedural first).
SCENE_SETS = ("procedural", "assets", "all", "mixed")


#: Procedural indoor recipes by their share of pixels near a discontinuity, highest first
#: (6 views each, seed 0: shop 19.7 %, office 18.4 %, auditorium 14.5 %, library 12.5 %, ...;
#: ``benchmarks/discontinuity_share.py``): the order of the ``"mixed"`` set.
_CLUTTERED_FIRST = ("shop", "office", "auditorium", "library", "classroom", "stairwell", "cafe",
                    "living_room", "museum", "gym")


def _by_clutter(names: tuple[str, ...]) -> tuple[str, ...]:
    rank = {n: i for i, n in enumerate(_CLUTTERED_FIRST)}
    return tuple(sorted(names, key=lambda n: rank.get(n, len(rank))))


def scene_names(kind: str | None = None, *, scenes: str = "procedural") -> tuple[str, ...]:
    """Names of the recipes of a scene set.

    Parameters
    ----------
    kind : {"indoor", "outdoor"} or None
        One kind, or both (indoor first).
    scenes : {"procedural", "assets", "all", "mixed"}, keyword-only
        ``"procedural"`` (default: the 10 + 10 procedural recipes), ``"assets"`` (the
        asset-mesh recipes), ``"all"`` (procedural first, then assets) or ``"mixed"`` (assets
        first, then procedural, the indoor ones most cluttered first: the first 10 scenes of a
        kind hold every asset recipe and procedural ones after them; the ``ssn`` preset's set).

    Returns
    -------
    tuple of str
    """
    if scenes not in SCENE_SETS:
        raise ValueError(f"scenes must be one of {', '.join(SCENE_SETS)}; got {scenes!r}")
    if kind not in (None, "indoor", "outdoor"):
        raise ValueError(f"kind must be 'indoor', 'outdoor' or None; got {kind!r}")
    kinds = ("indoor", "outdoor") if kind is None else (kind,)
    assets = {"indoor": ASSET_INDOOR, "outdoor": ASSET_OUTDOOR}
    procedural = sum((_procedural.scene_names(k) for k in kinds), ()) if scenes != "assets" else ()
    asset = sum((assets[k] for k in kinds), ()) if scenes != "procedural" else ()
    if scenes == "mixed":
        return sum((assets[k] + _by_clutter(_procedural.scene_names(k)) for k in kinds), ())
    return procedural + asset


def make_scene(name: str, *, seed: int = 0) -> Scene:
    """Build recipe ``name`` of any set from ``seed`` (same seed, same mesh, bit for bit).

    Procedural names go to :func:`depthnormals.synth.scenes.make_scene`. An asset-mesh
    scene's ``meta`` also holds ``scene_set = "assets"`` and ``assets``: one entry (name,
    package, path, licence) per asset mesh it uses (:data:`depthnormals.synth.assets.ASSETS`).

    Parameters
    ----------
    name : str
        One of ``scene_names(scenes="all")``.
    seed : int, keyword-only
        Non-negative seed of the recipe's random choices.

    Returns
    -------
    Scene

    Raises
    ------
    ValueError
        Unknown name or bad seed.
    ImportError
        An asset-mesh recipe without pybullet or trimesh installed.
    """
    if name in ASSET_INDOOR + ASSET_OUTDOOR:
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer; got {seed!r}")
        from .assets import ASSETS

        scene = asset_recipe(name)(np.random.default_rng(int(seed)))
        used = [{"name": n, "package": ASSETS[n].package, "path": ASSETS[n].path,
                 "licence": ASSETS[n].licence} for n in scene.meta["assets"]]
        scene.meta = {"recipe": name, "seed": int(seed), "scene_set": "assets", "assets": used}
        return scene
    if name not in _procedural.scene_names():
        raise ValueError(f"unknown scene recipe {name!r}; valid: {', '.join(scene_names(scenes='all'))}")
    return _procedural.make_scene(name, seed=seed)


def recipe_of_folder(folder: str) -> str:
    """The recipe of a generated scene folder ``<recipe>-<index>`` (recipe names hold no ``-``)."""
    return folder.rsplit("-", 1)[0]
