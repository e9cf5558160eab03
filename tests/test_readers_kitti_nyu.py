"""KITTI depth and NYU Depth v2 (labeled .mat) readers on files written to the published layouts.

No real samples: KITTI is CC BY-NC-SA 3.0 (non-commercial, incompatible with this MIT suite)
and the NYU labeled file is one 2.8 GB .mat. Files are written here to the published
specifications: KITTI depth devkit readme (uint16 PNG, depth = value / 256, 0 = invalid;
calib_cam_to_cam.txt P_rect_0N rows, the 2011_09_26 values), NYU toolbox (camera_params.m,
rgb_plane2rgb_world.m; MATLAB v7.3 = HDF5 with a 512-byte header, arrays column-major).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from PIL import Image

from depthnormals.camera import Intrinsics, backproject
from depthnormals.datasets import detect_format, read_kitti, read_nyu
from depthnormals.datasets import open as open_dataset
from depthnormals.datasets.nyu import NYU_CROP, NYU_INTRINSICS, NYU_INTRINSICS_MATLAB

N_TRUE = np.array([0.1, -0.8, -0.59])  # a road-like plane seen from above the camera
N_TRUE /= np.linalg.norm(N_TRUE)

P_RECT_02 = ("7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 "
             "1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03")
P_RECT_03 = ("7.215377e+02 0.000000e+00 6.095593e+02 -3.395242e+02 0.000000e+00 7.215377e+02 "
             "1.728540e+02 2.199936e+00 0.000000e+00 0.000000e+00 1.000000e+00 2.729905e-03")
KITTI_K = Intrinsics(721.5377, 721.5377, 609.5593, 172.8540)


def plane_depth(K: Intrinsics, shape: tuple[int, int], d: float) -> np.ndarray:
    v, u = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    z = -d / (N_TRUE[0] * (u - K.cx) / K.fx + N_TRUE[1] * (v - K.cy) / K.fy + N_TRUE[2])
    return np.where(z > 0, z, 0.0)


def angle_to_truth(depth: np.ndarray, K: np.ndarray) -> float:
    pts = backproject(depth, K)[depth > 0]
    n = np.linalg.svd(pts - pts.mean(0), full_matrices=False)[2][-1]
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(n, N_TRUE)), abs(n @ N_TRUE))))


def write_kitti_drive(root: Path, rng: np.random.Generator) -> dict[str, np.ndarray]:
    (root / "2011_09_26").mkdir(parents=True)
    (root / "2011_09_26" / "calib_cam_to_cam.txt").write_text(
        "calib_time: 09-Jan-2012 13:57:47\n"
        f"P_rect_02: {P_RECT_02}\nP_rect_03: {P_RECT_03}\n")
    drive = root / "train" / "2011_09_26_drive_0002_sync"
    raws = {}
    for cam in ("image_02", "image_03"):
        raw = np.round(plane_depth(KITTI_K, (375, 1242), 1.65) * 256.0)
        raw[raw > 65535] = 0
        raw[rng.random(raw.shape) > 0.16] = 0  # sparse like the accumulated LiDAR ground truth
        path = drive / "proj_depth" / "groundtruth" / cam / "0000000005.png"
        path.parent.mkdir(parents=True)
        Image.fromarray(raw.astype(np.uint16)).save(path)
        raws[cam] = raw
    return raws


def test_kitti_drive_scale_sparse_mask_and_calib(tmp_path):
    raws = write_kitti_drive(tmp_path, np.random.default_rng(3))
    drive = tmp_path / "train" / "2011_09_26_drive_0002_sync"
    assert detect_format(drive) == "kitti"
    frames = list(open_dataset(drive))
    assert [f.name for f in frames] == ["0000000005_image_02", "0000000005_image_03"]
    f = frames[0]
    assert f.group == drive.name and f.normals is None
    assert np.array_equal(f.K, KITTI_K.matrix)  # P_rect_02[:, :3]
    assert np.array_equal(f.depth, (raws["image_02"] / 256.0).astype(np.float32))
    assert np.array_equal(f.mask, raws["image_02"] > 0) and 0.1 < f.mask.mean() < 0.2
    assert angle_to_truth(f.depth, f.K) < 0.05
    assert angle_to_truth(f.depth, Intrinsics(721.5377, 721.5377, 621.0, 187.0).matrix) > 0.3
    # one camera folder alone, and the velodyne_raw kind missing
    one = list(read_kitti(drive / "proj_depth" / "groundtruth" / "image_03"))
    assert [g.name for g in one] == ["0000000005_image_03"]
    with pytest.raises(ValueError, match="velodyne_raw"):
        list(read_kitti(drive, kind="velodyne_raw"))


def test_kitti_without_calib_says_what_to_pass(tmp_path):
    write_kitti_drive(tmp_path, np.random.default_rng(0))
    (tmp_path / "2011_09_26" / "calib_cam_to_cam.txt").unlink()
    drive = tmp_path / "train" / "2011_09_26_drive_0002_sync"
    with pytest.raises(FileNotFoundError, match="pass calib= or intrinsics="):
        list(read_kitti(drive))
    f = next(iter(read_kitti(drive, intrinsics=KITTI_K)))
    assert np.array_equal(f.K, KITTI_K.matrix)


def test_kitti_val_selection_cropped(tmp_path):
    root = tmp_path / "val_selection_cropped"
    K = Intrinsics(721.5377, 721.5377, 596.5593, 149.854)  # the crop shifts the principal point
    raw = np.round(plane_depth(K, (352, 1216), 1.65) * 256.0)
    raw[raw > 65535] = 0
    stem = "2011_09_26_drive_0002_sync_{}_0000000005_image_02"
    (root / "groundtruth_depth").mkdir(parents=True)
    (root / "intrinsics").mkdir()
    png = root / "groundtruth_depth" / (stem.format("groundtruth_depth") + ".png")
    Image.fromarray(raw.astype(np.uint16)).save(png)
    np.savetxt(root / "intrinsics" / (stem.format("image") + ".txt"), K.matrix.reshape(1, 9), fmt="%f")
    assert detect_format(root) == "kitti"
    f = next(iter(open_dataset(root)))
    assert f.name == "0000000005_image_02" and f.group == "2011_09_26_drive_0002_sync"
    assert np.array_equal(f.K, K.matrix) and np.array_equal(f.depth, (raw / 256).astype(np.float32))


def write_nyu_mat(path: Path, depths: list[np.ndarray], *, raw_zero: bool = True) -> None:
    """A MATLAB v7.3 file as MATLAB writes it: 512-byte header block, arrays stored transposed."""
    with h5py.File(path, "w", userblock_size=512) as f:
        f.create_dataset("depths", data=np.stack([d.T for d in depths]).astype(np.float32))
        raws = [np.where(np.arange(640)[None, :] < 8, 0.0, d) if raw_zero else d for d in depths]
        f.create_dataset("rawDepths", data=np.stack([d.T for d in raws]).astype(np.float32))
        rgb = np.zeros((len(depths), 3, 640, 480), np.uint8)
        rgb[:, 0] = 200  # red
        f.create_dataset("images", data=rgb)
    with path.open("r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .")


def toolbox_points(depth: np.ndarray) -> np.ndarray:
    """rgb_plane2rgb_world.m before its y flip: meshgrid(1:640, 1:480) with camera_params.m."""
    fx, fy, cx, cy = NYU_INTRINSICS_MATLAB
    xx, yy = np.meshgrid(np.arange(1, 641), np.arange(1, 481))
    return np.dstack([(xx - cx) * depth / fx, (yy - cy) * depth / fy, depth])


def test_nyu_layout_units_and_one_based_principal_point(tmp_path):
    d0 = plane_depth(NYU_INTRINSICS, (480, 640), 1.3)
    d1 = d0 + np.linspace(0, 1, 640)[None, :]  # not a plane: any transposition slip shows
    mat = tmp_path / "nyu_depth_v2_labeled.mat"
    write_nyu_mat(mat, [d0, d1])
    assert detect_format(mat) == "nyu"
    frames = list(open_dataset(mat))
    assert [f.name for f in frames] == ["0000", "0001"] and frames[0].group == "nyu_depth_v2_labeled"
    f = frames[1]
    assert f.depth.shape == (480, 640) and np.array_equal(f.depth, d1.astype(np.float32))
    assert f.meta["rgb"].shape == (480, 640, 3) and np.all(f.meta["rgb"][..., 0] == 200)
    assert (NYU_INTRINSICS.cx, NYU_INTRINSICS.cy) == (325.58244941119034 - 1, 253.73616633400465 - 1)
    # our 0-based back-projection gives the toolbox's points exactly; with the raw (1-based)
    # principal point it is off by one pixel's footprint (about 2.5 mm here)
    ours = backproject(frames[0].depth.astype(np.float64), frames[0].K)
    assert np.abs(ours - toolbox_points(d0.astype(np.float32).astype(np.float64))).max() < 1e-6
    raw_k = Intrinsics(*NYU_INTRINSICS_MATLAB)
    off = backproject(frames[0].depth.astype(np.float64), raw_k) - toolbox_points(d0)
    assert np.abs(off).max() > 1e-3
    assert angle_to_truth(frames[0].depth, frames[0].K) < 0.01


def test_nyu_raw_crop_and_indices(tmp_path):
    d0 = plane_depth(NYU_INTRINSICS, (480, 640), 1.3)
    mat = tmp_path / "labeled.mat"
    write_nyu_mat(mat, [d0, d0 * 2, d0 * 3])
    f = next(iter(read_nyu(mat, raw=True, indices=[2])))
    assert f.name == "0002" and f.meta["key"] == "rawDepths"
    assert not f.mask[:, :8].any() and f.mask[:, 8:].all()
    full = next(iter(read_nyu(mat)))
    crop = next(iter(read_nyu(mat, crop=True)))
    assert crop.depth.shape == (427, 561) and crop.meta["rgb"].shape == (427, 561, 3)
    assert np.array_equal(backproject(crop.depth, crop.K), backproject(full.depth, full.K)[NYU_CROP])
    with h5py.File(tmp_path / "other.mat", "w", userblock_size=512) as h:
        h.create_dataset("images", data=np.zeros((1, 3, 4, 4), np.uint8))
    with pytest.raises(ValueError, match="no known dataset layout"):
        detect_format(tmp_path / "other.mat")
