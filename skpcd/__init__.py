"""skpcd: point feature histograms and LiDAR segment identification for scikit-learn.

The public estimators and functions are importable from the top level; they
are loaded on first use so that ``import skpcd`` stays fast.
"""

import importlib

__version__ = "0.1.0.dev0"

_PUBLIC = {
    "AutoEpsDBSCAN": "skpcd.segmentation",
    "BagOfFeatures": "skpcd.encoding",
    "CaseBasedClassifier": "skpcd.classification",
    "EuclideanClusters": "skpcd.segmentation",
    "FPFHTransformer": "skpcd.features",
    "GroundFilter": "skpcd.segmentation",
    "ImprovedPFHTransformer": "skpcd.features",
    "PFHTransformer": "skpcd.features",
    "RejectUnknown": "skpcd.classification",
    "ShapeFeatures": "skpcd.features",
    "TwoStepClassifier": "skpcd.classification",
    "VerticalProfile": "skpcd.features",
    "check_point_clouds": "skpcd.utils",
    "make_default_pipeline": "skpcd.classification",
    "make_point_clouds": "skpcd.datasets",
    "make_urban_objects": "skpcd.datasets",
    "point_spacing": "skpcd.preprocessing",
    "read_point_cloud": "skpcd.io",
    "read_segments": "skpcd.io",
    "segment_scene": "skpcd.segmentation",
    "write_point_cloud": "skpcd.io",
}
_SUBMODULES = (
    "classification",
    "datasets",
    "encoding",
    "exceptions",
    "features",
    "io",
    "metrics",
    "preprocessing",
    "segmentation",
    "utils",
)

__all__ = sorted([*_PUBLIC, *_SUBMODULES, "__version__"])


def __getattr__(name):
    if name in _PUBLIC:
        value = getattr(importlib.import_module(_PUBLIC[name]), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f"skpcd.{name}")
    raise AttributeError(f"module 'skpcd' has no attribute {name!r}")


def __dir__():
    return __all__
