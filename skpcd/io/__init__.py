"""Reading and writing point clouds (text, NPY, PLY, PCD, LAS/LAZ) and models."""

from skpcd.io._api import (
    SUPPORTED_EXTENSIONS,
    read_point_cloud,
    read_segments,
    write_point_cloud,
)
from skpcd.io._model import load_model, save_model

__all__ = [
    "SUPPORTED_EXTENSIONS",
    "load_model",
    "read_point_cloud",
    "read_segments",
    "save_model",
    "write_point_cloud",
]
