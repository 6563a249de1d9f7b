"""Helpers shared by the binary formats (PLY, PCD): header lines, writers."""

import io

import numpy as np

from skpcd.exceptions import PointCloudFileError

# longest header line read before a file is refused
MAX_LINE_BYTES = 1 << 16


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
