"""FALS, SRI and LINE-MOD side by side with OpenCV's cv2.rgbd.RgbdNormals."""

from __future__ import annotations

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.analytic import make_scene, planar_interior

cv2 = pytest.importorskip("cv2")
if not hasattr(cv2, "rgbd"):
    pytest.skip("OpenCV without the contrib rgbd module", allow_module_level=True)

METHODS = {
    "fals": cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_FALS,
    "sri": cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_SRI,
    "line-mod": cv2.rgbd.RgbdNormals_RGBD_NORMALS_METHOD_LINEMOD,
}


def opencv_normals(depth: np.ndarray, K: np.ndarray, method: str) -> np.ndarray:
    d = depth.astype(np.float32)
    k = K.astype(np.float32)
    est = cv2.rgbd.RgbdNormals_create(d.shape[0], d.shape[1], cv2.CV_32F, k, 5, METHODS[method])
    if method == "line-mod":
        return est.apply(d)  # depth image input (its 3-channel path is not needed)
    return est.apply(cv2.rgbd.depthTo3d(d, k))


@pytest.fixture(scope="module")
def box():
    return make_scene("box-on-floor").render()


@pytest.mark.parametrize("method", tuple(METHODS))
def test_agrees_with_opencv_on_planar_interiors(box, method):
    r = box
    K = r.K.matrix
    # OpenCV's LINE-MOD threshold is a fixed 50 depth units: 50 m on float metres
    opts = {"threshold": 50.0} if method == "line-mod" else {}
    ours = dn.estimate_normals(r.depth.astype(np.float32), K, method=method, **opts)
    ocv = opencv_normals(r.depth, K, method)
    rad = 6 if method == "line-mod" else 3   # LINE-MOD samples at +-5 px
    m = planar_interior(r, rad)
    m[:rad + 1] = m[-rad - 1:] = False
    m[:, :rad + 1] = m[:, -rad - 1:] = False
    assert m.sum() > 100000
    # OpenCV orients by n_z <= 0, we by dot(n, X) < 0: compare folded
    diff = dn.angular_error(ours, ocv, folded=True)[m]
    assert np.isfinite(diff).all()
    assert diff.mean() < 0.5
    # and ours is the closer of the two to the exact normals there
    e_ours = dn.angular_error(ours, r.normals)[m].mean()
    e_ocv = dn.angular_error(ocv, r.normals, folded=True)[m].mean()
    assert e_ours < e_ocv


def test_next_to_a_hole_ours_stays_exact_and_opencv_fals_bends():
    r = make_scene("tilted-plane").render()
    depth = r.depth.astype(np.float32)
    depth[200:280, 300:340] = 0.0
    K = r.K.matrix
    ours = dn.fals(depth, K)
    ocv = opencv_normals(depth, K, "fals")
    ring = np.zeros(depth.shape, bool)
    ring[198:282, 298:342] = True
    ring &= depth > 0
    e_ours = dn.angular_error(ours, r.normals)[ring]
    e_ocv = dn.angular_error(ocv, r.normals, folded=True)[ring]
    assert e_ours.max() < 0.01
    assert np.nanmean(e_ocv) > 1.0   # M keeps the invalid rays, b gets zeros from them
