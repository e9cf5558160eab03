"""depthnormals.torch: the estimators of depthnormals on torch tensors.

Batched (B, 1, H, W) depth, any device, differentiable, ``torch.compile``-able; the same
conventions and the same results as the numba library (``docs/torch.md``).

Public API
----------
estimate_normals    normals (B, 3, H, W) of a batch of depth images
EstimateNormals     its ``nn.Module`` twin (a model layer or a data transform)
normals_mask        (B, 1, H, W) where an estimate exists
method_defaults     the options of a method and their defaults (those of the numba library)
METHODS             the method names the torch path implements
undistort_depth     a lens's distortion undone (the numpy function's pixels, on the device)

Importing this package imports torch; ``import depthnormals`` does not.
"""

from __future__ import annotations

from ._api import METHODS, EstimateNormals, estimate_normals, method_defaults, normals_mask
from ._lens import undistort_depth

__all__ = ["METHODS", "EstimateNormals", "estimate_normals", "method_defaults", "normals_mask",
           "undistort_depth"]
