"""Point-to-plane ICP between real Kinect v1 frames: is the uncertainty map worth using?

Data: the five frames of ``../shared/data/real-sensors/nyu_registered_kinect1_slambook``
(640x480 millimetres, 0 = missing) and its ``pose.txt`` (camera-to-world ``tx ty tz qx qy qz
qw`` per frame). Pairs: every ``i -> i+1`` and the harder ``i -> i+2`` (7). The source
frame's points are registered onto the target frame's; the reference is
``inv(T_target) @ T_source`` from ``pose.txt``.

Variants, all on the same subsampled points (every ``--step``-th pixel in rows and columns,
valid depth), the same correspondence threshold, iteration cap and convergence test
(Open3D's: stop when fitness and inlier RMSE both change by < 1e-6), from the same start:

- ``ours``: our Gauss-Newton point-to-plane ICP (:func:`point_to_plane_icp`, numpy; nearest
  neighbours from Open3D's ``core.nns``) on the target's ``3f2n+`` normals (computed on the
  full frame, then subsampled), every correspondence weight 1;
- ``ours-weighted``: the same, each correspondence weighted by ``1 / max(u, floor)^2``, u the
  expected angular error (deg) of the target point's normal
  (``estimate_normals(..., return_uncertainty=True)``), floor ``--floor`` (1 deg);
- ``o3d-icp-ours``: Open3D's ``registration_icp`` + ``TransformationEstimationPointToPlane``
  on our normals (unweighted): the same normals as ``ours`` through Open3D's solver;
- ``o3d-default``: Open3D's default pipeline: ``PointCloud.estimate_normals`` (KNN 30) on the
  subsampled target cloud, then the same ``registration_icp``.

Two more with ``--variants`` (not in the default table): the uncertainty read as what it is, a
part of each pair's residual variance. The point-to-plane residual ``n . (p - q)`` errs by the
depth noise of both points along the normal and by the normal's error times the offset ``p -
q``: variance ``2 s_z^2 + |p - q|^2 s_n^2``, ``s_z`` the target point's depth noise (the frame's
measured level, ``noise_profile(...).sigma`` footprints, times ``z / fx``) and ``s_n = u /
sqrt(pi / 2)`` (radians; the per-axis spread of a Rayleigh angle of mean ``u``):

- ``ours-residual``: each pair weighted by the inverse of that variance (recomputed every
  iteration, as the pairs change);
- ``ours-depth-noise``: the same without the normal's term, ``1 / (2 s_z^2)``: what the depth's
  noise alone gives, to tell the map's part from it.

Starts: ``identity`` (the frames are 0.23-1.46 m and 4-25 deg apart: a plain-ICP failure
case, reported for completeness) and ``perturbed``: the reference pose moved by
``--perturb-deg`` about a random axis and ``--perturb-mm`` in a random direction (the same
draws for every variant; ``--seeds`` draws per pair).

Errors: rotation (deg) of ``T_est @ inv(T_ref)`` and ``|t_est - t_ref|`` (mm). ``pose.txt``
comes with the frames, its own accuracy unknown (slambook does not say how it was made):
errors near a common floor across variants are likely to be that floor.

    python benchmarks/icp.py [--step 4] [--max-dist 0.05] [--iterations 50] [--seeds 5]
                             [--perturb-deg 3] [--perturb-mm 50] [--floor 1.0] [--json OUT]
                             [--variants ours,ours-weighted,...]

docs/benchmarks.md section 18 has the table and the reading.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

import depthnormals as dn
from depthnormals.camera import backproject

ROOT = (Path(__file__).resolve().parents[2] / "shared" / "data" / "real-sensors"
        / "nyu_registered_kinect1_slambook")
VARIANTS = ("ours", "ours-weighted", "o3d-icp-ours", "o3d-default")
#: The residual-variance weightings (module doc), run with ``--variants``.
RESIDUAL_VARIANTS = ("ours-residual", "ours-depth-noise")
#: Open3D's default ICPConvergenceCriteria tolerances (fitness, inlier RMSE).
RELATIVE_FITNESS = 1e-6
RELATIVE_RMSE = 1e-6


# ------------------------------------------------------------------------------- geometry

def quat_pose(tx: float, ty: float, tz: float, qx: float, qy: float, qz: float,
              qw: float) -> np.ndarray:
    """4x4 pose from a translation and a unit quaternion (x, y, z, w)."""
    q = np.array([qx, qy, qz, qw], dtype=np.float64)
    x, y, z, w = q / np.linalg.norm(q)
    T = np.eye(4)
    T[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    T[:3, 3] = (tx, ty, tz)
    return T


def rodrigues(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``w`` (radians)."""
    theta = float(np.linalg.norm(w))
    if theta < 1e-12:
        return np.eye(3)
    k = w / theta
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * Kx + (1 - np.cos(theta)) * Kx @ Kx


