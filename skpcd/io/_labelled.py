"""A labelled copy of a scan: every input point and dimension, plus the answer.

:func:`write_labelled_scan` writes what ``skpcd identify`` found for each point
(segment, class, score, ground) beside everything the input scan held, and
:func:`read_class_names` reads the class names back from a LAS/LAZ output.

LAS/LAZ to LAS/LAZ is streamed chunk by chunk (the input may be larger than
memory); the layout of the output is in the user guide ("Labelled scans") and
in the docstring of :func:`write_labelled_scan`.
"""

import json
import os
import warnings
from pathlib import Path

import numpy as np

from skpcd.exceptions import MissingFileError, NonFiniteWarning, PointCloudFileError
from skpcd.io._api import SUPPORTED_EXTENSIONS, read_point_cloud, write_point_cloud
from skpcd.io._atomic import atomic_path
from skpcd.io._class_codes import classification_codes
from skpcd.io._common import check_chunk_size, take_rows
from skpcd.io._las_reader import checked_chunks, open_checked, read_vlr_records
from skpcd.io._las_structure import decoding, import_laspy
from skpcd.io._las_writer import carried_header
from skpcd.io._las_writer import write as write_las

__all__ = ["read_class_names", "write_labelled_scan"]

#: ASPRS class written into ``classification`` at ground points
GROUND_CLASS = 2
#: code of class ``j`` in the ``class`` dimension of a LAS output is 64 + j
FIRST_CODE = 64
MAX_CLASSES = 256 - FIRST_CODE
#: the VLR holding the full class names (JSON)
SKPCD_USER_ID = "skpcd"
SKPCD_RECORD_ID = 1
_LOOKUP_USER_ID = "LASF_Spec"
_LOOKUP_RECORD_ID = 0
_LAS = (".las", ".laz")
_RESERVED = ("segment", "class", "ground")
#: ASPRS class of the points without a class (and not ground) when the
#: classes go into ``classification``
UNCLASSIFIED = 1
#: the extra dimension that keeps the input's classification
ORIGINAL = "original_classification"
_CLASSES_INTO = ("classification", "extra")
# LAS 1.4 point format of the same fields as a legacy one (0 to 5), whose
# classification holds only 0 to 31
_UPGRADE = {0: 6, 1: 6, 2: 7, 3: 7, 4: 9, 5: 10}
_SCAN_ANGLE_UNIT = 0.006  # degrees per unit of scan_angle (formats 6 to 10)
_INT32 = np.iinfo(np.int32)


def _is_las(path):
    return path.suffix.lower() in _LAS


def _check_paths(source, output, overwrite):
    source = Path(os.fspath(source))
    output = Path(os.fspath(output))
    for path in (source, output):
        if path.suffix.lower() not in SUPPORTED_EXTENSIONS:
            raise PointCloudFileError(
                path,
                f"unknown point-cloud extension {path.suffix or '(none)'!r}; "
                "supported: " + ", ".join(SUPPORTED_EXTENSIONS),
            )
    if not source.is_file():
        what = "is a directory, not a file" if source.is_dir() else "no such file"
        raise MissingFileError(source, what)
    same = source.resolve() == output.resolve() or (
        output.exists() and os.path.samefile(source, output)
    )
    if same:
        raise ValueError(
            f"{output}: the output is the source scan; write the labelled copy "
            "to another file (the source is never replaced, even with overwrite)"
        )
    if output.exists() and not overwrite:
        raise FileExistsError(
            f"{output}: the file exists; pass overwrite=True to replace it."
        )
    return source, output


def _check_array(name, values, kinds):
    if values is None:
        return None
    if not hasattr(values, "dtype") or not hasattr(values, "shape"):
        values = np.asarray(values)  # lists; arrays and memmaps are kept as they are
    if values.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array, got shape {values.shape}")
    if values.dtype.kind not in kinds:
        raise ValueError(f"{name} must have a numeric dtype, got {values.dtype}")
    return values


def _check_score_name(score, score_name):
    if score is None:
        return None
    name = "score" if score_name is None else score_name
    if not isinstance(name, str) or not name or len(name.encode()) > 32:
        raise ValueError(
            f"score_name must be a non-empty name of at most 32 bytes, got {name!r}"
        )
    if name in (*_RESERVED, "x", "y", "z"):
        raise ValueError(f"score_name {name!r} clashes with another dimension")
    return name


