"""Descriptors of segments and points."""

from skpcd.features._fpfh import FPFHTransformer, compute_fpfh
from skpcd.features._improved import ImprovedPFHTransformer
from skpcd.features._overall import OverallDescriptor, box_dimensions
from skpcd.features._pfh import PFHTransformer, compute_pfh
from skpcd.features._shape import ShapeFeatures, shape_features
from skpcd.features._vertical import VerticalProfile, vertical_features

__all__ = [
    "FPFHTransformer",
    "ImprovedPFHTransformer",
    "OverallDescriptor",
    "PFHTransformer",
    "ShapeFeatures",
    "VerticalProfile",
    "box_dimensions",
    "compute_fpfh",
    "compute_pfh",
    "shape_features",
    "vertical_features",
]
