"""Descriptors of segments and points."""

from skpcd.features._pfh import (
    FPFHTransformer,
    PFHTransformer,
    compute_fpfh,
    compute_pfh,
)
from skpcd.features._shape import ShapeFeatures, shape_features

__all__ = [
    "FPFHTransformer",
    "PFHTransformer",
    "ShapeFeatures",
    "compute_fpfh",
    "compute_pfh",
    "shape_features",
]