def pose_error(T_est: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """(rotation error deg, translation error mm) of an estimated relative pose."""
    dR = T_est[:3, :3] @ T_ref[:3, :3].T
    cos = np.clip((np.trace(dR) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos))), float(np.linalg.norm(T_est[:3, 3] - T_ref[:3, 3]) * 1e3)


def perturbation(rng: np.random.Generator, deg: float, mm: float) -> np.ndarray:
    """A rigid motion of exactly ``deg`` about a random axis and ``mm`` in a random direction."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    T = np.eye(4)
    T[:3, :3] = rodrigues(axis * np.radians(deg))
    T[:3, 3] = direction * mm * 1e-3
    return T


def transform(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ T[:3, :3].T + T[:3, 3]


# ------------------------------------------------------------------------------- frames

class Frame(NamedTuple):
    """One depth frame: metres (0 = missing), camera, camera-to-world pose, and our normals
    with their expected error (full resolution). (NamedTuples, not dataclasses: the tests
    load this script without registering it in ``sys.modules``.)"""

    name: str
    depth: np.ndarray
    K: dn.Intrinsics
    pose: np.ndarray
    normals: np.ndarray
    uncertainty: np.ndarray
    sigma: float = float("nan")  # the frame's measured noise level, footprints


def load_frames(root: Path = ROOT) -> list[Frame]:
    """The frames of the folder in ``pose.txt`` order, with their 3f2n+ normals and map."""
    from depthnormals.datasets import read_realsensors

    poses = np.loadtxt(root / "pose.txt", ndmin=2)
    frames = []
    for f in sorted(read_realsensors(root), key=lambda f: int(f.name)):
        K = dn.as_intrinsics(f.K)
        n, u = dn.estimate_normals(f.depth, K, return_uncertainty=True)
        frames.append(Frame(f.name, f.depth, K, quat_pose(*poses[int(f.name) - 1]), n, u,
                            dn.noise_profile(f.depth, K).sigma))
    return frames


class Cloud(NamedTuple):
    """Subsampled valid points of a frame; ``normals``/``uncertainty`` are ours (NaN where
    3f2n+ gives none)."""

    points: np.ndarray
    normals: np.ndarray
    uncertainty: np.ndarray
    noise: np.ndarray | None = None  # each point's depth noise (m), where the frame has a level


def subsample(frame: Frame, step: int) -> Cloud:
    """Every ``step``-th pixel (rows and columns) with valid depth."""
    pts = backproject(frame.depth, frame.K)[::step, ::step]
    n = frame.normals[::step, ::step]
    u = frame.uncertainty[::step, ::step]
    ok = np.all(np.isfinite(pts), axis=-1) & (frame.depth[::step, ::step] > 0)
    pts = pts[ok].astype(np.float64)
    noise = pts[:, 2] * (frame.sigma / frame.K.fx) if frame.sigma > 0.0 else None
    return Cloud(pts, n[ok].astype(np.float64), u[ok].astype(np.float64), noise)


def moved_scene(scene: Any, yaw_deg: float, t: Any) -> tuple[Any, np.ndarray]:
    """An analytic scene (:mod:`depthnormals.analytic`) seen from a moved camera: every
    primitive mapped by ``p -> R p + t`` (R a turn of ``yaw_deg`` about the camera's y axis,
    so boxes turned about y stay boxes turned about y), and that 4x4 motion M. Rendering both
    gives a source view (the moved scene) whose exact registration onto the original is
    ``inv(M)``: the analytic check of the ICP (tests/test_icp_bench.py)."""
    from depthnormals import analytic as an

    R = an._rot(0.0, yaw_deg, 0.0)
    t = np.asarray(t, dtype=np.float64)
    prims = []
    for p in scene.primitives:
        if isinstance(p, an.Plane):
            n = R @ np.asarray(p.normal, dtype=np.float64)
            prims.append(an.Plane(tuple(n), float(p.offset + n @ t)))
        elif isinstance(p, an.Sphere):
            prims.append(an.Sphere(tuple(R @ np.asarray(p.center) + t), p.radius))
        elif isinstance(p, an.Box) and p.angles[0] == 0.0 and p.angles[2] == 0.0:
            prims.append(an.Box(tuple(R @ np.asarray(p.center) + t), p.half,
                                (0.0, p.angles[1] + yaw_deg, 0.0)))
        else:
            raise ValueError(f"moved_scene moves planes, spheres and boxes turned about y; got {p!r}")
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = t
    return an.Scene(prims, scene.name), M


def rendered_frame(scene: Any, K: Any, shape: tuple[int, int]) -> Frame:
    """An analytic view as a :class:`Frame` (exact depth, our normals and map, pose I)."""
    K = dn.as_intrinsics(K)
    depth = scene.render(K, shape).depth.astype(np.float32)
    n, u = dn.estimate_normals(depth, K, return_uncertainty=True)
    return Frame(scene.name, depth, K, np.eye(4), n, u)


def relative_reference(source: Frame, target: Frame) -> np.ndarray:
    """Source camera -> target camera from the camera-to-world poses."""
    return np.linalg.inv(target.pose) @ source.pose


# ------------------------------------------------------------------------------- ICP

class Nearest:
    """Nearest target point of each query point (Open3D's ``core.nns``, exact KNN, k = 1)."""

    def __init__(self, points: np.ndarray):
        import open3d as o3d

        self._o3d = o3d
        self._nns = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(np.ascontiguousarray(points)))
        self._nns.knn_index()

    def __call__(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(index, distance in metres) per query point."""
        idx, d2 = self._nns.knn_search(self._o3d.core.Tensor(np.ascontiguousarray(query)), 1)
        return idx.numpy()[:, 0].astype(np.int64), np.sqrt(d2.numpy()[:, 0])


def gauss_newton_step(p: np.ndarray, q: np.ndarray, n: np.ndarray,
                      w: np.ndarray | None) -> np.ndarray:
    """The 6-vector (rotation vector, translation) minimising ``sum w (n . (exp(xi) p - q))^2``
    linearised at xi = 0: ``J = [p x n, n]``, ``(J^T W J) xi = -J^T W r``."""
    r = np.einsum("ij,ij->i", n, p - q)
    J = np.concatenate([np.cross(p, n), n], axis=1)
    Jw = J if w is None else J * w[:, None]
    A = Jw.T @ J
    b = Jw.T @ r
    return np.linalg.solve(A, -b)


def point_to_plane_icp(source: np.ndarray, target: np.ndarray, target_normals: np.ndarray,
                       init: np.ndarray, *, max_dist: float, iterations: int,
                       target_weights: np.ndarray | None = None,
                       nearest: Nearest | None = None,
                       pair_weights: Any = None) -> dict[str, Any]:
    """Point-to-plane ICP of ``source`` onto ``target`` (Open3D's loop, our solver).

    Each iteration pairs every transformed source point with its nearest target point, keeps
    the pairs closer than ``max_dist`` (the inliers), takes one Gauss-Newton step
    (:func:`gauss_newton_step`, weights ``target_weights`` of the paired target points, or
    ``pair_weights(p, q, idx)`` of the pairs themselves, or 1) and applies it on the left
    (``T <- exp(xi) T``). It stops after ``iterations`` steps, or when the fitness (inliers /
    source points) and the inlier RMSE (point-to-point, m) both change by less than 1e-6, as
    Open3D's ``registration_icp`` does.

    Returns
    -------
    dict
        ``transformation`` (4x4), ``fitness``, ``inlier_rmse``, ``inliers``, ``iterations``.
    """
    nearest = nearest if nearest is not None else Nearest(target)
    T = np.array(init, dtype=np.float64)

    def match(T):
        p = transform(T, source)
        idx, dist = nearest(p)
        ok = dist < max_dist
        rmse = float(np.sqrt(np.mean(dist[ok] ** 2))) if ok.any() else 0.0
        return p[ok], idx[ok], float(ok.mean()), rmse

    p, idx, fitness, rmse = match(T)
    done = 0
    for done in range(1, iterations + 1):  # noqa: B007 - the count is returned
        if len(idx) < 6:
            break
        w = None if target_weights is None else target_weights[idx]
        if pair_weights is not None:
            w = pair_weights(p, target[idx], idx)
        xi = gauss_newton_step(p, target[idx], target_normals[idx], w)
        step = np.eye(4)
        step[:3, :3] = rodrigues(xi[:3])
        step[:3, 3] = xi[3:]
        T = step @ T
        prev = (fitness, rmse)
        p, idx, fitness, rmse = match(T)
        if abs(prev[0] - fitness) < RELATIVE_FITNESS and abs(prev[1] - rmse) < RELATIVE_RMSE:
            break
    return {"transformation": T, "fitness": fitness, "inlier_rmse": rmse, "inliers": len(idx),
            "iterations": done}


def open3d_icp(source: np.ndarray, target: np.ndarray, target_normals: np.ndarray | None,
               init: np.ndarray, *, max_dist: float, iterations: int, knn: int = 30) -> dict[str, Any]:
    """Open3D's ``registration_icp`` (point-to-plane) on the given target normals, or with
    ``target_normals=None`` on Open3D's own (``estimate_normals``, KNN ``knn``)."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(source)))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(target)))
    if target_normals is None:
        tgt.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn))
    else:
        tgt.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(target_normals))
    crit = reg.ICPConvergenceCriteria(relative_fitness=RELATIVE_FITNESS,
                                      relative_rmse=RELATIVE_RMSE, max_iteration=iterations)
    res = reg.registration_icp(src, tgt, max_dist, np.array(init, dtype=np.float64),
                               reg.TransformationEstimationPointToPlane(), crit)
    return {"transformation": np.asarray(res.transformation), "fitness": float(res.fitness),
            "inlier_rmse": float(res.inlier_rmse), "inliers": len(res.correspondence_set),
            "iterations": None}


