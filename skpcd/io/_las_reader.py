"""The points of a LAS/LAZ file, read through laspy once its structure is checked.

:func:`read` returns x, y, z as scaled float64 coordinates, then every other
dimension of the point format under laspy's names, then the extra-bytes
dimensions (see :mod:`skpcd.io._las`); :func:`iter_points` streams them chunk
by chunk and :func:`read_las_extent` reads the header only. Every file is
first checked by :func:`~skpcd.io._las_structure.checked_layout`, and the
points laspy decodes are counted against the header.
"""

import contextlib
import os
import typing
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from skpcd.exceptions import PointCloudFileError
from skpcd.io._common import check_chunk_size, group_fields
from skpcd.io._las_structure import (
    cannot_read,
    check_file,
    checked_layout,
    decoding,
    import_laspy,
)

__all__ = [
    "LasExtent",
    "checked_chunks",
    "iter_points",
    "open_checked",
    "read",
    "read_las_extent",
    "read_las_header",
    "read_vlr_records",
    "scaled_xyz",
]


def _open(laspy, path, layout=None):
    layout = checked_layout(path) if layout is None else layout
    with decoding(path):
        return laspy.open(str(path), laz_backend=layout.laz_backend)


@contextlib.contextmanager
def open_checked(laspy, path):
    """Open a checked ``path`` with laspy; yields ``(reader, n_points)``."""
    layout = checked_layout(path)
    with _open(laspy, path, layout) as reader:
        with decoding(path):  # laspy's own parsing of the header and VLRs
            reader.header.point_format.dtype()
        yield reader, layout.n_points


def checked_chunks(reader, path, chunk_size, n_points):
    """The point records of ``reader``, ``chunk_size`` at a time, failures
    turned into PointCloudFileError, and fewer points than the header
    declares an error too."""
    chunks = reader.chunk_iterator(chunk_size)
    n_read = 0
    while n_read < n_points:
        with decoding(path):
            chunk = next(chunks, None)
        if chunk is None or len(chunk) == 0:
            break
        n_read += len(chunk)
        yield chunk
    if n_read < n_points:
        raise cannot_read(
            path,
            f"truncated: the header declares {n_points} points, {n_read} could be read",
        )


def read_las_header(path):
    """The laspy header of a LAS/LAZ file (its VLRs and EVLRs too), once the
    structure of the file is checked: what an output carries through
    (:func:`~skpcd.io._las_writer.carried_header`) and what ``skpcd info``
    shows."""
    laspy = import_laspy()
    path = check_file(path)
    layout = checked_layout(path)
    with decoding(path):
        with open(path, "rb") as f:
            return laspy.LasHeader.read_from(f, read_evlrs=bool(layout.evlrs))


def read_vlr_records(path):
    """Every VLR and EVLR of a LAS/LAZ file as ``(user_id, record_id, data)``,
    read from the bytes (laspy rewrites the records it knows)."""
    path = check_file(path)
    layout = checked_layout(path, points=False)
    records = []
    with open(path, "rb") as f:
        for user_id, record_id, start, length in layout.vlrs + layout.evlrs:
            f.seek(start)
            records.append((user_id, record_id, f.read(length)))
    return records


class LasExtent(typing.NamedTuple):
    """What :func:`read_las_extent` returns (a named tuple).

    Attributes
    ----------
    n_points : int
        Number of points the header declares.
    mins : ndarray of shape (3,)
        Lowest x, y, z the header declares.
    maxs : ndarray of shape (3,)
        Highest x, y, z the header declares.
    dimensions : tuple of str
        The dimensions of the points, under laspy's names (``X``, ``Y``,
        ``Z``, ``intensity``..., then the extra bytes).
    """

    n_points: int
    mins: np.ndarray
    maxs: np.ndarray
    dimensions: tuple


