"""The structure of a LAS/LAZ file, read with :mod:`struct` and checked.

laspy trusts the header: it loops over the declared number of VLRs and
EVLRs, allocates the declared number of points and reads fewer without an
error, and lazrs allocates what the laszip VLR, the chunk table and the
chunk headers say (an allocation failure aborts the process) or panics
(PanicException, a BaseException). So the public header, the VLRs, the
EVLRs, the laszip VLR, the chunk table and the chunk headers of layered
LAZ are read here with struct and checked against the file size before
laspy sees the file (:func:`checked_layout`), and every failure of laspy or
lazrs met afterwards becomes a PointCloudFileError (:func:`decoding`): see
the user guide's "What the LAS reader checks".
"""

import contextlib
import os
import struct
import typing
from pathlib import Path

import numpy as np

from skpcd.exceptions import MissingFileError, PointCloudFileError

__all__ = [
    "MAX_CHUNK_POINTS",
    "cannot_read",
    "check_file",
    "checked_layout",
    "decoding",
    "import_laspy",
]

_MISSING = (
    "reading .las/.laz files needs laspy, a dependency of skpcd missing from "
    "this Python environment: pip install laspy lazrs"
)
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


def import_laspy():
    """laspy, imported now (an ImportError naming laspy without it: a core
    dependency, it is missing only from a broken environment)."""
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


@contextlib.contextmanager
def decoding(path):
    """laspy's and lazrs's failures as PointCloudFileError: lazrs's
    PanicException is a BaseException, so everything but an interrupt or an
    exit is caught."""
    try:
        yield
    except (PointCloudFileError, KeyboardInterrupt, SystemExit, GeneratorExit):
        raise
    except MemoryError as exc:
        raise cannot_read(path, "not enough memory to decode the points") from exc
    except BaseException as exc:
        raise cannot_read(path, _problem(exc)) from exc


def check_file(path):
    """``path`` as a Path, if it names an existing ``.las`` or ``.laz`` file."""
    path = Path(os.fspath(path))
    if path.suffix.lower() not in (".las", ".laz"):
        raise PointCloudFileError(
            path, f"not a LAS/LAZ file (extension {path.suffix or '(none)'!r})."
        )
    if not path.is_file():
        what = "is a directory, not a file" if path.is_dir() else "no such file"
        raise MissingFileError(path, what)
    return path


def cannot_read(path, problem):
    """The PointCloudFileError of a file that is not a readable LAS/LAZ file."""
    return PointCloudFileError(path, _BAD + problem)


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
    # (points, bytes) of each LAZ chunk in file order, from lazrs's reading
    # of the chunk table (None for LAS, or without lazrs)
    chunks: object = None


def _text(raw):
    return raw.split(b"\0")[0].decode("ascii", "replace")


def _header(path, head, size):
    """Parse and check the public header (its first bytes ``head``, of a file
    of ``size`` bytes): the layout without records, then ``(first byte,
    count)`` of the VLRs and of the EVLRs."""
    if head[:4] != b"LASF":
        raise cannot_read(path, "not a LAS file (no 'LASF' signature)")
    if size < 227:
        raise cannot_read(path, f"{size} bytes, too short for a LAS header (227 bytes)")
    major, minor = head[24], head[25]
    if major != 1 or minor not in _MIN_HEADER:
        raise cannot_read(path, f"unknown LAS version {major}.{minor}")
    (header_size,) = struct.unpack_from("<H", head, 94)
    offset, n_vlrs = struct.unpack_from("<II", head, 96)
    format_id, record_length, legacy = struct.unpack_from("<BHI", head, 104)
    if header_size < _MIN_HEADER[minor] or header_size > size:
        raise cannot_read(
            path,
            f"the header size is {header_size} bytes (LAS 1.{minor} "
            f"needs {_MIN_HEADER[minor]}; the file has {size})",
        )
    if not header_size <= offset <= size:
        raise cannot_read(
            path,
            f"the point data starts at byte {offset}, outside the file "
            f"after its header ({header_size} to {size})",
        )
    compressed = bool(format_id & 0x80) and not format_id & 0x40
    point_format = format_id & 0x3F
    if point_format >= len(_BASE_SIZE):
        raise cannot_read(path, f"unknown point format {point_format}")
    if record_length < _BASE_SIZE[point_format]:
        raise cannot_read(
            path,
            f"point records of {record_length} bytes, shorter than "
            f"point format {point_format} needs ({_BASE_SIZE[point_format]})",
        )
    n_points = legacy
    start_evlr = n_evlrs = 0
    if minor >= 4:
        start_evlr, n_evlrs, n_points = struct.unpack_from("<QIQ", head, 235)
        if legacy not in (0, n_points):
            raise cannot_read(
                path,
                f"the header's point counts disagree: {legacy} (legacy "
                f"field) and {n_points} (LAS 1.4 field)",
            )
    values = struct.unpack_from("<12d", head, 131)
    scales, offsets = np.array(values[0:3]), np.array(values[3:6])
    with np.errstate(all="ignore"):
        extreme = np.abs(scales) * 2.0**31 + np.abs(offsets)
    if not (np.isfinite(extreme).all() and np.all(scales != 0)):
        raise cannot_read(
            path,
            f"invalid coordinate scales {scales.tolist()} or offsets "
            f"{offsets.tolist()} (zero, NaN or infinite)",
        )
    layout = _Layout(
        size,
        minor,
        offset,
        point_format,
        record_length,
        n_points,
        compressed,
        [],
        [],
        None,
    )
    return layout, (header_size, n_vlrs), (start_evlr, n_evlrs)