def weights_from_uncertainty(u: np.ndarray, floor: float) -> np.ndarray:
    """``1 / max(u, floor)^2`` (u in degrees; the floor keeps near-zero predictions of flat,
    clean patches from swamping the sum)."""
    return 1.0 / np.maximum(u, floor) ** 2


def residual_weights(noise: np.ndarray, u: np.ndarray | None):
    """``pair_weights`` of :func:`point_to_plane_icp`: the inverse of each pair's residual
    variance ``2 s_z^2 + |p - q|^2 s_n^2`` (module doc; ``noise`` the target points' ``s_z``, m,
    ``u`` their expected normal error, deg; None: the depth's term alone)."""
    s_n2 = None if u is None else (np.radians(u) / np.sqrt(np.pi / 2.0)) ** 2
    s_z2 = 2.0 * noise ** 2

    def weights(p: np.ndarray, q: np.ndarray, idx: np.ndarray) -> np.ndarray:
        var = s_z2[idx]
        if s_n2 is not None:
            var = var + np.sum((p - q) ** 2, axis=1) * s_n2[idx]
        return 1.0 / var
    return weights


def register_pair(source: Cloud, target: Cloud, init: np.ndarray, *, max_dist: float,
                  iterations: int, floor: float,
                  variants: tuple[str, ...] = VARIANTS) -> dict[str, dict[str, Any]]:
    """Every variant of the module docstring on one pair from one start."""
    ok = np.all(np.isfinite(target.normals), axis=1)  # our normals: the target points that have one
    t_pts, t_n, t_u = target.points[ok], target.normals[ok], target.uncertainty[ok]
    out: dict[str, dict[str, Any]] = {}
    nearest = (Nearest(t_pts) if {"ours", "ours-weighted", *RESIDUAL_VARIANTS} & set(variants)
               else None)
    if set(RESIDUAL_VARIANTS) & set(variants) and target.noise is None:
        raise ValueError(f"{', '.join(RESIDUAL_VARIANTS)} need the target frame's noise level")
    for v in variants:
        t0 = time.perf_counter()
        if v == "ours":
            r = point_to_plane_icp(source.points, t_pts, t_n, init, max_dist=max_dist,
                                   iterations=iterations, nearest=nearest)
        elif v == "ours-weighted":
            r = point_to_plane_icp(source.points, t_pts, t_n, init, max_dist=max_dist,
                                   iterations=iterations, nearest=nearest,
                                   target_weights=weights_from_uncertainty(t_u, floor))
        elif v in RESIDUAL_VARIANTS:
            pw = residual_weights(target.noise[ok], t_u if v == "ours-residual" else None)
            r = point_to_plane_icp(source.points, t_pts, t_n, init, max_dist=max_dist,
                                   iterations=iterations, nearest=nearest, pair_weights=pw)
        elif v == "o3d-icp-ours":
            r = open3d_icp(source.points, t_pts, t_n, init, max_dist=max_dist, iterations=iterations)
        elif v == "o3d-default":
            r = open3d_icp(source.points, target.points, None, init, max_dist=max_dist,
                           iterations=iterations)
        else:
            raise ValueError(f"unknown variant {v!r}; use "
                             f"{', '.join(VARIANTS + RESIDUAL_VARIANTS)}")
        r["seconds"] = time.perf_counter() - t0
        out[v] = r
    return out


