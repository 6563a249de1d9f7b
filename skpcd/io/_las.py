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


def _open(laspy, path):
    try:
        return laspy.open(str(path))
    except Exception as exc:
        raise PointCloudFileError(
            path, f"cannot read as LAS/LAZ: {_problem(exc)}"
        ) from exc


@contextlib.contextmanager
def open_checked(laspy, path):
    """Open ``path`` with laspy; yields ``(reader, n_points)``."""
    with _open(laspy, path) as reader:
        yield reader, int(reader.header.point_count)


def checked_chunks(reader, path, chunk_size, n_points):
    """The point records of ``reader``, ``chunk_size`` at a time, laspy's
    errors turned into PointCloudFileError, and fewer points than the header
    declares an error too."""
    chunks = reader.chunk_iterator(chunk_size)
    n_read = 0
    while True:
        try:
            chunk = next(chunks)
        except StopIteration:
            break
        except Exception as exc:
            raise PointCloudFileError(
                path, f"cannot read as LAS/LAZ: {_problem(exc)}"
            ) from exc
        if len(chunk) == 0:
            break
        n_read += len(chunk)
        yield chunk
    if n_read < n_points:
        raise PointCloudFileError(
            path,
            f"cannot read as LAS/LAZ: truncated: the header declares {n_points} "
            f"points, the file holds {n_read}",
        )


def read_vlr_records(path):
    """Every VLR and EVLR of a LAS/LAZ file as ``(user_id, record_id, data)``,
    read from the bytes (not through laspy, which rewrites known records)."""
    path = _check_file(path)
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(375)
        if len(head) < 227 or head[:4] != b"LASF":
            raise PointCloudFileError(path, "cannot read as LAS/LAZ: not a LAS file")
        minor = head[25]
        (header_size,) = struct.unpack_from("<H", head, 94)
        offset, n_vlrs = struct.unpack_from("<II", head, 96)
        records = []
        pos = header_size
        for _ in range(n_vlrs):
            if pos + 54 > min(offset, size):
                break
            f.seek(pos)
            raw = f.read(54)
            (length,) = struct.unpack_from("<H", raw, 20)
            if pos + 54 + length > size:
                break
            records.append((_text(raw[2:18]), raw[18] | raw[19] << 8, f.read(length)))
            pos += 54 + length
        if minor >= 4 and len(head) >= 247:
            start, n_evlrs = struct.unpack_from("<QI", head, 235)
            pos = start
            for _ in range(n_evlrs if start else 0):
                if pos + 60 > size:
                    break
                f.seek(pos)
                raw = f.read(60)
                (length,) = struct.unpack_from("<Q", raw, 20)
                if pos + 60 + length > size:
                    break
                records.append(
                    (_text(raw[2:18]), raw[18] | raw[19] << 8, f.read(length))
                )
                pos += 60 + length
    return records


def _text(raw):
    return raw.split(b"\0")[0].decode("ascii", "replace")


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

    Nothing but the header is read, so this is instant whatever the size of
    the file. The bounds are those the writer stored (laspy and most tools
    store the exact extent of the points).

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
        If the file is not a readable LAS/LAZ file.

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
    with _open(laspy, path) as reader:
        header = reader.header
        return LasExtent(
            int(header.point_count),
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
        requested field. The error may come after some chunks were yielded
        (a file truncated in the middle).

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
    return _iter_points(laspy, path, int(chunk_size), fields)


def _iter_points(laspy, path, chunk_size, fields):
    with _open(laspy, path) as reader:
        available = set(reader.header.point_format.dimension_names)
        missing = [f for f in fields or () if f not in available or f in "XYZ"]
        if missing:
            raise PointCloudFileError(
                path,
                f"no field {missing[0]!r}; the file has: "
                + ", ".join(n for n in available if n not in ("X", "Y", "Z")),
            )
        chunks = reader.chunk_iterator(chunk_size)
        while True:
            try:
                chunk = next(chunks)
            except StopIteration:
                return
            except Exception as exc:
                raise PointCloudFileError(
                    path, f"cannot read as LAS/LAZ: {_problem(exc)}"
                ) from exc
            if len(chunk) == 0:
                return
            xyz = np.empty((len(chunk), 3))
            for j, c in enumerate("xyz"):
                xyz[:, j] = chunk[c]
            if fields is None:
                yield xyz
            else:
                yield xyz, {f: np.array(chunk[f]) for f in fields}


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
        If laspy cannot read the file (not a LAS file, truncated, no LAZ
        backend...).
    """
    laspy = _laspy()
    try:
        las = laspy.read(str(path))
    except Exception as exc:
        raise PointCloudFileError(
            path, f"cannot read as LAS/LAZ: {_problem(exc)}"
        ) from exc
    fields = {c: np.asarray(getattr(las, c), dtype=np.float64) for c in "xyz"}
    for name in las.point_format.dimension_names:
        if name not in ("X", "Y", "Z"):
            fields[name] = np.array(las[name])
    fields, grouped = _group(fields)
    header = las.header
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
