"""Scene segmentation: ground removal, DBSCAN with automatic eps, Euclidean clusters.

A scene becomes object segments in three steps: :class:`GroundFilter`
removes the terrain, :class:`AutoEpsDBSCAN` or :class:`EuclideanClusters`
cluster the rest, and :func:`segment_scene` chains them with a segment-size
range, in memory or tile by tile (:func:`tile_scene`) for scans larger than
memory.
"""

from skpcd.segmentation._clusters import EuclideanClusters, euclidean_clusters
from skpcd.segmentation._dbscan import AutoEpsDBSCAN, estimate_eps, plot_eps_curve
from skpcd.segmentation._ground import GROUND_PRESETS, GroundFilter
from skpcd.segmentation._scene import SceneSegmentation, make_scene, segment_scene
from skpcd.segmentation._tiling import TiledScene, TileGrid, tile_scene

__all__ = [
    "GROUND_PRESETS",
    "AutoEpsDBSCAN",
    "EuclideanClusters",
    "GroundFilter",
    "SceneSegmentation",
    "TileGrid",
    "TiledScene",
    "estimate_eps",
    "euclidean_clusters",
    "make_scene",
    "plot_eps_curve",
    "segment_scene",
    "tile_scene",
]
