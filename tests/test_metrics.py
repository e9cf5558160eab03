"""angular_error and normal_metrics on hand-made inputs with known answers."""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn


def vec(*rows):
    return np.asarray(rows, dtype=np.float64)[None, :, :]


def test_angular_error_exact_values():
    g = vec([0, 0, -1], [0, 0, -1], [0, 0, -1], [0, 0, -1], [1, 0, 0])
    n = vec([0, 0, -1], [0, 1, -1], [1, 0, 0], [0, 0, 1], [-1, 1e-9, 0])
    err = dn.angular_error(n, g)
    assert err.shape == (1, 5) and err.dtype == np.float64
    np.testing.assert_allclose(err[0], [0.0, 45.0, 90.0, 180.0, 180.0], atol=1e-6)
    folded = dn.angular_error(n, g, folded=True)
    np.testing.assert_allclose(folded[0], [0.0, 45.0, 90.0, 0.0, 0.0], atol=1e-6)
    # 135 folds to 45; 60 stays
    n2 = vec([0, 1, 1], [0, np.sin(np.radians(60)), -np.cos(np.radians(60))])
    g2 = vec([0, 0, -1], [0, 0, -1])
    np.testing.assert_allclose(dn.angular_error(n2, g2)[0], [135.0, 60.0], atol=1e-9)
    np.testing.assert_allclose(dn.angular_error(n2, g2, folded=True)[0], [45.0, 60.0], atol=1e-9)


def test_angular_error_is_accurate_near_zero():
    """atan2, not acos: a 1e-4 deg error is resolved (acos would give 0 or ~0.02 deg)."""
    a = np.radians(1e-4)
    n = vec([np.sin(a), 0, -np.cos(a)]).astype(np.float32)
    g = vec([0, 0, -1]).astype(np.float32)
    assert dn.angular_error(n, g)[0, 0] == pytest.approx(1e-4, rel=1e-2)


def test_renormalisation_and_symmetry():
    n = vec([0, 0, -7], [0, 3, -3], [0.2, 0, 0])
    g = vec([0, 0, -0.5], [0, 0, -100], [5, 0, 0])
    np.testing.assert_allclose(dn.angular_error(n, g)[0], [0, 45, 0], atol=1e-9)
    np.testing.assert_allclose(dn.angular_error(g, n), dn.angular_error(n, g), atol=1e-12)


def test_nan_handling():
    n = vec([np.nan, 0, -1], [0, 0, 0], [0, 0, -1], [0, 0, -1], [np.inf, 0, -1])
    g = vec([0, 0, -1], [0, 0, -1], [np.nan, np.nan, np.nan], [0, 0, 0], [0, 0, -1])
    err = dn.angular_error(n, g)
    assert np.isnan(err).all()
    assert np.isnan(dn.angular_error(n, g, folded=True)).all()


def test_inputs_are_not_modified_and_lists_work():
    n = vec([0, 0, -2])
    before = n.copy()
    dn.angular_error(n, n)
    np.testing.assert_array_equal(n, before)
    assert dn.angular_error([[[0, 0, -1]]], [[[0, 1, 0]]])[0, 0] == pytest.approx(90.0)


def _example():
    """Six pixels with errors 0, 3, 10, 20, 40 deg, one NaN estimate, one invalid truth."""
    angles = [0.0, 3.0, 10.0, 20.0, 40.0, 0.0, 0.0]
    g = np.zeros((1, 7, 3))
    g[..., 2] = -1.0
    n = np.stack([np.zeros(7), np.sin(np.radians(angles)), -np.cos(np.radians(angles))], -1)[None]
    n[0, 5] = np.nan           # no estimate: counts against coverage
    g[0, 6] = np.nan           # no truth: never scored
    return n, g


def test_normal_metrics_values():
    n, g = _example()
    m = dn.normal_metrics(n, g)
    e = np.array([0.0, 3.0, 10.0, 20.0, 40.0])
    assert m.count == 5
    assert m.mean == pytest.approx(e.mean())
    assert m.median == pytest.approx(10.0)
    assert m.rmse == pytest.approx(np.sqrt(np.mean(e ** 2)))
    assert (m.a5, m.a11_25, m.a22_5, m.a30) == pytest.approx((0.4, 0.6, 0.8, 0.8))
    assert m.coverage == pytest.approx(5 / 6)
    d = m.as_dict()
    assert set(d) == {"mean", "median", "rmse", "a5", "a11_25", "a22_5", "a30", "coverage",
                      "count"}
    assert d["median"] == pytest.approx(10.0)


def test_normal_metrics_mask_and_folding():
    n, g = _example()
    mask = np.array([[True, True, False, False, True, True, True]])
    m = dn.normal_metrics(n, g, mask=mask)
    assert m.count == 3 and m.mean == pytest.approx((0 + 3 + 40) / 3)
    assert m.coverage == pytest.approx(3 / 4)
    flipped = -n
    assert dn.normal_metrics(flipped, g).mean == pytest.approx(180 - (0 + 3 + 10 + 20 + 40) / 5)
    assert dn.normal_metrics(flipped, g, folded=True).mean == pytest.approx(73 / 5)


def test_normal_metrics_nothing_scored():
    n, g = _example()
    m = dn.normal_metrics(n, g, mask=np.zeros((1, 7), bool))
    assert m.count == 0 and m.coverage == 0.0 and np.isnan(m.mean) and np.isnan(m.median)
    m = dn.normal_metrics(np.full((2, 2, 3), np.nan), np.full((2, 2, 3), 1.0))
    assert m.count == 0 and m.coverage == 0.0


def test_mask_errors():
    n, g = _example()
    with pytest.raises(ValueError, match="mask has shape"):
        dn.normal_metrics(n, g, mask=np.ones((7, 1), bool))
    with pytest.raises(TypeError, match="boolean"):
        dn.normal_metrics(n, g, mask=np.ones((1, 7), np.uint8))
    with pytest.raises(ValueError, match="mask has shape"):
        dn.normal_metrics(n, g, mask=np.ones(7, bool))


def test_bad_normal_maps():
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        dn.angular_error(np.zeros((4, 3)), np.zeros((4, 3)))
    with pytest.raises(TypeError, match="real"):
        dn.angular_error(np.zeros((2, 2, 3), complex), np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match="empty"):
        dn.normal_metrics(np.zeros((0, 2, 3)), np.zeros((0, 2, 3)))
