"""Lens distortion undone: ``depthnormals.undistort_depth``, the real-sensor folders'
``distortion`` key, the camera file's and the command line's ``--distortion``, on the real
Azure Kinect frame of ``tests/data/azure_kinect_tof`` (SOURCE there) and on planes seen
through its lens. The frame's accuracy against the peers: tests/test_real_sensors_more.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import depthnormals as dn
from depthnormals.camera import DISTORTION_LENGTHS, as_intrinsics

TOF = Path(__file__).resolve().parent / "data" / "azure_kinect_tof"
INFO = json.loads((TOF / "intrinsics.json").read_text())
K = (INFO["fx"], INFO["fy"], INFO["cx"], INFO["cy"])
DIST = tuple(INFO["distortion"])


def raw_depth() -> np.ndarray:
    """The frame as recorded (uint16 millimetres, the distorted grid)."""
    from depthnormals._png import read_png

    return read_png(TOF / "depth.png")


def lands(u, v, dist, cam=K):
    """Where the pixel ``(u, v)`` of the pinhole grid lands through the lens: OpenCV's formula
    written out once more, term by term (the test's own reading of the model)."""
    fx, fy, cx, cy = cam
    k = list(dist) + [0.0] * (12 - len(dist))
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = k
    x, y = (u - cx) / fx, (v - cy) / fy
    r2 = x * x + y * y
    rad = (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / (1 + k4 * r2 + k5 * r2**2 + k6 * r2**3)
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r2**2
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r2**2
    return fx * xd + cx, fy * yd + cy


def distorted_plane(shape, cam, dist, n, offset):
    """Planar depth of the plane ``n . X = offset`` as a camera with lens ``dist`` (k1, k2, p1,
    p2, k3, k4, k5, k6) records it: each recorded pixel's ray found by inverting the lens
    (fixed-point iteration, converged to 1e-12 here), then ``z = offset / (n . ray)``."""
    h, w = shape
    fx, fy, cx, cy = cam
    k1, k2, p1, p2, k3, k4, k5, k6 = (list(dist) + [0.0] * 8)[:8]
    xd = np.broadcast_to(((np.arange(w) - cx) / fx)[None, :], shape)
    yd = np.broadcast_to(((np.arange(h) - cy) / fy)[:, None], shape)
    x, y = xd.copy(), yd.copy()
    for _ in range(300):
        r2 = x * x + y * y
        rad = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        x = (xd - 2 * p1 * x * y - p2 * (r2 + 2 * x * x)) / rad
        y = (yd - p1 * (r2 + 2 * y * y) - 2 * p2 * x * y) / rad
    return offset / (n[0] * x + n[1] * y + n[2])


# ---------------------------------------------------------------------------------------------
# the function


@pytest.mark.parametrize("n", DISTORTION_LENGTHS)
def test_each_output_pixel_takes_the_input_pixel_its_ray_lands_on(n):
    dist = (*DIST, 0.01, -0.002, 0.003, 0.001)[:n]
    h, w = 576, 640
    probe = np.arange(h * w, dtype=np.float64).reshape(h, w)  # each pixel names itself
    out = dn.undistort_depth(probe, K, dist)
    rng = np.random.default_rng(n)
    for u, v in zip(rng.integers(0, w, 300), rng.integers(0, h, 300), strict=True):
        us, vs = lands(float(u), float(v), dist)
        uu, vv = int(np.floor(us + 0.5)), int(np.floor(vs + 0.5))
        if 0 <= uu < w and 0 <= vv < h:
            assert out[v, u] == vv * w + uu, (u, v, us, vs)
        else:
            assert np.isnan(out[v, u])


def test_the_same_pixels_as_opencv_remap():
    cv2 = pytest.importorskip("cv2")
    raw = raw_depth()
    for dist in (DIST, DIST[:5], DIST[:4], (*DIST, 0.01, -0.002, 0.003, 0.001)):
        mx, my = cv2.initUndistortRectifyMap(as_intrinsics(K).matrix, np.array(dist), None,
                                             as_intrinsics(K).matrix, (640, 576), cv2.CV_32FC1)
        theirs = cv2.remap(raw, mx, my, cv2.INTER_NEAREST)
        ours = dn.undistort_depth(raw, K, dist)
        assert ours.dtype == np.uint16
        # OpenCV's float32 maps round a landing point within 1e-5 px of a half pixel either way
        assert np.count_nonzero(ours != theirs) <= 10, len(dist)


def test_no_distortion_is_a_copy_and_integer_codes_stay():
    d = np.array([[1000, 65535, 0], [1200, 1300, 1400]], np.uint16)
    out = dn.undistort_depth(d, (2.0, 2.0, 1.0, 0.5), [0.0] * 5)
    assert out.dtype == np.uint16 and (out == d).all() and out is not d
    out = dn.undistort_depth(d, (2.0, 2.0, 1.0, 0.5), [-0.2, 0.0, 0.0, 0.0])
    assert set(np.unique(out)) <= {0, 1000, 1200, 1300, 1400, 65535}


def test_rays_that_leave_the_image_are_invalid():
    # strong pincushion: the corners' rays land outside the recorded image
    d = np.full((48, 64), 1500, np.uint16)
    out = dn.undistort_depth(d, (40.0, 40.0, 31.5, 23.5), (0.5, 0.0, 0.0, 0.0))
    assert out[0, 0] == 0 and out[24, 32] == 1500
    f = dn.undistort_depth(d.astype(np.float32), (40.0, 40.0, 31.5, 23.5), (0.5, 0.0, 0.0, 0.0))
    assert np.isnan(f[0, 0]) and f[24, 32] == 1500.0


@pytest.mark.parametrize("bad, err", [
    ((0.1, 0.0, 0.0), ValueError), ((0.1,) * 14, ValueError), ((0.1, np.nan, 0.0, 0.0), ValueError),
    ("0.1,0,0,0", TypeError), (None, TypeError), ((0.1, "x", 0.0, 0.0), TypeError)])
def test_bad_distortion_is_refused(bad, err):
    with pytest.raises(err, match="distortion"):
        dn.undistort_depth(np.ones((4, 4)), (2.0, 2.0, 1.5, 1.5), bad)


def test_bad_depth_and_interpolation_are_refused():
    with pytest.raises(ValueError, match="2-D"):
        dn.undistort_depth(np.ones((2, 3, 3)), (2.0, 2.0, 1.0, 1.0), (0.1, 0, 0, 0))
    with pytest.raises(TypeError, match="real numbers"):
        dn.undistort_depth(np.ones((3, 3), bool), (2.0, 2.0, 1.0, 1.0), (0.1, 0, 0, 0))
    with pytest.raises(ValueError, match="interpolation"):
        dn.undistort_depth(np.ones((3, 3)), (2.0, 2.0, 1.0, 1.0), (0.1, 0, 0, 0),
                           interpolation="cubic")


def test_a_plane_through_the_lens_becomes_the_plane_again():
    """The Azure Kinect's lens (k1 0.55, k4 0.89) in front of an oblique plane: read as a
    pinhole image its normals err 5 deg on average (8 in the outer field); undistorted they
    are the plane's: to the model's curvature with ``"linear"`` on noise-free depth, and with
    the default ``"nearest"`` once the depth has a sensor's noise (its half-pixel shifts then
    drown in the noise; on noise-free depth they read as relief)."""
    n = np.array([0.3, -0.5, -1.0]) / np.linalg.norm([0.3, -0.5, -1.0])
    z = distorted_plane((576, 640), K, DIST, n, -1.5).astype(np.float32)
    truth = np.broadcast_to(n.astype(np.float32), (576, 640, 3))

    def err(depth):
        return float(np.nanmean(dn.angular_error(dn.estimate_normals(depth, K), truth)))

    assert err(z) > 4.0  # the lens ignored
    assert err(dn.undistort_depth(z, K, DIST, interpolation="linear")) < 0.01
    noisy = np.round((z + np.random.default_rng(0).normal(0, 0.002, z.shape)) * 1000) / 1000
    noisy = noisy.astype(np.float32)
    assert err(noisy) > 4.0
    assert err(dn.undistort_depth(noisy, K, DIST)) < 0.6  # measured 0.36


def test_linear_keeps_jumps_and_holes():
    # a step: no pixel takes a depth between the two sides
    d = np.where(np.arange(64)[None, :] < 30, 1.0, 2.0) * np.ones((48, 1))
    d[10, 10] = np.nan
    out = dn.undistort_depth(d, (40.0, 40.0, 31.5, 23.5), (0.05, 0.0, 0.0, 0.0), interpolation="linear")
    v = out[np.isfinite(out)]
    assert np.all((np.abs(v - 1.0) < 0.031) | (np.abs(v - 2.0) < 0.061))
    assert np.isnan(out).any()


# ---------------------------------------------------------------------------------------------
# the reader, the camera file and the command line


def test_the_folder_reader_undoes_the_folders_distortion():
    (f,) = list(dn.datasets.open(TOF))
    assert f.meta["undistorted"] == list(DIST)
    assert f.depth.shape == (576, 640) and f.depth.dtype == np.float32
    expected = dn.undistort_depth(raw_depth(), K, DIST).astype(np.float32) * np.float32(0.001)
    assert np.allclose(f.depth, expected, rtol=0, atol=1e-6)
    (g,) = list(dn.datasets.read_realsensors(TOF, undistort=False))
    assert g.meta["undistorted"] is None
    assert np.allclose(g.depth, raw_depth() * 0.001, atol=1e-6)
    assert np.count_nonzero(f.depth != g.depth) > 100_000


def test_a_bad_distortion_in_a_folder_names_the_file(tmp_path):
    info = dict(INFO, distortion=[0.1, 0.2])
    (tmp_path / "intrinsics.json").write_text(json.dumps(info))
    (tmp_path / "depth.png").write_bytes((TOF / "depth.png").read_bytes())
    with pytest.raises(ValueError, match=r"intrinsics\.json.*4, 5, 8 or 12"):
        list(dn.datasets.open(tmp_path))


def test_camera_file_distortion(tmp_path):
    from depthnormals.io import read_camera_file

    p = tmp_path / "cam.json"
    p.write_text(json.dumps({"fx": 500, "fy": 500, "cx": 320, "cy": 240, "distortion": [0.1, 0, 0, 0]}))
    assert read_camera_file(p).distortion == (0.1, 0.0, 0.0, 0.0)
    p.write_text(json.dumps({"fx": 500, "fy": 500, "cx": 320, "cy": 240, "distortion": [0, 0, 0, 0]}))
    assert read_camera_file(p).distortion == ()
    p.write_text(json.dumps({"fx": 500, "fy": 500, "cx": 320, "cy": 240}))
    assert read_camera_file(p).distortion == ()
    p.write_text(json.dumps({"fx": 500, "fy": 500, "cx": 320, "cy": 240, "distortion": [0.1]}))
    with pytest.raises(ValueError, match=r"cam\.json.*4, 5, 8 or 12"):
        read_camera_file(p)


def test_cli_undistorts_a_depth_file_and_records_it(tmp_path, capsys):
    from depthnormals.cli import main

    raw = raw_depth()
    src = tmp_path / "frame.npy"
    np.save(src, raw)
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"fx": K[0], "fy": K[1], "cx": K[2], "cy": K[3], "depth_scale": 0.001,
                               "distortion": list(DIST)}))
    assert main(["estimate", str(src), "-K", str(cam), "-o", str(tmp_path / "n.npy")]) == 0
    want = dn.estimate_normals(dn.undistort_depth(raw, K, DIST), K, depth_scale=0.001)
    got = np.load(tmp_path / "n.npy")
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    assert np.nanmax(np.abs(got - want)) == 0.0
    # --distortion overrides the file's: zeros = none
    assert main(["estimate", str(src), "-K", str(cam), "-o", str(tmp_path / "m.npy"),
                 "--distortion", "0,0,0,0"]) == 0
    plain = dn.estimate_normals(raw, K, depth_scale=0.001)
    np.testing.assert_array_equal(np.load(tmp_path / "m.npy"), plain)
    # many inputs: the manifest records it, and a resume with another lens refuses the folder
    out = tmp_path / "many"
    second = tmp_path / "frame2.npy"
    np.save(second, raw)
    assert main(["estimate", str(src), str(second), "-K", str(cam), "-o", str(out), "-q"]) == 0
    manifest = json.loads((out / "depthnormals-manifest.json").read_text())
    assert manifest["settings"]["distortion"] == list(DIST)
    np.testing.assert_array_equal(np.load(out / "frame2.npy"), got)
    capsys.readouterr()
    assert main(["estimate", str(src), str(second), "-K", str(cam), "-o", str(out), "-q",
                 "--distortion", "0.1,0,0,0"]) != 0
    assert "settings" in capsys.readouterr().err.lower()


