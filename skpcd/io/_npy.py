"""NumPy ``.npy`` point clouds: a plain ``(n, 3+)`` array or a structured array.

The header is read and checked before any data: NumPy's signature (an
``.npz`` archive renamed ``.npy`` is recognised and refused), a header that
parses, no Python objects (nothing is ever unpickled), and a data size --
the shape times the item size -- equal to what the file holds after the
header, so that a corrupt shape never allocates memory the file does not
back. A plain array must be 2-D with at least 3 numeric columns (x, y, z,
then ``field_3``...); a structured array 1-D with scalar numeric fields x,
y and z, or X, Y and Z as PDAL names them (other fields are kept, a
sub-array field as ``(n, c)``).
"""

import importlib
import os
import tokenize

import numpy as np

from skpcd.exceptions import PointCloudFileError
from skpcd.io._common import coordinate_names

_NUMERIC = "iuf"  # integer, unsigned, float: what can be a coordinate
_ZIP = (b"PK\x03\x04", b"PK\x05\x06")  # a zip member, an empty zip
# what numpy.lib.format's header readers raise on a corrupt header
_HEADER_ERRORS = (
    ValueError,  # includes UnicodeDecodeError
    SyntaxError,
    TypeError,
    KeyError,
    IndexError,
    OverflowError,
    RecursionError,
    MemoryError,
    EOFError,
    tokenize.TokenError,
)


def _private_reader():
    """NumPy's reader of any header version (private: numpy 1 and 2 keep it
    in different modules), or None; only version 3.0 needs it."""
    for module in ("numpy.lib._format_impl", "numpy.lib.format"):
        try:
            return getattr(importlib.import_module(module), "_read_array_header")
        except (ImportError, AttributeError):
            continue
    return None


_read_array_header = _private_reader()


def _read_header(path, fh):
    """``(shape, fortran_order, dtype)`` of an open ``.npy`` file."""
    fmt = np.lib.format
    start = fh.read(6)
    if start[:4] in _ZIP:
        raise PointCloudFileError(
            path,
            "this is a zip archive (an .npz file?), not an .npy array; load it "
            "with numpy.load and save the cloud's array with numpy.save",
        )
    fh.seek(0)
    try:
        version = fmt.read_magic(fh)
    except _HEADER_ERRORS as exc:
        raise PointCloudFileError(
            path, f"not a readable .npy file (no NumPy signature): {exc}"
        ) from exc
    try:
        if version == (1, 0):
            return fmt.read_array_header_1_0(fh)
        if version == (2, 0):
            return fmt.read_array_header_2_0(fh)
        if version == (3, 0) and _read_array_header is not None:
            return _read_array_header(fh, version)  # 2.0 with a UTF-8 header
    except _HEADER_ERRORS as exc:
        raise PointCloudFileError(
            path, f"corrupt .npy header ({type(exc).__name__}: {exc})"
        ) from exc
    raise PointCloudFileError(path, f"unsupported .npy format version {version}")


def _check_data_size(path, fh, shape, dtype):
    if any(not isinstance(n, int) or n < 0 for n in shape):
        raise PointCloudFileError(path, f"corrupt .npy header: shape {shape}")
    count = 1
    for n in shape:
        count *= n
    offset = fh.tell()
    size = os.fstat(fh.fileno()).st_size
    expected = count * dtype.itemsize
    if size - offset != expected:
        raise PointCloudFileError(
            path,
            f"the header declares shape {shape} of {dtype} "
            f"({expected} bytes of data after a {offset}-byte header, "
            f"{offset + expected} bytes in all), but the file holds {size} bytes "
            f"({'truncated' if size - offset < expected else 'trailing bytes'})",
        )
    return count


def _load(path):
    with open(path, "rb") as fh:
        shape, fortran, dtype = _read_header(path, fh)
        if dtype.hasobject:
            raise PointCloudFileError(
                path,
                f"the array holds Python objects ({dtype}), which only "
                "unpickling could read; skpcd never unpickles an .npy file",
            )
        if dtype.itemsize == 0:
            raise PointCloudFileError(path, f"the items are empty ({dtype}).")
        count = _check_data_size(path, fh, shape, dtype)
        if count == 0:
            raise PointCloudFileError(path, f"the file declares no points {shape}.")
        buffer = bytearray(count * dtype.itemsize)
        if fh.readinto(buffer) != len(buffer):  # the file shrank meanwhile
            raise PointCloudFileError(path, "the file is truncated.")
    if dtype.shape:  # a sub-array dtype: its shape is the array's last axes
        shape, count = shape + dtype.shape, count * int(np.prod(dtype.shape))
        dtype = dtype.base
    data = np.frombuffer(buffer, dtype=dtype, count=count)
    if fortran:
        return data.reshape(shape[::-1]).transpose()
    return data.reshape(shape)


def read(path):
    """Read an ``.npy`` cloud into ``(fields, info)``; see the module docstring."""
    data = _load(path)
    names = data.dtype.names
    renamed = coordinate_names(names or ())
    if renamed:  # PDAL's X Y Z (its writers.numpy and readers.numpy)
        data = data.view(
            np.dtype(
                {
                    "names": [renamed.get(n, n) for n in names],
                    "formats": [data.dtype.fields[n][0] for n in names],
                    "offsets": [data.dtype.fields[n][1] for n in names],
                    "itemsize": data.dtype.itemsize,
                }
            )
        )
        names = data.dtype.names
    if names:
        missing = [c for c in "xyz" if c not in names]
        if missing or data.ndim != 1:
            raise PointCloudFileError(
                path,
                "a structured .npy cloud needs 1-D records with fields x, y, z (or "
                "X, Y, Z); "
                f"found shape {data.shape} with fields {', '.join(names)}.",
            )
        for c in "xyz":
            field = data.dtype.fields[c][0]
            if field.shape or field.kind not in _NUMERIC:
                raise PointCloudFileError(
                    path,
                    f"field {c!r} must hold one number per point, found {field}.",
                )
        fields = {}
        for name in names:
            values = data[name]
            if values.ndim > 2:
                values = values.reshape(len(values), -1)
            fields[name] = values
        return fields, {}
    if data.ndim != 2 or data.shape[1] < 3:
        raise PointCloudFileError(
            path, f"expected an array of shape (n, 3+), found shape {data.shape}."
        )
    if data.dtype.kind not in _NUMERIC:
        raise PointCloudFileError(
            path, f"expected integers or floats, found dtype {data.dtype}."
        )
    names = ["x", "y", "z"] + [f"field_{j}" for j in range(3, data.shape[1])]
    return {name: data[:, j] for j, name in enumerate(names)}, {}


def write(path, fields, *, encoding=None):
    """Write a plain ``(n, 3)`` array, or a structured array when there are extras."""
    if encoding not in (None, "binary"):
        raise ValueError(f".npy files are always binary; got encoding={encoding!r}")
    if list(fields) == ["x", "y", "z"]:
        np.save(path, np.column_stack([fields[c] for c in "xyz"]))
        return
    dtype = [
        (name, np.asarray(v).dtype, np.asarray(v).shape[1:])
        for name, v in fields.items()
    ]
    n = len(fields["x"])
    out = np.empty(n, dtype=dtype)
    for name, values in fields.items():
        out[name] = values
    np.save(path, out)
