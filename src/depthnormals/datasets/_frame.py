"""The frame record every dataset reader yields."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Frame"]


@dataclass
class Frame:
    """One depth image with its ground truth.

    Attributes
    ----------
    depth : ndarray (H, W), float32 or float64
        Planar depth; invalid pixels are 0 or NaN.
    normals : ndarray (H, W, 3), float32, or None
        Ground-truth unit normals facing the camera, NaN where there is none; None for datasets
        without ground-truth normals (TUM, ScanNet, KITTI, NYU).
    K : ndarray (3, 3), float64
        Camera matrix, 0-based pixel centres.
    mask : ndarray (H, W), bool
        True where the ground truth is valid (where the depth is valid when ``normals`` is None).
    name : str
        Frame name, unique inside its group (e.g. ``"000001"``).
    group : str
        Scene and variant, e.g. ``"indoor/room-03/clean"`` or ``"torusknot"``.
    meta : dict
        Anything else the reader knows (sidecar settings, pose, ...).
    """

    depth: np.ndarray
    normals: np.ndarray | None
    K: np.ndarray
    mask: np.ndarray
    name: str
    group: str = ""
    meta: dict = field(default_factory=dict)
