"""COPC files (Cloud Optimized Point Clouds): the octree index, read by bounds.

A COPC file is a LAZ 1.4 file whose points are stored one octree node per
LAZ chunk, with a COPC info VLR (user id ``copc``, record 1, the first VLR)
giving the octree's cube, and a hierarchy (the ``copc`` EVLR 1000, in pages)
giving each node's key ``(level, x, y, z)``, chunk offset, chunk size and
point count. :func:`read_copc_index` reads and checks that index, and
:func:`read_nodes` decodes the x, y, z of some nodes only (lazrs's selective
decompression: the other layers of the chunks are skipped), so that a region
of a scan is read without the rest.

Every point keeps its index in file order, the order in which
:func:`~skpcd.io.read_point_cloud` returns the points of the same file (LAZ
chunks in the order of their offsets): the nodes are sorted by offset and
numbered by their cumulative point counts, and the index is checked against
the file's LAZ chunk table, node for chunk, so that the two orders cannot
differ.
"""

import math
import os
import struct
import typing
from pathlib import Path

import numpy as np

from skpcd.io._las_structure import (
    cannot_read,
    check_file,
    checked_layout,
    decoding,
)

__all__ = ["COPC_USER_ID", "CopcIndex", "is_copc", "read_copc_index", "read_nodes"]

_INFO = ("copc", 1)
_INFO_BYTES = 160
_HIERARCHY = ("copc", 1000)
#: user id of every COPC record (info, hierarchy, extents): all describe the
#: octree order of the points
COPC_USER_ID = "copc"
# a hierarchy entry: key (level, x, y, z), offset, byte size, point count
_ENTRY = struct.Struct("<4iQii")
_NODE_ARRAYS = ("keys", "offset", "nbytes", "count", "start", "lower", "upper")
# deeper than any octree of a real scan (2**40 cells along an axis)
_MAX_LEVEL = 40


class CopcIndex(typing.NamedTuple):
    """The checked octree of a COPC file (:func:`read_copc_index`).

    The node arrays hold the nodes with points, sorted by offset (file order).

    Attributes
    ----------
    path : str
        The file.
    laszip : bytes
        The laszip VLR's data (how the chunks are compressed).
    record_length : int
        Bytes per point record.
    n_points : int
        Points in the file (the header's count, checked against the nodes).
    scales, offsets : ndarray of shape (3,)
        The header's coordinate scales and offsets.
    mins, maxs : ndarray of shape (3,)
        The bounds the header declares.
    keys : ndarray of shape (n_nodes, 4), dtype int64
        ``(level, x, y, z)`` of each node.
    offset, nbytes, count, start : ndarray of shape (n_nodes,), dtype int64
        Each node's chunk (first byte and size), its points and the file
        index of its first point.
    lower, upper : ndarray of shape (n_nodes, 3)
        Each node's cube.
    """

    path: str
    laszip: bytes
    record_length: int
    n_points: int
    scales: np.ndarray
    offsets: np.ndarray
    mins: np.ndarray
    maxs: np.ndarray
    keys: np.ndarray
    offset: np.ndarray
    nbytes: np.ndarray
    count: np.ndarray
    start: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @property
    def slack(self):
        """How far a point may lie outside its node's cube: one quantum of
        the coordinates (a writer may assign a point to a node before
        rounding it to the file's scale)."""
        return float(np.max(np.abs(self.scales)))

    def nodes_in(self, x0, y0, x1, y1):
        """Rows of the nodes whose cube, grown by :attr:`slack`, meets the
        rectangle ``x0..x1, y0..y1`` (infinite sides allowed), in file order."""
        s = self.slack
        meets = (
            (self.lower[:, 0] - s <= x1) & (self.upper[:, 0] + s >= x0)
            & (self.lower[:, 1] - s <= y1) & (self.upper[:, 1] + s >= y0)
        )  # fmt: skip
        return np.flatnonzero(meets)

    def subset(self, rows):
        """The index of the nodes ``rows`` only (what a task needs to read a
        region: a few nodes, not the whole octree)."""
        rows = np.asarray(rows, dtype=np.int64)
        return self._replace(
            **{name: getattr(self, name)[rows] for name in _NODE_ARRAYS}
        )