def _check_lengths(source, n_points, arrays, n_finite=None):
    for name, values in arrays.items():
        if values is None or len(values) == n_points:
            continue
        if n_finite is not None and len(values) == n_finite:
            continue
        finite = (
            ""
            if n_finite is None or n_finite == n_points
            else f" ({n_finite} with finite coordinates)"
        )
        raise ValueError(
            f"{source}: {name} has {len(values)} values but the scan has {n_points} "
            f"points{finite}; give one value per point, in the file's order"
        )


def _chunk_values(arrays, start, stop, n_classes):
    """The per-point values of points ``start:stop``, checked and typed."""
    out = {}
    segment = np.asarray(arrays["segment"][start:stop])
    if len(segment) and (segment.min() < -1 or segment.max() > _INT32.max):
        raise ValueError(
            "segment values must be -1 (no segment) or 0 to 2**31 - 1; got "
            f"{segment.min()} to {segment.max()}"
        )
    out["segment"] = segment.astype(np.int32)
    index = np.asarray(arrays["class_index"][start:stop])
    if len(index) and (index.min() < -1 or index.max() >= n_classes):
        raise ValueError(
            f"class_index values must be -1 (no class) or 0 to {n_classes - 1} "
            f"(one per class name); got {index.min()} to {index.max()}"
        )
    out["class_index"] = index.astype(np.int64)
    if arrays["score"] is not None:
        out["score"] = np.asarray(arrays["score"][start:stop], dtype=np.float32)
    if arrays["ground"] is not None:
        ground = np.asarray(arrays["ground"][start:stop])
        if ground.dtype != np.bool_:
            if len(ground) and not np.isin(ground, (0, 1)).all():
                raise ValueError("ground must be boolean (or 0/1)")
            ground = ground.astype(bool)
        out["ground"] = ground
    return out


def _lookup_name(name):
    """A class name as the 15 ASCII bytes of a Classification Lookup entry."""
    text = name.encode("ascii", "replace")[:15]
    return text.replace(b"\0", b"?")


def _names_json(class_names, score_name, has_ground, codes=None):
    record = {
        "skpcd_labelled_scan": 1,
        "classes": {str(FIRST_CODE + j): name for j, name in enumerate(class_names)},
        "no_class": 0,
        "dimensions": {
            "segment": "segment",
            "class": "class",
            "score": score_name,
            "ground": "ground" if has_ground else None,
        },
        "no_segment": -1,
        "ground_classification": GROUND_CLASS if has_ground else None,
        "classes_into": "extra" if codes is None else "classification",
    }
    if codes is not None:
        record["classification"] = {
            str(code): name for code, name in _code_names(class_names, codes).items()
        }
        record["original_classification"] = ORIGINAL
    data = json.dumps(record, ensure_ascii=False, separators=(",", ":")).encode()
    if len(data) > 65535:
        raise ValueError(
            f"the class names take {len(data)} bytes of JSON; a LAS VLR holds at "
            "most 65535: use shorter names"
        )
    return data


def _code_names(class_names, codes):
    """Classification code -> name of what skpcd writes into
    ``classification`` (a code of several classes names them all)."""
    names = {UNCLASSIFIED: "unclassified"}
    for name, code in zip(class_names, codes, strict=True):
        names[code] = (
            name
            if names.get(code) in (None, "unclassified")
            else (f"{names[code]}/{name}")
        )
    return dict(sorted(names.items()))


def _class_vlrs(laspy, class_names, score_name, has_ground, existing=(), codes=None):
    """The Classification Lookup VLR and the skpcd VLR with the full names.

    With ``codes`` (the classes written into ``classification``), the lookup
    names exactly the codes written: 1 (unclassified), 2 (ground, with
    ``has_ground``) and the code of each class. Without, it names the codes
    64 + j of the ``class`` dimension, entries below 64 of an existing one
    kept."""
    entries = {}
    if codes is not None:
        existing = ()
        if has_ground:
            entries[GROUND_CLASS] = b"ground"
        for code, name in _code_names(class_names, codes).items():
            entries[code] = _lookup_name(name)
    for vlr in existing:
        if (
            vlr.user_id == _LOOKUP_USER_ID
            and vlr.record_id == _LOOKUP_RECORD_ID
            and hasattr(vlr, "lookups")
        ):
            for code, text in vlr.lookups.items():
                if code < FIRST_CODE:
                    entries[int(code)] = text.encode("ascii", "replace")[:15]
    if codes is None:
        for j, name in enumerate(class_names):
            entries[FIRST_CODE + j] = _lookup_name(name)
    lookup = b"".join(
        code.to_bytes(1, "little") + text.ljust(15, b"\0")
        for code, text in sorted(entries.items())
    )
    return [
        laspy.VLR(_LOOKUP_USER_ID, _LOOKUP_RECORD_ID, "Classification Lookup", lookup),
        laspy.VLR(
            SKPCD_USER_ID,
            SKPCD_RECORD_ID,
            "skpcd class names (JSON)",
            _names_json(class_names, score_name, has_ground, codes),
        ),
    ]