# ------------------------------------------------------------------------------- the run

def pairs(n: int) -> list[tuple[int, int]]:
    """(source, target) indices: every i -> i+1, then every i -> i+2."""
    return [(i, i + 1) for i in range(n - 1)] + [(i, i + 2) for i in range(n - 2)]


def run(frames: list[Frame], *, step: int, max_dist: float, iterations: int, seeds: int,
        perturb_deg: float, perturb_mm: float, floor: float,
        variants: tuple[str, ...] = VARIANTS) -> list[dict[str, Any]]:
    """One record per (pair, start, variant): errors, fitness, inliers, iterations, time."""
    clouds = [subsample(f, step) for f in frames]
    records = []
    for s, t in pairs(len(frames)):
        ref = relative_reference(frames[s], frames[t])
        starts = [("identity", None, np.eye(4))]
        for seed in range(seeds):
            rng = np.random.default_rng([seed, s, t])
            starts.append(("perturbed", seed, perturbation(rng, perturb_deg, perturb_mm) @ ref))
        for start, seed, init in starts:
            res = register_pair(clouds[s], clouds[t], init, max_dist=max_dist,
                                iterations=iterations, floor=floor, variants=variants)
            for v, r in res.items():
                rot, trans = pose_error(r["transformation"], ref)
                records.append({"pair": f"{frames[s].name}->{frames[t].name}", "gap": t - s,
                                "start": start, "seed": seed, "variant": v,
                                "rot_err_deg": rot, "trans_err_mm": trans,
                                "init_rot_err_deg": pose_error(init, ref)[0],
                                "init_trans_err_mm": pose_error(init, ref)[1],
                                "fitness": r["fitness"], "inliers": r["inliers"],
                                "inlier_rmse_mm": r["inlier_rmse"] * 1e3,
                                "iterations": r["iterations"], "seconds": r["seconds"],
                                "transformation": np.asarray(r["transformation"]).tolist()})
    return records