def is_copc(path):
    """Whether ``path`` is a COPC file: a LAZ file whose first VLR is a COPC
    info VLR (its name alone says nothing). Reads the header and the VLRs
    only; a file that is not a readable LAS/LAZ file is not COPC here (its
    reader reports the problem)."""
    path = Path(os.fspath(path))
    if path.suffix.lower() != ".laz" or not path.is_file():
        return False
    try:
        layout = checked_layout(path, points=False)
    except (OSError, ValueError):
        return False
    return bool(layout.vlrs) and tuple(layout.vlrs[0][:2]) == _INFO


def _info(path, f, layout):
    """center, halfsize, root page offset and size of the COPC info VLR."""
    _, _, start, length = layout.vlrs[0]
    if length != _INFO_BYTES:
        raise cannot_read(
            path, f"the COPC info VLR has {length} bytes ({_INFO_BYTES} expected)"
        )
    f.seek(start)
    raw = f.read(_INFO_BYTES)
    center = np.array(struct.unpack_from("<3d", raw, 0))
    (halfsize,) = struct.unpack_from("<d", raw, 24)
    root, root_size = struct.unpack_from("<QQ", raw, 40)
    if not (np.all(np.isfinite(center)) and math.isfinite(halfsize) and halfsize > 0):
        raise cannot_read(
            path,
            f"invalid COPC octree: center {center.tolist()}, halfsize {halfsize}",
        )
    return center, halfsize, root, root_size


def _walk_hierarchy(path, f, size, root, root_size):
    """Every entry of the hierarchy pages with points, as rows of
    ``(level, x, y, z, offset, bytes, count)``; the pages are checked
    against the file (in it, whole entries, each read once)."""
    rows, seen, pages = [], set(), [(root, root_size)]
    while pages:
        start, length = pages.pop()
        if start in seen:
            raise cannot_read(
                path,
                f"corrupt COPC hierarchy: the page at byte {start} is reached twice",
            )
        seen.add(start)
        if length % _ENTRY.size or start + length > size:
            raise cannot_read(
                path,
                f"corrupt COPC hierarchy: a page of {length} bytes at byte {start} "
                f"(whole {_ENTRY.size}-byte entries within the file's {size} "
                "bytes expected)",
            )
        f.seek(start)
        raw = f.read(length)
        for level, x, y, z, offset, nbytes, count in _ENTRY.iter_unpack(raw):
            key = (level, x, y, z)
            if not 0 <= level <= _MAX_LEVEL or not all(
                0 <= c < 2**level for c in (x, y, z)
            ):
                raise cannot_read(
                    path, f"corrupt COPC hierarchy: invalid node key {key}"
                )
            if count == -1:
                pages.append((offset, nbytes))
            elif count > 0:
                rows.append((*key, offset, nbytes, count))
            elif count < 0:
                raise cannot_read(
                    path, f"corrupt COPC hierarchy: node {key} has {count} points"
                )
    return rows


def _check_nodes(path, layout, nodes):
    """The nodes (sorted by offset) against the header's point count and the
    LAZ chunk table: node k is chunk k, same first byte, points and bytes."""
    n_indexed = int(nodes[:, 6].sum())
    if n_indexed != layout.n_points:
        raise cannot_read(
            path,
            f"corrupt COPC hierarchy: its nodes hold {n_indexed} points, the "
            f"header declares {layout.n_points}",
        )
    table, pos = [], layout.offset + 8  # the chunks follow the table's offset
    for c, b in layout.chunks:
        if c > 0:
            table.append((pos, int(c), int(b)))
        pos += b
    ours = [(int(o), int(c), int(b)) for o, b, c in nodes[:, 4:7]]
    if table != ours:
        k = next(
            (k for k, (a, b) in enumerate(zip(table, ours, strict=False)) if a != b),
            min(len(table), len(ours)),
        )
        node = f"node at byte {ours[k][0]}" if k < len(ours) else "no node"
        chunk = f"chunk at byte {table[k][0]}" if k < len(table) else "no chunk"
        raise cannot_read(
            path,
            f"corrupt COPC hierarchy: it does not index the LAZ chunks ({len(ours)} "
            f"nodes, {len(table)} chunks; {node} where the chunk table has {chunk})",
        )


