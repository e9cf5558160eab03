"""datasets.open recognises our synthetic format, the SSN EXR layout and the 3F2N format."""

from __future__ import annotations

import numpy as np
import pytest

from depthnormals.camera import Intrinsics
from depthnormals.datasets import open as open_dataset
from depthnormals.datasets import read_ssn, read_synthetic
from depthnormals.datasets.ssn import is_ssn, read_exr_channels
from depthnormals.synth import export_3f2n, generate

SMALL_K = Intrinsics(91.375, 91.375, 63.5, 52.5)


@pytest.fixture(scope="module")
def synth_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("syn") / "ds"
    generate(root, indoor=1, outdoor=1, views=2, seed=4, noise=("gaussian", "kinect_v2"), K=SMALL_K,
             size=(106, 128), progress=False)
    return root


def test_open_synthetic_groups_and_fields(synth_root):
    frames = list(open_dataset(synth_root))
    assert len(frames) == 2 * 2 * 3
    groups = sorted({f.group for f in frames})
    assert groups == ["indoor/living_room-00/clean", "indoor/living_room-00/gaussian",
                      "indoor/living_room-00/kinect_v2", "outdoor/street-00/clean",
                      "outdoor/street-00/gaussian", "outdoor/street-00/kinect_v2"]
    f = frames[0]
    assert f.depth.dtype == np.float32 and f.normals.shape == (106, 128, 3) and f.mask.dtype == bool
    assert np.allclose(f.K, SMALL_K.matrix) and f.name == "0000"
    assert np.all(np.isfinite(f.normals[f.mask])) and np.all(np.isnan(f.normals[~f.mask]))
    assert f.meta["pose"].shape == (4, 4)
    # one scene folder opens on its own; variants can be chosen
    one = list(open_dataset(synth_root / "outdoor" / "street-00"))
    assert {f.group for f in one} == {"outdoor/street-00/clean", "outdoor/street-00/gaussian",
                                      "outdoor/street-00/kinect_v2"}
    clean = list(read_synthetic(synth_root, variants=["clean"]))
    assert len(clean) == 4
    with pytest.raises(ValueError, match="variant"):
        list(read_synthetic(synth_root, variants=["kinect_v9"]))


def test_open_3f2n_export_with_its_own_size(synth_root, tmp_path):
    export_3f2n(synth_root, tmp_path / "x", variant="gaussian")
    frames = list(open_dataset(tmp_path / "x"))
    assert [f.group for f in frames] == ["indoor/living_room-00"] * 2 + ["outdoor/street-00"] * 2
    assert frames[0].depth.shape == (106, 128)


def _write_exr(path, channels):
    OpenEXR = pytest.importorskip("OpenEXR")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    data = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}
    with OpenEXR.File(header, data) as f:
        f.write(str(path))


def test_open_ssn_layout_reads_exr(tmp_path):
    pytest.importorskip("OpenEXR")
    h, w = 8, 10
    K = Intrinsics(365.5, 365.5, 255.5, 211.5)
    z = np.full((h, w), 2.5, dtype=np.float32)
    z[0, :3] = 1e10  # background as Blender writes it
    n = np.zeros((h, w, 3), np.float32)
    n[..., 2] = 1.0  # stored pointing away: the reader turns it to the camera
    for kind, scene in (("indoor", "office"), ("outdoor", "alley")):
        d = tmp_path / kind / scene / "standard_exr"
        d.mkdir(parents=True)
        for k in (1, 2):
            _write_exr(d / f"{k:04d}.exr", {"Z": z, "R": n[..., 0], "G": n[..., 1], "B": n[..., 2]})
    ch = read_exr_channels(tmp_path / "indoor" / "office" / "standard_exr" / "0001.exr")
    assert sorted(ch) == ["B", "G", "R", "Z"] and np.array_equal(ch["Z"], z)
    assert is_ssn(tmp_path)
    frames = list(open_dataset(tmp_path))
    assert [(f.group, f.name) for f in frames] == [
        ("indoor/office/standard", "0001"), ("indoor/office/standard", "0002"),
        ("outdoor/alley/standard", "0001"), ("outdoor/alley/standard", "0002")]
    f = frames[0]
    assert np.allclose(f.K, K.matrix)
    assert not f.mask[0, :3].any() and f.mask.sum() == h * w - 3
    assert np.all(f.depth[~f.mask] == 0) and np.all(f.depth[f.mask] == 2.5)
    assert np.allclose(f.normals[f.mask], [0, 0, -1])
    # any level of the layout opens
    assert len(list(open_dataset(tmp_path / "outdoor"))) == 2
    assert len(list(open_dataset(tmp_path / "indoor" / "office"))) == 2
    assert len(list(open_dataset(tmp_path / "indoor" / "office" / "standard_exr"))) == 2
    # a frame without the Z channel is a clear error
    bad = tmp_path / "outdoor" / "alley" / "standard_exr" / "0003.exr"
    _write_exr(bad, {"R": n[..., 0], "G": n[..., 1], "B": n[..., 2]})
    with pytest.raises(ValueError, match="Z"):
        list(read_ssn(tmp_path / "outdoor"))
    bad.write_bytes(b"not an exr")
    with pytest.raises(ValueError, match="cannot read EXR"):
        list(read_ssn(tmp_path / "outdoor"))


def test_open_unknown_and_missing(tmp_path):
    with pytest.raises(FileNotFoundError):
        list(open_dataset(tmp_path / "nope"))
    (tmp_path / "x.txt").write_text("hi")
    with pytest.raises(ValueError, match="no known dataset layout"):
        list(open_dataset(tmp_path))


def test_exr_needs_openexr_clear_message(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "OpenEXR", None)
    with pytest.raises(ImportError, match="pip install"):
        read_exr_channels(tmp_path / "a.exr")