def _mean(rows: list[dict], key: str) -> float:
    return float(np.mean([r[key] for r in rows])) if rows else float("nan")


def table(records: list[dict], start: str, variants: tuple[str, ...]) -> str:
    """Markdown: per pair and variant the mean over the starts of ``start``, then the means."""
    rows = [r for r in records if r["start"] == start]
    lines = ["| pair | method | rot err (deg) | trans err (mm) | fitness | inliers |",
             "|---|---|---:|---:|---:|---:|"]
    for pair in dict.fromkeys(r["pair"] for r in rows):
        for v in variants:
            sel = [r for r in rows if r["pair"] == pair and r["variant"] == v]
            lines.append(f"| {pair} | {v} | {_mean(sel, 'rot_err_deg'):.3f} | "
                         f"{_mean(sel, 'trans_err_mm'):.1f} | {_mean(sel, 'fitness'):.3f} | "
                         f"{_mean(sel, 'inliers'):.0f} |")
    for label, gaps in (("mean i->i+1", (1,)), ("mean i->i+2", (2,)), ("mean all", (1, 2))):
        for v in variants:
            sel = [r for r in rows if r["variant"] == v and r["gap"] in gaps]
            lines.append(f"| **{label}** | {v} | {_mean(sel, 'rot_err_deg'):.3f} | "
                         f"{_mean(sel, 'trans_err_mm'):.1f} | {_mean(sel, 'fitness'):.3f} | "
                         f"{_mean(sel, 'inliers'):.0f} |")
    return "\n".join(lines)


