"""discontinuity_share: exact counts on analytic step, box, crease and hole frames."""

from __future__ import annotations

import json

import numpy as np
import pytest

from depthnormals.evaluate import discontinuity_share, synth_discontinuity_shares

FACING = (0.0, 0.0, -1.0)


def _flat(h: int, w: int, z: float = 2.0):
    n = np.zeros((h, w, 3))
    n[...] = FACING
    return n, np.full((h, w), z), np.ones((h, w), bool)


def test_step_share_is_six_columns():
    # an occlusion between columns 9 and 10: edge columns 9, 10, dilated by 2 -> 7..12
    n, z, v = _flat(8, 20)
    z[:, 10:] = 2.5
    assert discontinuity_share(n, z, v) == pytest.approx(6 / 20, abs=0)
    # radius 1 -> columns 8..11
    assert discontinuity_share(n, z, v, radius=1) == pytest.approx(4 / 20, abs=0)
    # a 4 % jump is under the 5 % threshold, a 6 % one over it
    z[:, 10:] = 2.08
    assert discontinuity_share(n, z, v) == 0.0
    z[:, 10:] = 2.12
    assert discontinuity_share(n, z, v) == pytest.approx(6 / 20, abs=0)


def test_box_on_plane_exact_count():
    # a 10 x 12 box (rows 10..19, cols 14..25) standing out of a plane: the near region is the
    # box outline dilated by 2 px, counted in closed form:
    # (R+6)(C+4) + (R+4)(C+6) - (R+4)(C+4) - (R-6)(C-6) = 256 + 252 - 224 - 24 = 260
    n, z, v = _flat(30, 40)
    z[10:20, 14:26] = 1.5
    near_expected = 260
    assert discontinuity_share(n, z, v) * 1200 == pytest.approx(near_expected, abs=1e-9)


def test_crease_counts_and_sign_is_ignored():
    # a 30-degree crease between columns 9 and 10 with continuous depth
    n, z, v = _flat(6, 20)
    n[:, 10:] = (np.sin(np.radians(30)), 0.0, -np.cos(np.radians(30)))
    assert discontinuity_share(n, z, v) == pytest.approx(6 / 20, abs=0)
    # 9 degrees is under the 10-degree threshold
    n[:, 10:] = (np.sin(np.radians(9)), 0.0, -np.cos(np.radians(9)))
    assert discontinuity_share(n, z, v) == 0.0
    assert discontinuity_share(n, z, v, edge_angle=8.0) == pytest.approx(6 / 20, abs=0)


def test_invalid_neighbours_count_and_are_not_counted():
    # columns 0..4 invalid: the silhouette column 5 is an edge pixel; near = columns 5..7 of
    # the 15 valid columns; the invalid pixels are in neither count
    n, z, v = _flat(6, 20)
    v[:, :5] = False
    z[:, :5] = 0.0
    assert discontinuity_share(n, z, v) == pytest.approx(3 / 15, abs=0)
    # no valid pixel at all: NaN
    assert np.isnan(discontinuity_share(n, z, np.zeros_like(v)))


def test_bad_input_is_refused():
    n, z, v = _flat(4, 5)
    with pytest.raises(TypeError, match="boolean"):
        discontinuity_share(n, z, v.astype(np.uint8))
    with pytest.raises(ValueError, match="edge_angle"):
        discontinuity_share(n, z, v, edge_angle=120.0)
    with pytest.raises(ValueError, match="must match"):
        discontinuity_share(n, z[:, :4], v)


def test_synth_dataset_shares_match_the_frames(tmp_path):
    from depthnormals.synth import generate

    generate(tmp_path, indoor=1, outdoor=1, views=2, size=(48, 64), K=(36.5, 36.5, 31.5, 23.5),
             noise=("gaussian",), progress=False)
    shares = synth_discontinuity_shares(tmp_path)
    assert [s.scene for s in shares] == json.loads((tmp_path / "dataset.json").read_text())["scenes"]
    s = shares[0]
    sdir = tmp_path / s.scene
    for k, name in enumerate(("0000.npy", "0001.npy")):
        n, z, v = (np.load(sdir / sub / name) for sub in ("normals", "clean", "valid"))
        assert s.frames[k] == discontinuity_share(n, z, v)
        assert 0.0 < s.frames[k] < 1.0
    assert min(s.frames) <= s.pooled <= max(s.frames)
    assert [x.kind for x in shares] == ["indoor", "outdoor"]
    noisy = synth_discontinuity_shares(tmp_path, variant="gaussian", max_views=1)
    assert len(noisy[0].frames) == 1
    with pytest.raises(ValueError, match="variant"):
        synth_discontinuity_shares(tmp_path, variant="kinect_v9")
    with pytest.raises(ValueError, match="max_views"):
        synth_discontinuity_shares(tmp_path, max_views=0)
    with pytest.raises(FileNotFoundError):
        synth_discontinuity_shares(tmp_path / "nothing")
