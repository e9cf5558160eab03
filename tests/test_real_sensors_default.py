"""The default 3f2n+ on the real sensor frames of ``shared/data/real-sensors`` (Kinect v1,
Xtion, densified LiDAR): a noise estimate that never reads them as clean, and more accurate
normals than the peers on their planes (the plane reference, docs/evaluation.md). Skipped
when the shared folder is absent."""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.ddm.auto import PLANES_NOISE
from depthnormals.evaluate import plane_reference, score_planes, sensor_threshold

FOLDERS = ("kitti_road_lidar_sne_roadseg", "nyu_raw_kinect1_open3d", "nyu_registered_kinect1_slambook",
           "sunrgbd_open3d", "tum_fr2_kinect1_slambook", "tum_kinect1_open3d")


@pytest.fixture(scope="module")
def frames(shared_data):
    out = {}
    for name in FOLDERS:
        out[name] = list(dn.datasets.open(shared_data / "real-sensors" / name))
        assert out[name], name
    return out


#: The peers scored here, by their labels in benchmarks/real_sensors.py (its METHODS: the same
#: calls, and its _facing turns their arbitrary signs toward the camera).
PEERS = ("fals-11", "pcl-average-3d-gradient", "opencv-fals-7")


@pytest.fixture(scope="module")
def bench(load_benchmark):
    pytest.importorskip("cv2")
    return load_benchmark("real_sensors")


def test_noise_is_never_zero_and_steady_per_sensor(frames):
    for name, fs in frames.items():
        levels = [dn.estimate_noise(f.depth, f.K) for f in fs]
        # every frame reads noisy: quantised Kinect depth used to read exactly 0 (the clean branch)
        assert min(levels) > 10 * PLANES_NOISE, (name, levels)
        # frames of one sensor agree (the NYU registered five within 20 %)
        assert max(levels) <= 1.2 * min(levels), (name, levels)


@pytest.fixture(scope="module")
def scores(frames, bench):
    """Interior / rim mean error per folder and method, on the first frame of each folder
    (the plane reference costs seconds a frame; benchmarks/real_sensors.py scores every frame
    with the default reference)."""
    pytest.importorskip("cv2")
    table = {}
    for name, fs in frames.items():
        rows = {}
        for f in fs[:1]:
            # 64 RANSAC hypotheses a plane instead of 256: a few seconds a frame, the large
            # planes all the same (the margins below are several degrees)
            ref = plane_reference(f.depth, f.K, threshold=sensor_threshold(f.meta), hypotheses=64)
            for label in ("3f2n+", *PEERS):
                n = bench.METHODS[label](f.depth, f.K)
                s = score_planes(bench._facing(n, f.depth, f.K), ref)
                rows.setdefault(label, []).append((s["interior_mean"], s["rim_mean"]))
        table[name] = {k: np.nanmean(np.array(v), axis=0) for k, v in rows.items()}
    return table


@pytest.mark.parametrize("peer", sorted(PEERS))
def test_default_beats_the_peers_on_every_folder(scores, peer):
    for name, row in scores.items():
        ours, theirs = row["3f2n+"], row[peer]
        assert ours[0] < theirs[0], (name, "interior", ours, theirs)
        assert ours[1] < theirs[1], (name, "rim", ours, theirs)


def test_mean_over_folders(scores):
    ours = np.mean([row["3f2n+"] for row in scores.values()], axis=0)
    # all frames: 3.83 / 10.51 deg (docs/benchmarks.md section 16); the bounds leave room for
    # the reference's RANSAC seeds, not for a regression to the old default (25.9 / 36.6)
    assert ours[0] < 6.0
    assert ours[1] < 15.0


def test_the_crease_bands_as_measured(bench, shared_data):
    """``benchmarks/real_sensors.py``'s crease-band columns on TUM fr2 (docs/benchmarks.md
    section 16, "Session 19", and section 22): the default erred 29.30 deg in the bands by its
    planes' creases (its desk's front face took the top's normal) against PCL's 14.79; with the
    face switch (session 31, ddm/faceswitch.py) 16.09, while ahead on the interiors and rims
    (2.44 / 7.60 against 5.80 / 20.90). Pinned as measured: a default that places real creases
    better moves the first number down (then update it)."""
    acc = bench.accuracy(shared_data / "real-sensors" / "tum_fr2_kinect1_slambook",
                         ["3f2n+", "pcl-average-3d-gradient"], 0)
    (row,) = acc.values()
    ours, pcl = row["3f2n+"], row["pcl-average-3d-gradient"]
    assert ours["crease_mean"] == pytest.approx(16.09, abs=0.5)
    assert pcl["crease_mean"] == pytest.approx(14.79, abs=0.5)
    assert ours["interior_mean"] < pcl["interior_mean"] and ours["rim_mean"] < pcl["rim_mean"]
    assert ours["crease_near_mean"] > ours["crease_far_mean"]