def read_las_extent(path):
    """Point count and bounding box of a LAS/LAZ file, from its header only.

    Nothing but the header and the structure of the file (VLRs, the size of
    the point data, for LAZ the chunk table) is read, so this is instant
    whatever the size of the file. The bounds are those the writer stored
    (laspy and most tools store the exact extent of the points).

    Parameters
    ----------
    path : str or path-like
        A ``.las`` or ``.laz`` file.

    Returns
    -------
    extent : LasExtent
        Named tuple ``(n_points, mins, maxs, dimensions)``.

    Raises
    ------
    ImportError
        If laspy is not installed.
    MissingFileError
        If the file does not exist.
    PointCloudFileError
        If the file is not a readable LAS/LAZ file, or does not hold the
        points its header declares (see the user guide's "What the LAS
        reader checks").

    See Also
    --------
    iter_points : Read the points chunk by chunk.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from skpcd.io import read_las_extent, write_point_cloud
    >>> path = os.path.join(tempfile.mkdtemp(), "scan.las")
    >>> write_point_cloud(path, [[0, 0, 0], [10, 20, 3], [5, 5, 1]])
    >>> extent = read_las_extent(path)
    >>> extent.n_points, extent.maxs.tolist()
    (3, [10.0, 20.0, 3.0])
    """
    laspy = import_laspy()
    path = check_file(path)
    with decoding(path), open_checked(laspy, path) as (reader, n_points):
        header = reader.header
        return LasExtent(
            n_points,
            np.array(header.mins, dtype=np.float64),
            np.array(header.maxs, dtype=np.float64),
            tuple(header.point_format.dimension_names),
        )


def iter_points(path, *, chunk_size=1_000_000, fields=None):
    """Read a LAS/LAZ file chunk by chunk, in file order.

    Only one chunk is in memory at a time (laspy's chunk iterator), so a scan
    larger than memory can be streamed: concatenated, the chunks are exactly
    what :func:`read_point_cloud` returns for the whole file (with
    ``nonfinite="keep"``; LAS coordinates are always finite).

    The structure of the file is checked when this is called, before the
    first chunk: a file that does not hold the points its header declares
    (truncated, or a corrupt count) raises then, naming both counts.

    Parameters
    ----------
    path : str or path-like
        A ``.las`` or ``.laz`` file.
    chunk_size : int, default=1_000_000
        Points per chunk (the last chunk may be shorter). About 24 bytes per
        point for xyz, plus the requested fields.
    fields : None or list of str, default=None
        LAS dimensions to return besides xyz, by laspy's names
        (``"intensity"``, ``"classification"``, ``"gps_time"``, an extra
        dimension...). With None only the points are yielded.

    Yields
    ------
    points : ndarray of shape (n_chunk, 3), dtype float64
        The scaled coordinates of the next ``chunk_size`` points.
    extras : dict of str to ndarray
        Only when ``fields`` is given (the chunk is then a tuple
        ``(points, extras)``): each requested dimension for those points.

    Raises
    ------
    ImportError
        If laspy is not installed.
    ValueError
        If ``chunk_size`` is not a positive integer.
    MissingFileError
        If the file does not exist.
    PointCloudFileError
        If the file is not a readable LAS/LAZ file, is truncated, or lacks a
        requested field. Compressed data that fails to decode in the middle
        of a LAZ file raises after the chunks before it were yielded.

    See Also
    --------
    read_las_extent : The point count and bounds, from the header.
    read_point_cloud : Read a whole file.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from skpcd.io import iter_points, write_point_cloud
    >>> path = os.path.join(tempfile.mkdtemp(), "scan.las")
    >>> write_point_cloud(path, np.arange(30.0).reshape(10, 3))
    >>> [len(chunk) for chunk in iter_points(path, chunk_size=4)]
    [4, 4, 2]
    """
    chunk_size = check_chunk_size(chunk_size)
    if fields is not None:
        fields = [fields] if isinstance(fields, str) else list(fields)
    laspy = import_laspy()
    path = check_file(path)
    layout = checked_layout(path)
    return _iter_points(laspy, path, layout, chunk_size, fields)


