"""Reading and writing point clouds (text, NPY, PLY, PCD, LAS/LAZ) and models."""

from skpcd.io._api import SUPPORTED_EXTENSIONS, read_point_cloud, write_point_cloud
from skpcd.io._labelled import read_class_names, write_labelled_scan
from skpcd.io._las import LasExtent, iter_points, read_las_extent
from skpcd.io._model import load_model, save_model
from skpcd.io._segment_folder import read_segments

__all__ = [
    "SUPPORTED_EXTENSIONS",
    "LasExtent",
    "iter_points",
    "load_model",
    "read_class_names",
    "read_las_extent",
    "read_point_cloud",
    "read_segments",
    "save_model",
    "write_labelled_scan",
    "write_point_cloud",
]
