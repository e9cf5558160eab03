"""Input handling a sensor user expects (each test fails on the code before the manifest and
input-handling change): shapes, stray files, camera files with depth scale and invalid
codes, CLI-worded errors, output folders, interruption, and the one all-NaN policy."""

from __future__ import annotations

import json
import types

import numpy as np
import pytest

import depthnormals as dn
from depthnormals import io, jobs
from depthnormals._png import encode_png
from depthnormals.analytic import make_scene
from depthnormals.cli import main

K = (50.0, 50.0, 23.5, 17.5)
KMAT = [[50.0, 0.0, 23.5], [0.0, 50.0, 17.5], [0.0, 0.0, 1.0]]


@pytest.fixture(scope="module")
def depth():
    return make_scene("sphere-before-wall").render(K=K, shape=(36, 48)).depth.astype(np.float32)


@pytest.fixture
def kjson(tmp_path):
    path = tmp_path / "k.json"
    path.write_text(json.dumps(dict(zip(("fx", "fy", "cx", "cy"), K, strict=True))))
    return path


# --------------------------------------------------------------------------- API shapes

def test_colour_image_is_a_value_error_not_a_stack():
    with pytest.raises(ValueError, match=r"colour image \(3 channels\).*stack=True"):
        dn.estimate_normals(np.zeros((480, 640, 3), np.uint8), KMAT, depth_scale=0.001)
    with pytest.raises(ValueError, match=r"colour image \(4 channels\)"):
        dn.estimate_normals(np.ones((20, 30, 4)), KMAT)


def test_stack_true_takes_frames_of_width_3(depth):
    frames = np.ascontiguousarray(np.stack([depth[:, 10:13], depth[:, 20:23]]))
    got = dn.estimate_normals(frames, K, method="3f2n", stack=True)
    assert got.shape == (2, 36, 3, 3)
    assert np.array_equal(got[1], dn.estimate_normals(frames[1], K, method="3f2n"), equal_nan=True)
    with pytest.raises(ValueError, match="stack=True needs a 3-D depth"):
        dn.estimate_normals(depth, KMAT, stack=True)


def test_single_channel_is_squeezed(depth):
    want = dn.estimate_normals(depth, K, method="d2nt")
    assert np.array_equal(dn.estimate_normals(depth[..., None], K, method="d2nt"), want, equal_nan=True)


def test_all_nan_output_warns_in_the_api_1x1_included():
    with pytest.warns(dn.NoValidNormalWarning, match="none has a valid neighbour"):
        dn.estimate_normals(np.array([[2.0]]), K)
    with pytest.warns(RuntimeWarning, match="no pixel of the depth holds a valid depth"):
        dn.estimate_normals(np.zeros((5, 6)), K)
    with pytest.warns(dn.NoValidNormalWarning, match=r"1 of 2 frames .*frames 1\)"):
        dn.estimate_normals(np.stack([np.full((5, 6), 2.0), np.zeros((5, 6))]), K)


# ------------------------------------------------------------------------- intrinsics

def test_plain_3x3_text_is_a_camera_matrix(tmp_path):
    np.savetxt(tmp_path / "K.txt", np.asarray(KMAT))
    assert io.read_intrinsics(tmp_path / "K.txt") == dn.Intrinsics(*K)


def test_3x4_projection_matrix_in_text_and_api(tmp_path):
    P = [[50.0, 0.0, 23.5, -2.5], [0.0, 50.0, 17.5, 0.0], [0.0, 0.0, 1.0, 0.0]]
    np.savetxt(tmp_path / "P.txt", P)
    assert io.read_intrinsics(tmp_path / "P.txt") == dn.Intrinsics(*K)
    assert dn.as_intrinsics(np.asarray(P)) == dn.Intrinsics(*K)
    with pytest.raises(ValueError, match="3x4 projection matrix"):
        dn.as_intrinsics(np.ones((3, 4)))


def test_3f2n_params_txt_still_reads_1_based(tmp_path):
    (tmp_path / "params.txt").write_text("50 50 24.5 18.5 1\n")
    assert io.read_intrinsics(tmp_path / "params.txt") == dn.Intrinsics(*K)


