"""Helpers shared by the point-cloud formats: header and ascii lines, the
columns to write, the merging of ``name_0 ... name_{c-1}`` fields."""

import io
import re
from numbers import Integral

import numpy as np

from skpcd.exceptions import PointCloudFileError

# longest header line read before a file is refused
MAX_LINE_BYTES = 1 << 16
_GROUPED = re.compile(r"(.+)_0")


def header_line(path, data, pos, fmt):
    """The raw bytes of the header line at ``pos`` and the offset after it.

    ``data`` may be a memory map: a line is searched for in at most
    :data:`MAX_LINE_BYTES`, so a large file that is not a ``fmt`` file
    costs that much, not its size.
    """
    end = data.find(b"\n", pos, pos + MAX_LINE_BYTES)
    if end < 0:
        if len(data) - pos > MAX_LINE_BYTES:
            raise PointCloudFileError(
                path,
                f"not a {fmt} file or a corrupt header: no line end in "
                f"{MAX_LINE_BYTES} bytes at offset {pos}.",
            )
        end = len(data)
    return data[pos:end], end + 1


def data_lines(body):
    """The non-blank lines of an ascii body."""
    text = body.decode("ascii", errors="replace")
    return [line for line in text.splitlines() if line.strip()]


def float_rows(path, lines, n_columns, *, data, rows, unit=""):
    """The ascii ``lines`` parsed as an ``(n, n_columns)`` float64 array.

    A PointCloudFileError says ``cannot parse {data}`` when a value is not a
    number, ``{rows} have k values, but the header declares
    {n_columns}{unit}`` when the lines hold another number of columns.
    """
    if not lines:
        values = np.empty((0, n_columns))
    else:
        try:
            values = np.loadtxt(lines, dtype=np.float64, ndmin=2)
        except ValueError as exc:
            raise PointCloudFileError(path, f"cannot parse {data}: {exc}") from None
    if values.shape[1] != n_columns:
        raise PointCloudFileError(
            path,
            f"{rows} have {values.shape[1]} values, but the header declares "
            f"{n_columns}{unit}.",
        )
    return values


def is_whole(values):
    """True when every one of the float ``values`` is a finite whole number."""
    return bool(
        np.all(np.isfinite(values)) and np.array_equal(values, np.round(values))
    )


def check_integral(path, values, dtype, what, range_name):
    """Refuse float ``values`` read for an integer ``dtype`` that are not
    whole numbers within it (a PointCloudFileError naming ``what``)."""
    if not is_whole(values):
        raise PointCloudFileError(path, f"{what} has non-integer values.")
    limits = np.iinfo(dtype)
    if values.size and (values.min() < limits.min or values.max() > limits.max):
        raise PointCloudFileError(path, f"{what} has values out of {range_name}.")


def group_fields(fields):
    """Merge runs ``name_0 ... name_{c-1}`` of one dtype into ``(n, c)`` fields.

    Parameters
    ----------
    fields : dict of str to ndarray
        One-dimensional fields, in file order.

    Returns
    -------
    fields : dict of str to ndarray
        The fields, each run of two or more replaced by one ``(n, c)`` field
        ``name`` where it stood (unless ``name`` is a field already).
    grouped : dict of str to list of str
        The names merged into each new field.
    """
    names = list(fields)
    out, grouped = {}, {}
    i = 0
    while i < len(names):
        match = _GROUPED.fullmatch(names[i])
        if match:
            base = match.group(1)
            j = i + 1
            while (
                j < len(names)
                and names[j] == f"{base}_{j - i}"
                and fields[names[j]].dtype == fields[names[i]].dtype
            ):
                j += 1
            if j - i >= 2 and base not in fields and base not in out:
                out[base] = np.column_stack([fields[m] for m in names[i:j]])
                grouped[base] = names[i:j]
                i = j
                continue
        out[names[i]] = fields[names[i]]
        i += 1
    return out, grouped


