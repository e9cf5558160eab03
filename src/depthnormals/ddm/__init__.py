"""The discontinuity discrimination module (DDM) of 3F2N+, a plug-in for every estimator.

``discontinuity_discrimination(normals, depth, K, ...)`` refines the output of any estimator;
``estimate_normals(..., method="<name>+")`` runs estimator ``<name>`` followed by it.

Two parts. **The paper's module** (``selection="curvature"``): ``curvature`` (the depth
curvature), ``correlation`` (Kendall, Pearson), ``selection`` (stage 1), ``crf`` and
``crf_ring`` (stage 3), ``_module`` (the entry point), ``threefn_plus`` (the fused 3f2n+).
**Our adaptive selection** (the default ``selection="auto"``): ``noise`` (the noise estimate),
``support`` (the support measured on the depth), ``boxfit`` (plane fits over box windows),
``planes`` (plane hypotheses for clean depth), ``planefit``, and ``auto`` (which branch runs;
``noise_profile``). docs/3f2n-plus.md says which measurement chose each.

``depth_curvature`` and ``kendall_map`` expose the two discriminators; ``plane_normals`` and
``box_fit_normals`` the clean and noisy branches of the default; ``noise_profile`` what it
reads of the noise.
"""

from ._module import (
    NEIGHBOURHOODS,
    RENAMED,
    ModuleOptions,
    discontinuity_discrimination,
    module_defaults,
    renamed_option_error,
)
from .auto import NoiseProfile, noise_profile
from .boxfit import box_fit_normals
from .correlation import CORRELATIONS, kendall_map
from .curvature import CURVATURES, DERIVATIVES, depth_curvature
from .noise import estimate_noise, estimate_noise_map
from .planes import plane_normals
from .threefn_plus import fused_plus

__all__ = [
    "CORRELATIONS",
    "CURVATURES",
    "DERIVATIVES",
    "NEIGHBOURHOODS",
    "RENAMED",
    "ModuleOptions",
    "NoiseProfile",
    "box_fit_normals",
    "depth_curvature",
    "discontinuity_discrimination",
    "estimate_noise",
    "estimate_noise_map",
    "fused_plus",
    "kendall_map",
    "module_defaults",
    "noise_profile",
    "plane_normals",
    "renamed_option_error",
]
