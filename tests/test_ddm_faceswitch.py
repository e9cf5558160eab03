"""The face switch of the measured support (depthnormals.ddm.faceswitch): a cell by a crease takes
the face whose plane explains its own 3x3 clearly better.

Against a plain numpy reference of the rule (tests/faceswitch_reference.py), on analytic scenes
whose faces are known, and its conventions (occlusions left alone, planes untouched, the
decisions the uncertainty map reads)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import make_scene
from depthnormals.ddm import faceswitch, support
from depthnormals.kernels.depth import prepare
from depthnormals.synth.noise import kinect_v1_noise, realsense_d4xx_noise
from faceswitch_reference import _shift, reference_switch

K = (262.5, 262.5, 159.5, 119.5)
CAM = (262.5, 262.5, 159.5, 119.5)


def _frame(scene: str, model, seed: int = 0):
    r = make_scene(scene).render(K=K, shape=(240, 320))
    d = np.asarray(model(r.depth, r.normals, K, rng=np.random.default_rng(seed)), np.float32)
    z, _ = prepare(d, K, None)
    return r, z


def _switch_inputs(scene, model):
    """What the default's branch hands the face switch on a frame of ``scene`` under the
    sensor ``model``: its depth grid, its chosen normals (before the switch), the camera of
    that grid and the keyword options."""
    _, z = _frame(scene, model)
    captured = {}
    orig = support.switch_faces

    def spy(zz, n, *a, **k):
        captured["args"] = (zz.copy(), n.copy(), a, k)
        return orig(zz, n, *a, **k)

    support.switch_faces = spy
    try:
        dn.estimate_normals(z, K)
    finally:
        support.switch_faces = orig
    return captured["args"]


@pytest.mark.parametrize("scene, model", [("box-on-floor", kinect_v1_noise),
                                          ("stairs", realsense_d4xx_noise),
                                          ("demo-room", kinect_v1_noise)])
def test_agrees_with_the_numpy_reference(scene, model):
    """The default's own chosen normals (before the switch) switched by both: the same cells
    and the same normals (the kernel's pre-test and its ring change nothing); some cells
    switch, a few per cent at most."""
    zz, n, a, k = _switch_inputs(scene, model)
    got, mask, dec = faceswitch.switch_faces(zz, n.copy(), *a, span=k["span"], decisions=True)
    ref, ref_mask = reference_switch(zz, n, a, k["span"])
    assert 0 < mask.sum() < 0.05 * mask.size
    assert (mask == ref_mask).mean() > 0.9995  # exact ties may round either way
    both = mask == ref_mask
    assert np.array_equal(got[both], ref[both], equal_nan=True)
    # the decisions: where a cell saw another face; it switched exactly where log(other /
    # same) is below log(MARGIN), and the angle to the other face exceeds ANGLE
    seen = np.isfinite(dec[0])
    assert (mask <= seen).all()
    assert np.array_equal(mask[seen], dec[0][seen] < math.log(faceswitch.MARGIN))
    assert (dec[1][seen] > faceswitch.ANGLE - 1e-3).all()
    assert np.isnan(dec[1][~seen]).all()


def test_the_decisions_agree_with_the_numpy_reference():
    """What the map reads of the switch: where a cell saw another face, ``log(other / same)``
    over every candidate plane of both faces, and the angle to the other face; against the
    reference's (direct sums, every plane read): the same cells, the logarithms within 1e-6
    (the fits' sums rounded in another order), the angles within 1e-3 deg (float32 normals)."""
    zz, n, a, k = _switch_inputs("demo-room", kinect_v1_noise)
    _, _, dec = faceswitch.switch_faces(zz, n.copy(), *a, span=k["span"], decisions=True)
    _, _, log, theta = reference_switch(zz, n, a, k["span"], decisions=True)
    seen = np.isfinite(dec[0])
    assert seen.sum() > 0.05 * seen.size  # a fifth of the cells of a Kinect frame, about
    np.testing.assert_array_equal(seen, np.isfinite(log))
    np.testing.assert_allclose(dec[0][seen], log[seen], rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(dec[1][seen], theta[seen], rtol=0.0, atol=1e-3)


def test_a_carried_face_goes_back():
    """Clean depth, exact normals, then the normals of the cells within 3 px below a crease
    replaced by the face above it: most carried cells take their own face again, exactly, and
    few others move (a cell beside the band whose candidate cell carries the wrong face:
    measured 314 of 3906 switches on the stairs, the mean error 6.84 -> 3.00 deg)."""
    r = make_scene("stairs").render(K=K, shape=(240, 320))
    z, _ = prepare(r.depth.astype(np.float32), K, None)
    exact = r.normals.astype(np.float32)
    bad = exact.copy()
    carried = np.zeros(z.shape, dtype=bool)
    cos = np.cos(np.radians(30.0))
    for dv in range(1, 4):  # the face above carried down dv rows, where it differs
        up = np.full_like(exact, np.nan)
        up[dv:] = exact[:-dv]
        differ = np.isfinite(up).all(-1) & ((up * exact).sum(-1) < cos) & ~carried
        # only where the rows between are the face above (a crease dv rows up)
        bad[differ] = up[differ]
        carried |= differ
    out, mask, _ = faceswitch.switch_faces(z, bad.copy(), *CAM)
    err_before = dn.angular_error(bad, exact)
    err_after = dn.angular_error(out, exact)
    # the cells whose own 3x3 and span-neighbours lie on their own face come back exactly
    fixed = mask & carried
    assert fixed.sum() > 0.5 * carried.sum()
    assert np.nanmax(err_after[fixed]) < 1e-3
    assert np.nanmean(err_after[carried]) < 0.5 * np.nanmean(err_before[carried])
    assert np.nanmean(err_after) < 0.5 * np.nanmean(err_before)
    assert (mask & ~carried).sum() < 0.1 * fixed.sum()


@pytest.mark.parametrize("scene", ["tilted-plane", "box-on-floor", "stairs",
                                   "sphere-before-wall", "demo-room"])
def test_exact_normals_move_only_on_the_crease_line(scene):
    """Exact normals of clean depth: a cell switches only where its 3x3 straddles the crease
    (holds another face's exact normal; there the two faces' planes fit the 3x3's points about
    alike, and the pixel's own face is the one its centre saw), never by a depth jump (the
    sphere's rim before the wall) and never on a face's interior: a plane has none."""
    r = make_scene(scene).render(K=K, shape=(240, 320))
    z, _ = prepare(r.depth.astype(np.float32), K, None)
    exact = r.normals.astype(np.float32)
    out, mask, _ = faceswitch.switch_faces(z, exact.copy(), *CAM)
    straddle = np.zeros(z.shape, dtype=bool)
    jump = np.zeros(z.shape, dtype=bool)
    cos = np.cos(np.radians(faceswitch.ANGLE))
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            sn = _shift(exact, dv, du)
            sz = _shift(z, dv, du)
            with np.errstate(invalid="ignore"):
                straddle |= (sn * exact).sum(-1) < cos
                jump |= np.abs(sz - z) > faceswitch.JUMP * z
    assert not (mask & ~straddle).any()
    assert not (mask & jump).any()
    assert mask.sum() <= 0.5 * straddle.sum()
    if scene == "tilted-plane":
        assert not mask.any() and np.array_equal(out, exact, equal_nan=True)


def test_invalid_depth_and_no_normal():
    """Cells without depth or without a normal neither switch nor lend their normal; a cell of
    the half grid that has a normal but no depth (the choice fills them) keeps it."""
    r = make_scene("box-on-floor").render(K=K, shape=(240, 320))
    z, _ = prepare(r.depth.astype(np.float32), K, None)
    n = r.normals.astype(np.float32)
    z2 = z.copy()
    z2[100:120, 100:140] = np.nan  # a hole whose cells keep (filled) normals
    n2 = n.copy()
    n2[50:60, 200:220] = np.nan  # cells with depth and no normal
    out, mask, dec = faceswitch.switch_faces(z2, n2.copy(), *CAM, decisions=True)
    assert not mask[100:120, 100:140].any() and not mask[50:60, 200:220].any()
    assert np.array_equal(out[100:120, 100:140], n2[100:120, 100:140])
    assert np.isnan(out[50:60, 200:220]).all()
    assert np.isnan(dec[:, 100:120, 100:140]).all()


def test_the_default_on_a_kinect_crease_improves():
    """The default on the Kinect v1 model of the box and the stairs at 320x240: its mean error
    by the creases (within 4 px of adjacent exact normals over 30 deg apart, the depth
    continuous between them) is lower with the switch than without (measured: 34.93 -> 33.16
    deg; on the real frames' crease bands the gain is larger, docs/benchmarks.md 22)."""
    errs = []
    for switch in (False, True):
        total = []
        for scene in ("box-on-floor", "stairs"):
            r, z = _frame(scene, kinect_v1_noise, seed=3)
            orig = support.switch_faces
            if not switch:
                support.switch_faces = lambda zz, n, *a, **k: (n, np.zeros(zz.shape, bool), None)
            try:
                out = dn.estimate_normals(z, K)
            finally:
                support.switch_faces = orig
            g = r.normals
            crease = np.zeros(z.shape, dtype=bool)
            for ax in (0, 1):
                a = np.swapaxes(g, 0, ax)
                c0 = np.swapaxes(r.depth, 0, ax)
                with np.errstate(invalid="ignore"):
                    d = (((a[1:] * a[:-1]).sum(-1) < np.cos(np.radians(30.0)))
                         & (np.abs(c0[1:] - c0[:-1]) < 0.02 * c0[1:]))
                c = np.zeros(a.shape[:2], dtype=bool)
                c[1:] |= d
                c[:-1] |= d
                crease |= np.swapaxes(c, 0, ax)
            near = crease.copy()
            for _ in range(4):
                near[1:] |= near[:-1]
                near[:-1] |= near[1:]
                near[:, 1:] |= near[:, :-1]
                near[:, :-1] |= near[:, 1:]
            e = dn.angular_error(out, g)
            total.append(np.nanmean(e[near & np.isfinite(e)]))
        errs.append(np.mean(total))
    assert errs[1] < 0.97 * errs[0], errs


def test_log_acos_equal_libm_once_rounded_to_float32():
    """The decisions' logarithm and arc cosine, computed in loops without a call or a branch
    (series on the mantissa and on the half angle), agree with libm within a few units in
    the last place of float64, hence equal once stored as float32; zeros, infinities, NaN and
    cosines past +-1 (clipped) as libm reads them."""
    rng = np.random.default_rng(5)
    ratio = np.exp(rng.uniform(-40.0, 40.0, 200_000))
    ratio[:8] = [1e-300, 1.0, 0.5, 2.0, np.sqrt(2.0), 0.0, np.inf, np.nan]
    dot = rng.uniform(-1.0, 1.0, ratio.size).astype(np.float32).astype(np.float64)
    dot[:8] = [1.0, -1.0, 0.0, 0.5, -0.5, np.nextafter(0.5, 1.0), 1.5, np.nan]
    n = ratio.size
    logs, degs = np.empty(n), np.empty(n)
    faceswitch._log_acos(n, ratio, dot, np.empty(n, np.int64), logs, degs)
    with np.errstate(divide="ignore", invalid="ignore"):
        want_log = np.log(ratio)
    want_deg = np.degrees(np.arccos(np.clip(dot, -1.0, 1.0)))
    for got, want in ((logs, want_log), (degs, want_deg)):
        np.testing.assert_array_equal(got.astype(np.float32), want.astype(np.float32))
        ok = np.isfinite(want) & (want != 0.0)
        ulps = np.abs(got[ok] - want[ok]) / np.spacing(np.abs(want[ok]))
        assert ulps.max() <= 4.0
    assert logs[5] == -np.inf and logs[6] == np.inf and np.isnan(logs[7]) and np.isnan(degs[7])
    assert degs[0] == 0.0 and degs[1] == pytest.approx(180.0) and degs[6] == 0.0
