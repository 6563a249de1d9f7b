"""Text point clouds: ``.xyz``, ``.txt``, ``.pts`` and ``.csv``.

One point per line, whitespace or comma separated (comma when the first
line holds one). Lines starting with ``#`` or ``//`` are comments, and so is
the rest of a line after either. The file is UTF-8; a byte-order mark is
skipped.

The first line that is not a comment is one of:

- a point: every token a number as :func:`numpy.loadtxt` reads them
  (``1``, ``-2.5e3``, ``.5``, ``inf``, ``Infinity``, ``nan``, any case).
  The columns are then x, y, z and ``field_3``, ``field_4``...;
- a point count alone (an integer: the Leica ``.pts`` convention), checked
  against the number of points;
- a header naming the columns: every token a name (starting with a letter
  or an underscore, or quoted). Names are lower-cased; the columns named
  x, y and z are the coordinates wherever they are, the others keep their
  names. A header without x, y or z, or naming a column twice, is an error.

Anything else (``1.2.3``, ``x y 3``) is an error that quotes the line.
"""

import re
import warnings

import numpy as np

from skpcd.exceptions import PointCloudFileError

# what numpy.loadtxt parses as a float: ASCII digits (float() would also take
# "1_0" and other scripts' digits, loadtxt does not)
_NUMBER = re.compile(
    r"[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf(?:inity)?|nan)",
    re.IGNORECASE,
)
_COUNT = re.compile(r"[0-9]+")
_NAME = re.compile(r"[^\W\d]", re.UNICODE)  # a letter or an underscore
_QUOTES = "\"'"
_ENCODING = "utf-8-sig"  # a BOM is skipped, not read as part of the first token


def _is_comment(line):
    s = line.strip()
    return not s or s.startswith(("#", "//"))


def _uncomment(line):
    """``line`` without what follows ``#`` or ``//`` (as numpy.loadtxt)."""
    for mark in ("#", "//"):
        line = line.split(mark, 1)[0]
    return line


def _tokens(line, delimiter):
    if delimiter == ",":
        return [t.strip() for t in line.strip().split(",")]
    return line.split()


def _is_name(token):
    quoted = len(token) >= 2 and token[0] == token[-1] and token[0] in _QUOTES
    return quoted or bool(_NAME.match(token))


def _shown(line, limit=60):
    line = line.strip()
    return repr(line if len(line) <= limit else line[:limit] + "...")


def _header_names(path, tokens, line_no):
    names = [t.strip(_QUOTES).strip().lower() for t in tokens]
    empty = [j + 1 for j, name in enumerate(names) if not name]
    if empty:
        raise PointCloudFileError(
            path, f"line {line_no}: header column {empty[0]} has no name."
        )
    seen = {}
    for j, name in enumerate(names):
        if name in seen:
            raise PointCloudFileError(
                path,
                f"line {line_no}: the header names column {name!r} twice "
                f"(columns {seen[name] + 1} and {j + 1}).",
            )
        seen[name] = j
    missing = [c for c in "xyz" if c not in seen]
    if missing:
        raise PointCloudFileError(
            path,
            f"line {line_no}: the header names the columns {', '.join(names)} "
            f"but not {', '.join(missing)}; name the coordinate columns x, y "
            "and z.",
        )
    return names


def _first_line(path):
    """``(line_no, line)`` of the first line that is not a comment."""
    with open(path, encoding=_ENCODING, errors="replace") as fh:
        for line_no, line in enumerate(fh, start=1):
            if not _is_comment(line):
                return line_no, line
    raise PointCloudFileError(path, "the file is empty (no point lines).")


def read(path):
    """Read a text cloud into ``(fields, info)``; see the module docstring."""
    line_no, line = _first_line(path)
    delimiter = "," if "," in line else None
    tokens = _tokens(_uncomment(line), delimiter)
    names = None
    declared = None
    skip = line_no - 1
    if all(_NUMBER.fullmatch(t) for t in tokens):
        if len(tokens) == 1 and _COUNT.fullmatch(tokens[0]):
            declared = int(tokens[0])
            skip += 1
    elif all(_is_name(t) or not t for t in tokens):  # empty: an unnamed column
        names = _header_names(path, tokens, line_no)
        skip += 1
    else:
        odd = [t for t in tokens if not (_NUMBER.fullmatch(t) or _is_name(t))]
        why = (
            f"{odd[0]!r} is neither a number nor a name"
            if odd
            else "it mixes numbers and names"
        )
        raise PointCloudFileError(
            path,
            f"line {line_no} is neither a header nor a point: {_shown(line)}; "
            f"{why} (a point is numbers only, a header names only).",
        )
    try:
        with (
            open(path, encoding=_ENCODING, errors="replace") as fh,
            warnings.catch_warnings(),
        ):
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            data = np.loadtxt(
                # a line of only spaces or a comment is no point, with any
                # delimiter (with commas loadtxt would read one empty column)
                (line if _uncomment(line).strip() else "\n" for line in fh),
                delimiter=delimiter,
                comments=("#", "//"),
                skiprows=skip,
                ndmin=2,
            )
    except ValueError as exc:
        raise PointCloudFileError(path, f"cannot parse the point lines: {exc}") from exc
    if data.size == 0:
        what = "a point count" if declared is not None else "a header"
        raise PointCloudFileError(path, f"the file has {what} but no point lines.")
    n, d = data.shape
    if declared is not None and declared != n:
        raise PointCloudFileError(
            path, f"the header declares {declared} points but the file holds {n}."
        )
    if names is not None and len(names) != d:
        raise PointCloudFileError(
            path, f"the header names {len(names)} columns but the lines have {d}."
        )
    if d < 3:
        raise PointCloudFileError(
            path, f"each line needs at least 3 columns (x y z), found {d}."
        )
    if names is None:
        names = ["x", "y", "z"] + [f"field_{j}" for j in range(3, d)]
    column = {name: j for j, name in enumerate(names)}
    order = ["x", "y", "z"] + [name for name in names if name not in ("x", "y", "z")]
    return {name: data[:, column[name]] for name in order}, {}


def write(path, fields, *, encoding="ascii", precision=None):
    """Write ``fields`` as a text cloud with a header line for extra columns."""
    if encoding not in ("ascii", None):
        raise ValueError(f"text files are always ascii; got encoding={encoding!r}")
    names, columns = _flatten(fields)
    data = np.column_stack(columns)
    delimiter = "," if str(path).lower().endswith(".csv") else " "
    _check_names(names)
    fmt = "%.17g" if precision is None else f"%.{int(precision)}f"
    header = delimiter.join(names) if list(names) != ["x", "y", "z"] else ""
    np.savetxt(path, data, fmt=fmt, delimiter=delimiter, header=header, comments="")


def _check_names(names):
    """Names the reader gives back: names, no separators, unique in any case."""
    seen = set()
    for name in names:
        plain = _is_name(name) and not re.search(r"[\s,\"'#]|//", name)
        if not plain or name.lower() in seen:
            raise ValueError(
                f"cannot write a text column named {name!r}: header names start "
                "with a letter or an underscore, hold no space, comma, quote, # "
                "or //, and differ in more than case"
            )
        seen.add(name.lower())


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