def test_ros_camera_info_yaml(tmp_path):
    (tmp_path / "depth.yaml").write_text(
        "image_width: 48\nimage_height: 36\ncamera_name: depth\n"
        "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [50.0, 0.0, 23.5, 0.0, 50.0, 17.5, 0.0, 0.0, 1.0]\n"
        "distortion_model: plumb_bob\n"
        "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.0, 0.0, 0.0, 0.0, 0.0]\n"
        "projection_matrix:\n  rows: 3\n  cols: 4\n"
        "  data: [50.0, 0.0, 23.5, 0.0, 0.0, 50.0, 17.5, 0.0, 0.0, 0.0, 1.0, 0.0]\n")
    assert io.read_intrinsics(tmp_path / "depth.yaml") == dn.Intrinsics(*K)
    (tmp_path / "echo.yaml").write_text(
        "height: 36\nwidth: 48\nk: [50.0, 0.0, 23.5, 0.0, 50.0, 17.5, 0, 0, 1]\n")
    assert io.read_intrinsics(tmp_path / "echo.yaml") == dn.Intrinsics(*K)


def test_open3d_pinhole_camera_intrinsic_json_and_object(tmp_path):
    # what open3d.io.write_pinhole_camera_intrinsic writes: column-major
    (tmp_path / "o3d.json").write_text(json.dumps(
        {"width": 48, "height": 36, "intrinsic_matrix": [50.0, 0, 0, 0, 50.0, 0, 23.5, 17.5, 1]}))
    assert io.read_intrinsics(tmp_path / "o3d.json") == dn.Intrinsics(*K)
    like = types.SimpleNamespace(intrinsic_matrix=np.asarray(KMAT), width=48, height=36)
    assert dn.as_intrinsics(like) == dn.Intrinsics(*K)


def test_camera_file_carries_depth_scale_invalid_codes_and_max_depth(tmp_path, depth):
    (tmp_path / "intrinsics.json").write_text(json.dumps(
        {"fx": 50.0, "fy": 50.0, "cx": 23.5, "cy": 17.5, "depth_scale": 0.001, "invalid": [65535],
         "max_depth": 10.0}))
    cam = io.read_camera_file(tmp_path / "intrinsics.json")
    assert cam == io.CameraFile(dn.Intrinsics(*K), 0.001, (65535.0,), 10.0, tmp_path / "intrinsics.json")
    mm = np.round(depth * 1000).astype(np.uint16)
    mm[:4] = 65535
    (tmp_path / "d.png").write_bytes(encode_png(mm))
    # no --depth-scale: the camera file's is used; 65535 is invalid, not a point 65 m away
    assert main(["estimate", str(tmp_path / "d.png"), "-K", str(tmp_path / "intrinsics.json"),
                 "-o", str(tmp_path / "c.ply")]) == 0
    head = (tmp_path / "c.ply").read_bytes().split(b"end_header\n")[0].decode()
    n_points = int(head.split("element vertex ")[1].split()[0])
    assert n_points <= 32 * 48
    assert main(["estimate", str(tmp_path / "d.png"), "-K", str(tmp_path / "intrinsics.json"),
                 "-o", str(tmp_path / "n.npy")]) == 0
    n = np.load(tmp_path / "n.npy")
    assert np.isnan(n[:4]).all() and np.isfinite(n[10:30, 10:40]).all()


def test_invalid_and_max_depth_options(tmp_path, kjson, depth):
    mm = np.round(depth * 1000).astype(np.uint16)
    mm[:, :5] = 2047
    (tmp_path / "d.png").write_bytes(encode_png(mm))
    argv = ["estimate", str(tmp_path / "d.png"), "-K", str(kjson), "--depth-scale", "0.001"]
    assert main([*argv, "--invalid", "0,2047", "-o", str(tmp_path / "a.npy")]) == 0
    assert np.isnan(np.load(tmp_path / "a.npy")[:, :5]).all()
    far = float(np.median(depth))
    assert main([*argv, "--max-depth", str(far), "-o", str(tmp_path / "b.npy")]) == 0
    z = io.read_depth(tmp_path / "d.png", depth_scale=0.001, max_depth=far)
    assert np.isnan(z[mm * 0.001 > far + 1e-6]).all() and not np.isnan(z[mm * 0.001 < far - 1e-3]).any()


# -------------------------------------------------------------------------- folder runs

def test_folder_run_skips_colour_images_and_counts_them(tmp_path, kjson, depth, capsys):
    (tmp_path / "in").mkdir()
    mm = np.round(depth * 1000).astype(np.uint16)
    for i in range(2):
        (tmp_path / "in" / f"depth{i}.png").write_bytes(encode_png(mm))
        (tmp_path / "in" / f"rgb{i}.png").write_bytes(encode_png(np.zeros((36, 48, 3), np.uint8)))
    np.save(tmp_path / "in" / "rgb.npy", np.zeros((36, 48, 3), np.float32))
    np.save(tmp_path / "in" / "d.npy", depth[..., None])              # (H, W, 1): depth
    argv = ["estimate", str(tmp_path / "in"), "-K", str(kjson), "--depth-scale", "0.001",
            "-o", str(tmp_path / "out"), "-q"]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert "3 frames by 3f2n+" in out
    assert "skipped 3 file(s) that are not depth images" in err
    assert "rgb0.png: a colour image (RGB PNG)" in err
    assert sorted(p.name for p in (tmp_path / "out").glob("*.npy")) == ["d.npy", "depth0.npy", "depth1.npy"]
    # a glob too
    argv[1] = str(tmp_path / "in" / "*.png")
    argv[-2] = str(tmp_path / "out2")
    assert main(argv) == 0
    assert "2 frames" in capsys.readouterr().out