def test_a_frame_whose_reader_undid_its_lens_refuses_a_second_distortion(tmp_path, capsys):
    """A real-sensor folder's reader undoes the folder's lens; ``--distortion`` (``distortion=``)
    on that folder would undo it again: refused, naming the frame, before any output. Without
    it the folder runs and gives the reader's undistorted normals."""
    from depthnormals.cli import main
    from depthnormals.datasets.realsensors import read_realsensors
    from depthnormals.jobs import run_estimate

    with pytest.raises(ValueError, match="undone the frame's lens already"):
        run_estimate([TOF], tmp_path / "twice", method="3f2n+", distortion=DIST)
    assert not (tmp_path / "twice").exists() or not any((tmp_path / "twice").rglob("*.npy"))
    assert main(["estimate", str(TOF), "-o", str(tmp_path / "cli"), "-q", "--distortion",
                 ",".join(map(str, DIST))]) != 0
    assert "twice" in capsys.readouterr().err
    assert main(["estimate", str(TOF), "-o", str(tmp_path / "once"), "-q"]) == 0
    (frame,) = read_realsensors(TOF)
    (out,) = (tmp_path / "once").rglob("*.npy")
    np.testing.assert_array_equal(np.load(out), dn.estimate_normals(frame.depth, frame.K))


