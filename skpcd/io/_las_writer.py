"""LAS/LAZ files written through laspy: the point format, scales and dimensions.

Writing uses LAS 1.4 point format 6, or 7 when there are colours, or 8 with
``nir``; how each coordinate is scaled and where each field is stored is in
the docstring of :mod:`skpcd.io._las`.
"""

import numpy as np

from skpcd.exceptions import PointCloudFileError
from skpcd.io._common import distinct_columns, field_columns, is_whole
from skpcd.io._las_structure import import_laspy

__all__ = ["write"]

_SCALE = 1e-4
_INT32_MAX = 2**31 - 1


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
        ok = is_whole(values)
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
            values.dtype.kind == "f" and is_whole(values)
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
    components = {"normals": ("normal_x", "normal_y", "normal_z")}
    if split_colors:
        components["colors"] = ("red", "green", "blue")
    standard, extra = {}, {}
    for name, values in distinct_columns(field_columns(extras, components), "field"):
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
    """Write ``fields`` as a LAS or LAZ file; see :mod:`skpcd.io._las`.

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
    laspy = import_laspy()
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
