"""Point-cloud files read chunk by chunk, for scans larger than memory.

LAS/LAZ files are streamed (:func:`skpcd.io.iter_points`) and their bounds
come from the header; other formats have no chunked reader here and are
read whole, then handed out in chunks, so that the callers (the tiling of
:func:`skpcd.segmentation.tile_scene`, the segment members of the CLI) see
one interface.
"""

import os
from pathlib import Path

from skpcd.io._api import read_point_cloud
from skpcd.io._common import group_fields
from skpcd.io._las_reader import iter_points, read_las_extent

__all__ = ["file_bounds", "is_path", "is_streamed", "iter_file_chunks"]


def is_path(source):
    """Whether ``source`` names a file (rather than holding the points)."""
    return isinstance(source, (str, os.PathLike))


def is_streamed(path):
    """Whether the file is read chunk by chunk (LAS/LAZ), not whole."""
    return Path(os.fspath(path)).suffix.lower() in (".las", ".laz")


def iter_file_chunks(path, chunk_size, *, fields=None):
    """Chunks of xyz (float64, ``(n, 3)``) of a point-cloud file; with
    ``fields`` True, ``(xyz, extras)`` chunks with every field of the file,
    named as :func:`~skpcd.io.read_point_cloud` with ``fields="all"`` names
    them."""
    if is_streamed(path):
        if not fields:
            yield from iter_points(path, chunk_size=chunk_size)
            return
        names = [
            n for n in read_las_extent(path).dimensions if n not in ("X", "Y", "Z")
        ]
        for xyz, extras in iter_points(path, chunk_size=chunk_size, fields=names):
            yield xyz, group_fields(extras)[0]
        return
    # not out of core: no chunked reader for this format
    if not fields:
        xyz = read_point_cloud(path)
        for start in range(0, len(xyz), chunk_size):
            yield xyz[start : start + chunk_size]
        return
    xyz, extras = read_point_cloud(path, fields="all")
    for start in range(0, len(xyz), chunk_size):
        stop = start + chunk_size
        yield xyz[start:stop], {k: v[start:stop] for k, v in extras.items()}


def file_bounds(path):
    """``(mins, maxs)`` from a LAS/LAZ header (no pass over the points), or
    None for a format without one."""
    if not is_streamed(path):
        return None
    extent = read_las_extent(path)
    return extent.mins, extent.maxs
