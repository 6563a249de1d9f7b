"""Reading and writing point clouds (text, NPY, PLY, PCD, LAS/LAZ) and models.

The functions are loaded on first use, so that the readers load without
scikit-learn (which only the model files need): ``skpcd info`` stays fast.
"""

import importlib

_PUBLIC = {
    "SUPPORTED_EXTENSIONS": "skpcd.io._api",
    "ClassMap": "skpcd.io._point_labels",
    "LasExtent": "skpcd.io._las",
    "LinearUnit": "skpcd.io._crs",
    "PointLabels": "skpcd.io._point_labels",
    "iter_points": "skpcd.io._las",
    "labelled_scan_paths": "skpcd.io._point_labels",
    "linear_unit": "skpcd.io._crs",
    "load_model": "skpcd.io._model",
    "read_las_crs": "skpcd.io._crs",
    "read_class_names": "skpcd.io._labelled",
    "read_las_extent": "skpcd.io._las",
    "read_class_map": "skpcd.io._point_labels",
    "read_point_cloud": "skpcd.io._api",
    "read_point_labels": "skpcd.io._point_labels",
    "read_predicted_labels": "skpcd.io._point_labels",
    "read_segments": "skpcd.io._segment_folder",
    "save_model": "skpcd.io._model",
    "write_labelled_scan": "skpcd.io._labelled",
    "write_point_cloud": "skpcd.io._api",
}

__all__ = sorted(_PUBLIC)


def __getattr__(name):
    if name in _PUBLIC:
        value = getattr(importlib.import_module(_PUBLIC[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'skpcd.io' has no attribute {name!r}")


def __dir__():
    return __all__