def head_to_head(records: list[dict], start: str, a: str, b: str) -> dict[str, Any]:
    """How often ``b`` has the lower error than ``a`` over the runs from ``start``."""
    key = ("pair", "seed")
    ra = {tuple(r[k] for k in key): r for r in records if r["start"] == start and r["variant"] == a}
    rb = {tuple(r[k] for k in key): r for r in records if r["start"] == start and r["variant"] == b}
    common = sorted(set(ra) & set(rb), key=str)
    rot = [rb[c]["rot_err_deg"] - ra[c]["rot_err_deg"] for c in common]
    trans = [rb[c]["trans_err_mm"] - ra[c]["trans_err_mm"] for c in common]
    return {"runs": len(common), "b_better_rot": int(np.sum(np.array(rot) < 0)),
            "b_better_trans": int(np.sum(np.array(trans) < 0)),
            "mean_rot_diff_deg": float(np.mean(rot)) if rot else float("nan"),
            "mean_trans_diff_mm": float(np.mean(trans)) if trans else float("nan")}


def loop_errors(records: list[dict], start: str, variant: str) -> list[dict[str, Any]]:
    """Reference-free consistency: for each triple i, i+1, i+2 and start, the rotation (deg)
    and translation (mm) of ``inv(T_{i->i+2}) T_{i+1->i+2} T_{i->i+1}`` (identity for exact
    registrations; ``pose.txt`` composes exactly by construction, so it cannot judge this)."""
    T = {(r["pair"], r["seed"]): np.array(r["transformation"]) for r in records
         if r["start"] == start and r["variant"] == variant}
    out = []
    for (pair, seed), T02 in T.items():
        a, c = pair.split("->")
        if int(c) - int(a) != 2:
            continue
        b = str(int(a) + 1)
        T01, T12 = T.get((f"{a}->{b}", seed)), T.get((f"{b}->{c}", seed))
        if T01 is None or T12 is None:
            continue
        rot, trans = pose_error(T12 @ T01, T02)
        out.append({"triple": f"{a}->{b}->{c}", "seed": seed, "rot_deg": rot, "trans_mm": trans})
    return out


