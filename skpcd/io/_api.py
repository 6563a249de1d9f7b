"""Reading and writing one point cloud: the format-independent front end.

Each format lives in its own module (``_text``, ``_npy``, ``_ply``, ``_pcd``,
``_las``) with two functions: ``read(path) -> (fields, info)``, where
``fields`` maps a field name to an array of shape ``(n,)`` or ``(n, c)`` in
file order, and ``write(path, fields, *, encoding)``. This module picks the
format from the extension, assembles xyz and the requested extra fields, and
applies the policy for non-finite coordinates.
"""

import importlib
import os
import stat
import warnings
from pathlib import Path

import numpy as np

from skpcd.exceptions import (
    MissingFileError,
    NonFiniteWarning,
    PointCloudFileError,
)
from skpcd.io._atomic import atomic_path
from skpcd.io._common import take_rows

__all__ = [
    "SUPPORTED_EXTENSIONS",
    "read_point_cloud",
    "write_point_cloud",
]

_FORMATS = {
    ".xyz": "_text",
    ".txt": "_text",
    ".pts": "_text",
    ".csv": "_text",
    ".npy": "_npy",
    ".ply": "_ply",
    ".pcd": "_pcd",
    ".las": "_las",
    ".laz": "_las",
    ".bin": "_kitti",
}
SUPPORTED_EXTENSIONS = tuple(_FORMATS)

# Names under which the same quantity appears in different formats.
_ALIASES = {
    "normals": (("normal_x", "normal_y", "normal_z"), ("nx", "ny", "nz")),
    "colors": (("red", "green", "blue"), ("r", "g", "b")),
}


def _format_module(path):
    suffix = Path(path).suffix.lower()
    if suffix not in _FORMATS:
        raise PointCloudFileError(
            path,
            f"unknown point-cloud extension {suffix or '(none)'!r}; supported: "
            + ", ".join(SUPPORTED_EXTENSIONS),
        )
    return importlib.import_module(f"skpcd.io.{_FORMATS[suffix]}")


def check_regular_file(path):
    """Raise a clear error unless ``path`` is a regular file (or a link to
    one): missing, a folder, a symbolic-link loop, a FIFO, a socket or a
    device each get their own message, and none is opened."""
    path = Path(os.fspath(path))
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        kind = "a broken symbolic link" if path.is_symlink() else "no such file"
        raise MissingFileError(path, kind) from None
    except OSError as exc:  # ELOOP, EACCES, ENAMETOOLONG...
        raise PointCloudFileError(path, f"cannot be read: {exc.strerror}") from None
    if stat.S_ISREG(mode):
        return path
    if stat.S_ISDIR(mode):
        raise MissingFileError(path, "is a directory, not a file")
    kind = (
        "a FIFO (named pipe)"
        if stat.S_ISFIFO(mode)
        else "a socket"
        if stat.S_ISSOCK(mode)
        else "a device"
    )
    raise PointCloudFileError(path, f"is {kind}, not a regular file")


def _pick(fields, name, path):
    """One requested field, with format aliases resolved."""
    if name in ("x", "y", "z"):  # a copy: the points may hold this column
        return np.array(fields[name])
    if name in fields:
        return np.asarray(fields[name])
    for group in _ALIASES.get(name, ()):
        if all(g in fields for g in group):
            return np.column_stack([fields[g] for g in group])
    available = [n for n in fields if n not in ("x", "y", "z")]
    available += [
        a
        for a, groups in _ALIASES.items()
        if any(all(g in fields for g in grp) for grp in groups)
    ]
    raise PointCloudFileError(
        path,
        f"no field {name!r}; the file has: {', '.join(available) or 'x, y, z only'}.",
    )


def read_point_cloud(path, *, fields=None, nonfinite="drop"):
    """Read one point cloud from a file.

    Read more in the :ref:`User Guide <io>`.

    Parameters
    ----------
    path : str or path-like
        The file. Its extension selects the format: ``.xyz``, ``.txt``,
        ``.pts``, ``.csv`` (text), ``.npy``, ``.ply`` (ascii, binary little or
        big endian), ``.pcd`` (ascii, binary, binary_compressed),
        ``.las``/``.laz`` (through laspy and lazrs) and ``.bin`` (KITTI
        Velodyne: float32 x, y, z, remission, read as ``intensity``).
    fields : None, "all" or list of str, default=None
        Extra per-point fields to return besides xyz, by their name in the
        file (``"intensity"``, ``"classification"``...). ``"normals"`` and
        ``"colors"`` collect the three components under any of their usual
        names (``normal_x``/``nx``...). ``"all"`` returns every field other
        than x, y, z. With None only the points are returned.
    nonfinite : {"drop", "keep", "raise"}, default="drop"
        What to do with points whose x, y or z is NaN or infinite (for
        example the invalid points of an organized PCD): drop them with a
        :class:`~skpcd.exceptions.NonFiniteWarning` that counts them, keep
        them (organized clouds then keep their ``height x width`` layout,
        row-major), or raise. When no finite point remains, "drop" raises.

    Returns
    -------
    points : ndarray of shape (n_points, 3), dtype float64
        The coordinates.
    extras : dict of str to ndarray
        Only when ``fields`` is given: each requested field, with the same
        points removed as from ``points``.

    Raises
    ------
    MissingFileError
        If the file does not exist.
    PointCloudFileError
        For an unknown extension, an empty or corrupt file, a wrong column
        count, a header that disagrees with the data, a missing field, or a
        file without a valid point.

    See Also
    --------
    write_point_cloud : The reverse.
    read_segments : Read a folder of per-object files with their labels.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from skpcd.io import read_point_cloud, write_point_cloud
    >>> path = os.path.join(tempfile.mkdtemp(), "cloud.ply")
    >>> write_point_cloud(path, np.eye(3), fields={"intensity": [1.0, 2.0, 3.0]})
    >>> points, extras = read_point_cloud(path, fields=["intensity"])
    >>> points.shape, extras["intensity"].tolist()
    ((3, 3), [1.0, 2.0, 3.0])
    """
    return read_fields(path, fields, nonfinite=nonfinite)


