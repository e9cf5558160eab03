"""Camera poses by rejection sampling.

A candidate look-at point is drawn uniformly in the scene's ``target_box``, a viewing
distance uniformly in ``median_depth``, a camera height uniformly in the ``eye_box`` and an
azimuth uniformly; the camera centre then follows (it must fall in ``eye_box``), with a small
random roll. The candidate is kept when

- the centre is not inside any solid of the scene (boxes enlarged by ``clearance``),
- a low-resolution preview render (``preview_scale`` of the image size) sees a surface in at
  least ``min_valid`` of its pixels,
- no seen surface is nearer than ``min_depth``,
- the median seen depth lies in ``median_depth``.

Examples
--------
>>> import numpy as np
>>> from depthnormals.synth.scenes import make_scene
>>> from depthnormals.synth.poses import sample_poses
>>> poses = sample_poses(make_scene("office", seed=0), 2, rng=np.random.default_rng(0))
>>> poses.shape
(2, 4, 4)
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..camera import as_intrinsics
from ..render import KINECT_V2, KINECT_V2_SIZE, look_at, render_mesh
from .scenes import Scene

__all__ = ["PoseConstraints", "check_view", "sample_poses"]


@dataclass(frozen=True)
class PoseConstraints:
    """Acceptance rules of :func:`sample_poses` (lengths in metres)."""

    min_valid: float = 0.9
    min_depth: float = 0.5
    median_depth: tuple[float, float] = (0.8, 4.0)
    clearance: float = 0.15
    max_roll_deg: float = 5.0
    max_tries: int = 300
    preview_scale: float = 0.25

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_valid <= 1.0:
            raise ValueError(f"min_valid must be in [0, 1]; got {self.min_valid}")
        lo, hi = self.median_depth
        if not 0.0 < lo <= hi:
            raise ValueError(f"median_depth must be (lo, hi) with 0 < lo <= hi; got {self.median_depth}")
        if self.max_tries < 1 or not 0.0 < self.preview_scale <= 1.0:
            raise ValueError("max_tries must be >= 1 and preview_scale in (0, 1]")
        if self.min_depth < 0 or self.clearance < 0:
            raise ValueError("min_depth and clearance must be >= 0")

    def as_dict(self) -> dict:
        d = asdict(self)
        d["median_depth"] = list(self.median_depth)
        return d


def _inside_solid(eye: np.ndarray, solids: np.ndarray, margin: float) -> bool:
    if solids.shape[0] == 0:
        return False
    lo = solids[:, 0] - margin
    hi = solids[:, 1] + margin
    return bool(np.any(np.all((eye >= lo) & (eye <= hi), axis=1)))


def check_view(scene: Scene, pose: np.ndarray, K: Any = KINECT_V2, *,
               size: tuple[int, int] = KINECT_V2_SIZE,
               constraints: PoseConstraints | None = None) -> tuple[bool, str]:
    """Whether ``pose`` meets ``constraints`` for ``scene``; returns ``(ok, reason)``."""
    cam = as_intrinsics(K)
    c = PoseConstraints() if constraints is None else constraints
    if _inside_solid(pose[:3, 3], scene.solids, c.clearance):
        return False, "camera inside a solid"
    h, w = size
    s = c.preview_scale
    hs, ws = max(8, round(h * s)), max(8, round(w * s))
    r = render_mesh(scene.vertices, scene.faces, cam.scaled(ws / w), pose=pose, width=ws, height=hs)
    valid = r.face >= 0
    frac = float(valid.mean())
    if frac == 0.0:
        return False, "camera sees nothing"
    if frac < c.min_valid:
        return False, f"valid fraction {frac:.2f} < {c.min_valid}"
    z = r.depth[valid]
    if z.min() < c.min_depth:
        return False, f"surface at {z.min():.2f} m < min_depth {c.min_depth}"
    med = float(np.median(z))
    if not c.median_depth[0] <= med <= c.median_depth[1]:
        return False, f"median depth {med:.2f} m outside {c.median_depth}"
    return True, "ok"


def sample_poses(scene: Scene, n: int, *, rng: np.random.Generator, K: Any = KINECT_V2,
                 size: tuple[int, int] = KINECT_V2_SIZE,
                 constraints: PoseConstraints | None = None) -> np.ndarray:
    """Draw ``n`` accepted camera poses for ``scene`` (camera-to-world, OpenCV axes).

    Parameters
    ----------
    scene : Scene
        Mesh with ``solids``, ``eye_box`` and ``target_box``.
    n : int
        Number of poses (>= 1).
    rng : numpy.random.Generator, keyword-only
        Source of randomness (the result is a pure function of its state).
    K : intrinsics, keyword-only
        Camera of the final images (the preview uses it scaled down).
    size : (H, W), keyword-only
        Image size of the final images.
    constraints : PoseConstraints, keyword-only
        Acceptance rules.

    Returns
    -------
    poses : ndarray (n, 4, 4) float64

    Raises
    ------
    ValueError
        If a pose cannot be found in ``constraints.max_tries`` draws; the message gives the
        commonest rejection reason (e.g. "camera sees nothing").
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be a positive integer; got {n!r}")
    constraints = PoseConstraints() if constraints is None else constraints
    poses = np.empty((int(n), 4, 4))
    lo_e, hi_e = scene.eye_box
    lo_t, hi_t = scene.target_box
    for k in range(int(n)):
        reasons: dict[str, int] = {}
        for _ in range(constraints.max_tries):
            target = rng.uniform(lo_t, hi_t)
            dist = rng.uniform(*constraints.median_depth)
            ez = rng.uniform(lo_e[2], hi_e[2])
            az = rng.uniform(0.0, 2.0 * np.pi)
            roll = np.radians(rng.uniform(-constraints.max_roll_deg, constraints.max_roll_deg))
            dz = ez - target[2]
            if dist < 0.5 or abs(dz) > 0.95 * dist:
                reasons["degenerate view direction"] = reasons.get("degenerate view direction", 0) + 1
                continue
            horiz = np.sqrt(dist * dist - dz * dz)
            eye = np.array([target[0] + horiz * np.cos(az), target[1] + horiz * np.sin(az), ez])
            if np.any(eye < lo_e) or np.any(eye > hi_e):
                reasons["camera outside eye_box"] = reasons.get("camera outside eye_box", 0) + 1
                continue
            pose = look_at(eye, target)
            cr, sr = np.cos(roll), np.sin(roll)
            pose[:3, :2] = pose[:3, :2] @ np.array([[cr, sr], [-sr, cr]])
            ok, why = check_view(scene, pose, K, size=size, constraints=constraints)
            if ok:
                poses[k] = pose
                break
            key = re.sub(r"\d+(\.\d+)?", "#", why)
            reasons[key] = reasons.get(key, 0) + 1
        else:
            common = max(reasons, key=reasons.get) if reasons else "unknown"
            raise ValueError(
                f"scene {scene.name!r}: no camera pose met the constraints in {constraints.max_tries} "
                f"tries (commonest rejection: {common}; all: {reasons}); enlarge eye_box/target_box "
                "or relax the constraints")
    return poses
