"""NumPy ``.npy`` point clouds: a plain ``(n, 3+)`` array or a structured array."""

import numpy as np

from skpcd.exceptions import PointCloudFileError


def read(path):
    """Read an ``.npy`` cloud into ``(fields, info)``."""
    try:
        data = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise PointCloudFileError(path, f"not a readable .npy array: {exc}") from exc
    if data.dtype.names:
        missing = [c for c in "xyz" if c not in data.dtype.names]
        if missing or data.ndim != 1:
            raise PointCloudFileError(
                path, "a structured .npy cloud needs 1-D records with fields x, y, z."
            )
        return {name: data[name] for name in data.dtype.names}, {}
    if data.ndim != 2 or data.shape[1] < 3:
        raise PointCloudFileError(
            path, f"expected an array of shape (n, 3+), found shape {data.shape}."
        )
    if not np.issubdtype(data.dtype, np.number):
        raise PointCloudFileError(path, f"expected numbers, found dtype {data.dtype}.")
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