def _layout(path):
    """Parse and check the header, VLRs and EVLRs of ``path``; no points."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        layout, (start, count), (start_evlr, n_evlrs) = _header(path, f.read(393), size)
        offset = layout.offset
        vlrs = _walk(
            f, path, start, count, offset, _VLR_HEADER, "VLR", "the point data"
        )
        evlrs = []
        if layout.minor >= 4 and n_evlrs:
            if start_evlr < offset:
                raise cannot_read(
                    path,
                    f"the EVLRs start at byte {start_evlr}, before the point "
                    f"data (byte {offset})",
                )
            evlrs = _walk(
                f, path, start_evlr, n_evlrs, size, _EVLR_HEADER, "EVLR", "the file"
            )
            n_bytes = layout.n_points * layout.record_length
            if not layout.compressed and offset + n_bytes > start_evlr:
                raise cannot_read(
                    path,
                    f"the {layout.n_points} points declared (records of "
                    f"{layout.record_length} bytes from byte {offset}) run into "
                    f"the EVLRs at byte {start_evlr}",
                )
    return layout._replace(vlrs=vlrs, evlrs=evlrs)


def _walk(f, path, start, count, end, header, what, limit):
    """The (E)VLRs from byte ``start``: ``count`` of them, within ``end``."""
    records = []
    pos = start
    length_format = "<H" if header == _VLR_HEADER else "<Q"
    for k in range(count):
        if pos + header > end:
            raise cannot_read(
                path,
                f"the header declares {count} {what}s, but only {k} fit "
                f"before the end of {limit} (byte {end})",
            )
        f.seek(pos)
        raw = f.read(header)
        (length,) = struct.unpack_from(length_format, raw, 20)
        if pos + header + length > end:
            raise cannot_read(
                path,
                f"{what} {k + 1} of {count} ({_text(raw[2:18])!r}, "
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
            raise cannot_read(
                path,
                f"truncated: the header declares {n} points, the file holds "
                f"{available} ({layout.size - data} bytes of {layout.record_length}"
                f"-byte records from byte {data})",
            )
        return layout
    laszip = [v for v in layout.vlrs if v[:2] == _LASZIP]
    if not laszip:
        raise cannot_read(path, "compressed points but no laszip VLR (not a LAZ file)")
    with open(path, "rb") as f:
        f.seek(laszip[0][2])
        record = f.read(laszip[0][3])
        chunk_size, items = _check_laszip(path, layout, record)
        if n == 0:
            return layout
        backend, chunks = _check_chunks(path, layout, f, record, chunk_size, items)
    return layout._replace(laz_backend=backend, chunks=chunks)


def _check_laszip(path, layout, record):
    """Check the laszip VLR; returns (chunk_size, items)."""

    def bad(problem):
        return cannot_read(path, f"invalid laszip VLR: {problem}")

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
    the file; returns the laspy backend to decode with and the chunk table
    (None without lazrs)."""
    laspy = import_laspy()
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
    # a layered chunk starts with the first point raw, the point count, then
    # the size of every layer
    head = layout.record_length + 4 + 4 * sum(_LAYERS.get(t, s) for t, s, _ in items)
    if table is None or not first <= table <= size - 8:
        held = ""
        if layered and table is not None and table > size - 8:
            n_held, n_chunks = _complete_layered(f, layout, first, size, head)
            held = f", the file holds {n_held} (its first {n_chunks} complete chunks)"
        raise cannot_read(
            path,
            f"truncated or corrupt LAZ: the header declares {n} points"
            f"{held}; the chunk table that indexes them, {where}, is outside the "
            f"point data (bytes {first} to {size})",
        )
    f.seek(table)
    version, n_chunks = struct.unpack("<II", f.read(8))
    # a chunk holds at least one raw point; lazrs ends variable-size chunks
    # with an empty one
    most = max((table - first) // layout.record_length, 0) + 1
    if version != 0 or not 1 <= n_chunks <= most:
        raise cannot_read(
            path,
            f"corrupt LAZ chunk table {where}: version {version}, "
            f"{n_chunks} chunks (1 to {most} fit in the point data)",
        )
    try:
        import lazrs
    except ImportError:
        return None, None  # laspy reports the missing backend
    f.seek(data)
    with decoding(path):
        chunks = lazrs.read_chunk_table(f, lazrs.LazVlr(record))
    variable = chunk_size == _VARIABLE_CHUNKS
    n_indexed = sum(c for c, _ in chunks) if variable else len(chunks) * chunk_size
    n_bytes = sum(b for _, b in chunks)
    if len(chunks) != n_chunks or n_bytes > table - first:
        raise cannot_read(
            path,
            f"corrupt LAZ chunk table {where}: {len(chunks)} chunks of "
            f"{n_bytes} bytes, the point data has {table - first}",
        )
    if n_indexed < n:
        raise cannot_read(
            path,
            f"truncated or corrupt LAZ: the header declares {n} points, the "
            f"chunk table indexes {n_indexed} ({len(chunks)} chunks)",
        )
    if layered:
        pos = first
        for k, (count, n_bytes) in enumerate(chunks):
            if variable and count == n_bytes == 0:
                continue
            most = count if variable else chunk_size
            problem = _layered_chunk(f, layout, pos, pos + n_bytes, head, most)
            if problem:
                raise cannot_read(
                    path, f"corrupt LAZ chunk {k + 1} at byte {pos}: {problem}"
                )
            pos += n_bytes
    # the parallel decoder pays off from two chunks on (and starts threads)
    parallel = (
        not variable
        and len(chunks) > 1
        and chunk_size * layout.record_length <= _PARALLEL_CHUNK_BYTES
    )
    backend = laspy.LazBackend.LazrsParallel if parallel else laspy.LazBackend.Lazrs
    return (backend if backend.is_available() else None), chunks


def _chunk_header(f, layout, start, head):
    """The point count and the bytes of the layers of the layered chunk at
    ``start``, from its header of ``head`` bytes (the first point raw, the
    point count, then the size of every layer)."""
    f.seek(start + layout.record_length)
    raw = f.read(head - layout.record_length)
    count, *sizes = struct.unpack(f"<{len(raw) // 4}I", raw)
    return count, sum(sizes)


def _layered_chunk(f, layout, start, end, head, most):
    """What is wrong with the layered chunk at ``start:end`` (or None)."""
    if start + head > end:
        return f"{end - start} bytes, fewer than its header ({head})"
    count, n_bytes = _chunk_header(f, layout, start, head)
    if not 1 <= count <= most:
        return f"{count} points (1 to {most} expected)"
    if start + head + n_bytes > end:
        return f"its layers take {n_bytes} bytes, the chunk has {end - start - head}"
    return None


def _complete_layered(f, layout, start, size, head):
    """Points and number of the layered chunks complete in a truncated file,
    found by walking the chunk headers."""
    pos, n_points, n_chunks = start, 0, 0
    while pos + head <= size:
        count, n_bytes = _chunk_header(f, layout, pos, head)
        end = pos + head + n_bytes
        if end > size or n_points + count > layout.n_points:
            break
        n_points += count
        n_chunks += 1
        pos = end
    return n_points, n_chunks


def checked_layout(path, *, points=True):
    """The checked layout of a LAS/LAZ file (its point data too)."""
    layout = _layout(path)
    return _check_points(path, layout) if points else layout
