"""Road scenes with a freespace label, for the downstream experiment of the 3F2N+ paper (section V).

A frame is a car-like view of a procedural road scene (:mod:`depthnormals.synth.scenes`:
``street``, ``alley``, ``boulevard``, ``shopping_street``, ``parking_lot``) rendered exactly
(:func:`depthnormals.render.render_mesh`), a noisy copy of its depth from one of the
sensor models of :mod:`depthnormals.synth.noise` (given as a spec string, so a model added
there is accepted here), and a boolean freespace label.

**Freespace** (our interpretation of "drivable area" on these meshes): a pixel whose visible
face belongs to the ground part (``Scene.parts``, :data:`~depthnormals.synth.scenes.PART_NAMES`)
and whose face normal points up in the world (``n_z > min_up``, 0.9 by default). The street
recipes raise the pavements on kerbs (part ``kerb``, 15 cm), so their tops, though horizontal,
are not freespace; vehicles, buildings, poles and vegetation occlude the ground; the vertical
end faces of the ground slab are excluded by the normal test. In ``parking_lot`` the whole
ground is drivable.

**Camera** (a car's): ``height`` 1.2-1.7 m above the ground, looking along the road (the
street recipes lay it along world x; yaw towards the farther end of the street plus
``N(0, 8 deg)``; in the parking
lot any yaw), pitch ``U(-6, 0)`` deg (down), roll ``N(0, 1 deg)``; horizontal field of view
80 deg by default (KITTI's colour cameras: about 82 deg). A pose is kept only if the camera
is outside every solid (vehicles), the pixel at the bottom centre of the image is freespace
(the car stands on the road) and at least ``min_free`` of the image is freespace.

Examples
--------
>>> from depthnormals.synth.freespace import road_frames
>>> f = road_frames(2, seed=0, size=(32, 64), noise="gaussian:sigma_px=0.5")
>>> len(f), f[0].depth.shape, f[0].label.dtype.name
(2, (32, 64), 'bool')
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import check_int, check_real
from ..camera import Intrinsics
from ..render import RenderResult, look_at, render_mesh
from . import noise as _noise
from .scenes import PART_NAMES, Scene, make_scene
from .views import _apply_model

__all__ = ["ROAD_RECIPES", "RoadFrame", "freespace_label", "road_camera", "road_frames",
           "sample_road_pose", "segmentation_scores"]

#: The procedural recipes with a drivable ground (the order seeds derive from: append only).
ROAD_RECIPES = ("street", "alley", "boulevard", "shopping_street", "parking_lot")

_GROUND = PART_NAMES.index("ground")
_KERB = PART_NAMES.index("kerb")


@dataclass(frozen=True)
class RoadFrame:
    """One labelled road view.

    Attributes
    ----------
    depth : ndarray (H, W) float32
        Noisy planar depth, metres, 0 where the sensor returns nothing (and where nothing
        is seen: the sky).
    clean : ndarray (H, W) float32
        Exact depth, 0 where nothing is seen.
    normals : ndarray (H, W, 3) float32
        Ground-truth camera-frame normals (facing the camera), NaN where nothing is seen.
    label : ndarray (H, W) bool
        Freespace.
    K : Intrinsics
    pose : ndarray (4, 4)
        Camera-to-world (OpenCV axes, world z up).
    scene : str
        ``"<recipe>/<scene seed>"``.
    """

    depth: np.ndarray
    clean: np.ndarray
    normals: np.ndarray
    label: np.ndarray
    K: Intrinsics
    pose: np.ndarray
    scene: str


def road_camera(size: tuple[int, int] = (128, 256), *, hfov_deg: float = 80.0) -> Intrinsics:
    """Square-pixel intrinsics of an image ``size = (H, W)`` with horizontal field of view ``hfov_deg``.

    Examples
    --------
    >>> K = road_camera((128, 256), hfov_deg=90.0)
    >>> round(K.fx, 6), K.cx, K.cy
    (128.0, 127.5, 63.5)
    """
    h, w = _check_size(size)
    hfov = check_real(hfov_deg, "hfov_deg", minimum=10.0, maximum=170.0)
    f = (w / 2.0) / np.tan(np.radians(hfov) / 2.0)
    return Intrinsics(f, f, (w - 1) / 2.0, (h - 1) / 2.0)


def _check_size(size: Any) -> tuple[int, int]:
    if not (isinstance(size, (tuple, list)) and len(size) == 2):
        raise ValueError(f"size must be (height, width) in pixels; got {size!r}")
    return (check_int(size[0], "size[0] (height)", minimum=8, maximum=4096),
            check_int(size[1], "size[1] (width)", minimum=8, maximum=4096))


def freespace_label(scene: Scene, result: RenderResult, pose: Any, *, min_up: float = 0.9) -> np.ndarray:
    """Freespace of a rendered view: ground-part faces whose world normal points up.

    Parameters
    ----------
    scene : Scene
        A scene with per-face part labels (``scene.parts``, procedural recipes).
    result : RenderResult
        :func:`depthnormals.render.render_mesh` of ``scene`` from ``pose``.
    pose : array_like (4, 4)
        The camera-to-world pose of the render.
    min_up : float, keyword-only
        Least world z component of the (camera-facing) face normal, in (0, 1].

    Returns
    -------
    label : ndarray (H, W) bool
    """
    if scene.parts is None:
        raise ValueError(f"scene {scene.name!r} has no part labels (Scene.parts); freespace needs a "
                         "procedural recipe (depthnormals.synth.scenes.make_scene)")
    up = check_real(min_up, "min_up", minimum=1e-6, maximum=1.0)
    R = np.asarray(pose, dtype=np.float64)[:3, :3]
    face = result.face
    seen = face >= 0
    ground = np.zeros(face.shape, dtype=bool)
    ground[seen] = scene.parts[face[seen]] == _GROUND
    n_world = np.nan_to_num(result.normals) @ R.T
    return ground & (n_world[..., 2] >= up)


def _drivable_box(scene: Scene) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) where the car may stand: between the kerbs, else the inner ground."""
    V, F, parts = scene.vertices, scene.faces, scene.parts
    g = V[np.unique(F[parts == _GROUND])]
    x0, x1 = g[:, 0].min(), g[:, 0].max()
    y0, y1 = g[:, 1].min(), g[:, 1].max()
    if np.any(parts == _KERB):
        k = V[np.unique(F[parts == _KERB])]
        # street recipes: road along x between the kerbs, ground 5 m beyond the street's ends
        return x0 + 5.0, x1 - 5.0, float(k[k[:, 1] < 0, 1].max()), float(k[k[:, 1] > 0, 1].min())
    mx, my = 0.3 * (x1 - x0), 0.3 * (y1 - y0)
    return x0 + mx, x1 - mx, y0 + my, y1 - my


