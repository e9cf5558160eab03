"""How much of a benchmark lies near a discontinuity: the share of pixels near an edge.

The share of valid pixels within ``radius`` pixels of a ground-truth discontinuity (a normal
crease over ``edge_angle`` degrees, a relative depth jump over ``depth_jump``, or an invalid
neighbour; :func:`depthnormals.evaluate.discontinuity_mask`) measures how hard a benchmark
is for normal estimators, whose errors concentrate at edges. Measured on real 3F2N frames:
22 % (Easy), 46 % (Medium), 82 % (Hard).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._protocol import discontinuity_mask

__all__ = ["SceneShare", "discontinuity_share", "synth_discontinuity_shares"]


def discontinuity_share(truth: Any, depth: Any, valid: Any, *, radius: int = 2, edge_angle: float = 10.0,
                        depth_jump: float = 0.05) -> float:
    """Share of valid pixels within ``radius`` pixels of a discontinuity, in [0, 1].

    ``near.sum() / valid.sum()`` with ``near`` from :func:`discontinuity_mask` (same
    parameters): an edge lies between two 4-neighbours whose ground-truth normals differ by
    more than ``edge_angle`` degrees (sign-agnostic), whose depths differ by more than
    ``depth_jump`` times the nearer depth, or of which exactly one is valid; the image border
    is not an edge. Both pixels of an edge pair count, dilated by a (2 radius + 1)^2 square.

    Parameters
    ----------
    truth : array_like, shape (H, W, 3)
        Ground-truth normals.
    depth : array_like, shape (H, W)
        Planar depth (metres or any unit: only ratios count).
    valid : array_like of bool, shape (H, W)
        Pixels with ground truth and depth (invalid pixels are neither counted nor near).
    radius : int, keyword-only, default 2
        Pixels (Chebyshev distance).
    edge_angle : float, keyword-only, default 10.0
        Crease threshold, degrees.
    depth_jump : float, keyword-only, default 0.05
        Relative depth jump threshold.

    Returns
    -------
    float
        NaN when no pixel is valid.

    Examples
    --------
    >>> import numpy as np
    >>> n = np.zeros((4, 10, 3)); n[..., 2] = -1
    >>> z = np.ones((4, 10)); z[:, 5:] = 2.0          # an occlusion between columns 4 and 5
    >>> discontinuity_share(n, z, np.ones((4, 10), bool))  # columns 2..7 are near it
    0.6
    """
    near = discontinuity_mask(truth, depth, valid, radius=radius, edge_angle=edge_angle,
                              depth_jump=depth_jump)
    n_valid = int(np.count_nonzero(valid))
    return float(np.count_nonzero(near) / n_valid) if n_valid else float("nan")


@dataclass(frozen=True)
class SceneShare:
    """Discontinuity shares of one scene of a generated dataset.

    Attributes
    ----------
    scene : str
        ``<kind>/<folder>`` as in the dataset's ``dataset.json``.
    kind : str
        ``"indoor"``, ``"outdoor"`` or ``"mesh"`` (the split).
    frames : tuple of float
        Share of each view, in view order.
    pooled : float
        Near pixels / valid pixels over all views of the scene.
    """

    scene: str
    kind: str
    frames: tuple[float, ...]
    pooled: float


def synth_discontinuity_shares(root: str | Path, *, variant: str = "clean", max_views: int | None = None,
                               radius: int = 2, edge_angle: float = 10.0,
                               depth_jump: float = 0.05) -> list[SceneShare]:
    """Per-scene discontinuity shares of a ``depthnormals synth`` dataset.

    Parameters
    ----------
    root : str or Path
        A dataset written by :func:`depthnormals.synth.generate`.
    variant : str, keyword-only
        ``"clean"`` (ground-truth depth) or a noise model's folder: then pixels without a
        noisy depth are invalid too, so sensor holes count as invalid neighbours.
    max_views : int, optional, keyword-only
        Use the first ``max_views`` views of each scene (default: all).
    radius, edge_angle, depth_jump : keyword-only
        As in :func:`discontinuity_share`.

    Returns
    -------
    list of SceneShare
        In the dataset's scene order.

    Raises
    ------
    FileNotFoundError
        ``root`` holds no dataset.
    ValueError
        Unknown variant, or ``max_views`` < 1.
    """
    root = Path(root)
    sidecar = root / "dataset.json"
    if not sidecar.is_file():
        raise FileNotFoundError(f"{root} holds no depthnormals-synth dataset (dataset.json missing)")
    meta = json.loads(sidecar.read_text())
    if variant not in meta["variants"]:
        raise ValueError(f"variant {variant!r} not in the dataset; valid: {', '.join(meta['variants'])}")
    if max_views is not None and (isinstance(max_views, bool) or not isinstance(max_views, int)
                                  or max_views < 1):
        raise ValueError(f"max_views must be an integer >= 1 or None; got {max_views!r}")
    from ..datasets.synthetic import read_synthetic  # both storage formats (1: .npy, 2: .npz)

    per_scene: dict[str, list[tuple[int, int]]] = {rel: [] for rel in meta["scenes"]}
    for f in read_synthetic(root, variants=[variant]):
        rel = f.group.rsplit("/", 1)[0]
        if max_views is not None and len(per_scene[rel]) >= max_views:
            continue
        z = f.depth
        v = np.asarray(f.mask, dtype=bool) & np.isfinite(z) & (z > 0)
        near = discontinuity_mask(f.normals, z, v, radius=radius, edge_angle=edge_angle,
                                  depth_jump=depth_jump)
        per_scene[rel].append((int(near.sum()), int(v.sum())))
    out = []
    for rel, counts in per_scene.items():
        shares = [k / m if m else float("nan") for k, m in counts]
        near_total = sum(k for k, _ in counts)
        valid_total = sum(m for _, m in counts)
        pooled = near_total / valid_total if valid_total else float("nan")
        out.append(SceneShare(rel, rel.split("/", 1)[0], tuple(shares), pooled))
    return out
