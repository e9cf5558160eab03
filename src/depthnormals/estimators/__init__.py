"""The estimators: one public function each (the registry lists them by name)."""

from .cross_product import cross_product
from .d2nt import d2nt
from .pcl import (
    pcl_average_3d_gradient,
    pcl_average_depth_change,
    pcl_covariance_matrix,
    pcl_integral_image,
    pcl_simple_3d_gradient,
)
from .pointcloud import angle_weighted, area_weighted, plane_pca, plane_svd, vector_svd
from .range_image import fals, line_mod, sri
from .roadseg import sne_roadseg
from .sda_sne import sda_sne
from .threefn import three_filters_to_normal

__all__ = [
    "angle_weighted",
    "area_weighted",
    "cross_product",
    "d2nt",
    "fals",
    "line_mod",
    "pcl_average_3d_gradient",
    "pcl_average_depth_change",
    "pcl_covariance_matrix",
    "pcl_integral_image",
    "pcl_simple_3d_gradient",
    "plane_pca",
    "plane_svd",
    "sda_sne",
    "sne_roadseg",
    "sri",
    "three_filters_to_normal",
    "vector_svd",
]
