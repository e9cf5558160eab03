"""Invalid pixels in the comparison family: NaN there, never poisoning valid neighbours."""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import make_scene

FAMILY = ("sda-sne", "sne-roadseg", "fals", "sri", "line-mod", "plane-svd", "plane-pca",
          "vector-svd", "area-weighted", "angle-weighted")
K = (131.25, 131.25, 79.5, 59.5)
# exact methods (a plane fit) stay exact next to holes; derivative methods lose a little
TOL = {"sda-sne": 0.2, "sri": 0.3, "line-mod": 0.5}


@pytest.fixture(scope="module")
def holed():
    r = make_scene("tilted-plane").render(K=K, shape=(120, 160))
    depth = r.depth.copy()
    depth[50:60, 70:85] = 0.0        # a hole
    depth[20, 30] = np.nan           # a NaN pixel
    depth[90, 40:44] = -1.0          # negative depth
    depth[100, 120] = np.inf
    return depth, r.normals


@pytest.mark.parametrize("method", FAMILY)
def test_invalid_gives_nan_and_neighbours_stay_accurate(holed, method):
    depth, gt = holed
    # LINE-MOD's depth threshold would also drop steep samples here: test holes only
    opts = {"threshold": 100.0} if method == "line-mod" else {}
    n = dn.estimate_normals(depth, K, method=method, **opts)
    bad = ~(np.isfinite(depth) & (depth > 0))
    assert np.isnan(n[bad]).all()
    # the ring of valid pixels around the hole
    ring = np.zeros(depth.shape, bool)
    ring[49:61, 69:86] = True
    ring &= ~bad
    assert ring.sum() == 12 * 17 - 150
    err = dn.angular_error(n, gt)
    assert not np.isnan(err[ring]).any()
    assert err[ring].max() < TOL.get(method, 1e-3)
    assert not np.isnan(n[~bad]).any()   # every valid pixel of a plane gets an estimate


@pytest.mark.parametrize("method", FAMILY)
def test_isolated_pixel_is_nan(method):
    depth = np.zeros((15, 15))
    depth[7, 7] = 2.0
    with pytest.warns(dn.NoValidNormalWarning):
        n = dn.estimate_normals(depth, K, method=method)
    assert np.isnan(n).all()


@pytest.mark.parametrize(("method", "opts", "exc"), [
    ("plane-svd", {"window": 4}, ValueError),
    ("vector-svd", {"window": "3"}, TypeError),
    ("fals", {"window": 1}, ValueError),
    ("sri", {"window": 13}, ValueError),
    ("line-mod", {"threshold": 0.0}, ValueError),
    ("line-mod", {"window": True}, TypeError),
    ("sda-sne", {"iterations": -1}, ValueError),
    ("sda-sne", {"iterations": 1.5}, TypeError),
])
def test_bad_options(method, opts, exc):
    with pytest.raises(exc):
        dn.estimate_normals(np.full((8, 8), 2.0), K, method=method, **opts)


def test_sda_sne_iterations_zero_is_the_initial_choice():
    r = make_scene("box-on-floor").render(K=K, shape=(120, 160))
    a = dn.sda_sne(r.depth, r.K, iterations=0)
    b = dn.sda_sne(r.depth, r.K, iterations=3)
    assert np.isfinite(a[..., 0]).sum() == np.isfinite(b[..., 0]).sum()
    assert np.nanmax(dn.angular_error(a, b)) > 1.0   # the DP moves pixels near creases
