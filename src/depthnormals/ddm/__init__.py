"""The discontinuity discrimination module (DDM) of 3F2N+, a plug-in for every estimator.

``discontinuity_discrimination(normals, depth, K, ...)`` refines the output of any estimator;
``estimate_normals(..., method="<name>+")`` runs estimator ``<name>`` followed by it.
``depth_curvature`` and ``kendall_map`` expose the two discriminators.
"""

from ._module import NEIGHBOURHOODS, discontinuity_discrimination, fused_plus, module_defaults
from .boxfit import box_fit_normals  # r13 wiring
from .correlation import CORRELATIONS, kendall_map
from .curvature import CURVATURES, DERIVATIVES, depth_curvature
from .noise import estimate_noise  # r13 wiring

__all__ = [
    "CORRELATIONS",
    "CURVATURES",
    "DERIVATIVES",
    "NEIGHBOURHOODS",
    "box_fit_normals",  # r13 wiring
    "depth_curvature",
    "discontinuity_discrimination",
    "estimate_noise",  # r13 wiring
    "fused_plus",
    "kendall_map",
    "module_defaults",
]