def test_cli_refuses_a_bad_distortion(tmp_path, capsys):
    from depthnormals.cli import main

    with pytest.raises(SystemExit):
        main(["estimate", "x.npy", "-K", "1,1,0,0", "-o", str(tmp_path / "n.npy"),
              "--distortion", "0.1,0.2"])
    assert "4, 5, 8 or 12" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# the torch twin


def test_torch_twin_gives_the_numpy_pixels():
    torch = pytest.importorskip("torch")
    from depthnormals.torch import undistort_depth as tundistort

    raw = raw_depth().astype(np.float32) * np.float32(0.001)
    want = dn.undistort_depth(raw, K, DIST)
    batch = torch.stack([torch.from_numpy(raw), torch.from_numpy(raw * 2)])[:, None]
    got = tundistort(batch, K, DIST)
    assert got.shape == batch.shape and got.dtype == torch.float32
    np.testing.assert_array_equal(got[0, 0].numpy(), want)
    np.testing.assert_array_equal(got[1, 0].numpy(), dn.undistort_depth(raw * 2, K, DIST))
    np.testing.assert_array_equal(tundistort(torch.from_numpy(raw).double(), K, DIST).numpy(),
                                  want.astype(np.float64))
    # differentiable in the depth: each output value is one input value
    x = torch.from_numpy(raw).clone().requires_grad_(True)
    y = tundistort(x, K, DIST)
    torch.nan_to_num(y).sum().backward()
    assert x.grad is not None and float(x.grad.sum()) == float(np.count_nonzero(np.isfinite(want)))
    with pytest.raises(TypeError, match=r"torch\.Tensor"):
        tundistort(raw, K, DIST)
    with pytest.raises(TypeError, match="floating"):
        tundistort(torch.zeros(4, 4, dtype=torch.int32), K, DIST)
    with pytest.raises(ValueError, match="4, 5, 8 or 12"):
        tundistort(torch.zeros(4, 4), K, (0.1,))


