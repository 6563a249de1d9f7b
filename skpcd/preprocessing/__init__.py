"""Preprocessing of point clouds: spacing, neighbourhoods, normals, sampling."""

from skpcd.preprocessing._spacing import point_spacing

__all__ = ["point_spacing"]
