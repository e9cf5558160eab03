"""The torch path's shared helpers against the loops they replace: ``first_least`` (the
running minimum of the numba kernels' ``if v < best`` over candidates in order, taken a chunk
at a time on an accelerator) and ``shifted_views`` (a map read at offsets, fill outside)."""

from __future__ import annotations

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from depthnormals.torch._common import first_least, shift, shifted_views

# few distinct values, so equal candidates (ties) are common; NaN and inf among them
VALUES = st.sampled_from([0.0, 1.0, 1.0, 2.0, -1.0, float("inf"), float("nan")])


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 9), st.integers(1, 9), st.data())
def test_first_least_a_chunk_at_a_time_is_the_loop(k, chunk, data):
    """Any chunking of K candidates gives the sequential loop's minimum and first index
    (NaN never taken, a tie kept by the earlier candidate, within and across chunks), from any
    running minimum so far (NaN included: then nothing is taken, as ``v < NaN`` is false)."""
    n = 5
    vals = torch.tensor(data.draw(st.lists(VALUES, min_size=k * n, max_size=k * n)),
                        dtype=torch.float64).reshape(k, n)
    start_least = torch.tensor(data.draw(st.lists(VALUES, min_size=n, max_size=n)), dtype=torch.float64)
    start_index = torch.full((n,), -1, dtype=torch.long)
    least, index = start_least.clone(), start_index.clone()
    for j in range(k):  # the loop
        take = vals[j] < least
        least = torch.where(take, vals[j], least)
        index = torch.where(take, j, index)
    got_least, got_index = start_least.clone(), start_index.clone()
    for j0 in range(0, k, chunk):
        got_least, got_index = first_least(vals[j0:j0 + chunk], got_least, got_index, j0)
    assert torch.equal(got_index, index)
    assert torch.equal(torch.nan_to_num(got_least, nan=7.0), torch.nan_to_num(least, nan=7.0))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.integers(-3, 3), st.integers(-3, 3)), min_size=1, max_size=6),
       st.integers(2, 6), st.integers(2, 7))
def test_shifted_views_read_the_map_at_each_offset(offsets, h, w):
    """``out[k][..., v, u] = x[..., v + dv, u + du]`` inside, the fill outside, for every
    offset at once, as ``shift`` reads one; the leading dimensions are kept."""
    x = torch.arange(2 * h * w, dtype=torch.float64).reshape(2, h, w)
    views = shifted_views(x, offsets, -1.0)
    for (dv, du), got in zip(offsets, views, strict=True):
        want = np.full((2, h, w), -1.0)
        for v in range(h):
            for u in range(w):
                if 0 <= v + dv < h and 0 <= u + du < w:
                    want[:, v, u] = x[:, v + dv, u + du].numpy()
        np.testing.assert_array_equal(got.numpy(), want)
        assert torch.equal(shift(x, dv, du, -1.0), got)