def _is_ours(vlr):
    return (vlr.user_id, vlr.record_id) in (
        (_LOOKUP_USER_ID, _LOOKUP_RECORD_ID),
        (SKPCD_USER_ID, SKPCD_RECORD_ID),
    )


def _new_dims(laspy, score_name, has_ground):
    params = [
        laspy.ExtraBytesParams(
            "segment", "int32", description="segment id (-1: none)", no_data=[-1]
        ),
        laspy.ExtraBytesParams(
            "class", "uint8", description="class code 64+j (0: none)", no_data=[0]
        ),
    ]
    if score_name is not None:
        description = f"{score_name} (NaN: none)"
        if len(description) > 32:
            description = score_name[:32]
        params.append(
            laspy.ExtraBytesParams(
                score_name, "float32", description=description, no_data=[np.nan]
            )
        )
    if has_ground:
        params.append(
            laspy.ExtraBytesParams("ground", "uint8", description="ground point (1/0)")
        )
    return params


class _ExtraStats:
    """The true min and max of each extra dimension, whatever the chunking.

    laspy 2.7 records the first value of each written chunk as the extra
    bytes' min/max; these are recomputed from every point and set in the
    Extra Bytes VLR before the header is written.
    """

    def __init__(self, header):
        self.structs = []
        for vlr in header.vlrs:
            for struct in getattr(vlr, "extra_bytes_structs", ()):
                if struct.data_type == 0 or not (
                    struct.min_is_relevant() and struct.max_is_relevant()
                ):
                    continue
                long_type = struct._long_type()
                count = struct.num_elements()
                info = np.finfo if long_type == np.float64 else np.iinfo
                low = np.full(count, info(long_type).max, dtype=long_type)
                high = np.full(count, info(long_type).min, dtype=long_type)
                self.structs.append(
                    (struct, struct.format_name(), long_type, count, low, high)
                )

    def grow(self, array):
        for struct, name, long_type, count, low, high in self.structs:
            values = array[name].reshape(len(array), count)
            no_data = struct.no_data
            for i in range(count):
                column = values[:, i]
                keep = np.ones(len(column), dtype=bool)
                if column.dtype.kind == "f":
                    keep &= ~np.isnan(column)
                if no_data is not None and not np.isnan(no_data[i]):
                    keep &= column != no_data[i]
                column = column[keep]
                if len(column):
                    low[i] = min(low[i], long_type(column.min()))
                    high[i] = max(high[i], long_type(column.max()))

    def store(self):
        for struct, _, long_type, count, low, high in self.structs:
            np.frombuffer(struct._min, dtype=long_type)[:count] = low
            np.frombuffer(struct._max, dtype=long_type)[:count] = high


def _written(score_name, has_ground):
    """The names of the dimensions written (an input one of these is replaced)."""
    names = {"segment", "class"}
    if score_name is not None:
        names.add(score_name)
    if has_ground:
        names.add("ground")
    return names


def _upgraded(laspy, header, codes):
    """``header`` with the LAS 1.4 point format of the same fields when its
    legacy point format (0 to 5, classification 0 to 31) cannot hold the
    codes; None when it can."""
    fmt = header.point_format
    if fmt.id not in _UPGRADE or max(codes, default=0) <= 31:
        return None
    point_format = laspy.PointFormat(_UPGRADE[fmt.id])
    for dim in fmt.extra_dimensions:
        point_format.dimensions.append(dim)
    header.set_version_and_point_format(laspy.header.Version(1, 4), point_format)
    # formats 6 to 10 read the CRS from the WKT VLR when this bit says so
    if any((v.user_id, v.record_id) == ("LASF_Projection", 2112) for v in header.vlrs):
        header.global_encoding.wkt = True
    return header