def _iter_points(laspy, path, layout, chunk_size, fields):
    with decoding(path), _open(laspy, path, layout) as reader:
        available = set(reader.header.point_format.dimension_names)
        missing = [f for f in fields or () if f not in available or f in "XYZ"]
        if missing:
            raise PointCloudFileError(
                path,
                f"no field {missing[0]!r}; the file has: "
                + ", ".join(n for n in available if n not in ("X", "Y", "Z")),
            )
        header = reader.header
        for chunk in checked_chunks(reader, path, chunk_size, layout.n_points):
            xyz = scaled_xyz(chunk.array, header.scales, header.offsets)
            if fields is None:
                yield xyz
            else:
                yield xyz, {f: np.array(chunk[f]) for f in fields}


def _read_raw(path, layout, dtype):
    """The point records of an uncompressed LAS file, read straight into one
    array of ``dtype`` (the size was checked against the file: fewer bytes
    than declared now is a truncated file)."""
    n = layout.n_points
    with decoding(path):
        array = np.empty(n, dtype)
    view = array.view(np.uint8)
    n_bytes = 0
    with open(path, "rb") as f:
        f.seek(layout.offset)
        while n_bytes < len(view):
            got = f.readinto(view[n_bytes:])
            if not got:
                raise cannot_read(
                    path,
                    f"truncated: the header declares {n} points, "
                    f"{n_bytes // layout.record_length} could be read",
                )
            n_bytes += got
    return array


def _read_records(path, layout, reader):
    """Every point record of ``reader`` in one structured array. An
    uncompressed file is read as bytes; a LAZ file is decoded a million
    points at a time into an array of the declared size, allocated up front
    when the file can hold that much (up to 64 times the file size or 256
    MiB); beyond that (a LAZ file whose points compress better than any
    survey), the array grows with the points decoded."""
    n = layout.n_points
    dtype = reader.header.point_format.dtype()
    if not layout.compressed and dtype.itemsize == layout.record_length:
        return _read_raw(path, layout, dtype)
    chunks = checked_chunks(reader, path, 1_000_000, n)
    budget = max(2**28, 64 * layout.size)
    if not layout.compressed or n * layout.record_length <= budget:
        with decoding(path):
            array = np.empty(n, dtype)
        flat, start = array.view(np.uint8), 0
        for chunk in chunks:  # as bytes: a copy field by field is 3x slower
            records = np.ascontiguousarray(chunk.array).view(np.uint8)
            flat[start : start + len(records)] = records
            start += len(records)
        return array
    return np.concatenate([chunk.array for chunk in chunks])


def scaled_xyz(records, scales, offsets):
    """The x, y, z of point ``records`` as one ``(n, 3)`` float64 array.

    Each coordinate is ``X * scale + offset`` in float64, as laspy computes
    it (the same bits), a block of rows at a time so that the records are
    read once and the output written in order.

    Parameters
    ----------
    records : ndarray
        Point records of a LAS point format (structured, with the int32
        fields ``X``, ``Y``, ``Z``).
    scales, offsets : sequence of 3 float
        The scales and offsets of the header.

    Returns
    -------
    xyz : ndarray of shape (n, 3), dtype float64
        The scaled coordinates.
    """
    n = len(records)
    xyz = np.empty((n, 3))
    block = 1 << 14
    scale = np.tile(np.asarray(scales, dtype=np.float64), block)
    offset = np.tile(np.asarray(offsets, dtype=np.float64), block)
    columns = [records[c] for c in "XYZ"]
    for start in range(0, n, block):
        rows = xyz[start : start + block]
        for j, column in enumerate(columns):
            rows[:, j] = column[start : start + block]
        flat = rows.reshape(-1)
        np.multiply(flat, scale[: len(flat)], out=flat)
        np.add(flat, offset[: len(flat)], out=flat)
    return xyz


