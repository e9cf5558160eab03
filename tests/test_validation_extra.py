"""Intrinsics given as sequences must hold real numbers: no silent coercion."""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn


@pytest.mark.parametrize("K", [(100, 100, "2", 2), (100, 100, True, 2), np.array([1.0, 1.0, 0.0, 0.0]) > 0])
def test_intrinsics_reject_strings_and_booleans(K):
    with pytest.raises(TypeError, match="real numbers"):
        dn.as_intrinsics(K)


def test_intrinsics_accept_integer_sequences():
    assert dn.as_intrinsics((100, 90, 2, 3)) == dn.Intrinsics(100.0, 90.0, 2.0, 3.0)


def test_atomic_writes_get_the_usual_permissions(tmp_path):
    import os
    import stat

    from depthnormals.io import write_bytes_atomic

    mask = os.umask(0o022)
    try:
        write_bytes_atomic(tmp_path / "a.bin", b"x")
    finally:
        os.umask(mask)
    assert stat.S_IMODE((tmp_path / "a.bin").stat().st_mode) == 0o644
