"""The estimators. Importing this package registers every one of them."""

from .d2nt import d2nt
from .threefn import three_filters_to_normal

__all__ = ["d2nt", "three_filters_to_normal"]
