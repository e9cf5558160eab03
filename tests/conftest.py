"""Small shared fixtures: the shared data folder, the 3F2N torus-knot frame, a rough
analytic scene for the fast-path equivalence tests, a loader of the benchmark scripts and a
depth whose 3F2N normal is perpendicular to its ray (the orientation's tie)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="session")
def load_benchmark():
    """``load(name)``: the script ``benchmarks/<name>.py`` as a module (``<name>_bench``),
    loaded once per session (the scripts are not a package; those with helpers beside them
    put their folder on ``sys.path`` themselves)."""
    import importlib.util

    loaded: dict = {}

    def load(name: str):
        if name not in loaded:
            spec = importlib.util.spec_from_file_location(f"{name}_bench", BENCHMARKS / f"{name}.py")
            mod = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(mod)
            loaded[name] = mod
        return loaded[name]

    return load


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


ROUGH_K = (131.25, 131.25, 79.5, 59.5)  # the intrinsics rough_sphere renders with


@pytest.fixture(scope="session")
def rough_sphere():
    """``make(seed, sigma)``: a rough analytic depth map (see :func:`_rough_sphere`)."""
    return _rough_sphere


def _rough_sphere(seed: int, sigma: float):
    """Depth (120, 160) of the sphere before a wall at ``ROUGH_K``: Gaussian noise ``sigma``
    (m), 3 % random holes and a 7x10 hole (0 = invalid), so every branch of the row passes
    (borders, invalid neighbours, occlusions, curvature) is exercised."""
    import numpy as np

    from depthnormals.analytic import make_scene

    rng = np.random.default_rng(seed)
    z = make_scene("sphere-before-wall").render(K=ROUGH_K, shape=(120, 160)).depth.copy()
    z += rng.normal(0.0, sigma, z.shape) * (z > 0)
    z[rng.random(z.shape) < 0.03] = 0.0
    z[40:47, 60:70] = 0.0
    return z


@pytest.fixture
def two_threads():
    """The library's threads set to 2 for the test (batches spread over threads), then back."""
    import depthnormals as dn

    old = dn.get_num_threads()
    dn.set_num_threads(2)
    yield
    dn.set_num_threads(old)


def tie_depth(v: int, u: int = 4, shape=(42, 8)) -> np.ndarray:
    """Depth whose 3F2N normal at (v, u) is exactly perpendicular to the pixel's ray: left,
    up-left and up-right invalid, the pixel above and the one below-left 1 cm nearer, the rest
    level with it. The horizontal gradient is 0 and the median of the two candidates (their
    mean) makes ``n_z = -n_y (v - cy) / fy``, so ``n . ray = 0``: its sign is rounding (on
    quantised Kinect depth hundreds of pixels a frame are such ties)."""
    z = np.full(shape, 2.1)
    z[v, u - 1] = z[v - 1, u - 1] = z[v - 1, u + 1] = 0.0
    z[v - 1, u] = z[v + 1, u - 1] = 2.09
    return z


#: The intrinsics of :func:`tie_depth`.
TIE_K = (300.0, 300.0, 3.5, 20.25)
