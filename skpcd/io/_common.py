"""Helpers shared by the binary formats' writers (PLY, PCD)."""

import io

import numpy as np


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
