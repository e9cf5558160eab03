"""Hypersim reader: ray distance -> planar depth, the tilt-shift camera, the normal convention.

The real frame (tests/data/hypersim, see SOURCE) pins the camera model and the conversion; a
tilted plane rendered to Hypersim's published convention (x right, y up, z backward; depth as
Euclidean distance) pins the normal mapping.
"""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from depthnormals.camera import Intrinsics, backproject
from depthnormals.datasets import detect_format, read_hypersim
from depthnormals.datasets import open as open_dataset
from depthnormals.datasets._common import face_camera
from depthnormals.datasets.hypersim import HYPERSIM_DEFAULT_M_CAM_FROM_UV, hypersim_camera
from depthnormals.metrics import angular_error

DATA = Path(__file__).parent / "data" / "hypersim"
DEPTH_FILE = DATA / "ai_037_002" / "images" / "scene_cam_00_geometry_hdf5" / "frame.0000.depth_meters.hdf5"
F = np.diag([1.0, -1.0, -1.0])


def _scene_M(scene: str) -> np.ndarray:
    with (DATA / "metadata_camera_parameters.csv").open() as fh:
        row = next(r for r in csv.DictReader(fh) if r["scene_name"] == scene)
    return np.array([[float(row[f"M_cam_from_uv_{i}{j}"]) for j in range(3)] for i in range(3)])


def _notebook_rays(M: np.ndarray, w: int = 1024, h: int = 768) -> np.ndarray:
    """Camera-space rays (Hypersim frame) as contrib notebook 01 builds them: (h, w, 3)."""
    half_du, half_dv = 1.0 / w, 1.0 / h
    u, v = np.meshgrid(np.linspace(-1 + half_du, 1 - half_du, w),
                       np.linspace(-1 + half_dv, 1 - half_dv, h)[::-1])
    return np.dstack([u, v, np.ones_like(u)]) @ M.T


def test_real_frame_camera_and_planar_depth():
    frame = next(iter(open_dataset(DATA / "ai_037_002")))
    assert detect_format(DATA / "ai_037_002") == "hypersim"
    assert frame.group == "ai_037_002/cam_00" and frame.name == "0000"
    assert frame.meta["intrinsics"] == "metadata_camera_parameters.csv:ai_037_002"
    assert frame.normals is None and frame.depth.dtype == np.float32 and frame.depth.shape == (768, 1024)
    K = Intrinsics.from_matrix(frame.K)
    # pinned (derived from the CSV row; a half-pixel or y-flip slip moves cx/cy by >= 0.5)
    assert K.fx == pytest.approx(887.535381, abs=1e-5) and K.fy == pytest.approx(887.535381, abs=1e-5)
    assert K.cx == pytest.approx(572.939999, abs=1e-5) and K.cy == pytest.approx(457.142352, abs=1e-5)
    # every pixel's notebook ray, rotated into the virtual frame, projects back onto that pixel
    R = frame.meta["R_virtual_from_cam"]
    rays = _notebook_rays(_scene_M("ai_037_002")) @ (R @ F).T
    proj = rays @ frame.K.T
    jj, ii = np.mgrid[0:768, 0:1024]
    assert np.abs(proj[..., 0] / proj[..., 2] - ii).max() < 1e-9
    assert np.abs(proj[..., 1] / proj[..., 2] - jj).max() < 1e-9
    # planar depth = distance * cos(angle to the optical axis), computed independently
    with h5py.File(DEPTH_FILE) as f:
        distance = f["dataset"][...].astype(np.float64)
    expect = distance * rays[..., 2] / np.linalg.norm(rays, axis=-1)
    assert np.abs(frame.depth - expect).max() < 1e-5 * expect.max()
    # golden values of this reader on the real frame (file distances 7.883, 6.293, 3.283 m)
    for (r, c), value in {(384, 512): 7.8378506, (0, 0): 4.852216, (767, 1023): 2.7958353}.items():
        assert frame.depth[r, c] == pytest.approx(value, rel=2e-7)
    assert frame.mask.all()


def _flatness(depth: np.ndarray, K: np.ndarray, patch: int = 64) -> np.ndarray:
    """RMS distance to the best plane of each patch x patch block of back-projected points (m)."""
    X = backproject(depth, K)
    out = []
    for r in range(0, depth.shape[0] - patch + 1, patch):
        for c in range(0, depth.shape[1] - patch + 1, patch):
            pts = X[r:r + patch, c:c + patch].reshape(-1, 3)
            s = np.linalg.svd(pts - pts.mean(0), compute_uv=False)
            out.append(s[-1] / np.sqrt(len(pts)))
    return np.array(out)


def test_real_frame_walls_are_flat_only_after_the_conversion():
    # measured: 10th percentile of patch RMS 0.29 mm converted vs 0.91 mm with distance as depth
    frame = next(iter(read_hypersim(DATA)))
    with h5py.File(DEPTH_FILE) as f:
        distance = f["dataset"][...].astype(np.float32)
    good = np.percentile(_flatness(frame.depth, frame.K), 10)
    wrong = np.percentile(_flatness(distance, frame.K), 10)
    assert good < 0.0005 and wrong > 2.5 * good