@pytest.mark.parametrize("extra, kept, other", [
    ({"distortion_model": "plumb_bob", "D": [0.1, 0.2, 0.0, 0.0, 0.0]}, (0.1, 0.2, 0.0, 0.0, 0.0), ""),
    ({"D": [0.1, 0.2, 0.0, 0.0]}, (0.1, 0.2, 0.0, 0.0), ""),  # ROS's default model
    # RealSense's name for OpenCV's model (the rosbag reader undoes it too)
    ({"distortion_model": "Brown Conrady", "D": [0.1, 0.2, 0.0, 0.0, 0.0]},
     (0.1, 0.2, 0.0, 0.0, 0.0), ""),
    ({"distortion_model": "equidistant", "D": [0.0, 0.0, 0.0, 0.0]}, (), ""),  # nothing to undo
    ({"distortion_model": "equidistant", "D": [0.1, 0.0, 0.0, 0.0]}, (), "equidistant"),
    ({"distortion_model": "", "D": [0.1, 0.0, 0.0, 0.0]}, (), "(none named)"),
    ({"distortion_model": "plumb_bob", "D": [0.1, 0.0, 0.0, float("nan")]}, (), "plumb_bob"),
    ({"distortion_model": "plumb_bob", "D": "k1=0.1"}, (), "plumb_bob"),
])
def test_a_ros_distortion_is_kept_or_named(tmp_path, extra, kept, other):
    """A camera file's ROS ``D``: kept where OpenCV's model reads it, else its model named
    for the command line's note (never dropped without a word), nothing where it is all 0."""
    from depthnormals.io import read_camera_file

    cam = tmp_path / "camera_info.json"
    cam.write_text(json.dumps({"K": [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0],
                               **extra}))
    info = read_camera_file(cam)
    assert (info.ros_distortion, info.ros_other_lens) == (kept, other)


