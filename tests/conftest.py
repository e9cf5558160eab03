"""Small shared fixtures: the shared data folder and the 3F2N torus-knot frame."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` beside the repository; the test is skipped when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared data folder {SHARED_DATA} is absent")
    return SHARED_DATA


@pytest.fixture(scope="session")
def torusknot(shared_data):
    """The one frame of the 3F2N torus-knot scene, read with ``read_3f2n`` (default options)."""
    from depthnormals.datasets import read_3f2n

    folder = shared_data / "3f2n-torusknot"
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent")
    frames = list(read_3f2n(folder))
    assert len(frames) == 1
    return frames[0]
