"""LAS and LAZ point clouds (the ASPRS LiDAR format), through laspy.

Needs the ``las`` extra (``pip install 'skpcd[las]'``: laspy, and lazrs for
the compressed ``.laz``); laspy is imported only when a file is read or
written.

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

Before laspy reads a file, its structure is read here with :mod:`struct` and
checked against the file size (header, VLRs, EVLRs, point count, and for LAZ
the laszip VLR, the chunk table and the chunk headers), and every failure of
laspy or lazrs, lazrs's PanicException included, becomes a
PointCloudFileError: see the user guide's "What the LAS reader checks".
"""

import contextlib
import os
import struct
import typing
from numbers import Integral
from pathlib import Path

import numpy as np

from skpcd.exceptions import MissingFileError, PointCloudFileError
from skpcd.io._ply import _group

__all__ = ["LasExtent", "iter_points", "read_las_extent"]

_MISSING = "reading .las/.laz files needs laspy: pip install 'skpcd[las]'"
_SCALE = 1e-4
_INT32_MAX = 2**31 - 1


def _laspy():
    try:
        import laspy
    except ImportError as exc:
        raise ImportError(_MISSING) from exc
    return laspy


def _problem(exc):
    problem = str(exc) or type(exc).__name__
    if "LazBackend" in problem:
        problem += " (pip install lazrs)"
    if not isinstance(exc, Exception):  # lazrs's PanicException
        problem = f"the LAZ decoder failed ({type(exc).__name__}: {problem})"
    return problem


def _check_file(path):
    path = Path(os.fspath(path))
    if path.suffix.lower() not in (".las", ".laz"):
        raise PointCloudFileError(
            path, f"not a LAS/LAZ file (extension {path.suffix or '(none)'!r})."
        )
    if not path.is_file():
        what = "is a directory, not a file" if path.is_dir() else "no such file"
        raise MissingFileError(path, what)
    return path


# --- what is checked before laspy sees a file -----------------------------
#
# laspy trusts the header: it loops over the declared number of VLRs and
# EVLRs, allocates the declared number of points and reads fewer without an
# error, and lazrs allocates what the laszip VLR, the chunk table and the
# chunk headers say (an allocation failure aborts the process) or panics
# (PanicException, a BaseException). So the public header, the VLRs, the
# EVLRs, the laszip VLR, the chunk table and the chunk headers of layered
# LAZ are read here with struct and checked against the file size first.

_BAD = "cannot read as LAS/LAZ: "
_MIN_HEADER = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375, 5: 393}
_BASE_SIZE = (20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67)
_VLR_HEADER = 54
_EVLR_HEADER = 60
_LASZIP = ("laszip encoded", 22204)
# laszip item types and their sizes; BYTE (0) and BYTE14 (14) hold the
# extra bytes, of any size
_ITEM_SIZE = {6: 20, 7: 8, 8: 6, 9: 29, 10: 30, 11: 6, 12: 8, 13: 29}
_ITEMS = {
    0: (6,),
    1: (6, 7),
    2: (6, 8),
    3: (6, 7, 8),
    4: (6, 7, 9),
    5: (6, 7, 8, 9),
    6: (10,),
    7: (10, 11),
    8: (10, 12),
    9: (10, 13),
    10: (10, 12, 13),
}
# layers per item in a layered chunk (BYTE14: one per byte)
_LAYERS = {10: 9, 11: 1, 12: 2, 13: 1}
_VARIABLE_CHUNKS = 0xFFFFFFFF
#: largest fixed LAZ chunk accepted (LASzip writes 50 000 points per chunk)
MAX_CHUNK_POINTS = 2**24
# the parallel decoder allocates chunk_size * record length up front
_PARALLEL_CHUNK_BYTES = 2**27


class _Layout(typing.NamedTuple):
    """What the bytes of a LAS/LAZ file say, checked."""

    size: int
    minor: int
    offset: int
    point_format: int
    record_length: int
    n_points: int
    compressed: bool
    vlrs: list  # (user_id, record_id, data offset, data length)
    evlrs: list
    laz_backend: object  # None: laspy's choice


def _text(raw):
    return raw.split(b"\0")[0].decode("ascii", "replace")