def main(argv: list[str] | None = None) -> int:
    from depthnormals.commands.bench import machine

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", type=Path, default=ROOT, help="the slambook Kinect v1 folder")
    parser.add_argument("--step", type=int, default=4, help="subsampling (every step-th pixel)")
    parser.add_argument("--max-dist", type=float, default=0.05,
                        help="correspondence threshold, metres")
    parser.add_argument("--iterations", type=int, default=50, help="iteration cap")
    parser.add_argument("--seeds", type=int, default=5, help="perturbed starts per pair")
    parser.add_argument("--perturb-deg", type=float, default=3.0)
    parser.add_argument("--perturb-mm", type=float, default=50.0)
    parser.add_argument("--floor", type=float, default=1.0,
                        help="uncertainty floor of the weights, degrees")
    parser.add_argument("--json", type=Path, default=None, metavar="OUT",
                        help="write every run, the settings and the machine here")
    parser.add_argument("--variants", default=",".join(VARIANTS),
                        help=f"comma-separated, of {', '.join(VARIANTS + RESIDUAL_VARIANTS)}")
    args = parser.parse_args(argv)
    if not args.root.is_dir():
        parser.error(f"{args.root} does not exist")
    variants = tuple(v.strip() for v in args.variants.split(",") if v.strip())
    bad = sorted(set(variants) - set(VARIANTS + RESIDUAL_VARIANTS))
    if bad or not variants:
        parser.error(f"--variants: unknown {bad or 'none given'}; use "
                     f"{', '.join(VARIANTS + RESIDUAL_VARIANTS)}")
    t0 = time.perf_counter()
    frames = load_frames(args.root)  # our normals first: numba before Open3D's TBB is loaded
    records = run(frames, step=args.step, max_dist=args.max_dist, iterations=args.iterations,
                  seeds=args.seeds, perturb_deg=args.perturb_deg, perturb_mm=args.perturb_mm,
                  floor=args.floor, variants=variants)
    import open3d

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from real_sensors import _git_state  # HEAD + uncommitted src/ (the map is under work)

    git = _git_state()
    command = "python benchmarks/icp.py " + " ".join(argv if argv is not None else sys.argv[1:])
    print(f"machine: {machine()}; open3d {open3d.__version__}; depthnormals {dn.__version__}; "
          f"git {git}")
    print(f"command: {command.strip()}")
    print(f"step {args.step}, max_dist {args.max_dist} m, <= {args.iterations} iterations, "
          f"weights 1/max(u, {args.floor} deg)^2; {time.perf_counter() - t0:.0f} s\n")
    summary = {}
    for start, what in (("perturbed", f"{args.seeds} starts per pair: reference pose moved by "
                                      f"{args.perturb_deg} deg and {args.perturb_mm} mm"),
                        ("identity", "identity start")):
        print(f"### {start} ({what}); means over the starts\n")
        print(table(records, start, variants))
        summary[start] = {f"{a} vs {b}": head_to_head(records, start, a, b)
                          for a, b in (("ours", "ours-weighted"), ("o3d-default", "ours-weighted"),
                                       ("o3d-default", "ours"), ("o3d-icp-ours", "ours"),
                                       ("ours", "ours-residual"), ("ours", "ours-depth-noise"),
                                       ("ours-depth-noise", "ours-residual"),
                                       ("o3d-default", "ours-depth-noise"))
                          if a in variants and b in variants}
        for k, h in summary[start].items():
            print(f"\n{k}: the second lower in rotation on {h['b_better_rot']}/{h['runs']} runs, "
                  f"in translation on {h['b_better_trans']}/{h['runs']}; mean difference "
                  f"{h['mean_rot_diff_deg']:+.3f} deg, {h['mean_trans_diff_mm']:+.1f} mm")
        loops = {v: loop_errors(records, start, v) for v in variants}
        summary[start]["loop"] = {v: {"triples": len(x), "mean_rot_deg": _mean(x, "rot_deg"),
                                      "mean_trans_mm": _mean(x, "trans_mm")}
                                  for v, x in loops.items()}
        print("\nloop i->i+1->i+2 against i->i+2 (no reference needed), mean over triples and "
              "starts: " + "; ".join(f"{v} {d['mean_rot_deg']:.3f} deg / {d['mean_trans_mm']:.1f} mm"
                                     for v, d in summary[start]["loop"].items()))
        print()
    if args.json is not None:
        args.json.write_text(json.dumps({
            "command": command.strip(), "machine": machine(), "git": git,
            "open3d": open3d.__version__,
            "depthnormals": dn.__version__,
            "settings": {"step": args.step, "max_dist_m": args.max_dist,
                         "iterations": args.iterations, "seeds": args.seeds,
                         "perturb_deg": args.perturb_deg, "perturb_mm": args.perturb_mm,
                         "uncertainty_floor_deg": args.floor, "open3d_knn": 30,
                         "variants": list(variants),
                         "root": str(args.root)},
            "summary": summary, "runs": records}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