class _Fields(Mapping):
    """The fields of the points read, each decoded from the point records
    when first looked up, then kept: a caller that wants x, y, z only never
    pays for the other dimensions.

    Parameters
    ----------
    path : Path
        The file (named by the errors of decoding).
    points : laspy.ScaleAwarePointRecord
        The point records.
    xyz : ndarray of shape (n, 3)
        The scaled coordinates; fields ``x``, ``y``, ``z`` are its columns.
    names : dict of str to list of str
        Every field in file order, each with the dimensions it is made of
        (several for a run ``name_0 ... name_{c-1}`` grouped into one
        ``(n, c)`` field).
    """

    def __init__(self, path, points, xyz, names):
        self._path = path
        self._points = points
        self._names = names
        self._values = {c: xyz[:, j] for j, c in enumerate("xyz")}

    def _dimension(self, name):
        values = np.asarray(self._points[name])
        if np.may_share_memory(values, self._points.array):
            values = values.copy()  # a field of the records: its own array
        return values

    def __getitem__(self, name):
        if name not in self._values:
            members = self._names[name]  # KeyError for an unknown name
            with decoding(self._path):
                if len(members) == 1:
                    self._values[name] = self._dimension(name)
                else:
                    self._values[name] = np.column_stack(
                        [self._dimension(m) for m in members]
                    )
        return self._values[name]

    def __contains__(self, name):  # without decoding (Mapping's looks it up)
        return name in self._names

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)


def _field_names(laspy, points):
    """Every field of ``points`` in file order, with the dimensions each is
    made of, and the runs of extra dimensions grouped (by
    :func:`~skpcd.io._common.group_fields`, on the types that decoding no
    point gives); returns ``(names, grouped)``."""
    empty = laspy.ScaleAwarePointRecord(
        points.array[:0], points.point_format, points.scales, points.offsets
    )
    probes = {c: np.empty(0) for c in "xyz"}
    for name in points.point_format.dimension_names:
        if name not in ("X", "Y", "Z"):
            probes[name] = np.asarray(empty[name])
    fields, grouped = group_fields(probes)
    return {name: grouped.get(name, [name]) for name in fields}, grouped


def read(path):
    """Read a LAS or LAZ file into ``(fields, info)``; see :mod:`skpcd.io._las`.

    The point records are read at once; x, y, z are scaled then, every other
    field is decoded from the records when it is first looked up in
    ``fields``.

    Parameters
    ----------
    path : path-like
        The ``.las`` or ``.laz`` file.

    Returns
    -------
    fields : mapping of str to ndarray
        ``x``, ``y``, ``z`` (float64, scaled) then every other dimension.
    info : dict
        ``version``, ``point_format``, ``scales``, ``offsets``,
        ``compressed``, ``grouped`` (the extra dimensions merged into each
        ``(n, c)`` field) and ``xyz``, the ``(n, 3)`` array whose columns
        are the fields ``x``, ``y``, ``z``.

    Raises
    ------
    ImportError
        If laspy is not installed.
    PointCloudFileError
        If the file is not a LAS file, its header, VLRs or LAZ structure are
        corrupt, it holds fewer points than it declares, the points fail to
        decode, or there is no LAZ backend.
    """
    laspy = import_laspy()
    path = Path(os.fspath(path))
    layout = checked_layout(path)
    with decoding(path), _open(laspy, path, layout) as reader:
        records = _read_records(path, layout, reader)
        header = reader.header
        xyz = scaled_xyz(records, header.scales, header.offsets)
        points = laspy.ScaleAwarePointRecord(
            records, header.point_format, header.scales, header.offsets
        )
        names, grouped = _field_names(laspy, points)
    info = {
        "version": str(header.version),
        "point_format": header.point_format.id,
        "scales": tuple(float(s) for s in header.scales),
        "offsets": tuple(float(o) for o in header.offsets),
        "compressed": str(path).lower().endswith(".laz"),
        "grouped": grouped,
        "xyz": xyz,
    }
    return _Fields(path, points, xyz, names), info
