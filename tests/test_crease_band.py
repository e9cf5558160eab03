"""``depthnormals.evaluate.crease_band``: the pixels by the creases of a frame's reference
planes, each against the face it sees by geometry (concave: the nearer plane, convex: the
farther)."""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import Box, Plane, Scene, box_on_floor, demo_room, stairs
from depthnormals.evaluate import CreaseBand, crease_band, plane_reference, score_creases


def _band(scene, **kw):
    r = scene.render()
    ref = plane_reference(r.depth, r.K, min_fraction=0.005)
    return r, ref, crease_band(r.depth, r.K, ref, **kw)


@pytest.mark.parametrize("make", [box_on_floor, stairs, demo_room])
def test_band_takes_the_face_each_pixel_sees(make):
    """On exact renders the band's normal is the exact one: within 4 deg (the reference planes'
    own fit: one riser of the stairs is 3 deg off, the rest within 0.3) on at least 98 % of its
    pixels a pixel or more off the crease line (measured 99.2-99.9 %), the other face (over 30
    deg off) on at most 1 % (the ends of a crease, where a third face begins). Reading a convex
    crease as concave (the nearer plane by a desk's edge) or the reverse gives the other face on
    half the band."""
    r, _, band = _band(make())
    on = band.mask & (band.distance >= 1.0)
    assert on.sum() > 1000
    err = dn.angular_error(band.normals.astype(np.float32), r.normals)[on]
    assert np.mean(err < 4.0) >= 0.98
    assert np.mean(err > 30.0) <= 0.01
    # most of the band is what the plane reference leaves out or keeps only on one side
    assert np.all(np.isfinite(band.normals[band.mask]))
    assert np.all(np.isnan(band.normals[~band.mask]))


def test_stairs_hold_both_kinds_of_crease():
    """A staircase's tread meets the next riser in a concave crease and its own riser in a
    convex one: the band has both, each pair over 30 deg apart, and ``convex`` follows the
    pair."""
    _, _, band = _band(stairs())
    kinds = {p["convex"] for p in band.pairs}
    assert kinds == {True, False}
    assert all(p["angle_deg"] >= 30.0 and p["n_pixels"] > 0 for p in band.pairs)
    assert sum(p["n_pixels"] for p in band.pairs) == int(band.mask.sum())
    assert band.convex[band.mask].any() and not band.convex[band.mask].all()
    assert not band.convex[~band.mask].any()


def test_distance_is_to_the_crease_line():
    """A floor (y = 1 m) meeting a wall (z = 4 m) square to the camera: the crease projects on
    the image row ``cy + fy / 4``, so the distance is ``|v - cy - fy / 4|`` exactly; the wall
    above it, the floor below, none of it further than ``band_px``."""
    r, _, band = _band(Scene([Plane((0.0, -1.0, 0.0), -1.0), Plane((0.0, 0.0, -1.0), -4.0)]),
                         band_px=6)
    assert len(band.pairs) == 1 and band.pairs[0]["convex"] is False
    v0 = r.K.cy + r.K.fy / 4.0
    vv = np.broadcast_to(np.arange(r.depth.shape[0], dtype=float)[:, None], r.depth.shape)
    on = band.mask
    np.testing.assert_allclose(band.distance[on], np.abs(vv[on] - v0), atol=1e-6)
    assert band.distance[on].max() <= 6.0
    assert set(np.unique(np.round(vv[on] - v0))) <= set(range(-6, 7))
    wall = on & (vv < v0)
    np.testing.assert_allclose(band.normals[wall], np.broadcast_to([0.0, 0.0, -1.0], (wall.sum(), 3)),
                               atol=1e-6)
    np.testing.assert_allclose(band.normals[on & (vv > v0)][:, 1], -1.0, atol=1e-6)


def test_no_band_between_planes_that_do_not_meet():
    """A panel floating 1 m in front of a wall, tilted 45 deg, whose plane would cut the wall
    behind the panel: its edge against the wall is an occlusion, not a crease (the pixels by it
    are neither all nearer nor all farther than the other plane), so no band."""
    scene = Scene([Plane((0.0, 0.0, -1.0), -5.0),
                   Box((0.0, 0.0, 3.0), (0.8, 0.6, 0.01), (0.0, 45.0, 0.0))])
    _, ref, band = _band(scene)
    assert ref.n_planes >= 2
    assert not band.mask.any() and band.pairs == ()


def test_bad_arguments():
    r = box_on_floor().render()
    ref = plane_reference(r.depth, r.K, min_fraction=0.005)
    with pytest.raises(TypeError, match="PlaneReference"):
        crease_band(r.depth, r.K, ref.labels)
    with pytest.raises(ValueError, match="differ in shape"):
        crease_band(r.depth[:-1], r.K, ref)
    with pytest.raises(ValueError, match="band_px"):
        crease_band(r.depth, r.K, ref, band_px=0)
    assert isinstance(crease_band(r.depth, r.K, ref), CreaseBand)


def test_score_creases_near_and_far():
    """``score_creases``: the exact normals score about 0 (median) with full coverage; an
    estimate missing the 3 px by the line is scored on the rest only (coverage their share, the
    near part NaN); a normal map facing away errs 180 deg everywhere."""
    r, _, band = _band(box_on_floor())
    exact = score_creases(r.normals, band)
    assert exact["median"] < 0.1 and exact["coverage"] == 1.0 and exact["n"] == band.mask.sum()
    near = band.mask & (band.distance < 3.0)
    est = r.normals.copy()
    est[near] = np.nan
    s = score_creases(est, band)
    assert np.isnan(s["near_mean"]) and s["scored"] == int((band.mask & ~near).sum())
    assert s["coverage"] == pytest.approx(1.0 - near.sum() / band.mask.sum())
    assert s["far_mean"] == pytest.approx(exact["far_mean"])
    away = score_creases(-r.normals, band)
    assert away["median"] == pytest.approx(180.0, abs=0.1)
    with pytest.raises(TypeError, match="CreaseBand"):
        score_creases(r.normals, band.normals)
    with pytest.raises(ValueError, match="differ in shape"):
        score_creases(r.normals[:-1], band)


def test_integer_depth_and_a_frame_without_planes():
    """Millimetre depth with ``depth_scale`` gives the band of the metric depth (within a pixel
    of rounding); a frame without planes (uniform random depth) an empty band, scored as NaN
    with coverage NaN, and no warning either way."""
    import warnings

    r = box_on_floor().render()
    metric = crease_band(r.depth, r.K, plane_reference(r.depth, r.K, min_fraction=0.005))
    mm = np.round(r.depth * 1000.0).astype(np.uint16)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        band = crease_band(mm, r.K, plane_reference(mm, r.K, depth_scale=0.001, min_fraction=0.005),
                           depth_scale=0.001)
        assert abs(int(band.mask.sum()) - int(metric.mask.sum())) <= 20
        z = np.random.default_rng(0).uniform(1.0, 3.0, (120, 160))
        K = (100.0, 100.0, 79.5, 59.5)
        empty = crease_band(z, K, plane_reference(z, K))
        s = score_creases(np.zeros((120, 160, 3), np.float32), empty)
    assert not empty.mask.any() and empty.pairs == ()
    assert s["n"] == 0 and np.isnan(s["mean"]) and np.isnan(s["coverage"])
