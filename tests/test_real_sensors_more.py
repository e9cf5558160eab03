"""The default on real sensors beyond the shared set's structured light and LiDAR: one Azure
Kinect time-of-flight frame (``tests/data/azure_kinect_tof``, its lens undone by the reader)
and one RealSense D435 active-stereo frame (``tests/data/realsense_d435``); SOURCE and
LICENSE in each folder. Scored as ``benchmarks/real_sensors.py`` scores the shared frames (a
RANSAC plane reference; interiors and rims), with its peers' calls."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.ddm.auto import PLANES_NOISE
from depthnormals.evaluate import plane_reference, score_planes, sensor_threshold

DATA = Path(__file__).resolve().parent / "data"
#: folder -> (interior, rim) mean error of the default measured with the full reference
#: (docs/benchmarks.md section 25: ``python benchmarks/real_sensors.py --root <folder>``)
MEASURED = {"azure_kinect_tof": (2.14, 10.58), "realsense_d435": (2.69, 8.29)}
PEERS = ("fals-11", "pcl-average-3d-gradient", "opencv-fals-7")


@pytest.fixture(scope="module")
def bench(load_benchmark):
    pytest.importorskip("cv2")
    return load_benchmark("real_sensors")


@pytest.fixture(scope="module", params=sorted(MEASURED))
def scored(request, bench):
    """(folder, the frame, its reference, {label: (interior, rim)})."""
    (f,) = list(dn.datasets.open(DATA / request.param))
    ref = plane_reference(f.depth, f.K, threshold=sensor_threshold(f.meta), hypotheses=64)
    out = {}
    for label in ("3f2n+", *PEERS):
        s = score_planes(bench._facing(bench.METHODS[label](f.depth, f.K), f.depth, f.K), ref)
        out[label] = (s["interior_mean"], s["rim_mean"])
    return request.param, f, ref, out


def test_read_as_a_noisy_sensor(scored):
    name, f, _, _ = scored
    assert f.depth.dtype == np.float32 and np.count_nonzero(f.depth > 0) > 0.7 * f.depth.size
    # never the clean branch: the D435's and the ToF's noise is correlated (docs/benchmarks.md 25)
    assert dn.estimate_noise(f.depth, f.K) > 10 * PLANES_NOISE, name
    assert dn.noise_profile(f.depth, f.K).branch == "measured-support", name


@pytest.mark.parametrize("peer", PEERS)
def test_default_beats_the_peer(scored, peer):
    name, _, _, s = scored
    ours, theirs = s["3f2n+"], s[peer]
    assert ours[0] < theirs[0] and ours[1] < theirs[1], (name, peer, ours, theirs)


def test_default_as_measured(scored):
    # the bounds leave room for the reference's 64 RANSAC hypotheses (256 in the benchmark)
    name, _, _, s = scored
    interior, rim = MEASURED[name]
    assert s["3f2n+"][0] < interior + 1.0 and s["3f2n+"][1] < rim + 2.5, (name, s["3f2n+"])


def test_tof_lens_ignored_costs(bench):
    """The Azure Kinect frame read as a pinhole image (the benchmark's ``_lens_ignored``: the
    stored grid's normals carried onto the undistorted grid by the same pixel map), scored on
    the undistorted frame's reference: measured 4.93 / 13.66 deg against 2.14 / 10.58."""
    (f,) = list(dn.datasets.open(DATA / "azure_kinect_tof"))
    ref = plane_reference(f.depth, f.K, threshold=sensor_threshold(f.meta), hypotheses=64)
    ignored = score_planes(bench._lens_ignored(f, "3f2n+"), ref)
    undone = score_planes(bench._facing(dn.estimate_normals(f.depth, f.K), f.depth, f.K), ref)
    assert ignored["interior_mean"] > 1.5 * undone["interior_mean"]
    assert ignored["rim_mean"] > undone["rim_mean"]
