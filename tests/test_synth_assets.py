"""Asset-mesh scenes: the meshes (pybullet_data) with their licences, the recipes, the scene sets."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("pybullet_data", reason="asset-mesh scenes need pybullet (the assets extra)")
pytest.importorskip("trimesh", reason="asset meshes are read with trimesh")

from depthnormals.render import render_mesh
from depthnormals.synth import generate
from depthnormals.synth.asset_scenes import ASSET_INDOOR, ASSET_OUTDOOR
from depthnormals.synth.assets import ASSETS, asset_root, load_asset
from depthnormals.synth.catalog import make_scene, recipe_of_folder, scene_names
from depthnormals.synth.poses import sample_poses

SMALL_K, SMALL = (36.5, 36.5, 31.5, 26.0), (53, 64)  # the Kinect v2 field of view at 1/8 size
LICENCES = {"zlib", "BSD-2-Clause", "Apache-2.0"}


def test_every_asset_is_shipped_and_has_a_reuse_licence():
    root = asset_root()
    for name, a in ASSETS.items():
        assert (root / a.path).is_file(), name
        assert a.package == "pybullet" and a.path.startswith("pybullet_data/")
        assert a.licence in LICENCES, name
        assert a.scale > 0 and a.up in ("y", "z")
    # folders whose own notice is not a plain reuse licence are not used
    left_out = ("bicycle", "laikago", "duck", "bunny")
    assert not any(part in a.path for a in ASSETS.values() for part in left_out)


def test_load_asset_places_and_sizes_meshes():
    V, F = load_asset("mug")
    assert F.shape[1] == 3 and F.shape[0] > 500
    assert V[:, 2].min() == 0.0  # standing on z = 0, centred in x and y
    assert np.allclose((V[:, :2].min(0) + V[:, :2].max(0)) / 2, 0.0, atol=1e-12)
    V2, _ = load_asset("mug", height=0.3, rotate_z_deg=90.0, translate=(1.0, 2.0, 0.75))
    assert V2[:, 2].max() - V2[:, 2].min() == pytest.approx(0.3, rel=1e-12)
    assert V2[:, 2].min() == pytest.approx(0.75, abs=1e-12)
    # a 90-degree turn swaps the x and y extents
    ext, ext2 = np.ptp(V, axis=0), np.ptp(V2, axis=0) / (0.3 / np.ptp(V[:, 2]))
    assert ext2[0] == pytest.approx(ext[1], rel=1e-9) and ext2[1] == pytest.approx(ext[0], rel=1e-9)
    with pytest.raises(ValueError, match="unknown asset"):
        load_asset("sofa9")
    with pytest.raises(ValueError, match="height"):
        load_asset("mug", height=0.0)


def test_urdf_robots_are_assembled_at_rest_pose():
    # heights at rest (all joints 0) of the pybullet 3.2.7 models: r2d2 0.931 m (base to head
    # top), the Husky UGV 0.391 m, the KUKA iiwa arm 1.306 m, y-up monastery 30.36 m tall
    for name, height in (("r2d2", 0.931), ("husky", 0.391), ("kuka_iiwa", 1.306), ("monastery", 30.361)):
        V, _ = load_asset(name)
        assert np.ptp(V[:, 2]) == pytest.approx(height, abs=2e-3), name


def test_scene_sets():
    procedural = scene_names("indoor")
    assert len(procedural) == 10 and "living_room" in procedural
    assert scene_names("indoor", scenes="assets") == ASSET_INDOOR
    assert scene_names("outdoor", scenes="all") == scene_names("outdoor") + ASSET_OUTDOOR
    assert scene_names(scenes="all") == scene_names() + ASSET_INDOOR + ASSET_OUTDOOR
    assert not set(scene_names(scenes="assets")) & set(scene_names())
    assert all("-" not in n for n in scene_names(scenes="all"))  # folders are <recipe>-<index>
    assert recipe_of_folder("dining_table-04") == "dining_table"
    with pytest.raises(ValueError, match="scenes must be"):
        scene_names("indoor", scenes="real")


def test_asset_scene_is_reproducible_and_records_its_meshes():
    a, b = make_scene("dining_table", seed=3), make_scene("dining_table", seed=3)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    c = make_scene("dining_table", seed=4)
    assert not (a.vertices.shape == c.vertices.shape and np.array_equal(a.vertices, c.vertices))
    assert a.kind == "indoor" and a.meta["scene_set"] == "assets" and a.meta["seed"] == 3
    used = a.meta["assets"]
    assert {"mug", "tray"} <= {u["name"] for u in used}
    for u in used:
        assert u["licence"] == ASSETS[u["name"]].licence and u["path"] == ASSETS[u["name"]].path
    # camera boxes of a robot's or hand-held camera: centres 0.4-1.8 m high at most
    assert a.eye_box[0, 2] >= 0.4 and a.eye_box[1, 2] <= 1.8


@pytest.mark.parametrize("name", ["kids_room", "sidewalk"])
def test_asset_scene_renders(name):
    scene = make_scene(name, seed=0)
    pose = sample_poses(scene, 1, rng=np.random.default_rng(0), K=SMALL_K, size=SMALL)[0]
    r = render_mesh(scene.vertices, scene.faces, SMALL_K, pose=pose, width=SMALL[1], height=SMALL[0])
    valid = r.face >= 0
    assert valid.mean() >= 0.9  # the sampler's default min_valid
    assert np.all(np.isfinite(r.normals[valid])) and np.all(r.depth[valid] >= 0.5)
    assert 0.4 - 1e-9 <= pose[2, 3] <= 1.8 + 1e-9


def test_generate_asset_set(tmp_path):
    generate(tmp_path / "a", indoor=1, outdoor=0, views=1, size=SMALL, K=SMALL_K, noise=(),
             progress=False, scenes="assets")
    meta = json.loads((tmp_path / "a" / "dataset.json").read_text())
    assert meta["settings"]["scenes"] == "assets"
    assert meta["scenes"] == ["indoor/furnished_living-00"]
    info = json.loads((tmp_path / "a" / "indoor" / "furnished_living-00" / "scene.json").read_text())
    assert info["recipe"] == "furnished_living" and info["scene_set"] == "assets"
    assert all(u["licence"] in LICENCES for u in info["assets"]) and len(info["assets"]) >= 5
    # the default set writes no "scenes" key: procedural datasets keep their bytes
    generate(tmp_path / "p", indoor=1, outdoor=0, views=1, size=SMALL, K=SMALL_K, noise=(), progress=False)
    assert "scenes" not in json.loads((tmp_path / "p" / "dataset.json").read_text())["settings"]
    with pytest.raises(ValueError, match="scenes must be"):
        generate(tmp_path / "x", indoor=1, outdoor=0, views=1, scenes="real", progress=False)


def test_cli_scene_set(tmp_path, capsys):
    from depthnormals.cli import main

    out = tmp_path / "cli"
    argv = ["synth", str(out), "--scenes", "assets", "--indoor", "0", "--outdoor", "1", "--views", "1",
            "--width", "64", "--height", "53", "--noise", "none", "--no-progress"]
    assert main(argv) == 0
    assert "1 views" in capsys.readouterr().out
    assert json.loads((out / "dataset.json").read_text())["scenes"] == ["outdoor/street_assets-00"]
    with pytest.raises(ValueError, match="seed"):
        make_scene("pantry", seed=-1)
    with pytest.raises(ValueError, match="unknown scene recipe"):
        make_scene("pantry2")


def test_plain_synth_command_renders_the_realistic_set(tmp_path, capsys):
    """Issue 25: the default scene set is ``mixed``; its indoor views are as cluttered as real frames."""
    import statistics

    from depthnormals.cli import main
    from depthnormals.evaluate import synth_discontinuity_shares

    out = tmp_path / "plain"
    # the command, clean only (the share is measured on the clean ground truth)
    assert main(["synth", str(out), "--indoor", "3", "--outdoor", "0", "--views", "3", "--seed", "5",
                 "--noise", "none", "--no-progress"]) == 0
    meta = json.loads((out / "dataset.json").read_text())
    assert meta["settings"]["scenes"] == "mixed"
    shares = synth_discontinuity_shares(out)
    assert statistics.median(f for s in shares for f in s.frames) >= 0.20
    assert main(["synth", "x", "--dry-run"]) == 0
    assert "scenes mixed" in capsys.readouterr().out