def _copy_upgraded(record, points, names):
    """The dimensions ``names`` of a legacy-format chunk into a record of
    its LAS 1.4 counterpart (scan_angle_rank in degrees becomes scan_angle
    in units of 0.006 degree)."""
    for name in names:
        if name == "scan_angle_rank":
            degrees = np.asarray(points[name], dtype=np.float64)
            record["scan_angle"] = np.round(degrees / _SCAN_ANGLE_UNIT).astype(np.int16)
        elif name not in ("X", "Y", "Z"):
            record[name] = points[name]
    for axis in "XYZ":
        record[axis] = points[axis]


def _stream_las(
    source, output, arrays, class_names, score_name, keep_fields, chunk, codes
):
    laspy = import_laspy()
    has_ground = arrays["ground"] is not None
    with open_checked(laspy, source) as (reader, n_points):
        _check_lengths(source, n_points, arrays)
        standard = set(reader.header.point_format.standard_dimension_names)
        if score_name in standard:
            raise ValueError(
                f"score_name {score_name!r} is a standard LAS dimension; pick another"
            )
        with decoding(source):  # laspy's parsing of the source's header
            header = carried_header(reader.header)
            ours = _written(score_name, has_ground)
            extra = list(header.point_format.extra_dimension_names)
            # an earlier output's original classification is the original
            keep_original = codes is not None and ORIGINAL in extra
            drop = [
                n
                for n in extra
                if n in ours or not (keep_fields or (keep_original and n == ORIGINAL))
            ]
            if drop:
                header.remove_extra_dims(drop)
            names = list(header.point_format.dimension_names)
            kept_raw = [
                n for n in reader.header.point_format.dtype().names if n not in drop
            ]
            new_dims = _new_dims(laspy, score_name, has_ground)
            if codes is not None and not keep_original:
                new_dims.append(
                    laspy.ExtraBytesParams(
                        ORIGINAL, "uint8", description="classification of the input"
                    )
                )
            header.add_extra_dims(new_dims)
            upgraded = codes is not None and _upgraded(laspy, header, codes)
            vlrs = [v for v in header.vlrs if not _is_ours(v)]
            header.vlrs = vlrs + _class_vlrs(
                laspy, class_names, score_name, has_ground, header.vlrs, codes
            )
            evlrs = list(header.evlrs or ())
        n_classes = len(class_names)
        code_of = None if codes is None else np.array([UNCLASSIFIED, *codes])
        with atomic_path(output, overwrite=True) as tmp:
            compress = output.suffix.lower() == ".laz"
            with laspy.open(
                str(tmp), mode="w", header=header, do_compress=compress
            ) as writer:
                stats = _ExtraStats(writer.header)
                start = 0
                for points in checked_chunks(reader, source, chunk, n_points):
                    stop = start + len(points)
                    values = _chunk_values(arrays, start, stop, n_classes)
                    record = laspy.ScaleAwarePointRecord.zeros(
                        len(points), header=writer.header
                    )
                    if upgraded:
                        _copy_upgraded(record, points, names)
                    else:
                        for name in kept_raw:
                            record.array[name] = points.array[name]
                    index = values["class_index"]
                    if code_of is not None:
                        classification = code_of[index + 1]
                        if not keep_original:
                            record[ORIGINAL] = np.asarray(points["classification"])
                    else:
                        classification = np.array(record["classification"])
                    if has_ground:
                        classification[values["ground"]] = GROUND_CLASS
                    record["classification"] = classification
                    record["segment"] = values["segment"]
                    record["class"] = np.where(index >= 0, index + FIRST_CODE, 0)
                    if score_name is not None:
                        record[score_name] = values["score"]
                    if has_ground:
                        record["ground"] = values["ground"].astype(np.uint8)
                    stats.grow(record.array)
                    writer.write_points(record)
                    start = stop
                stats.store()
                if evlrs and header.version.minor >= 4:
                    writer.write_evlrs(laspy.vlrs.vlrlist.VLRList(evlrs))


