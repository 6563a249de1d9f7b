"""Reading and writing point clouds (text, NPY, PLY, PCD, LAS/LAZ)."""

from skpcd.io._api import (
    SUPPORTED_EXTENSIONS,
    read_point_cloud,
    read_segments,
    write_point_cloud,
)

__all__ = [
    "SUPPORTED_EXTENSIONS",
    "read_point_cloud",
    "read_segments",
    "write_point_cloud",
]