def test_output_folder_of_a_file_is_created(tmp_path, kjson, depth):
    np.save(tmp_path / "d.npy", depth)
    assert main(["estimate", str(tmp_path / "d.npy"), "-K", str(kjson),
                 "-o", str(tmp_path / "new" / "dir" / "n.npy")]) == 0
    assert (tmp_path / "new" / "dir" / "n.npy").is_file()


def test_failed_folder_run_leaves_no_output_folder(tmp_path, kjson, depth, capsys):
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "d.png").write_bytes(encode_png(np.round(depth * 1000).astype(np.uint16)))
    assert main(["estimate", str(tmp_path / "in"), "-K", str(kjson), "-o", str(tmp_path / "out"), "-q"]) == 1
    assert "--depth-scale" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_failed_single_run_leaves_no_output_folder(tmp_path, kjson):
    (tmp_path / "d.npy").write_bytes(b"\x93NUMPY garbage")
    assert main(["estimate", str(tmp_path / "d.npy"), "-K", str(kjson),
                 "-o", str(tmp_path / "new" / "n.npy")]) == 1
    assert not (tmp_path / "new").exists()


# ------------------------------------------------------------------------ CLI messages

def test_errors_name_the_flag_and_the_file(tmp_path, kjson, depth, capsys):
    (tmp_path / "d.png").write_bytes(encode_png(np.round(depth * 1000).astype(np.uint16)))
    assert main(["estimate", str(tmp_path / "d.png"), "-K", str(kjson), "-o", str(tmp_path / "n.npy")]) == 1
    err = capsys.readouterr().err
    assert "--depth-scale 0.001" in err and "d.png" in err and "depth_scale" not in err
    assert main(["estimate", str(tmp_path / "d.png"), "-K", str(kjson), "--depth-scale", "-1",
                 "-o", str(tmp_path / "n.npy")]) == 1
    assert "--depth-scale must be" in capsys.readouterr().err


def test_unknown_output_format_lists_ply(tmp_path, kjson, depth, capsys):
    np.save(tmp_path / "d.npy", depth)
    assert main(["estimate", str(tmp_path / "d.npy"), "-K", str(kjson), "-o", str(tmp_path / "x.jpg")]) == 1
    err = capsys.readouterr().err
    assert ".ply" in err and ".vis.png" in err and "x.jpg" in err
    assert not (tmp_path / "x.jpg").exists()


def test_corrupt_npy_names_the_file(tmp_path, kjson, capsys):
    (tmp_path / "broken.npy").write_bytes(b"not a numpy file at all")
    argv = ["estimate", str(tmp_path / "broken.npy"), "-K", str(kjson), "-o", str(tmp_path / "n.npy")]
    assert main(argv) == 1
    assert "broken.npy" in capsys.readouterr().err


def test_single_channel_npy_is_read(tmp_path, kjson, depth):
    np.save(tmp_path / "d.npy", depth[..., None])
    assert main(["estimate", str(tmp_path / "d.npy"), "-K", str(kjson), "-o", str(tmp_path / "n.npy")]) == 0


def test_colour_png_named_as_a_colour_image(tmp_path, kjson, capsys):
    (tmp_path / "c.png").write_bytes(encode_png(np.zeros((6, 8, 3), np.uint8)))
    assert main(["estimate", str(tmp_path / "c.png"), "-K", str(kjson), "--depth-scale", "0.001",
                 "-o", str(tmp_path / "n.npy")]) == 1
    err = capsys.readouterr().err
    assert "c.png" in err and "colour image" in err and "[..., 0]" not in err


def test_ctrl_c_says_how_to_resume_and_exits_130(tmp_path, kjson, depth, monkeypatch, capsys):
    np.save(tmp_path / "d.npy", depth)
    import depthnormals.registry as registry

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(registry, "compute_normals", interrupted)
    rc = main(["estimate", str(tmp_path / "d.npy"), "-K", str(kjson), "-o", str(tmp_path / "n.npy")])
    assert rc == 130
    err = capsys.readouterr().err
    assert "interrupted; run the same command again to resume" in err and "Traceback" not in err
    assert not (tmp_path / "n.npy").exists()


