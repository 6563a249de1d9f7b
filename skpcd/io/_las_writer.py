"""LAS/LAZ files written through laspy: the point format, scales and dimensions.

Writing uses LAS 1.4 point format 6, or 7 when there are colours, or 8 with
``nir``; how each coordinate is scaled and where each field is stored is in
the docstring of :mod:`skpcd.io._las`. Given the header of a source file
(``header=``), the output takes it over instead, as PDAL's ``forward=all``
does: LAS version, point format, scales, offsets, CRS and other VLRs (see
:func:`write`).
"""

import numpy as np

from skpcd.exceptions import PointCloudFileError
from skpcd.io._common import distinct_columns, field_columns, is_whole
from skpcd.io._copc import COPC_USER_ID
from skpcd.io._las_structure import import_laspy

__all__ = ["carried_header", "is_copc", "write"]

_SCALE = 1e-4
_INT32_MAX = 2**31 - 1


def _scale_offset(values, scale=_SCALE, offset=None):
    """The scale and offset of one axis: ``scale`` and ``offset`` when the
    values fit the 32-bit range with them, else the offset ``floor(min)``
    and ``scale`` coarsened by powers of ten until they fit."""
    if not len(values):
        return scale, 0.0 if offset is None else offset
    low, high = float(values.min()), float(values.max())
    if offset is not None:
        if max(abs(low - offset), abs(high - offset)) / scale <= _INT32_MAX:
            return scale, offset
    offset = float(np.floor(low))
    while (high - offset) / scale > _INT32_MAX:
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


def _plan(laspy, fields, template=None):
    """The point format id, standard dimensions and extra dimensions to write
    (with a ``template`` header, its point format, and its extra dimensions
    as the types of the fields named like them)."""
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
    if template is None:
        point_format = 8 if "nir" in extras else 7 if has_rgb else 6
        formats = laspy.PointFormat(point_format).dimensions
    else:
        point_format = template.point_format.id
        formats = template.point_format.dimensions
    dimensions = {d.name: d for d in formats if d.name not in ("X", "Y", "Z")}
    components = {"normals": ("normal_x", "normal_y", "normal_z")}
    if split_colors:
        components["colors"] = ("red", "green", "blue")
    standard, extra = {}, {}
    for name, values in distinct_columns(field_columns(extras, components), "field"):
        if name in dimensions and not dimensions[name].is_standard:
            standard[name] = values  # the template's extra dimension, its type
        elif name in dimensions:
            standard[name] = _fits(name, values, dimensions[name])
        elif len(name.encode()) > 32:
            raise ValueError(
                f"field {name!r}: LAS extra dimension names have at most 32 bytes."
            )
        else:
            extra[name] = values.astype(_extra_type(name, values))
    return point_format, standard, extra


def is_copc(vlr):
    """Whether ``vlr`` is a COPC record (info, hierarchy, extents): it
    describes the octree order of a source's points, which a copy does not
    keep, so no output carries it."""
    return vlr.user_id == COPC_USER_ID


def carried_header(header):
    """A copy of a source's laspy header for an output: its version, point
    format, scales, offsets, VLRs and EVLRs (the CRS among them), but for
    the COPC records. laspy sets the counts and bounds when writing."""
    header = header.copy()
    header.vlrs = [v for v in header.vlrs if not is_copc(v)]
    if header.evlrs is not None:
        header.evlrs = [v for v in header.evlrs if not is_copc(v)]
    return header


def _same_record(vlr, others):
    return any((vlr.user_id, vlr.record_id) == (o.user_id, o.record_id) for o in others)


def write(path, fields, *, encoding=None, extra_params=None, vlrs=(), header=None):
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
        VLRs to add to the header (one of the same user id and record id as
        a VLR of ``header`` replaces it).
    header : laspy.LasHeader, default=None
        The header of a source file to carry through, as PDAL's
        ``forward=all`` does: the output keeps its LAS version, point
        format, scales and offsets (an offset is moved, and a scale
        coarsened by powers of ten, only for points beyond the 32-bit
        range of the source's), and its VLRs and EVLRs (the CRS: WKT,
        GeoKeys), but for COPC records. Fields named as a dimension of its
        point format are stored there (``scan_angle_rank`` of format 3
        stays ``scan_angle_rank``), fields named as one of its extra
        dimensions keep that dimension's definition, its other extra
        dimensions are left out, and other fields become new extra
        dimensions. None writes skpcd's own layout (LAS 1.4, format 6, 7
        or 8, scale 0.0001).

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
    point_format, standard, extra = _plan(laspy, fields, header)
    try:
        if header is None:
            header = laspy.LasHeader(point_format=point_format, version="1.4")
            scales_offsets = [_scale_offset(v) for v in coords]
        else:
            header = carried_header(header)
            unused = [
                n
                for n in header.point_format.extra_dimension_names
                if n not in standard
            ]
            if unused:
                header.remove_extra_dims(unused)
            scales_offsets = [
                _scale_offset(v, float(s), float(o))
                for v, s, o in zip(coords, header.scales, header.offsets, strict=True)
            ]
        given = extra_params or {}
        if extra:
            header.add_extra_dims(
                [
                    given.get(name) or laspy.ExtraBytesParams(name, v.dtype)
                    for name, v in extra.items()
                ]
            )
        if vlrs:
            kept = [v for v in header.vlrs if not _same_record(v, vlrs)]
            header.vlrs = [*kept, *vlrs]
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