def _roll(T: np.ndarray, roll_deg: float) -> np.ndarray:
    a = np.radians(roll_deg)
    Rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    out = T.copy()
    out[:3, :3] = T[:3, :3] @ Rz
    return out


def sample_road_pose(scene: Scene, K: Any, size: tuple[int, int], *, rng: np.random.Generator,
                     height: tuple[float, float] = (1.2, 1.7), min_free: float = 0.1,
                     max_tries: int = 200) -> tuple[np.ndarray, RenderResult]:
    """Draw a car-like camera pose on the road of ``scene`` (rules in the module docstring).

    Parameters
    ----------
    scene : Scene
        A road recipe (:data:`ROAD_RECIPES`).
    K : intrinsics
    size : (H, W)
    rng : numpy.random.Generator, keyword-only
    height : (lo, hi), keyword-only
        Camera height above the ground, metres.
    min_free : float, keyword-only
        Least freespace share of the image.
    max_tries : int, keyword-only

    Returns
    -------
    pose : ndarray (4, 4)
    result : RenderResult
        The clean render from ``pose``.

    Raises
    ------
    ValueError
        If no pose is accepted in ``max_tries`` draws.
    """
    h, w = _check_size(size)
    min_free = check_real(min_free, "min_free", minimum=0.0, maximum=1.0)
    max_tries = check_int(max_tries, "max_tries", minimum=1, maximum=10**6)
    lo, hi = (check_real(v, "height", minimum=0.1, maximum=100.0) for v in height)
    if scene.parts is None or not np.any(scene.parts == _GROUND):
        raise ValueError(f"scene {scene.name!r} has no ground part to drive on; use one of {ROAD_RECIPES}")
    x0, x1, y0, y1 = _drivable_box(scene)
    street = bool(np.any(scene.parts == _KERB))
    for _ in range(max_tries):
        eye = np.array([rng.uniform(x0, x1), rng.uniform(y0 + 1.0, y1 - 1.0), rng.uniform(lo, hi)])
        if street:
            ahead = 0.0 if eye[0] < (x0 + x1) / 2 else 180.0  # towards the farther end of the street
            yaw = np.radians(ahead + rng.normal(0.0, 8.0))
        else:
            yaw = rng.uniform(0.0, 2.0 * np.pi)
        pitch = np.radians(rng.uniform(-6.0, 0.0))
        roll = rng.normal(0.0, 1.0)
        d = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
        pose = _roll(look_at(eye, eye + d), roll)
        if scene.solids.shape[0] and np.any(np.all((eye >= scene.solids[:, 0] - 0.3)
                                                   & (eye <= scene.solids[:, 1] + 0.3), axis=1)):
            continue
        r = render_mesh(scene.vertices, scene.faces, K, pose=pose, width=w, height=h)
        label = freespace_label(scene, r, pose)
        if label[-1, w // 2] and label.mean() >= min_free:
            return pose, r
    raise ValueError(f"no car-like pose with {min_free:.0%} freespace in {max_tries} tries on {scene.name}")


def _apply_noise(spec: str, scene: Scene, r: RenderResult, pose: np.ndarray, K: Intrinsics,
                 size: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    name, settings = _noise.parse_noise_spec(spec)
    # the benchmark writer's dispatcher: every sensor model of the generator, with its settings
    return _apply_model(name, settings, r, scene, pose, K, size, 0.05, rng)


def road_frames(n: int, *, seed: int = 0, size: tuple[int, int] = (128, 256),
                noise: str | None = "gaussian:sigma_px=0.5", views_per_scene: int = 10,
                recipes: tuple[str, ...] = ROAD_RECIPES, hfov_deg: float = 80.0) -> list[RoadFrame]:
    """``n`` labelled road frames, deterministic for ``seed``.

    Scenes cycle through ``recipes``; each scene instance (recipe seed drawn from ``seed``)
    gives ``views_per_scene`` views, so two calls with different ``seed`` share no scene
    instance in practice (held-out scenes, not only held-out views).

    Parameters
    ----------
    n : int
        Number of frames.
    seed : int, keyword-only
        Seed of the scene instances, poses and noise.
    size : (H, W), keyword-only
        Image size in pixels.
    noise : str or None, keyword-only
        Sensor model spec (:func:`depthnormals.synth.noise.parse_noise_spec`, e.g.
        ``"kinect_v2"`` or ``"gaussian:sigma_px=0.5"``), or None for clean depth.
    views_per_scene : int, keyword-only
    recipes : tuple of str, keyword-only
        Subset of :data:`ROAD_RECIPES`.
    hfov_deg : float, keyword-only
        Horizontal field of view (:func:`road_camera`).

    Returns
    -------
    list of RoadFrame
    """
    n = check_int(n, "n", minimum=1, maximum=10**6)
    seed = check_int(seed, "seed", minimum=0, maximum=2**63 - 1)
    vps = check_int(views_per_scene, "views_per_scene", minimum=1, maximum=10**6)
    size = _check_size(size)
    for r in recipes:
        if r not in ROAD_RECIPES:
            raise ValueError(f"unknown road recipe {r!r}; valid: {', '.join(ROAD_RECIPES)}")
    if noise is not None:
        _noise.parse_noise_spec(noise)  # fail before rendering
    K = road_camera(size, hfov_deg=hfov_deg)
    frames: list[RoadFrame] = []
    k = 0
    while len(frames) < n:
        recipe = recipes[k % len(recipes)]
        ss = np.random.SeedSequence([seed, ROAD_RECIPES.index(recipe), k])
        scene_seed = int(ss.generate_state(1)[0])
        scene = make_scene(recipe, seed=scene_seed)
        pose_ss, noise_ss = ss.spawn(2)  # the poses do not depend on the noise model
        pose_rng, noise_rng = np.random.default_rng(pose_ss), np.random.default_rng(noise_ss)
        for _ in range(min(vps, n - len(frames))):
            pose, r = sample_road_pose(scene, K, size, rng=pose_rng)
            depth = r.depth if noise is None else _apply_noise(noise, scene, r, pose, K, size, noise_rng)
            frames.append(RoadFrame(depth.astype(np.float32), r.depth.astype(np.float32),
                                    r.normals.astype(np.float32), freespace_label(scene, r, pose), K,
                                    pose, f"{recipe}/{scene_seed}"))
        k += 1
    return frames


def segmentation_scores(pred: Any, label: Any) -> dict[str, float]:
    """Pixel counts and scores of a binary segmentation, pooled over all pixels given.

    ``IoU = TP / (TP + FP + FN)``, ``F1 = 2 TP / (2 TP + FP + FN)`` (the harmonic mean of
    precision and recall), ``precision = TP / (TP + FP)``, ``recall = TP / (TP + FN)``;
    a score whose denominator is 0 is NaN. Pooled counts (not a mean of per-image scores),
    as the KITTI road benchmark does.

    Parameters
    ----------
    pred, label : array_like bool, same shape (any)

    Returns
    -------
    dict
        ``tp``, ``fp``, ``fn``, ``tn`` (counts), ``iou``, ``f1``, ``precision``, ``recall``.

    Examples
    --------
    >>> s = segmentation_scores([1, 1, 0, 0], [1, 0, 1, 0])
    >>> s["iou"], s["f1"]
    (0.3333333333333333, 0.5)
    """
    p = np.asarray(pred)
    g = np.asarray(label)
    if p.shape != g.shape:
        raise ValueError(f"pred and label must have the same shape; got {p.shape} and {g.shape}")
    if p.dtype.kind not in "biu" or g.dtype.kind not in "biu":
        raise TypeError(f"pred and label must be boolean (or 0/1 integers); got {p.dtype} and {g.dtype}")
    p, g = p.astype(bool), g.astype(bool)
    tp = int(np.count_nonzero(p & g))
    fp = int(np.count_nonzero(p & ~g))
    fn = int(np.count_nonzero(~p & g))
    tn = int(p.size - tp - fp - fn)

    def ratio(a: int, b: int) -> float:
        return a / b if b else float("nan")

    return {"tp": tp, "fp": fp, "fn": fn, "tn": tn, "iou": ratio(tp, tp + fp + fn),
            "f1": ratio(2 * tp, 2 * tp + fp + fn), "precision": ratio(tp, tp + fp),
            "recall": ratio(tp, tp + fn)}