def _in_memory(source, output, arrays, class_names, score_name, keep_fields, codes):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NonFiniteWarning)
        read = read_point_cloud(
            source, fields="all" if keep_fields else None, nonfinite="keep"
        )
    points, fields = read if keep_fields else (read, {})
    n_points = len(points)
    finite = np.isfinite(points).all(axis=1)
    n_finite = int(finite.sum())
    _check_lengths(source, n_points, arrays, n_finite)
    values = _chunk_values(arrays, 0, len(arrays["segment"]), len(class_names))
    if len(values["segment"]) != n_points:  # given for the finite points only
        values = _spread(values, finite)
    has_ground = arrays["ground"] is not None
    ours = _written(score_name, has_ground)
    fields = {k: v for k, v in fields.items() if k not in ours}
    if _is_las(output):
        if n_finite < n_points:
            warnings.warn(
                f"{source}: {n_points - n_finite} of {n_points} points have NaN or "
                f"infinite coordinates, which LAS cannot store; {output} leaves "
                "them out.",
                NonFiniteWarning,
                stacklevel=3,
            )
            points, fields, values = take_rows(finite, points, fields, values)
        _write_las_memory(
            output, points, fields, values, class_names, score_name, codes
        )
        return
    if has_ground and "classification" in fields:
        classification = np.array(fields["classification"])
        classification[values["ground"]] = GROUND_CLASS
        fields["classification"] = classification
    out = dict(fields)
    out["segment"] = values["segment"]
    out["class"] = values["class_index"].astype(np.int32)
    if score_name is not None:
        out[score_name] = values["score"]
    if has_ground:
        out["ground"] = values["ground"].astype(np.uint8)
    write_point_cloud(output, points, fields=out, overwrite=True)


def _spread(values, finite):
    """Values given for the finite points only, spread over every point (the
    others get no segment, no class, no score, not ground)."""
    fill = {"segment": -1, "class_index": -1, "score": np.nan, "ground": False}
    out = {}
    for name, v in values.items():
        full = np.full(len(finite), fill[name], dtype=v.dtype)
        full[finite] = v
        out[name] = full
    return out


def _write_las_memory(output, points, fields, values, class_names, score_name, codes):
    """A LAS/LAZ output from a source of another format: skpcd's own LAS
    layout (see :mod:`skpcd.io._las`) with the labelled dimensions."""
    laspy = import_laspy()
    has_ground = "ground" in values
    out = {c: points[:, j] for j, c in enumerate("xyz")}
    out.update(fields)
    index = values["class_index"]
    if codes is not None:
        if "classification" in out and ORIGINAL not in out:
            out[ORIGINAL] = out["classification"]
        out["classification"] = np.array([UNCLASSIFIED, *codes])[index + 1]
    if has_ground or "classification" in out:
        classification = np.array(out.get("classification", np.zeros(len(points))))
        if has_ground:
            classification[values["ground"]] = GROUND_CLASS
        out["classification"] = classification
    out["segment"] = values["segment"]
    out["class"] = np.where(index >= 0, index + FIRST_CODE, 0).astype(np.uint8)
    if score_name is not None:
        out[score_name] = values["score"]
    if has_ground:
        out["ground"] = values["ground"].astype(np.uint8)
    dims = {p.name: p for p in _new_dims(laspy, score_name, has_ground)}
    with atomic_path(output, overwrite=True) as tmp:
        write_las(
            tmp,
            out,
            extra_params=dims,
            vlrs=_class_vlrs(laspy, class_names, score_name, has_ground, codes=codes),
        )


