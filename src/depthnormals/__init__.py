"""depthnormals: surface normals from depth images.

Public API
----------
estimate_normals, methods          the dispatcher over every registered estimator
three_filters_to_normal, d2nt, ... one function per estimator
angular_error, normal_metrics      evaluation
Intrinsics, backproject            the camera (undistort_depth: lens distortion undone)
datasets, io                       readers and writers

``import depthnormals`` stays light: no torch, no matplotlib.
"""

from __future__ import annotations

from . import _numba_cache, datasets, io  # noqa: F401 (_numba_cache first: before any kernel)
from ._parallel import get_num_threads, set_num_threads
from ._validate import NoValidNormalWarning
from .camera import Intrinsics, as_intrinsics, backproject, undistort_depth
from .ddm import (
    NoiseProfile,
    discontinuity_discrimination,
    estimate_noise,
    estimate_noise_map,
    noise_profile,
)
from .ddm.uncertainty import kappa_to_uncertainty, uncertainty_to_covariance, uncertainty_to_kappa
from .estimators import (
    angle_weighted,
    area_weighted,
    cross_product,
    d2nt,
    fals,
    line_mod,
    pcl_integral_image,
    plane_pca,
    plane_svd,
    sda_sne,
    sne_roadseg,
    sri,
    three_filters_to_normal,
    vector_svd,
)
from .io import to_open3d
from .metrics import NormalMetrics, angular_error, normal_metrics
from .registry import estimate_normals, get_estimator, methods

__version__ = "0.1.0"

__all__ = [
    "Intrinsics",
    "NoValidNormalWarning",
    "NoiseProfile",
    "NormalMetrics",
    "__version__",
    "angle_weighted",
    "angular_error",
    "area_weighted",
    "as_intrinsics",
    "backproject",
    "cross_product",
    "d2nt",
    "datasets",
    "discontinuity_discrimination",
    "estimate_noise",
    "estimate_noise_map",
    "estimate_normals",
    "fals",
    "get_estimator",
    "get_num_threads",
    "io",
    "kappa_to_uncertainty",
    "line_mod",
    "methods",
    "noise_profile",
    "normal_metrics",
    "pcl_integral_image",
    "plane_pca",
    "plane_svd",
    "sda_sne",
    "set_num_threads",
    "sne_roadseg",
    "sri",
    "three_filters_to_normal",
    "to_open3d",
    "uncertainty_to_covariance",
    "uncertainty_to_kappa",
    "undistort_depth",
    "vector_svd",
]
