"""Text point clouds: ``.xyz``, ``.txt``, ``.pts`` and ``.csv``.

One point per line, whitespace or comma separated, x y z first. An optional
header line names the columns; a ``.pts`` file may start with its point count
(the Leica convention), which is then checked against the data. Lines starting
with ``#`` or ``//`` are comments.
"""

import re
import warnings

import numpy as np

from skpcd.exceptions import PointCloudFileError

_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf)$", re.I)


def _is_comment(line):
    s = line.strip()
    return not s or s.startswith(("#", "//"))


def _tokens(line, delimiter):
    if delimiter == ",":
        return [t.strip() for t in line.strip().split(",")]
    return line.split()


def read(path):
    """Read a text cloud into ``(fields, info)``; see the module docstring."""
    skip = 0
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if not _is_comment(line):
                break
            skip += 1
        else:
            raise PointCloudFileError(path, "the file is empty (no point lines).")
    delimiter = "," if "," in line else None
    tokens = _tokens(line, delimiter)
    names = None
    declared = None
    if not all(_NUMBER.match(t) for t in tokens):
        names = [t.strip("\"'").lower() for t in tokens]
        skip += 1
    elif len(tokens) == 1 and tokens[0].isdigit():
        declared = int(tokens[0])
        skip += 1
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            data = np.loadtxt(
                path,
                delimiter=delimiter,
                comments=("#", "//"),
                skiprows=skip,
                ndmin=2,
                encoding="utf-8",
            )
    except ValueError as exc:
        raise PointCloudFileError(path, f"cannot parse the point lines: {exc}") from exc
    if data.size == 0:
        raise PointCloudFileError(path, "the file has a header but no point lines.")
    n, d = data.shape
    if d < 3:
        raise PointCloudFileError(
            path, f"each line needs at least 3 columns (x y z), found {d}."
        )
    if declared is not None and declared != n:
        raise PointCloudFileError(
            path, f"the header declares {declared} points but the file holds {n}."
        )
    if names is not None and len(names) != d:
        raise PointCloudFileError(
            path, f"the header names {len(names)} columns but the lines have {d}."
        )
    if names is None:
        names = ["x", "y", "z"] + [f"field_{j}" for j in range(3, d)]
    if names[:3] != ["x", "y", "z"]:
        names = ["x", "y", "z", *names[3:]]
    fields = {name: data[:, j] for j, name in enumerate(names)}
    return fields, {}


def write(path, fields, *, encoding="ascii", precision=None):
    """Write ``fields`` as a text cloud with a header line for extra columns."""
    if encoding not in ("ascii", None):
        raise ValueError(f"text files are always ascii; got encoding={encoding!r}")
    names, columns = _flatten(fields)
    data = np.column_stack(columns)
    delimiter = "," if str(path).lower().endswith(".csv") else " "
    fmt = "%.17g" if precision is None else f"%.{int(precision)}f"
    header = delimiter.join(names) if list(names) != ["x", "y", "z"] else ""
    np.savetxt(path, data, fmt=fmt, delimiter=delimiter, header=header, comments="")


def _flatten(fields):
    names, columns = [], []
    for name, values in fields.items():
        values = np.asarray(values)
        if values.ndim == 1:
            names.append(name)
            columns.append(values)
        else:
            for j in range(values.shape[1]):
                names.append(f"{name}_{j}")
                columns.append(values[:, j])
    return names, columns