def write_labelled_scan(
    source,
    output,
    *,
    segment,
    class_index,
    class_names,
    score=None,
    score_name=None,
    ground=None,
    keep_fields=True,
    classes_into="classification",
    class_codes=None,
    chunk_size=1_000_000,
    overwrite=False,
):
    """Write a copy of a scan with the segment and class of every point.

    Read more in the :ref:`User Guide <labelled-scans>`.

    A LAS/LAZ source written to a LAS/LAZ output is streamed, ``chunk_size``
    points at a time: the scan may be larger than memory, and so may the
    per-point arrays (pass :class:`numpy.memmap` arrays; they are read a
    chunk at a time). Every point, every standard and extra-bytes dimension
    (bit for bit), the header's scales, offsets and other fields, and every
    VLR and EVLR of the source are kept, but for the records of a COPC
    source's octree (user id ``copc``: the copy is a plain LAZ file, its
    points are not in octree order). Then:

    - with ``classes_into="classification"`` (the default), ``classification``
      holds the class of each point as the code
      :func:`~skpcd.io._class_codes.classification_codes` gives it (ASPRS
      codes where they exist, user codes from 64 otherwise), 2 (ASPRS
      ground) where ``ground`` is True and 1 (unclassified) elsewhere, its
      flag bits kept, and the input's classification goes to an extra
      dimension ``original_classification`` (uint8; an input that has one
      keeps its own). A legacy point format (0 to 5: codes 0 to 31 only)
      becomes its LAS 1.4 counterpart (6, 7, 9 or 10) when a code above 31
      is needed; the header is otherwise kept;
    - with ``classes_into="extra"``, ``classification`` is set to 2 (ASPRS
      ground) where ``ground`` is True, unchanged elsewhere (its flag bits
      too);
    - extra-bytes dimensions are added, each with a description in the Extra
      Bytes VLR: ``segment`` (int32, -1 = no segment), ``class`` (uint8,
      64 + j for ``class_names[j]``, 0 = no class), the score under
      ``score_name`` (float32, NaN = none) and ``ground`` (uint8, 1/0). An
      input extra dimension of one of these names (an earlier output) is
      replaced, not duplicated;
    - the class names go into the file: a Classification Lookup VLR
      (``LASF_Spec``, record 0; entries ``uint8 code + 15 ASCII bytes``: the
      codes that ``classification`` holds, or with ``classes_into="extra"``
      the codes 64 + j, those below 64 of an input lookup kept) and, since 15
      bytes truncate, a VLR of user id ``skpcd``, record 1, holding the full
      names as UTF-8 JSON (:func:`read_class_names` reads either).

    Other combinations (a source or output in another format) are read into
    memory with :func:`read_point_cloud` and written with
    :func:`write_point_cloud`: fields ``segment`` (int32), ``class`` (int32
    index into ``class_names``, -1 = none), the score, ``ground`` (uint8) and,
    with ``keep_fields``, every field of the source (one named like a new
    field is replaced; a ``classification`` field gets 2 at ground points).
    A LAS/LAZ output from another format gets the LAS layout above (format
    6, 7 or 8, as :func:`write_point_cloud` picks).

    Parameters
    ----------
    source : str or path-like
        The scan, in any format skpcd reads.
    output : str or path-like
        The labelled copy; its extension picks the format. Must not be the
        source (refused even with ``overwrite``).
    segment : array-like of int of shape (n_points,)
        Segment of each point, -1 for none, in the source's point order.
    class_index : array-like of int of shape (n_points,)
        Class of each point: j for ``class_names[j]``, -1 for none.
    class_names : sequence of str
        The class names (may include ``"unknown"``); at most 192 for a
        LAS/LAZ output (codes 64 to 255).
    score : array-like of float of shape (n_points,), default=None
        Confidence of each point's class (the probability or the similarity),
        NaN for none. None writes no score.
    score_name : str, default=None
        Name of the score dimension (``"probability"``, ``"similarity"``);
        ``"score"`` when None.
    ground : array-like of bool of shape (n_points,), default=None
        Ground points. None leaves ``classification`` as it is and writes no
        ``ground`` dimension.
    keep_fields : bool, default=True
        Keep the source's own fields. With False, a LAS/LAZ to LAS/LAZ copy
        drops the input's extra-bytes dimensions (the standard dimensions of
        its point format stay) and other copies hold only xyz and the new
        fields.
    classes_into : {"classification", "extra"}, default="classification"
        Where the classes go in a LAS/LAZ output: into ``classification``
        as well as the ``class`` dimension (what LAS viewers colour by and
        PDAL filters select on; the input's classification kept in
        ``original_classification``), or into ``class`` alone, leaving
        ``classification`` as it was but for the ground. Other outputs are
        the same either way.
    class_codes : dict of str to int, default=None
        Classification codes (0 to 255) for some class names, in place of
        those of :func:`~skpcd.io._class_codes.classification_codes`.
    chunk_size : int, default=1_000_000
        Points per chunk when streaming. The file content does not depend on
        it.
    overwrite : bool, default=False
        Replace an existing output. The output is written under a hidden name
        and renamed when whole, so an error or interrupt leaves no partial
        file.

    Raises
    ------
    ValueError
        If an array's length differs from the source's point count (the
        message names the file and both counts), values are out of range,
        there are more than 192 classes for a LAS output, ``score_name``
        clashes with a dimension, ``output`` is the source, ``classes_into``
        is neither "classification" nor "extra", or a code of
        ``class_codes`` is not 0 to 255.
    FileExistsError
        If ``output`` exists and ``overwrite`` is False.
    MissingFileError
        If the source does not exist.
    PointCloudFileError
        If the source cannot be read.

    Notes
    -----
    Only LAS/LAZ to LAS/LAZ streams. The in-memory path reads the source with
    ``nonfinite="keep"``, so that the arrays line up with every point of the
    file; they may instead describe only the points with finite coordinates
    (``len == n_finite``, what :func:`read_point_cloud` returns by default),
    and the other points then get no segment, no class, a NaN score and no
    ground. Text, NPY, PLY and PCD outputs keep the non-finite points; a
    LAS/LAZ output cannot store them and leaves them out with a
    :class:`~skpcd.exceptions.NonFiniteWarning`.

    See Also
    --------
    read_class_names : The class names of a labelled LAS/LAZ file.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from skpcd.io import read_class_names, write_labelled_scan, write_point_cloud
    >>> folder = tempfile.mkdtemp()
    >>> scan = os.path.join(folder, "scan.las")
    >>> write_point_cloud(scan, np.arange(12.0).reshape(4, 3))
    >>> out = os.path.join(folder, "labelled.las")
    >>> write_labelled_scan(
    ...     scan, out, segment=[0, 0, 1, -1], class_index=[1, 1, 0, -1],
    ...     class_names=["car", "tree"], ground=[False, False, False, True])
    >>> read_class_names(out)
    {64: 'car', 65: 'tree'}
    """
    check_chunk_size(chunk_size)
    if classes_into not in _CLASSES_INTO:
        raise ValueError(
            f"classes_into must be 'classification' or 'extra', got {classes_into!r}"
        )
    class_names = [str(c) for c in class_names]
    source, output = _check_paths(source, output, overwrite)
    if _is_las(output) and len(class_names) > MAX_CLASSES:
        raise ValueError(
            f"{len(class_names)} classes: a LAS/LAZ output holds at most "
            f"{MAX_CLASSES} (class codes {FIRST_CODE} to 255)"
        )
    score_name = _check_score_name(score, score_name)
    arrays = {
        "segment": _check_array("segment", segment, "iu"),
        "class_index": _check_array("class_index", class_index, "iu"),
        "score": _check_array("score", score, "fiu"),
        "ground": _check_array("ground", ground, "biu"),
    }
    codes = None
    if _is_las(output) and classes_into == "classification":
        codes = classification_codes(class_names, class_codes)
    if _is_las(source) and _is_las(output):
        _stream_las(
            source,
            output,
            arrays,
            class_names,
            score_name,
            keep_fields,
            chunk_size,
            codes,
        )
    else:
        _in_memory(source, output, arrays, class_names, score_name, keep_fields, codes)