def is_float32_exact(values):
    """True when float32 stores ``values`` without changing any of them."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.array_equal(values.astype(np.float32), values, equal_nan=True)


def coordinate_names(names):
    """``{name in the file: "x" | "y" | "z"}`` for files whose coordinates
    are named ``X``, ``Y``, ``Z`` (PDAL's dimension names, as its
    ``writers.numpy`` and the PCD files of its test data have them): the
    renaming to apply when the file has upper-case ``X``, ``Y`` and ``Z``
    and none of ``x``, ``y``, ``z``; empty otherwise."""
    names = set(names)
    if names.isdisjoint("xyz") and names.issuperset("XYZ"):
        return {"X": "x", "Y": "y", "Z": "z"}
    return {}


def coordinate_columns(fields):
    """``[(name, values)]`` for x, y, z, as float32 when float32 holds all
    three exactly, else as float64."""
    coords = [np.asarray(fields[c], dtype=np.float64) for c in "xyz"]
    coord_type = np.float32 if all(is_float32_exact(v) for v in coords) else np.float64
    return [(c, v.astype(coord_type)) for c, v in zip("xyz", coords, strict=True)]


def field_columns(fields, components, *, split=True):
    """``[(name, values)]`` for the fields other than x, y, z, to write.

    A field of ``components`` with as many columns as it lists names becomes
    a column under each name (``normals`` as ``nx ny nz``, say); any other
    ``(n, c)`` field becomes ``name_0 ... name_{c-1}`` when ``split``, else
    stays one column.
    """
    columns = []
    for name, values in fields.items():
        if name in ("x", "y", "z"):
            continue
        values = np.asarray(values)
        names = components.get(name)
        if values.ndim == 1:
            columns.append((name, values))
        elif names is not None and values.shape[1] == len(names):
            columns += [(c, values[:, j]) for j, c in enumerate(names)]
        elif split:
            columns += [(f"{name}_{j}", values[:, j]) for j in range(values.shape[1])]
        else:
            columns.append((name, values))
    return columns


def distinct_columns(columns, what):
    """The ``(name, values)`` columns one by one, refusing a name given twice
    (ValueError naming it a ``what``)."""
    seen = set()
    for name, values in columns:
        if name in seen:
            raise ValueError(f"{what} {name!r} would be written twice.")
        seen.add(name)
        yield name, values


def packed_records(columns, dtype, n):
    """The bytes of ``n`` records of ``dtype`` holding the ``(name, values)``
    columns."""
    records = np.empty(n, dtype=dtype)
    for name, values in columns:
        records[name] = values
    return records.tobytes()


def float_format(itemsize):
    """printf format that round-trips a float of ``itemsize`` bytes."""
    return "%.9g" if itemsize == 4 else "%.17g"


def ascii_rows(formats, columns):
    """One text line per point: ``columns[j]`` formatted with ``formats[j]``."""
    line = " ".join(formats) + "\n"
    out = io.StringIO()
    for row in zip(*(c.tolist() for c in columns), strict=True):
        out.write(line % row)
    return out.getvalue().encode("ascii")


def take_rows(keep, points, *columns):
    """``points`` and every dict of per-point ``columns`` at the rows ``keep``.

    Parameters
    ----------
    keep : ndarray of bool or int
        The rows to keep.
    points : ndarray of shape (n, ...)
        Per-point values.
    *columns : dict of str to ndarray
        More per-point values, each of length ``n``.

    Returns
    -------
    taken : tuple
        ``points[keep]``, then each dict with its values at ``keep``.
    """
    return (points[keep], *({k: v[keep] for k, v in c.items()} for c in columns))


def check_chunk_size(chunk_size):
    """``chunk_size`` as an int, if it is a positive integer (else ValueError)."""
    if (
        isinstance(chunk_size, bool)
        or not isinstance(chunk_size, Integral)
        or chunk_size < 1
    ):
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    return int(chunk_size)
