"""Scene segmentation: ground removal, DBSCAN with automatic eps, Euclidean clusters.

A scene becomes object segments in three steps: :class:`GroundFilter`
removes the terrain, :class:`AutoEpsDBSCAN` or :class:`EuclideanClusters`
cluster the rest, and :func:`segment_scene` chains them with a segment-size
range.
"""

from skpcd.segmentation._clusters import EuclideanClusters, euclidean_clusters
from skpcd.segmentation._dbscan import AutoEpsDBSCAN, estimate_eps, plot_eps_curve
from skpcd.segmentation._ground import GROUND_PRESETS, GroundFilter
from skpcd.segmentation._scene import SceneSegmentation, make_scene, segment_scene

__all__ = [
    "GROUND_PRESETS",
    "AutoEpsDBSCAN",
    "EuclideanClusters",
    "GroundFilter",
    "SceneSegmentation",
    "estimate_eps",
    "euclidean_clusters",
    "make_scene",
    "plot_eps_curve",
    "segment_scene",
]
