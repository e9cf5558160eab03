"""The share of a depth's jumps drawn through mixed pixels (:mod:`depthnormals.ddm.flying`)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from depthnormals.analytic import make_scene
from depthnormals.ddm.flying import INSIDE, MIN_JUMPS, mixed_share
from depthnormals.synth.noise import gaussian_noise, tof_noise


def _step(h=40, w=60, near=1.0, far=2.0, col=30):
    z = np.full((h, w), far, dtype=np.float32)
    z[:, :col] = near
    return z


def test_a_clean_step_reads_no_mixed_pixel_and_one_between_reads_all():
    """A wall before a wall, one jump per row: drawn in one pixel 0; with the column at the
    step halfway between the sides (a flying pixel), every jump is mixed; a column at 0.1 or
    0.9 of the step lies outside :data:`INSIDE` (the pixel sees one side)."""
    z = _step()
    assert mixed_share(z) == 0.0
    for t, want in ((0.5, 1.0), (0.3, 1.0), (0.1, 0.0), (0.9, 0.0)):
        y = z.copy()
        y[:, 30] = 1.0 + t  # between the near side (1 m, columns < 30) and the far one (2 m)
        assert INSIDE[0] < 0.3 and INSIDE[1] > 0.7
        assert mixed_share(y) == want, t
    # half the rows mixed: half the jumps
    y = z.copy()
    y[::2, 30] = 1.5
    assert mixed_share(y) == pytest.approx(0.5)


def test_columns_count_as_rows_do_and_slopes_are_not_jumps():
    """The same step turned a quarter reads the same; a ramp whose every step passes the
    relative test (3 %) has no flat side: no jump counted, so no reading (NaN), as on a
    plane."""
    y = _step()
    y[:, 30] = 1.5
    assert mixed_share(np.ascontiguousarray(y.T)) == 1.0
    ramp = np.tile(1.0 * 1.05 ** np.arange(60, dtype=np.float32), (40, 1))
    assert math.isnan(mixed_share(ramp))
    assert math.isnan(mixed_share(np.full((40, 60), 2.0, np.float32)))


def test_too_few_jumps_or_invalid_sides_give_no_reading():
    """Fewer than :data:`MIN_JUMPS` counted jumps: NaN; a NaN anywhere in the five depths
    leaves that jump out (a hole beside a step is no side)."""
    z = _step(h=MIN_JUMPS - 1)
    assert math.isnan(mixed_share(z))
    z = _step(h=MIN_JUMPS)
    assert mixed_share(z) == 0.0
    z = _step()
    z[:, 30] = 1.5
    z[:10, 28] = np.nan  # these rows' near side is not flat: not counted
    z[10:20, 30] = np.nan  # no middle pixel: not counted
    assert mixed_share(z) == 1.0
    z[20:, 30] = 1.0  # the rest clean
    assert mixed_share(z) == 0.0


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="2-D"):
        mixed_share(np.ones((2, 3, 4), np.float32))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), k=st.integers(-8, 8))
def test_the_share_is_a_share_and_depends_on_relative_depth_only(seed, k):
    """In [0, 1]; the same under a scale of the depth (every test is relative; a power of two
    keeps float32 exact), a flip of the image and a transposition (a step without a mixed
    pixel counts a half from each side: the same read either way). Depths 1, 1.37 and 3.1 m:
    no comparison ties at a threshold."""
    rng = np.random.default_rng(seed)
    z = rng.choice(np.array([1.0, 1.37, 3.1], np.float32), size=(30, 40)).astype(np.float32)
    z = np.repeat(z, 3, axis=1)  # runs of three: flat sides along the rows
    z[rng.random(z.shape) < 0.05] = np.nan
    s = mixed_share(z)
    assert not math.isnan(s)
    assert 0.0 < s < 1.0  # the columns' runs of one hold mixed pixels, the rows none
    assert mixed_share(z * np.float32(2.0**k)) == s
    assert mixed_share(np.ascontiguousarray(z[:, ::-1])) == s
    assert mixed_share(np.ascontiguousarray(z[::-1])) == s
    assert mixed_share(np.ascontiguousarray(z.T)) == s


def test_sensor_models_read_apart():
    """The box on the floor: Gaussian noise on the ray-cast depth keeps its one-pixel steps
    (0.0 mixed); the time-of-flight model mixes each pixel beside a jump with the other
    side's return (:func:`depthnormals.synth.noise.tof_noise`, 0.73). The synthetic
    benchmark's frames read 0.006 and 0.57 at the median."""
    r = make_scene("box-on-floor").render()
    rng = np.random.default_rng(0)
    g = gaussian_noise(r.depth, r.K, rng=rng, sigma_px=0.1)
    assert mixed_share(np.where(g > 0, g, np.nan).astype(np.float32)) < 0.02
    t = tof_noise(r.depth, r.normals, r.K, rng=rng)
    assert mixed_share(np.where(t > 0, t, np.nan).astype(np.float32)) > 0.5