def read_copc_index(path):
    """The octree of a COPC file, read and checked.

    The header, VLRs, EVLRs and LAZ chunk table are checked as for any LAZ
    file (:func:`~skpcd.io._las_structure.checked_layout`); then the COPC
    info VLR, every hierarchy page (within the file, each reached once), the
    node keys, and the nodes against the header's point count and the chunk
    table. Nothing is allocated from a count before it is checked.

    Parameters
    ----------
    path : str or path-like
        A COPC ``.laz`` file.

    Returns
    -------
    index : CopcIndex
        The nodes with points, in file order.

    Raises
    ------
    ImportError
        If laspy is not installed.
    PointCloudFileError
        If the file is not a readable COPC file: a one-line message naming
        the file and the problem.
    """
    path = check_file(path)
    layout = checked_layout(path)
    if not (layout.vlrs and tuple(layout.vlrs[0][:2]) == _INFO):
        raise cannot_read(path, "not a COPC file (its first VLR is not COPC info)")
    if layout.chunks is None:
        raise cannot_read(path, "reading COPC files needs lazrs: pip install lazrs")
    laszip = next(v for v in layout.vlrs if v[:2] == ("laszip encoded", 22204))
    with open(path, "rb") as f:
        center, halfsize, root, root_size = _info(path, f, layout)
        rows = _walk_hierarchy(path, f, layout.size, root, root_size)
        f.seek(laszip[2])
        record = f.read(laszip[3])
        f.seek(131)
        values = struct.unpack("<12d", f.read(96))
    nodes = np.array(rows, dtype=np.int64).reshape(-1, 7)
    nodes = nodes[np.argsort(nodes[:, 4], kind="stable")]
    _check_nodes(path, layout, nodes)
    count = nodes[:, 6]
    side = 2 * halfsize / 2.0 ** nodes[:, 0]
    lower = center - halfsize + side[:, None] * nodes[:, 1:4]
    return CopcIndex(
        str(path),
        record,
        layout.record_length,
        layout.n_points,
        np.array(values[0:3]),
        np.array(values[3:6]),
        np.array(values[7:12:2]),
        np.array(values[6:12:2]),
        nodes[:, :4],
        nodes[:, 4].copy(),
        nodes[:, 5].copy(),
        count.copy(),
        np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64),
        lower,
        lower + side[:, None],
    )


def read_nodes(index, rows):
    """The points of some nodes of a COPC file, node by node.

    Only the x, y and z layers of the chunks are decompressed. Each node's
    points are checked to lie in its cube (grown by the index's slack).

    Parameters
    ----------
    index : CopcIndex
        The file's octree.
    rows : sequence of int
        Nodes to read (rows of the index), in the order wanted.

    Yields
    ------
    row : int
        The node.
    xyz : ndarray of shape (count, 3), dtype float64
        Its points, scaled as :func:`~skpcd.io.read_point_cloud` scales
        them, in file order (their file indices are ``start[row]`` onwards).

    Raises
    ------
    PointCloudFileError
        If a chunk cannot be read or decoded, or holds a point outside its
        node.
    """
    import lazrs

    path = index.path
    selection = lazrs.DecompressionSelection(
        lazrs.SELECTIVE_DECOMPRESS_XY_RETURNS_CHANNEL | lazrs.SELECTIVE_DECOMPRESS_Z
    )
    n_bytes = index.record_length
    with open(path, "rb") as f:
        for row in rows:
            offset, size, count = (
                int(index.offset[row]), int(index.nbytes[row]), int(index.count[row])
            )  # fmt: skip
            f.seek(offset)
            raw = f.read(size)
            if len(raw) != size:
                raise cannot_read(
                    path,
                    f"truncated: the COPC node at byte {offset} has {size} bytes, "
                    f"the file {len(raw)}",
                )
            with decoding(path):
                out = np.zeros(count * n_bytes, dtype=np.uint8)
                lazrs.decompress_points_with_chunk_table(
                    raw, index.laszip, out, [(count, size)], selection
                )
            # X, Y, Z lead every record (int32, little-endian), scaled as
            # laspy scales them
            ints = out.reshape(count, n_bytes)[:, :12].copy().view("<i4")
            xyz = ints * index.scales + index.offsets
            s = index.slack
            lo, hi = index.lower[row] - s, index.upper[row] + s
            if np.any(xyz < lo) or np.any(xyz > hi):
                raise cannot_read(
                    path,
                    f"corrupt COPC: node {tuple(index.keys[row].tolist())} (chunk "
                    f"at byte {offset}) decodes to points outside its cube",
                )
            yield row, xyz
