"""Scene segmentation: ground removal, DBSCAN with automatic eps, Euclidean clusters.

A scene becomes object segments in a few steps: :class:`GroundFilter`
removes the terrain (chosen from what :func:`describe_scan` finds the scan
to be: SMRF for airborne tiles, the cloth simulation filter with the bases
of objects given back for street scans),
facades and overhead wires are taken out as segments of their own,
:class:`AutoEpsDBSCAN` or :class:`EuclideanClusters` cluster the rest and
clusters holding several vertical trunks are split; :func:`segment_scene`
chains them with a segment-size range, in memory or, with an SMRF preset
and no structures, tile by tile (:func:`tile_scene`) for scans larger than
memory.
"""

import importlib

from skpcd.segmentation._clusters import EuclideanClusters, euclidean_clusters
from skpcd.segmentation._dbscan import AutoEpsDBSCAN, estimate_eps
from skpcd.segmentation._eps_plot import plot_eps_curve
from skpcd.segmentation._range_image import RangeImage, range_image
from skpcd.segmentation._result import SceneSegmentation
from skpcd.segmentation._scan_kind import (
    SCAN_KINDS,
    ScanKind,
    describe_scan,
    sweep_coordinates,
)
from skpcd.segmentation._scene import segment_scene
from skpcd.segmentation._structures import STRUCTURE_DEFAULTS
from skpcd.segmentation._sweeps import SWEEP_DEFAULTS, SweepSegmenter, segment_sweep
from skpcd.segmentation.ground import GROUND_PRESETS, GroundFilter
from skpcd.segmentation.tiling import TiledScene, TileGrid, tile_scene

__all__ = [
    "GROUND_PRESETS",
    "SCAN_KINDS",
    "STRUCTURE_DEFAULTS",
    "SWEEP_DEFAULTS",
    "AutoEpsDBSCAN",
    "EuclideanClusters",
    "GroundFilter",
    "RangeImage",
    "ScanKind",
    "SceneSegmentation",
    "SweepSegmenter",
    "TileGrid",
    "TiledScene",
    "describe_scan",
    "estimate_eps",
    "euclidean_clusters",
    "make_scene",
    "plot_eps_curve",
    "range_image",
    "segment_scene",
    "segment_sweep",
    "sweep_coordinates",
    "tile_scene",
]


def __getattr__(name):
    # make_scene lives in skpcd.datasets; loaded when asked for, so that
    # importing skpcd.segmentation does not load the street simulator
    if name == "make_scene":
        return importlib.import_module("skpcd.datasets").make_scene
    raise AttributeError(f"module 'skpcd.segmentation' has no attribute {name!r}")
