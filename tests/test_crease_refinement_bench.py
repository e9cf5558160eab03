"""benchmarks/crease_refinement.py: the prototype of a crease rule for the noisy branches
(each pixel by a crease takes the face whose plane explains its own 3x3)."""

from __future__ import annotations

import numpy as np
import pytest

from depthnormals.analytic import Plane, Scene


@pytest.fixture(scope="module")
def bench(load_benchmark):
    return load_benchmark("crease_refinement")


def _floor_and_wall(noise_m: float, seed: int = 0):
    """A floor (y = 1 m) meeting a wall (z = 4 m); the crease on row cy + fy / 4 (370.75)."""
    r = Scene([Plane((0.0, -1.0, 0.0), -1.0), Plane((0.0, 0.0, -1.0), -4.0)]).render()
    rng = np.random.default_rng(seed)
    depth = r.depth + noise_m * rng.standard_normal(r.depth.shape)
    return r, depth.astype(np.float32)


@pytest.mark.parametrize("half", [False, True])
def test_a_crease_placed_rows_off_moves_back(bench, half):
    """The wall's last five rows above the crease carrying the floor's normal (a crease placed
    five rows too high, as the windows of the default place real ones) take the wall's again
    with 1 mm of depth noise, all but the row by the line (0.75 px: its 3x3 holds the floor's
    row, a tie the rule leaves as it is); rows eight or more from the crease keep their
    normals. The same on every second row and column (``--half``: rows 366-369 take their
    cells' switch)."""
    r, depth = _floor_and_wall(0.001)
    v0 = r.K.cy + r.K.fy / 4.0
    rows = np.arange(depth.shape[0])[:, None] + np.zeros(depth.shape[1], int)[None, :]
    est = r.normals.astype(np.float32).copy()
    wrong = (rows > v0 - 5) & (rows < v0)
    est[wrong] = r.normals[rows > v0][0]
    out, switch = (bench.refine_half if half else bench.refine)(depth, r.K, est)
    clear = (wrong & (rows < v0 - 1))[:, 8:-8]
    fixed = np.abs(out[:, 8:-8][clear] - r.normals[:, 8:-8][clear]).max(-1) < 1e-6
    assert clear.sum() == 4 * (depth.shape[1] - 16) and fixed.all()
    far = np.abs(rows - v0) >= 8
    np.testing.assert_array_equal(out[far], est[far])
    assert switch[:, 8:-8][clear].all() and not switch[far].any()


def test_one_plane_never_switches(bench):
    """On a single noisy plane every candidate lies on the pixel's own face: nothing switches."""
    r = Scene([Plane((0.2, -0.3, -1.0 / np.sqrt(1.13)), -3.0)]).render()
    depth = (r.depth + 0.003 * np.random.default_rng(1).standard_normal(r.depth.shape)).astype(np.float32)
    est = r.normals.astype(np.float32)
    out, switch = bench.refine(depth, r.K, est)
    assert not switch.any()
    np.testing.assert_array_equal(out, est)


def test_tile_lower_median(bench):
    """Per tile the lower median of its finite values (the frame's where a tile has none)."""
    a = np.arange(64, dtype=float).reshape(8, 8)
    a[:4, 4:] = np.nan
    m = bench._tile_lower_median(a, 4)
    assert m[0, 0] == np.sort(a[:4, :4].ravel())[7]
    finite = np.sort(a[np.isfinite(a)])
    assert m[0, 5] == finite[(finite.size - 1) // 2]
    assert m[5, 5] == np.sort(a[4:, 4:].ravel())[7]


def test_measured_only_leaves_the_iid_branch(bench):
    """``--measured-only`` leaves a frame of the i.i.d. branch (1 mm of independent noise) as
    it is, even where the rule would move a misplaced crease back."""
    r, depth = _floor_and_wall(0.001)
    v0 = r.K.cy + r.K.fy / 4.0
    rows = np.arange(depth.shape[0])[:, None] + np.zeros(depth.shape[1], int)[None, :]
    est = r.normals.astype(np.float32).copy()
    est[(rows > v0 - 5) & (rows < v0)] = r.normals[rows > v0][0]
    same, none = bench._apply(depth, r.K, est, measured_only=True)
    assert not none.any()
    np.testing.assert_array_equal(same, est)