def test_default_camera_is_the_60_degree_one():
    K, R = hypersim_camera(HYPERSIM_DEFAULT_M_CAM_FROM_UV)
    f = 512.0 / np.tan(np.pi / 6)
    assert (K.fx, K.fy, K.cx, K.cy) == pytest.approx((f, f, 511.5, 383.5), abs=1e-9)
    assert np.array_equal(R, np.eye(3))


def test_skewed_scene_is_rejected():
    M = np.array([[0.58, 0.02, 0.0], [0.0, 0.43, 0.0], [0.0, 0.0, -1.0]])
    with pytest.raises(ValueError, match="skew"):
        hypersim_camera(M)


# --- a tilted plane rendered to Hypersim's convention ------------------------------------------

N_TRUE = np.array([0.35, -0.45, -0.8213])
N_TRUE /= np.linalg.norm(N_TRUE)  # OpenCV frame, faces the camera (its z < 0)
PLANE_D = 2.5  # n . X = -d : the plane is 2.5 m from the camera


def write_hypersim_plane(root: Path, *, flip_half: bool, dtype: str = "float16") -> Path:
    """Scene ``ai_001_001`` (default 60 degree camera, no CSV) seeing the plane; returns the scene.

    ``depth_meters`` = Euclidean distance, ``normal_cam`` = the normal in Hypersim's frame
    (x, -y, -z of ours); ``flip_half`` stores the left half as the back-face normal.
    """
    K, _ = hypersim_camera(HYPERSIM_DEFAULT_M_CAM_FROM_UV)
    v, u = np.mgrid[0:768, 0:1024].astype(np.float64)
    ray = np.dstack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones_like(u)])
    t = -PLANE_D / (ray @ N_TRUE)
    distance = t * np.linalg.norm(ray, axis=-1)
    n_h = np.broadcast_to(F @ N_TRUE, (768, 1024, 3)).copy()
    if flip_half:
        n_h[:, :512] *= -1
    gdir = root / "ai_001_001" / "images" / "scene_cam_00_geometry_hdf5"
    gdir.mkdir(parents=True)
    for name, arr in (("depth_meters", distance), ("normal_cam", n_h)):
        with h5py.File(gdir / f"frame.0003.{name}.hdf5", "w") as f:
            f.create_dataset("dataset", data=arr.astype(dtype), compression="gzip")
    return root / "ai_001_001"


def test_plane_normal_convention(tmp_path):
    scene = write_hypersim_plane(tmp_path, flip_half=True, dtype="float32")
    frame = next(iter(open_dataset(scene)))
    assert frame.meta["intrinsics"].startswith("default")
    assert frame.mask.all() and frame.normals.dtype == np.float32
    err = angular_error(frame.normals, np.broadcast_to(N_TRUE, frame.normals.shape))
    assert np.nanmax(err) < 1e-4  # degrees
    # planar depth of the plane: z = -d / (n . K^-1 p)
    K = Intrinsics.from_matrix(frame.K)
    v, u = np.mgrid[0:768, 0:1024]
    z = -PLANE_D / (N_TRUE[0] * (u - K.cx) / K.fx + N_TRUE[1] * (v - K.cy) / K.fy + N_TRUE[2])
    assert np.abs(frame.depth - z).max() < 1e-5


def test_plane_wrong_mappings_would_fail(tmp_path):
    """The plausible wrong readings of normal_cam give errors far above the tolerance above."""
    scene = write_hypersim_plane(tmp_path, flip_half=False, dtype="float32")
    frame = next(iter(read_hypersim(scene)))
    K = Intrinsics.from_matrix(frame.K)
    with h5py.File(scene / "images/scene_cam_00_geometry_hdf5/frame.0003.normal_cam.hdf5") as f:
        n_h = f["dataset"][...].astype(np.float64)
    truth = np.broadcast_to(N_TRUE, n_h.shape)
    # (-x, y, z) is -1 times the right map: the same after orienting, so not a wrong reading
    for wrong in (np.eye(3), np.diag([1.0, 1.0, -1.0]), np.diag([1.0, -1.0, 1.0])):
        n = face_camera(n_h @ wrong.T, frame.depth, K, frame.mask)
        assert np.nanmin(angular_error(n, truth)) > 10.0


def test_float16_files_as_published(tmp_path):
    scene = write_hypersim_plane(tmp_path, flip_half=True, dtype="float16")
    frame = next(iter(read_hypersim(scene)))
    err = angular_error(frame.normals, np.broadcast_to(N_TRUE, frame.normals.shape))
    assert np.nanmax(err) < 0.1  # float16 normals: ~1e-3 per component


def test_folder_of_scenes_and_csv_lookup(tmp_path):
    root = tmp_path / "hypersim"
    shutil.copytree(DATA / "ai_037_002", root / "ai_037_002")
    write_hypersim_plane(root, flip_half=False)
    frames = list(open_dataset(root))
    assert [f.group for f in frames] == ["ai_001_001/cam_00", "ai_037_002/cam_00"]
    assert all(f.meta["intrinsics"].startswith("default") for f in frames)  # no CSV in root
    shutil.copy(DATA / "metadata_camera_parameters.csv", root)
    with pytest.raises(ValueError, match="no row for scene 'ai_001_001'"):
        list(read_hypersim(root))
    frames = list(read_hypersim(root / "ai_037_002" / "images"))
    assert frames[0].meta["intrinsics"].endswith("ai_037_002")
