"""TUM RGB-D and ScanNet readers on sequences written to the published layouts.

No real frames: the TUM and ScanNet licences do not allow redistribution in a test suite of
this kind (TUM: CC BY 4.0 would allow it, but no small public copy was found in the time given;
ScanNet: terms of use forbid it). The files are written here to the published specifications
(TUM: https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats; ScanNet:
SensReader/python/reader.py export) with Pillow, an encoder independent of ours: a tilted plane
seen by the dataset's camera, so the scale, K and geometry are all pinned.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from depthnormals.camera import Intrinsics, backproject
from depthnormals.datasets import TUM_INTRINSICS, detect_format, read_scannet, read_tum
from depthnormals.datasets import open as open_dataset

N_TRUE = np.array([0.3, -0.4, -0.866])
N_TRUE /= np.linalg.norm(N_TRUE)


def plane_depth(K: Intrinsics, shape: tuple[int, int], d: float) -> np.ndarray:
    """Planar depth of the plane N_TRUE . X = -d seen by K (float64, metres)."""
    v, u = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    return -d / (N_TRUE[0] * (u - K.cx) / K.fx + N_TRUE[1] * (v - K.cy) / K.fy + N_TRUE[2])


def fitted_normal(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    pts = backproject(depth, K)[depth > 0]
    n = np.linalg.svd(pts - pts.mean(0), full_matrices=False)[2][-1]
    return n if n @ N_TRUE > 0 else -n


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)))


def write_png16(path: Path, raw: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(raw.astype(np.uint16)).save(path)


def write_tum(root: Path, K: Intrinsics, *,
              stamps=("1305031102.160407", "1305031102.194330")) -> list[np.ndarray]:
    raws = []
    lines = ["# depth maps", "# file: 'rgbd_dataset_freiburg1_xyz.bag'", "# timestamp filename"]
    for i, stamp in enumerate(stamps):
        raw = np.round(plane_depth(K, (480, 640), 1.2 + 0.1 * i) * 5000.0)
        raw[:10, :20] = 0  # no data
        write_png16(root / "depth" / f"{stamp}.png", raw)
        lines.append(f"{stamp} depth/{stamp}.png")
        raws.append(raw)
    (root / "depth.txt").write_text("\n".join(lines) + "\n")
    return raws


def test_tum_fr1_scale_k_and_geometry(tmp_path):
    root = tmp_path / "rgbd_dataset_freiburg1_xyz"
    raws = write_tum(root, TUM_INTRINSICS["fr1"])
    assert detect_format(root) == "tum"
    frames = list(open_dataset(root))
    assert [f.name for f in frames] == ["1305031102.160407", "1305031102.194330"]
    f = frames[0]
    assert f.group == root.name and f.normals is None and f.meta["intrinsics"] == "fr1"
    assert np.array_equal(f.K, [[517.3, 0, 318.6], [0, 516.5, 255.3], [0, 0, 1]])
    assert f.depth.dtype == np.float32
    assert np.array_equal(f.depth, (raws[0] / 5000.0).astype(np.float32))  # 5000 units per metre
    assert f.depth[240, 320] == pytest.approx(plane_depth(TUM_INTRINSICS["fr1"], (480, 640), 1.2)[240, 320],
                                              abs=1e-4)
    assert not f.mask[:10, :20].any() and f.mask[10:, 20:].all() and np.all(f.depth[:10, :20] == 0)
    assert angle(fitted_normal(f.depth, f.K), N_TRUE) < 0.05
    # the wrong preset tilts the plane: the test above would fail on it
    assert angle(fitted_normal(f.depth, TUM_INTRINSICS["ros"].matrix), N_TRUE) > 0.5


@pytest.mark.parametrize("seq,preset", [("rgbd_dataset_freiburg2_desk", "fr2"),
                                        ("rgbd_dataset_freiburg3_long_office_household", "fr3")])
def test_tum_preset_from_sequence_name(tmp_path, seq, preset):
    write_tum(tmp_path / seq, TUM_INTRINSICS[preset], stamps=("1.0",))
    f = next(iter(read_tum(tmp_path / seq)))
    assert f.meta["intrinsics"] == preset and np.array_equal(f.K, TUM_INTRINSICS[preset].matrix)
    assert TUM_INTRINSICS["fr2"] == Intrinsics(520.9, 521.0, 325.1, 249.7)
    assert TUM_INTRINSICS["fr3"] == Intrinsics(535.4, 539.2, 320.1, 247.6)
    assert TUM_INTRINSICS["ros"] == Intrinsics(525.0, 525.0, 319.5, 239.5)


def test_tum_unnamed_folder_needs_intrinsics(tmp_path):
    root = tmp_path / "my_recording"
    write_tum(root, TUM_INTRINSICS["fr3"], stamps=("1.0",))
    with pytest.raises(ValueError, match="pass intrinsics='fr1'"):
        list(read_tum(root))
    assert next(iter(read_tum(root, intrinsics="fr3"))).meta["intrinsics"] == "fr3"
    (tmp_path / "K.json").write_text(json.dumps({"fx": 500.0, "fy": 501.0, "cx": 320.0, "cy": 240.0}))
    f = next(iter(open_dataset(root, intrinsics=tmp_path / "K.json", depth_scale=0.001)))
    assert f.K[0, 0] == 500.0 and f.meta["intrinsics"] == "given"
    raw = np.asarray(Image.open(root / "depth" / "1.0.png"))
    assert np.array_equal(f.depth, (raw / 1000.0).astype(np.float32))
    with pytest.raises(ValueError, match="neither a preset"):
        list(read_tum(root, intrinsics="fr9"))


def test_tum_associations_either_column_order(tmp_path):
    root = tmp_path / "rgbd_dataset_freiburg1_desk"
    write_tum(root, TUM_INTRINSICS["fr1"])
    (root / "associations.txt").write_text(
        "1305031102.175304 rgb/1305031102.175304.png 1305031102.160407 depth/1305031102.160407.png\n")
    frames = list(read_tum(root))
    assert [(f.name, f.meta["rgb"]) for f in frames] == [("1305031102.160407", "rgb/1305031102.175304.png")]
    (root / "associations.txt").unlink()
    (root / "pairs.txt").write_text("1305031102.194330 depth/1305031102.194330.png 1.0 rgb/1.0.png\n")
    frames = list(read_tum(root, associations=root / "pairs.txt"))
    assert [(f.name, f.meta["rgb"]) for f in frames] == [("1305031102.194330", "rgb/1.0.png")]


SCANNET_K = Intrinsics(577.590698, 578.729797, 318.905426, 242.683609)


def write_scannet(root: Path) -> list[np.ndarray]:
    (root / "intrinsic").mkdir(parents=True)
    M = np.eye(4)
    M[:3, :3] = SCANNET_K.matrix
    np.savetxt(root / "intrinsic" / "intrinsic_depth.txt", M, fmt="%f")
    raws = []
    for i in (2, 10):
        raw = np.round(plane_depth(SCANNET_K, (480, 640), 1.5 + 0.01 * i) * 1000.0)
        raw[-5:, :] = 0
        write_png16(root / "depth" / f"{i}.png", raw)
        raws.append(raw)
    (root / "pose").mkdir()
    np.savetxt(root / "pose" / "10.txt", np.eye(4) * 2, fmt="%f")
    return raws


def test_scannet_mm_k_file_order_and_pose(tmp_path):
    root = tmp_path / "scene0000_00"
    raws = write_scannet(root)
    assert detect_format(root) == "scannet"
    frames = list(open_dataset(root))
    assert [f.name for f in frames] == ["2", "10"]  # numeric, not lexicographic, order
    f = frames[0]
    assert np.allclose(f.K, SCANNET_K.matrix, rtol=0, atol=1e-6) and f.normals is None
    assert np.array_equal(f.depth, (raws[0] / 1000.0).astype(np.float32))
    assert not f.mask[-5:].any() and f.mask[:-5].all()
    assert angle(fitted_normal(f.depth, f.K), N_TRUE) < 0.2  # 1 mm steps
    assert "pose" not in f.meta and np.array_equal(frames[1].meta["pose"], np.eye(4) * 2)
    g = next(iter(read_scannet(root, intrinsics=(500.0, 500.0, 320.0, 240.0))))
    assert g.K[0, 0] == 500.0


def test_open_refuses_options_a_format_does_not_take(tmp_path):
    root = tmp_path / "scene0000_00"
    write_scannet(root)
    with pytest.raises(TypeError, match="does not take depth_scale"):
        list(open_dataset(root, format="hypersim", depth_scale=0.001))
    with pytest.raises(ValueError, match="unknown dataset format 'tum2'"):
        list(open_dataset(root, format="tum2"))
    with pytest.raises(ValueError, match="no known dataset layout"):
        list(open_dataset(tmp_path / "scene0000_00" / "pose"))


def test_replica_nice_slam_layout(tmp_path):
    from depthnormals.datasets import REPLICA_INTRINSICS

    root = tmp_path / "room0"
    raws = []
    for i in range(2):
        raw = np.round(plane_depth(REPLICA_INTRINSICS, (680, 1200), 2.0 + i) * 6553.5)
        raw[raw > 65535] = 0
        write_png16(root / "results" / f"depth{i:06d}.png", raw)
        raws.append(raw)
    poses = np.stack([np.eye(4) + 0.1 * i for i in range(2)])
    np.savetxt(root / "traj.txt", poses.reshape(2, 16))
    assert detect_format(root) == "replica"
    frames = list(open_dataset(root))
    assert [f.name for f in frames] == ["000000", "000001"] and frames[0].normals is None
    f = frames[1]
    assert np.array_equal(f.K, [[600, 0, 599.5], [0, 600, 339.5], [0, 0, 1]])
    assert np.array_equal(f.depth, (raws[1] / 6553.5).astype(np.float32))
    assert np.array_equal(f.meta["pose"], poses[1])
    assert angle(fitted_normal(f.depth, f.K), N_TRUE) < 0.05
