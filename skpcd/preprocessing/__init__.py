"""Preprocessing of point clouds: spacing, neighbourhoods, normals."""

from skpcd.preprocessing._neighbors import Neighborhoods, compute_neighborhoods
from skpcd.preprocessing._normals import NormalEstimator, estimate_normals
from skpcd.preprocessing._spacing import point_spacing

__all__ = [
    "Neighborhoods",
    "NormalEstimator",
    "compute_neighborhoods",
    "estimate_normals",
    "point_spacing",
]
