"""LAS and LAZ point clouds (the ASPRS LiDAR format), through laspy.

Through laspy, and lazrs for the compressed ``.laz`` (both core
dependencies); laspy is imported only when a file is read or written.

Reading returns x, y, z as scaled float64 coordinates, then every other
dimension of the point format under laspy's names (``intensity``,
``return_number``, ``classification``, ``gps_time``, ``red``...), then the
extra-bytes dimensions under their own names. Consecutive extra dimensions
``name_0 ... name_{c-1}`` of one type come back as one ``(n, c)`` field, as
:func:`write` stores such fields.

Writing uses LAS 1.4 point format 6, or 7 when there are colours, or 8 with
``nir``. Each coordinate axis gets the offset ``floor(min)`` and the scale
0.0001 (finer is pointless for LiDAR; coarser, by powers of ten, only when
the extent along the axis exceeds the 32-bit range at that scale, about 214
km), so coordinates are kept to 0.05 mm. Fields named as a standard dimension
of the point format are stored there (their values must fit its type: for
example ``classification`` 0-255, ``return_number`` 0-15); ``colors`` of
shape ``(n, 3)`` becomes ``red green blue`` when its values fit uint16;
``normals`` becomes the extra dimensions ``normal_x normal_y normal_z``; any
other field becomes extra bytes (``(n, c)`` fields as ``name_0 ...
name_{c-1}``).

Before laspy reads a file, its structure is read with :mod:`struct` and
checked against the file size (header, VLRs, EVLRs, point count, and for LAZ
the laszip VLR, the chunk table and the chunk headers), and every failure of
laspy or lazrs, lazrs's PanicException included, becomes a
PointCloudFileError: see the user guide's "What the LAS reader checks".

This module is the LAS/LAZ format of :func:`~skpcd.io.read_point_cloud` and
:func:`~skpcd.io.write_point_cloud` (its ``read`` and ``write``); the work is
done in :mod:`skpcd.io._las_structure` (the checks of the structure),
:mod:`skpcd.io._las_reader` (the points) and :mod:`skpcd.io._las_writer`.
"""

from skpcd.io._las_reader import LasExtent, iter_points, read, read_las_extent
from skpcd.io._las_writer import write

__all__ = ["LasExtent", "iter_points", "read", "read_las_extent", "write"]