def test_a_ros_camera_info_distortion_is_named_not_applied(tmp_path, capsys):
    """ROS depth topics are taken as rectified (image_rect): the ``D`` of a camera_info is not
    applied, but the command line says it is there and how to apply it (an image_raw stream
    read without it would be silently off)."""
    from depthnormals.cli import main
    from depthnormals.io import read_camera_file

    pytest.importorskip("yaml")
    src = tmp_path / "frame.npy"
    np.save(src, raw_depth())
    data = ", ".join(f"{c!r}" for c in DIST)
    cam = tmp_path / "depth.yaml"
    cam.write_text(
        "image_width: 640\nimage_height: 576\ncamera_name: depth\n"
        f"camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{K[0]!r}, 0.0, {K[2]!r}, 0.0, {K[1]!r}, "
        f"{K[3]!r}, 0.0, 0.0, 1.0]\n"
        f"distortion_model: rational_polynomial\ndistortion_coefficients:\n  rows: 1\n  cols: 8\n"
        f"  data: [{data}]\n")
    info = read_camera_file(cam)
    assert info.ros_distortion == DIST and info.distortion == ()
    capsys.readouterr()
    assert main(["estimate", str(src), "-K", str(cam), "--depth-scale", "0.001", "-o",
                 str(tmp_path / "n.npy")]) == 0
    err = capsys.readouterr().err
    assert "not applied" in err and "--distortion 0.5479397774,-0.02097137086," in err
    np.testing.assert_array_equal(np.load(tmp_path / "n.npy"),
                                  dn.estimate_normals(raw_depth(), K, depth_scale=0.001))
    # given explicitly: applied, and no note
    assert main(["estimate", str(src), "-K", str(cam), "--depth-scale", "0.001", "-o",
                 str(tmp_path / "m.npy"), "--distortion", ",".join(repr(c) for c in DIST)]) == 0
    assert "not applied" not in capsys.readouterr().err
    np.testing.assert_array_equal(np.load(tmp_path / "m.npy"), dn.estimate_normals(
        dn.undistort_depth(raw_depth(), K, DIST), K, depth_scale=0.001))
    # zeros (most depth cameras' camera_info): nothing to say
    cam.write_text(cam.read_text().replace(f"data: [{data}]", "data: [0, 0, 0, 0, 0, 0, 0, 0]"))
    info = read_camera_file(cam)
    assert info.ros_distortion == () and info.ros_other_lens == ""
    assert main(["estimate", str(src), "-K", str(cam), "--depth-scale", "0.001", "-o",
                 str(tmp_path / "z.npy")]) == 0
    assert "not applied" not in capsys.readouterr().err
    # a fisheye model, or OpenCV's with coefficients it cannot read: not applied either, and
    # said (until session 39 nothing was, and an image_raw stream read as pinhole silently)
    for model, coeffs in (("equidistant", "0.1, 0.01, 0.0, 0.0"),
                          ("plumb_bob", "0.1, 0.01, 0.0, 0.0, 0.0, 0.0, 0.0")):
        cam.write_text(cam.read_text().replace("rational_polynomial", model).replace(
            "data: [0, 0, 0, 0, 0, 0, 0, 0]", f"data: [{coeffs}]"))
        info = read_camera_file(cam)
        assert info.ros_distortion == () and info.ros_other_lens == model
        assert main(["estimate", str(src), "-K", str(cam), "--depth-scale", "0.001", "-o",
                     str(tmp_path / "f.npy")]) == 0
        err = capsys.readouterr().err
        assert f"model {model!r}" in err and "not applied" in err and "rectify" in err
        np.testing.assert_array_equal(np.load(tmp_path / "f.npy"),
                                      dn.estimate_normals(raw_depth(), K, depth_scale=0.001))
        cam.write_text(cam.read_text().replace(model, "rational_polynomial").replace(
            f"data: [{coeffs}]", "data: [0, 0, 0, 0, 0, 0, 0, 0]"))