def _layout(path):
    """Parse and check the header, VLRs and EVLRs of ``path``; no points."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(393)
        if head[:4] != b"LASF":
            raise PointCloudFileError(
                path, _BAD + "not a LAS file (no 'LASF' signature)"
            )
        if size < 227:
            raise PointCloudFileError(
                path, _BAD + f"{size} bytes, too short for a LAS header (227 bytes)"
            )
        major, minor = head[24], head[25]
        if major != 1 or minor not in _MIN_HEADER:
            raise PointCloudFileError(
                path, _BAD + f"unknown LAS version {major}.{minor}"
            )
        (header_size,) = struct.unpack_from("<H", head, 94)
        offset, n_vlrs = struct.unpack_from("<II", head, 96)
        format_id, record_length, legacy = struct.unpack_from("<BHI", head, 104)
        if header_size < _MIN_HEADER[minor] or header_size > size:
            raise PointCloudFileError(
                path,
                _BAD + f"the header size is {header_size} bytes (LAS 1.{minor} "
                f"needs {_MIN_HEADER[minor]}; the file has {size})",
            )
        if not header_size <= offset <= size:
            raise PointCloudFileError(
                path,
                _BAD + f"the point data starts at byte {offset}, outside the file "
                f"after its header ({header_size} to {size})",
            )
        compressed = bool(format_id & 0x80) and not format_id & 0x40
        point_format = format_id & 0x3F
        if point_format >= len(_BASE_SIZE):
            raise PointCloudFileError(
                path, _BAD + f"unknown point format {point_format}"
            )
        if record_length < _BASE_SIZE[point_format]:
            raise PointCloudFileError(
                path,
                _BAD + f"point records of {record_length} bytes, shorter than "
                f"point format {point_format} needs ({_BASE_SIZE[point_format]})",
            )
        n_points = legacy
        if minor >= 4:
            start_evlr, n_evlrs, n_points = struct.unpack_from("<QIQ", head, 235)
            if legacy not in (0, n_points):
                raise PointCloudFileError(
                    path,
                    _BAD + f"the header's point counts disagree: {legacy} (legacy "
                    f"field) and {n_points} (LAS 1.4 field)",
                )
        values = struct.unpack_from("<12d", head, 131)
        scales, offsets = np.array(values[0:3]), np.array(values[3:6])
        with np.errstate(all="ignore"):
            extreme = np.abs(scales) * 2.0**31 + np.abs(offsets)
        if not (np.isfinite(extreme).all() and np.all(scales != 0)):
            raise PointCloudFileError(
                path,
                _BAD + f"invalid coordinate scales {scales.tolist()} or offsets "
                f"{offsets.tolist()} (zero, NaN or infinite)",
            )
        vlrs = _walk(
            f, path, header_size, n_vlrs, offset, _VLR_HEADER, "VLR", "the point data"
        )
        evlrs = []
        if minor >= 4 and n_evlrs:
            if start_evlr < offset:
                raise PointCloudFileError(
                    path,
                    _BAD + f"the EVLRs start at byte {start_evlr}, before the point "
                    f"data (byte {offset})",
                )
            evlrs = _walk(
                f, path, start_evlr, n_evlrs, size, _EVLR_HEADER, "EVLR", "the file"
            )
            if not compressed and offset + n_points * record_length > start_evlr:
                raise PointCloudFileError(
                    path,
                    _BAD + f"the {n_points} points declared (records of "
                    f"{record_length} bytes from byte {offset}) run into the EVLRs "
                    f"at byte {start_evlr}",
                )
    return _Layout(
        size,
        minor,
        offset,
        point_format,
        record_length,
        n_points,
        compressed,
        vlrs,
        evlrs,
        None,
    )


def _walk(f, path, start, count, end, header, what, limit):
    """The (E)VLRs from byte ``start``: ``count`` of them, within ``end``."""
    records = []
    pos = start
    length_format = "<H" if header == _VLR_HEADER else "<Q"
    for k in range(count):
        if pos + header > end:
            raise PointCloudFileError(
                path,
                _BAD + f"the header declares {count} {what}s, but only {k} fit "
                f"before the end of {limit} (byte {end})",
            )
        f.seek(pos)
        raw = f.read(header)
        (length,) = struct.unpack_from(length_format, raw, 20)
        if pos + header + length > end:
            raise PointCloudFileError(
                path,
                _BAD + f"{what} {k + 1} of {count} ({_text(raw[2:18])!r}, "
                f"{length} bytes from byte {pos + header}) runs past the end of "
                f"{limit} (byte {end})",
            )
        records.append((_text(raw[2:18]), raw[18] | raw[19] << 8, pos + header, length))
        pos += header + length
    return records


def _check_points(path, layout):
    """Check that the point data holds the declared points; the layout with
    the LAZ backend to decode it with."""
    n = layout.n_points
    data = layout.offset
    if not layout.compressed:
        available = (layout.size - data) // layout.record_length
        if n > available:
            raise PointCloudFileError(
                path,
                _BAD + f"truncated: the header declares {n} points, the file holds "
                f"{available} ({layout.size - data} bytes of {layout.record_length}"
                f"-byte records from byte {data})",
            )
        return layout
    laszip = [v for v in layout.vlrs if v[:2] == _LASZIP]
    if not laszip:
        raise PointCloudFileError(
            path, _BAD + "compressed points but no laszip VLR (not a LAZ file)"
        )
    with open(path, "rb") as f:
        f.seek(laszip[0][2])
        record = f.read(laszip[0][3])
        chunk_size, items = _check_laszip(path, layout, record)
        if n == 0:
            return layout
        backend = _check_chunks(path, layout, f, record, chunk_size, items)
    return layout._replace(laz_backend=backend)


def _check_laszip(path, layout, record):
    """Check the laszip VLR; returns (chunk_size, items)."""

    def bad(problem):
        return PointCloudFileError(path, _BAD + f"invalid laszip VLR: {problem}")

    if len(record) < 34:
        raise bad(f"{len(record)} bytes, fewer than 34")
    compressor, coder, major, minor = struct.unpack_from("<HHBB", record, 0)
    (chunk_size,) = struct.unpack_from("<I", record, 12)
    (n_items,) = struct.unpack_from("<H", record, 32)
    if compressor not in (2, 3):
        what = "none" if compressor == 0 else "pointwise, not chunked"
        raise bad(
            f"compressor {compressor} ({what}); chunked (2) or layered (3) expected"
            if compressor < 2
            else f"unknown compressor {compressor}"
        )
    if coder != 0:
        raise bad(f"unknown coder {coder} (0, arithmetic, expected)")
    if not 1 <= major <= 3:
        raise bad(f"unknown LASzip version {major}.{minor}")
    if chunk_size == 0 or (
        chunk_size != _VARIABLE_CHUNKS and chunk_size > MAX_CHUNK_POINTS
    ):
        raise bad(
            f"chunk size {chunk_size} points (1 to {MAX_CHUNK_POINTS}, or "
            f"{_VARIABLE_CHUNKS} for variable chunks)"
        )
    if not 1 <= n_items <= 10 or len(record) < 34 + 6 * n_items:
        raise bad(f"{n_items} items in {len(record)} bytes")
    items = [struct.unpack_from("<HHH", record, 34 + 6 * k) for k in range(n_items)]
    fmt = layout.point_format
    expected = list(_ITEMS[fmt])
    n_extra = layout.record_length - _BASE_SIZE[fmt]
    if n_extra:
        expected.append(14 if fmt >= 6 else 0)
    types = [t for t, _, _ in items]
    if types != expected:
        raise bad(f"items {types} do not match point format {fmt} ({expected})")
    for item_type, item_size, _ in items:
        if item_size != _ITEM_SIZE.get(item_type, n_extra):
            raise bad(
                f"item {item_type} of {item_size} bytes (expected "
                f"{_ITEM_SIZE.get(item_type, n_extra)})"
            )
    if compressor == 3 and fmt < 6:
        raise bad(f"layered compression (3) of point format {fmt}")
    return chunk_size, items


def _check_chunks(path, layout, f, record, chunk_size, items):
    """Check the chunk table (and the chunk headers of layered LAZ) against
    the file; returns the laspy backend to decode with."""
    laspy = _laspy()
    n, data, size = layout.n_points, layout.offset, layout.size
    first = data + 8  # the chunks follow the offset of the chunk table
    f.seek(data)
    raw = f.read(8)
    table = struct.unpack("<q", raw)[0] if len(raw) == 8 else None
    where = f"at byte {table}"
    if table == -1:  # written at the end: the last 8 bytes point to it
        f.seek(max(size - 8, 0))
        table = struct.unpack("<q", f.read(8))[0]
        where = f"at byte {table} (given at the end of the file)"
    layered = record[0] == 3
    n_layers = [_LAYERS.get(t, s) for t, s, _ in items]
    if table is None or not first <= table <= size - 8:
        held = ""
        if layered and table is not None and table > size - 8:
            n_held, n_chunks = _complete_layered(f, layout, first, size, n_layers)
            held = f", the file holds {n_held} (its first {n_chunks} complete chunks)"
        raise PointCloudFileError(
            path,
            _BAD + f"truncated or corrupt LAZ: the header declares {n} points"
            f"{held}; the chunk table that indexes them, {where}, is outside the "
            f"point data (bytes {first} to {size})",
        )
    f.seek(table)
    version, n_chunks = struct.unpack("<II", f.read(8))
    # a chunk holds at least one raw point; lazrs ends variable-size chunks
    # with an empty one
    most = max((table - first) // layout.record_length, 0) + 1
    if version != 0 or not 1 <= n_chunks <= most:
        raise PointCloudFileError(
            path,
            _BAD + f"corrupt LAZ chunk table {where}: version {version}, "
            f"{n_chunks} chunks (1 to {most} fit in the point data)",
        )
    try:
        import lazrs
    except ImportError:
        return None  # laspy reports the missing backend
    f.seek(data)
    with _decoding(path):
        chunks = lazrs.read_chunk_table(f, lazrs.LazVlr(record))
    variable = chunk_size == _VARIABLE_CHUNKS
    n_indexed = sum(c for c, _ in chunks) if variable else len(chunks) * chunk_size
    n_bytes = sum(b for _, b in chunks)
    if len(chunks) != n_chunks or n_bytes > table - first:
        raise PointCloudFileError(
            path,
            _BAD + f"corrupt LAZ chunk table {where}: {len(chunks)} chunks of "
            f"{n_bytes} bytes, the point data has {table - first}",
        )
    if n_indexed < n:
        raise PointCloudFileError(
            path,
            _BAD + f"truncated or corrupt LAZ: the header declares {n} points, the "
            f"chunk table indexes {n_indexed} ({len(chunks)} chunks)",
        )
    if layered:
        pos = first
        for k, (count, n_bytes) in enumerate(chunks):
            if variable and count == n_bytes == 0:
                continue
            most = count if variable else chunk_size
            problem = _layered_chunk(f, layout, pos, pos + n_bytes, n_layers, most)
            if problem:
                raise PointCloudFileError(
                    path, _BAD + f"corrupt LAZ chunk {k + 1} at byte {pos}: {problem}"
                )
            pos += n_bytes
    # the parallel decoder pays off from two chunks on (and starts threads)
    parallel = (
        not variable
        and len(chunks) > 1
        and chunk_size * layout.record_length <= _PARALLEL_CHUNK_BYTES
    )
    backend = laspy.LazBackend.LazrsParallel if parallel else laspy.LazBackend.Lazrs
    return backend if backend.is_available() else None


def _layered_chunk(f, layout, start, end, n_layers, most):
    """What is wrong with the layered chunk at ``start:end`` (or None): the
    first point raw, the point count, then the size of every layer."""
    head = layout.record_length + 4 + 4 * sum(n_layers)
    if start + head > end:
        return f"{end - start} bytes, fewer than its header ({head})"
    f.seek(start + layout.record_length)
    raw = f.read(head - layout.record_length)
    count, *sizes = struct.unpack(f"<{len(raw) // 4}I", raw)
    if not 1 <= count <= most:
        return f"{count} points (1 to {most} expected)"
    if start + head + sum(sizes) > end:
        return f"its layers take {sum(sizes)} bytes, the chunk has {end - start - head}"
    return None


def _complete_layered(f, layout, start, size, n_layers):
    """Points and number of the layered chunks complete in a truncated file,
    found by walking the chunk headers."""
    head = layout.record_length + 4 + 4 * sum(n_layers)
    pos, n_points, n_chunks = start, 0, 0
    while pos + head <= size:
        f.seek(pos + layout.record_length)
        raw = f.read(head - layout.record_length)
        count, *sizes = struct.unpack(f"<{len(raw) // 4}I", raw)
        end = pos + head + sum(sizes)
        if end > size or n_points + count > layout.n_points:
            break
        n_points += count
        n_chunks += 1
        pos = end
    return n_points, n_chunks


def _checked(path, *, points=True):
    """The checked layout of a LAS/LAZ file (its point data too)."""
    layout = _layout(path)
    return _check_points(path, layout) if points else layout


@contextlib.contextmanager
def _decoding(path):
    """laspy's and lazrs's failures as PointCloudFileError: lazrs's
    PanicException is a BaseException, so everything but an interrupt or an
    exit is caught."""
    try:
        yield
    except (PointCloudFileError, KeyboardInterrupt, SystemExit, GeneratorExit):
        raise
    except MemoryError as exc:
        raise PointCloudFileError(
            path, _BAD + "not enough memory to decode the points"
        ) from exc
    except BaseException as exc:
        raise PointCloudFileError(path, _BAD + _problem(exc)) from exc


def _open(laspy, path, layout=None):
    layout = _checked(path) if layout is None else layout
    with _decoding(path):
        return laspy.open(str(path), laz_backend=layout.laz_backend)


@contextlib.contextmanager
def open_checked(laspy, path):
    """Open a checked ``path`` with laspy; yields ``(reader, n_points)``."""
    layout = _checked(path)
    with _open(laspy, path, layout) as reader:
        with _decoding(path):  # laspy's own parsing of the header and VLRs
            reader.header.point_format.dtype()
        yield reader, layout.n_points


def checked_chunks(reader, path, chunk_size, n_points):
    """The point records of ``reader``, ``chunk_size`` at a time, failures
    turned into PointCloudFileError, and fewer points than the header
    declares an error too."""
    chunks = reader.chunk_iterator(chunk_size)
    n_read = 0
    while n_read < n_points:
        with _decoding(path):
            chunk = next(chunks, None)
        if chunk is None or len(chunk) == 0:
            break
        n_read += len(chunk)
        yield chunk
    if n_read < n_points:
        raise PointCloudFileError(
            path,
            _BAD + f"truncated: the header declares {n_points} points, "
            f"{n_read} could be read",
        )


def read_vlr_records(path):
    """Every VLR and EVLR of a LAS/LAZ file as ``(user_id, record_id, data)``,
    read from the bytes (laspy rewrites the records it knows)."""
    path = _check_file(path)
    layout = _checked(path, points=False)
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
    laspy = _laspy()
    path = _check_file(path)
    with _decoding(path), open_checked(laspy, path) as (reader, n_points):
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
    if (
        isinstance(chunk_size, bool)
        or not isinstance(chunk_size, Integral)
        or chunk_size < 1
    ):
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    if fields is not None:
        fields = [fields] if isinstance(fields, str) else list(fields)
    laspy = _laspy()
    path = _check_file(path)
    layout = _checked(path)
    return _iter_points(laspy, path, layout, int(chunk_size), fields)


def _iter_points(laspy, path, layout, chunk_size, fields):
    with _decoding(path), _open(laspy, path, layout) as reader:
        available = set(reader.header.point_format.dimension_names)
        missing = [f for f in fields or () if f not in available or f in "XYZ"]
        if missing:
            raise PointCloudFileError(
                path,
                f"no field {missing[0]!r}; the file has: "
                + ", ".join(n for n in available if n not in ("X", "Y", "Z")),
            )
        for chunk in checked_chunks(reader, path, chunk_size, layout.n_points):
            xyz = np.empty((len(chunk), 3))
            for j, c in enumerate("xyz"):
                xyz[:, j] = chunk[c]
            if fields is None:
                yield xyz
            else:
                yield xyz, {f: np.array(chunk[f]) for f in fields}


def _read_records(laspy, path, layout, reader):
    """Every point record of ``reader`` in one array. The points are decoded
    a million at a time into an array of the declared size, allocated up
    front when the file can hold that much (always for LAS: the size was
    checked; for LAZ up to 64 times the file size or 256 MiB); beyond that (a
    LAZ file whose points compress better than any survey), the array grows
    with the points decoded."""
    n = layout.n_points
    dtype = reader.header.point_format.dtype()
    chunks = checked_chunks(reader, path, 1_000_000, n)
    budget = max(2**28, 64 * layout.size)
    if not layout.compressed or n * layout.record_length <= budget:
        with _decoding(path):
            array = np.empty(n, dtype)
        start = 0
        for chunk in chunks:
            array[start : start + len(chunk)] = chunk.array
            start += len(chunk)
    else:
        array = np.concatenate([chunk.array for chunk in chunks])
    header = reader.header
    return laspy.ScaleAwarePointRecord(
        array, header.point_format, header.scales, header.offsets
    )


def read(path):
    """Read a LAS or LAZ file into ``(fields, info)``; see the module docstring.

    Parameters
    ----------
    path : path-like
        The ``.las`` or ``.laz`` file.

    Returns
    -------
    fields : dict of str to ndarray
        ``x``, ``y``, ``z`` (float64, scaled) then every other dimension.
    info : dict
        ``version``, ``point_format``, ``scales``, ``offsets`` and
        ``compressed``.

    Raises
    ------
    ImportError
        If laspy is not installed.
    PointCloudFileError
        If the file is not a LAS file, its header, VLRs or LAZ structure are
        corrupt, it holds fewer points than it declares, the points fail to
        decode, or there is no LAZ backend.
    """
    laspy = _laspy()
    path = Path(os.fspath(path))
    layout = _checked(path)
    with _decoding(path), _open(laspy, path, layout) as reader:
        points = _read_records(laspy, path, layout, reader)
        header = reader.header
        fields = {c: np.asarray(points[c], dtype=np.float64) for c in "xyz"}
        for name in points.point_format.dimension_names:
            if name not in ("X", "Y", "Z"):
                fields[name] = np.array(points[name])
    fields, grouped = _group(fields)
    info = {
        "version": str(header.version),
        "point_format": header.point_format.id,
        "scales": tuple(float(s) for s in header.scales),
        "offsets": tuple(float(o) for o in header.offsets),
        "compressed": str(path).lower().endswith(".laz"),
        "grouped": grouped,
    }
    return fields, info


def _scale_offset(values):
    if not len(values):
        return _SCALE, 0.0
    offset = float(np.floor(values.min()))
    extent = float(values.max()) - offset
    scale = _SCALE
    while extent / scale > _INT32_MAX:
        scale *= 10
    return scale, offset


def _fits(name, values, dimension):
    """``values`` cast to the standard ``dimension``, or ValueError."""
    if dimension.dtype is not None and dimension.dtype.kind == "f":
        return values.astype(dimension.dtype)
    if dimension.dtype is not None:
        low, high = np.iinfo(dimension.dtype).min, np.iinfo(dimension.dtype).max
        what = str(dimension.dtype)
    else:
        low, high = 0, 2**dimension.num_bits - 1
        what = f"{dimension.num_bits}-bit unsigned"
    ok = True
    if values.dtype.kind == "f":
        ok = bool(
            np.all(np.isfinite(values)) and np.array_equal(values, np.round(values))
        )
    elif values.dtype.kind not in "biu":
        ok = False
    if len(values) and ok:
        ok = values.min() >= low and values.max() <= high
    if not ok:
        raise ValueError(
            f"field {name!r} does not fit the LAS dimension {name!r} ({what} "
            f"integers {low} to {high})."
        )
    return values.astype(dimension.dtype or np.uint8)


def _extra_type(name, values):
    if values.dtype == np.bool_:
        return np.dtype(np.uint8)
    if values.dtype == np.float16:
        return np.dtype(np.float32)
    if values.dtype.kind not in "iuf" or values.dtype.itemsize > 8:
        raise ValueError(
            f"field {name!r} has dtype {values.dtype}; LAS cannot store it."
        )
    return values.dtype.newbyteorder("=")


def _plan(laspy, fields):
    """The point format id, standard dimensions and extra dimensions to write."""
    extras = {k: np.asarray(v) for k, v in fields.items() if k not in ("x", "y", "z")}
    colors = extras.get("colors")
    split_colors = False
    if colors is not None and colors.ndim == 2 and colors.shape[1] == 3:
        values = colors
        integral = values.dtype.kind in "biu" or (
            values.dtype.kind == "f"
            and np.all(np.isfinite(values))
            and np.array_equal(values, np.round(values))
        )
        split_colors = bool(
            integral
            and (not len(values) or (values.min() >= 0 and values.max() <= 65535))
        )
    has_rgb = split_colors or any(c in extras for c in ("red", "green", "blue"))
    point_format = 8 if "nir" in extras else 7 if has_rgb else 6
    dimensions = {
        d.name: d
        for d in laspy.PointFormat(point_format).dimensions
        if d.name not in ("X", "Y", "Z")
    }
    columns = []
    for name, values in extras.items():
        if name == "colors" and split_colors:
            columns += [
                (c, values[:, j]) for j, c in enumerate(("red", "green", "blue"))
            ]
        elif values.ndim == 1:
            columns.append((name, values))
        elif name == "normals" and values.shape[1] == 3:
            columns += [(f"normal_{c}", values[:, j]) for j, c in enumerate("xyz")]
        else:
            columns += [(f"{name}_{j}", values[:, j]) for j in range(values.shape[1])]
    standard, extra = {}, {}
    for name, values in columns:
        if name in standard or name in extra:
            raise ValueError(f"field {name!r} would be written twice.")
        if name in dimensions:
            standard[name] = _fits(name, values, dimensions[name])
        elif len(name.encode()) > 32:
            raise ValueError(
                f"field {name!r}: LAS extra dimension names have at most 32 bytes."
            )
        else:
            extra[name] = values.astype(_extra_type(name, values))
    return point_format, standard, extra


def write(path, fields, *, encoding=None, extra_params=None, vlrs=()):
    """Write ``fields`` as a LAS or LAZ file; see the module docstring.

    The extension picks the compression: ``.laz`` is compressed with lazrs.

    Parameters
    ----------
    path : path-like
        The destination ``.las`` or ``.laz`` file.
    fields : dict of str to ndarray
        ``x``, ``y``, ``z`` then extra fields of shape ``(n,)`` or ``(n, c)``.
    encoding : None or "binary", default=None
        LAS is always binary.
    extra_params : dict of str to laspy.ExtraBytesParams, default=None
        The definition (type, description, no-data value) of some extra
        dimensions, in place of the default one (the field's type, no
        description).
    vlrs : sequence of laspy.VLR, default=()
        VLRs to add to the header.

    Raises
    ------
    ImportError
        If laspy is not installed.
    ValueError
        For another encoding, non-finite coordinates, a standard field whose
        values do not fit its LAS type, or a non-numeric field.
    PointCloudFileError
        If laspy fails to write the file.
    """
    if encoding not in (None, "binary"):
        raise ValueError(f"LAS files are always binary; got encoding={encoding!r}")
    laspy = _laspy()
    coords = [np.asarray(fields[c], dtype=np.float64) for c in "xyz"]
    if not all(np.all(np.isfinite(v)) for v in coords):
        raise ValueError("LAS cannot store NaN or infinite coordinates.")
    point_format, standard, extra = _plan(laspy, fields)
    try:
        header = laspy.LasHeader(point_format=point_format, version="1.4")
        given = extra_params or {}
        if extra:
            header.add_extra_dims(
                [
                    given.get(name) or laspy.ExtraBytesParams(name, v.dtype)
                    for name, v in extra.items()
                ]
            )
        if vlrs:
            header.vlrs = [*header.vlrs, *vlrs]
        scales_offsets = [_scale_offset(v) for v in coords]
        header.scales = np.array([s for s, _ in scales_offsets])
        header.offsets = np.array([o for _, o in scales_offsets])
        las = laspy.LasData(header)
        las.points = laspy.ScaleAwarePointRecord.zeros(len(coords[0]), header=header)
        for axis, values, (scale, offset) in zip(
            "XYZ", coords, scales_offsets, strict=True
        ):
            las[axis] = np.round((values - offset) / scale).astype(np.int32)
        for name, values in {**standard, **extra}.items():
            las[name] = values
        las.write(str(path))
    except laspy.errors.LaspyException as exc:
        raise PointCloudFileError(path, f"cannot write as LAS: {exc}") from exc