def read_class_names(path):
    """The class names stored in a LAS/LAZ file by :func:`write_labelled_scan`.

    Parameters
    ----------
    path : str or path-like
        A ``.las`` or ``.laz`` file.

    Returns
    -------
    names : dict of int to str
        Class code (64 + j in the ``class`` dimension) to name: the full names
        of the ``skpcd`` VLR, or, in a file without it, the (at most 15
        character) descriptions of the Classification Lookup VLR for codes 64
        to 255. Empty when the file has neither.

    Raises
    ------
    MissingFileError
        If the file does not exist.
    PointCloudFileError
        If it is not a readable LAS/LAZ file, or its skpcd VLR is corrupt.
    """
    path = Path(os.fspath(path))
    records = read_vlr_records(path)
    for user_id, record_id, data in records:
        if (user_id, record_id) == (SKPCD_USER_ID, SKPCD_RECORD_ID):
            try:
                classes = json.loads(data.decode())["classes"]
                return {int(code): str(name) for code, name in classes.items()}
            except (ValueError, KeyError, TypeError, AttributeError) as exc:
                raise PointCloudFileError(
                    path, f"the skpcd class-names VLR is corrupt: {exc}"
                ) from exc
    names = {}
    for user_id, record_id, data in records:
        if (user_id, record_id) == (_LOOKUP_USER_ID, _LOOKUP_RECORD_ID):
            for k in range(len(data) // 16):
                code = data[16 * k]
                if code >= FIRST_CODE:
                    text = data[16 * k + 1 : 16 * k + 16].split(b"\0")[0]
                    names[code] = text.decode("ascii", "replace")
    return names
