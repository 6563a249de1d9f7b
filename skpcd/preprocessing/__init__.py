"""Preprocessing of point clouds: spacing, sampling, normals, outliers.

The neighbourhoods (:func:`compute_neighborhoods`, :class:`Neighborhoods`)
live in :mod:`skpcd.neighbors` and are importable from here too.
"""

from skpcd.neighbors import Neighborhoods, compute_neighborhoods
from skpcd.preprocessing._normals import NormalEstimator, estimate_normals
from skpcd.preprocessing._outliers import RadiusOutlierFilter, StatisticalOutlierFilter
from skpcd.preprocessing._sampling import GridSampler, grid_sample
from skpcd.preprocessing._spacing import point_spacing

__all__ = [
    "GridSampler",
    "Neighborhoods",
    "NormalEstimator",
    "RadiusOutlierFilter",
    "StatisticalOutlierFilter",
    "compute_neighborhoods",
    "estimate_normals",
    "grid_sample",
    "point_spacing",
]
