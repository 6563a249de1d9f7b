"""Descriptors of segments and points."""

from skpcd.features._shape import ShapeFeatures, shape_features

__all__ = ["ShapeFeatures", "shape_features"]