def read_fields(path, fields=None, *, nonfinite="drop", optional=()):
    """:func:`read_point_cloud`, with ``optional``: more fields returned in
    ``extras`` only when the file has them (the first of each tuple of
    names it has, under that name)."""
    if nonfinite not in ("drop", "keep", "raise"):
        raise ValueError(
            f"nonfinite must be 'drop', 'keep' or 'raise', got {nonfinite!r}"
        )
    path = Path(os.fspath(path))
    module = _format_module(path)
    check_regular_file(path)
    if path.stat().st_size == 0:
        raise PointCloudFileError(path, "the file is empty (0 bytes).")
    data, info = module.read(path)
    for c in "xyz":
        if c not in data:
            raise PointCloudFileError(path, f"the file has no {c!r} field.")
    points = info.get("xyz")  # a format that reads the coordinates as one array
    if points is None:
        points = np.column_stack([np.asarray(data[c], dtype=np.float64) for c in "xyz"])
    if fields is None:
        wanted = []
    elif fields == "all":
        wanted = [n for n in data if n not in ("x", "y", "z")]
    elif isinstance(fields, str):
        wanted = [fields]
    else:
        wanted = list(fields)
    for names in optional:
        present = [n for n in names if n in data and n not in wanted]
        wanted += present[:1]
    extras = {name: _pick(data, name, path) for name in wanted}
    if len(points) == 0:
        raise PointCloudFileError(path, "the file declares no points.")
    # the extremes are finite only when every coordinate is (NaN propagates)
    all_finite = np.isfinite(points.min()) and np.isfinite(points.max())
    finite = None if all_finite else np.isfinite(points).all(axis=1)
    n_bad = 0 if all_finite else int(len(points) - finite.sum())
    if n_bad and nonfinite != "keep":
        if nonfinite == "raise":
            raise PointCloudFileError(
                path,
                f"{n_bad} of {len(points)} points have NaN or infinite coordinates.",
            )
        if n_bad == len(points):
            raise PointCloudFileError(
                path, f"no valid point: all {n_bad} points are NaN or infinite."
            )
        warnings.warn(
            f"{path}: dropped {n_bad} of {len(points)} points with NaN or infinite "
            "coordinates (nonfinite='keep' keeps them).",
            NonFiniteWarning,
            stacklevel=2,
        )
        points, extras = take_rows(finite, points, extras)
    if fields is None and not optional:
        return points
    return points, extras


def write_point_cloud(path, points, *, fields=None, encoding=None, overwrite=False):
    """Write one point cloud to a file.

    Read more in the :ref:`User Guide <io>`.

    Parameters
    ----------
    path : str or path-like
        Destination; its extension selects the format (see
        :func:`read_point_cloud`).
    points : array-like of shape (n_points, 3)
        The coordinates. Written as float64 except in ``.pcd`` and ``.ply``,
        which store float32 unless the values need float64 to round-trip.
    fields : dict of str to array-like, default=None
        Extra per-point fields: arrays of shape ``(n_points,)`` or
        ``(n_points, c)``. ``"normals"`` is written under the format's usual
        names (``normal_x``... in PCD, ``nx``... in PLY).
    encoding : str, default=None
        ``"ascii"``, ``"binary"`` or, for PCD, ``"binary_compressed"``; for PLY
        also ``"binary_big_endian"``. None picks the format's default: binary
        for PLY, PCD and NPY, ascii for text.
    overwrite : bool, default=False
        Replace an existing file. Without it an existing file is never
        touched and :class:`FileExistsError` is raised. The file is written
        under a hidden name beside ``path`` and renamed when whole, so an
        error or an interrupt never leaves a partial file under ``path``.

    Raises
    ------
    FileExistsError
        If the file exists and ``overwrite`` is False.
    PointCloudFileError
        For an unknown extension.
    ValueError
        If the arrays have the wrong shape or lengths.

    See Also
    --------
    read_point_cloud : The reverse.
    """
    path = Path(os.fspath(path))
    module = _format_module(path)
    if path.exists() and not overwrite:
        raise FileExistsError(
            f"{path}: the file exists; pass overwrite=True to replace it."
        )
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (n_points, 3), got {points.shape}.")
    out = {c: points[:, j] for j, c in enumerate("xyz")}
    for name, values in (fields or {}).items():
        values = np.asarray(values)
        if values.ndim not in (1, 2) or len(values) != len(points):
            raise ValueError(
                f"field {name!r} must have shape (n_points,) or (n_points, c) with "
                f"n_points={len(points)}, got {values.shape}."
            )
        if name in ("x", "y", "z"):
            raise ValueError(f"field {name!r} clashes with the coordinates.")
        out[name] = values
    kwargs = {} if encoding is None else {"encoding": encoding}
    with atomic_path(path, overwrite=overwrite) as tmp:
        module.write(tmp, out, **kwargs)