def test_one_pixel_exits_3(tmp_path, kjson, capsys):
    np.save(tmp_path / "d.npy", np.array([[2.0]], np.float32))
    assert main(["estimate", str(tmp_path / "d.npy"), "-K", str(kjson), "-o", str(tmp_path / "n.npy")]) == 3
    assert "none has a valid neighbour" in capsys.readouterr().err
    assert np.isnan(np.load(tmp_path / "n.npy")).all()


def test_folder_run_with_an_all_nan_frame_exits_3(tmp_path, kjson, depth, capsys):
    (tmp_path / "in").mkdir()
    np.save(tmp_path / "in" / "a.npy", depth)
    np.save(tmp_path / "in" / "b.npy", np.zeros_like(depth))
    assert main(["estimate", str(tmp_path / "in"), "-K", str(kjson), "-o", str(tmp_path / "out"), "-q"]) == 3
    assert "1 output(s) hold no finite normal" in capsys.readouterr().err


# ----------------------------------------------------------------------- .vis.png colours

def test_vis_png_colour_conventions(tmp_path, kjson, depth):
    wall = np.zeros((2, 2, 3), np.float32)
    wall[..., 2] = -1.0
    assert io.normals_to_rgb8(wall)[0, 0].tolist() == [128, 128, 255]                    # (1 - n) / 2
    assert io.normals_to_rgb8(wall, convention="open3d")[0, 0].tolist() == [128, 128, 0]  # (n + 1) / 2
    np.save(tmp_path / "d.npy", depth)
    for vis in ("3f2n", "open3d"):
        assert main(["estimate", str(tmp_path / "d.npy"), "-K", str(kjson), "--vis", vis,
                     "-o", str(tmp_path / f"{vis}.vis.png")]) == 0
    a = io.read_png(tmp_path / "3f2n.vis.png").astype(int)
    b = io.read_png(tmp_path / "open3d.vis.png").astype(int)
    ok = a.any(axis=-1)
    assert np.abs(a[ok] + b[ok] - 255).max() <= 1


def test_manifest_name_is_public():
    assert jobs.MANIFEST == "depthnormals-manifest.json"


def test_invalid_codes_never_wrap_around(tmp_path):
    np.save(tmp_path / "u.npy", np.array([[1000, 4464, 65535], [5, 6, 7]], np.uint16))
    z = io.read_depth(tmp_path / "u.npy", depth_scale=0.001, invalid=[70000, -1, 65535, 5.5])
    assert np.isnan(z[0, 2]) and np.isfinite(z[0, :2]).all() and np.isfinite(z[1]).all()


def test_evaluate_warm_up_on_an_empty_corner_does_not_warn(tmp_path, capsys):
    """KITTI-like frames have no depth in their top-left corner, where evaluate warms the
    estimators up: that is not an all-NaN output to warn about (warnings are errors here)."""
    from depthnormals.synth import generate

    generate(tmp_path / "ds", indoor=1, outdoor=0, views=1, size=(40, 48), noise=(),
             K=(22.0, 22.0, 23.5, 19.5), progress=False, scenes="procedural")
    path = next((tmp_path / "ds").rglob("clean/0000.npy"))
    z = np.load(path)
    z[:32, :32] = 0.0
    np.save(path, z)
    assert main(["evaluate", str(tmp_path / "ds"), "-m", "3f2n", "-o", str(tmp_path / "ev"), "-q",
                 "--figures", "0"]) == 0


def test_camera_file_of_a_real_sensor_folder(tmp_path, depth, capsys):
    """The real-sensor folder reader's intrinsics.json spells the codes invalid_value; an
    encoding other than linear depth is refused for a single file (no silent misreading)."""
    info = {"fx": 50.0, "fy": 50.0, "cx": 23.5, "cy": 17.5, "depth_scale": 0.001, "invalid_value": 65535}
    (tmp_path / "intrinsics.json").write_text(json.dumps(info))
    assert io.read_camera_file(tmp_path / "intrinsics.json").invalid == (65535.0,)
    mm = np.round(depth * 1000).astype(np.uint16)
    (tmp_path / "d.png").write_bytes(encode_png(mm))
    argv = ["estimate", str(tmp_path / "d.png"), "-K", str(tmp_path / "intrinsics.json"), "-o",
            str(tmp_path / "n.npy")]
    assert main(argv) == 0
    (tmp_path / "intrinsics.json").write_text(json.dumps({**info, "encoding": "nyu_raw_disparity"}))
    assert main(argv) == 1
    assert "nyu_raw_disparity" in capsys.readouterr().err
