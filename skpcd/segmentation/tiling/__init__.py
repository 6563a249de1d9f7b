"""Segmentation tile by tile, for scans larger than memory.

:func:`tile_scene` cuts a scene (an array or a point-cloud file, read in
chunks) into the tiles of a :class:`TileGrid`, spilled to disk;
``segment_scene(..., tile_size=...)`` segments them with overlapping margins
and stitches the segments, with the same result as in memory
(:class:`TiledScene`). The parts: the tile geometry (``_geometry``), the
spill to disk (``_spill``), running the tiles on threads, processes or a
Dask cluster (``_dispatch``) and the segmentation and stitching
(``_segment``).
"""

from skpcd.segmentation.tiling._geometry import TileGrid
from skpcd.segmentation.tiling._segment import segment_tiled
from skpcd.segmentation.tiling._spill import TiledScene, tile_scene

__all__ = ["TileGrid", "TiledScene", "segment_tiled", "tile_scene"]
