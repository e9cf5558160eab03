"""Synthetic benchmark generation: procedural and asset-mesh scenes, camera poses, sensor noise, writer.

Not imported by ``import depthnormals``; trimesh (user meshes) and tqdm (progress bar) are
imported only when used (``pip install 'depthnormals[synth]'``).

Examples
--------
>>> from depthnormals.synth import scene_names
>>> scene_names("indoor")[:3]
('living_room', 'office', 'classroom')
"""

from __future__ import annotations

from .catalog import SCENE_SETS, make_scene, scene_names
from .noise import (
    MODELS,
    gaussian_noise,
    kinect_v1_noise,
    kinect_v2_noise,
    noise_std,
    parse_noise_spec,
    realsense_d4xx_noise,
    tof_noise,
)
from .poses import PoseConstraints, check_view, sample_poses
from .presets import PRESETS, SSN_NOISE_MODELS, preset
from .scenes import Scene, load_mesh_scene
from .writer import FORMAT, FORMAT_VERSION, SynthSummary, export_3f2n, generate, scene_plan

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MODELS",
    "PRESETS",
    "SCENE_SETS",
    "SSN_NOISE_MODELS",
    "PoseConstraints",
    "Scene",
    "SynthSummary",
    "check_view",
    "export_3f2n",
    "gaussian_noise",
    "generate",
    "kinect_v1_noise",
    "kinect_v2_noise",
    "load_mesh_scene",
    "make_scene",
    "noise_std",
    "parse_noise_spec",
    "preset",
    "realsense_d4xx_noise",
    "sample_poses",
    "scene_names",
    "scene_plan",
    "tof_noise",
]
