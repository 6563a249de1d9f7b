"""Helpers shared by the point-cloud formats: header lines, columns, writers."""

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


def is_float32_exact(values):
    """True when float32 stores ``values`` without changing any of them."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.array_equal(values.astype(np.float32), values, equal_nan=True)


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


def check_chunk_size(chunk_size):
    """``chunk_size`` as an int, if it is a positive integer (else ValueError)."""
    if (
        isinstance(chunk_size, bool)
        or not isinstance(chunk_size, Integral)
        or chunk_size < 1
    ):
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    return int(chunk_size)
