"""Scans labelled point by point: the class (and object) of every point.

:func:`read_point_labels` reads the labels a user already has: a LAS/LAZ
dimension (``classification`` by default, named by the file's
Classification Lookup VLR or the ASPRS table), a scalar field of a PLY, PCD,
NPY or text export (CloudCompare's ``scalar_Classification``...), or a
SemanticKITTI ``.label`` file beside its ``.bin`` scan. A class map
(:func:`read_class_map`) renames classes and leaves some out (``ignore``).
:func:`read_predicted_labels` reads back what ``skpcd identify`` wrote, and
:func:`labelled_scan_paths` expands folders of scans (SemanticKITTI's
``sequences/NN/velodyne`` + ``labels`` layout among them).
"""

import csv
import json
import os
import typing
from pathlib import Path

import numpy as np

from skpcd.exceptions import MissingFileError, PointCloudFileError
from skpcd.io._api import (
    SUPPORTED_EXTENSIONS,
    check_regular_file,
    read_fields,
    read_point_cloud,
)
from skpcd.io._class_codes import ASPRS_NAMES
from skpcd.io._labelled import ORIGINAL, read_class_names
from skpcd.io._las_reader import read_vlr_records

__all__ = [
    "IGNORE",
    "SEMANTICKITTI_NAMES",
    "ClassMap",
    "PointLabels",
    "labelled_scan_paths",
    "read_class_map",
    "read_point_labels",
    "read_predicted_labels",
]

#: the class name of the points a class map leaves out
IGNORE = "ignore"
#: the fields searched for instance ids when ``instances="auto"``
INSTANCE_FIELDS = ("instance", "object_id")
_LAS = (".las", ".laz")
_LOOKUP = ("LASF_Spec", 0)
_SKPCD_VLR = ("skpcd", 1)

#: SemanticKITTI's raw class ids and names (``semantic-kitti.yaml``)
SEMANTICKITTI_NAMES = {
    0: "unlabeled",
    1: "outlier",
    10: "car",
    11: "bicycle",
    13: "bus",
    15: "motorcycle",
    16: "on-rails",
    18: "truck",
    20: "other-vehicle",
    30: "person",
    31: "bicyclist",
    32: "motorcyclist",
    40: "road",
    44: "parking",
    48: "sidewalk",
    49: "other-ground",
    50: "building",
    51: "fence",
    52: "other-structure",
    60: "lane-marking",
    70: "vegetation",
    71: "trunk",
    72: "terrain",
    80: "pole",
    81: "traffic-sign",
    99: "other-object",
    252: "moving-car",
    253: "moving-bicyclist",
    254: "moving-person",
    255: "moving-motorcyclist",
    256: "moving-on-rails",
    257: "moving-bus",
    258: "moving-truck",
    259: "moving-other-vehicle",
}

# The class maps known by name: SemanticKITTI's raw ids with the moving
# classes folded onto the static ones and unlabeled/outlier left out.
_MOVING = {252: 10, 253: 31, 254: 30, 255: 32, 256: 16, 257: 13, 258: 18, 259: 20}
BUILTIN_MAPS = {
    "semantickitti": {
        **{
            code: name
            for code, name in SEMANTICKITTI_NAMES.items()
            if code not in _MOVING and code > 1
        },
        **{code: SEMANTICKITTI_NAMES[static] for code, static in _MOVING.items()},
        0: IGNORE,
        1: IGNORE,
    },
}


class PointLabels(typing.NamedTuple):
    """What :func:`read_point_labels` returns (a named tuple).

    Attributes
    ----------
    points : ndarray of shape (n_points, 3)
        The coordinates.
    labels : ndarray of shape (n_points,), dtype object
        The class name of each point (``"ignore"`` where the class map
        leaves the point out).
    instances : ndarray of shape (n_points,), dtype int64, or None
        The object of each point (0: none), where the file has object ids.
    codes : ndarray of shape (n_points,), dtype int64
        The label of each point as the file holds it.
    path : pathlib.Path
        The file read.
    """

    points: np.ndarray
    labels: np.ndarray
    instances: np.ndarray | None
    codes: np.ndarray
    path: Path

    @property
    def ignored(self):
        """Mask of the points the class map leaves out."""
        return self.labels == IGNORE


class ClassMap(typing.NamedTuple):
    """What :func:`read_class_map` returns (a named tuple).

    Attributes
    ----------
    by_code : dict of int to str
        The class each code becomes (``"ignore"``: left out).
    by_name : dict of str to str
        The class each class name becomes, for codes the map does not name
        (their name from the file's legend) and for the names of a
        prediction.
    source : str
        The file the map was read from, or the built-in map's name.
    """

    by_code: dict
    by_name: dict
    source: str

    def names(self, codes, default):
        """The name of each code: the map's, else the map's name of its
        default name, else the default name."""
        out = {}
        for code in map(int, codes):
            name = default.get(code, str(code))
            out[code] = self.by_code.get(code, self.by_name.get(name, name))
        return out


def read_class_map(path):
    """Read a class map: how class codes or names become the names used.

    Parameters
    ----------
    path : str or path-like
        A CSV file of ``code,name`` rows (a first row ``code,name`` is a
        header). ``code`` is an integer class code (``2``, ``40``) or a class
        name as the file names it (``low vegetation``, ``street_light``), so
        that one map can fold both a truth's codes and a prediction's names;
        ``name`` is the class it becomes, ``ignore`` to leave its points out
        of training and scoring. Or the name of a built-in map:
        ``"semantickitti"`` (SemanticKITTI's raw ids to its class names, the
        moving classes onto the static ones, ``unlabeled`` and ``outlier``
        ignored).

    Returns
    -------
    class_map : ClassMap
        The map (``by_code``, ``by_name``, ``source``).

    Raises
    ------
    MissingFileError
        If the file does not exist.
    PointCloudFileError
        For a row that is not two values, an empty name, a negative or
        non-integer code, or a code or name given twice.

    Examples
    --------
    >>> from skpcd.io import read_class_map
    >>> read_class_map("semantickitti").by_code[252]
    'car'
    """
    if isinstance(path, ClassMap):
        return path
    if str(path) in BUILTIN_MAPS and not Path(path).exists():
        return ClassMap(dict(BUILTIN_MAPS[str(path)]), {}, str(path))
    path = check_regular_file(path)
    by_code, by_name = {}, {}
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise PointCloudFileError(path, f"not a CSV class map: {exc}") from None
    for line, row in enumerate(rows, 1):
        row = [cell.strip() for cell in row]
        if not any(row) or row[0].startswith("#"):
            continue
        if line == 1 and [c.lower() for c in row] == ["code", "name"]:
            continue
        if len(row) != 2 or not row[1]:
            raise PointCloudFileError(
                path, f"line {line}: expected 'code,name' (two values), got {row}"
            )
        key, name = row
        name = IGNORE if name.lower() == IGNORE else name
        if key.lstrip("+-").isdigit():
            code = int(key)
            if code < 0:
                raise PointCloudFileError(
                    path, f"line {line}: class code {code} is negative"
                )
            table = by_code
            key = code
        else:
            try:
                float(key)
            except ValueError:
                table = by_name
            else:
                raise PointCloudFileError(
                    path, f"line {line}: class code {key!r} is not an integer"
                ) from None
        if key in table:
            raise PointCloudFileError(path, f"line {line}: {key!r} is mapped twice")
        table[key] = name
    if not by_code and not by_name:
        raise PointCloudFileError(path, "the class map has no code,name row")
    return ClassMap(by_code, by_name, str(path))


def _label_file(path):
    """The SemanticKITTI ``.label`` file of a ``.bin`` scan: beside it, or
    in ``../labels/`` (the ``sequences/NN/velodyne`` layout)."""
    for candidate in (
        path.with_suffix(".label"),
        path.parent.parent / "labels" / f"{path.stem}.label",
    ):
        if candidate.is_file():
            return candidate
    raise MissingFileError(
        path.with_suffix(".label"),
        f"no .label file for {path} (looked beside it and in ../labels/)",
    )


def _read_label_file(path, n_points, scan):
    """Semantic ids (low 16 bits) and objects (the whole label where its
    instance bits are set, so that an id is unique in the scan) of a
    ``.label`` file."""
    path = check_regular_file(path)
    size = path.stat().st_size
    if size != 4 * n_points:
        raise PointCloudFileError(
            path,
            f"holds {size // 4} labels{' and a partial one' if size % 4 else ''} "
            f"but its scan {scan.name} has {n_points} points",
        )
    raw = np.fromfile(path, dtype="<u4")
    semantic = (raw & 0xFFFF).astype(np.int64)
    instances = np.where(raw >> 16 > 0, raw, 0).astype(np.int64)
    return semantic, instances


def _integer_codes(path, field, values):
    values = np.asarray(values)
    if values.ndim != 1:
        raise PointCloudFileError(
            path, f"field {field!r} has {values.shape[1]} values per point, not one"
        )
    if values.dtype.kind == "f":
        finite = np.isfinite(values)
        if not finite.all() or (values != np.round(values)).any():
            raise PointCloudFileError(
                path, f"field {field!r} holds non-integer values: not class codes"
            )
    elif values.dtype.kind not in "iub":
        raise PointCloudFileError(
            path, f"field {field!r} holds {values.dtype} values: not class codes"
        )
    return values.astype(np.int64)


def _las_names(path):
    """Class names of a LAS/LAZ ``classification``: the Classification Lookup
    VLR (or the full names of an skpcd VLR) over the ASPRS names."""
    names = dict(ASPRS_NAMES)
    full = {}
    for user_id, record_id, data in read_vlr_records(path):
        if (user_id, record_id) == _LOOKUP:
            for k in range(len(data) // 16):
                text = data[16 * k + 1 : 16 * k + 16].split(b"\0")[0]
                names[data[16 * k]] = text.decode("ascii", "replace").strip()
        elif (user_id, record_id) == _SKPCD_VLR:
            try:
                record = json.loads(data.decode())
                full = {int(c): str(n) for c, n in record["classification"].items()}
            except (ValueError, KeyError, TypeError, AttributeError):
                full = {}
    return {**names, **full}


def _check_codes(class_map, limit):
    """A class map's codes, refused when the field cannot hold them."""
    for code in class_map.by_code:
        if limit is not None and code > limit:
            raise PointCloudFileError(
                class_map.source,
                f"class code {code} cannot occur: the field holds 0 to {limit}",
            )


def _read_field(path, field, instances):
    """``(points, codes, objects, names, limit)`` of a scan file."""
    suffix = path.suffix.lower()
    if suffix == ".bin":
        if field not in (None, "label"):
            raise PointCloudFileError(
                path, f"a .bin scan's labels are its .label file, not {field!r}"
            )
        points = read_point_cloud(path, nonfinite="keep")
        codes, objects = _read_label_file(_label_file(path), len(points), path)
        if instances is None:
            objects = None
        elif instances != "auto":
            raise PointCloudFileError(
                path, f"a .bin scan's objects are in its .label file, not {instances!r}"
            )
        return points, codes, objects, SEMANTICKITTI_NAMES, 0xFFFF
    field = field or "classification"
    optional = [INSTANCE_FIELDS] if instances == "auto" else []
    wanted = [field] if instances in ("auto", None, field) else [field, instances]
    points, extras = read_fields(path, wanted, nonfinite="keep", optional=optional)
    codes = _integer_codes(path, field, extras[field])
    if instances == "auto":
        instances = next((f for f in INSTANCE_FIELDS if f in extras), None)
    objects = None
    if instances is not None:
        objects = _integer_codes(path, instances, extras[instances])
    names = {}
    if suffix in _LAS and field == "classification":
        names = _las_names(path)
    elif suffix in _LAS and field == ORIGINAL:  # skpcd identify's copy
        names = dict(ASPRS_NAMES)
    raw = np.asarray(extras[field])
    limit = np.iinfo(raw.dtype).max if raw.dtype.kind in "iu" else None
    return points, codes, objects, names, limit


def read_point_labels(
    path, field=None, *, instances="auto", class_map=None, nonfinite="drop"
):
    """Read a scan labelled point by point: its points and the class of each.

    Read more in the :ref:`User Guide <labelled-scan-training>`.

    Parameters
    ----------
    path : str or path-like
        The scan: any format :func:`read_point_cloud` reads, or a KITTI
        ``.bin`` whose SemanticKITTI ``.label`` lies beside it or in
        ``../labels/``.
    field : str, default=None
        The field holding the class codes: ``"classification"`` when None (a
        ``.bin`` scan's labels are its ``.label``'s low 16 bits). Integer
        values, or floats holding integers (CloudCompare's scalar fields).
    instances : "auto", str or None, default="auto"
        The field holding object ids (0: none). ``"auto"``: the high 16 bits
        of a SemanticKITTI label (the whole label where they are set, so an
        id is unique in the scan), else a field named ``instance`` or
        ``object_id`` if the file has one; None reads none.
    class_map : str, path-like or ClassMap, default=None
        How codes become class names (:func:`read_class_map`). Codes it does
        not name keep their default name: the file's Classification Lookup
        VLR or the ASPRS name for a LAS ``classification``, the ASPRS name
        for the ``original_classification`` that ``skpcd identify`` keeps,
        SemanticKITTI's names for a ``.label``, the code as text otherwise.
    nonfinite : {"drop", "keep"}, default="drop"
        Points with NaN or infinite coordinates: dropped with their labels,
        or kept (their labels too).

    Returns
    -------
    scan : PointLabels
        ``points``, ``labels`` (class names; ``"ignore"`` where the map says
        so), ``instances`` (or None), ``codes`` and ``path``.

    Raises
    ------
    MissingFileError
        If the scan or a ``.bin`` scan's ``.label`` is missing.
    PointCloudFileError
        For a field the file does not have, values that are not class codes,
        a ``.label`` whose length does not match its ``.bin``, a class map
        code the field cannot hold; or any problem with the scan itself.

    See Also
    --------
    read_predicted_labels : The classes ``skpcd identify`` wrote.
    skpcd.datasets.objects_from_labelled_scans : Objects to train on.
    skpcd.metrics.scan_scores : Per-point IoU of a prediction.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from skpcd.io import read_point_labels, write_point_cloud
    >>> path = os.path.join(tempfile.mkdtemp(), "painted.ply")
    >>> write_point_cloud(path, np.eye(3), fields={"scalar_class": [2.0, 6.0, 6.0]})
    >>> read_point_labels(path, "scalar_class").labels.tolist()
    ['2', '6', '6']
    """
    if nonfinite not in ("drop", "keep"):
        raise ValueError(f"nonfinite must be 'drop' or 'keep', got {nonfinite!r}")
    path = Path(os.fspath(path))
    if path.suffix.lower() not in SUPPORTED_EXTENSIONS:
        raise PointCloudFileError(
            path,
            f"not a labelled scan: the extension {path.suffix or '(none)'!r} is "
            "none of " + ", ".join(SUPPORTED_EXTENSIONS),
        )
    points, codes, objects, default, limit = _read_field(path, field, instances)
    present, inverse = np.unique(codes, return_inverse=True)
    names = {c: default.get(c, str(c)) for c in present.tolist()}
    if class_map is not None:
        class_map = read_class_map(class_map)
        _check_codes(class_map, limit)
        names = class_map.names(present.tolist(), default)
    table = np.array([names[c] for c in present.tolist()] + [""], dtype=object)
    labels = table[inverse.reshape(-1)]
    if nonfinite == "drop":
        finite = np.isfinite(points).all(axis=1)
        if not finite.all():
            points, labels, codes = points[finite], labels[finite], codes[finite]
            objects = None if objects is None else objects[finite]
    return PointLabels(points, labels, objects, codes, path)


def read_predicted_labels(path, field=None, *, class_map=None):
    """The class of every point of a scan ``skpcd identify`` labelled.

    Parameters
    ----------
    path : str or path-like
        What ``skpcd identify`` wrote: a LAS/LAZ file (the ``class`` and
        ``ground`` dimensions named by its skpcd VLR) or another format (the
        ``class`` and ``ground`` fields named by ``PATH.classes.csv``).
    field : str, default=None
        Read this field instead, as :func:`read_point_labels` does (a
        prediction of another tool).
    class_map : str, path-like or ClassMap, default=None
        Renames classes by name (:func:`read_class_map`; its codes apply to
        ``field`` only).

    Returns
    -------
    labels : ndarray of shape (n_points,), dtype object
        The class of each point, every point of the file in file order:
        ``"ground"`` for ground points, ``"unclassified"`` for points in no
        segment.

    Raises
    ------
    PointCloudFileError
        If the file holds no skpcd classes (and ``field`` is None).
    """
    path = Path(os.fspath(path))
    if field is not None:
        return read_point_labels(
            path, field, instances=None, class_map=class_map, nonfinite="keep"
        ).labels
    _, fields = read_fields(
        path, [], nonfinite="keep", optional=[("class",), ("ground",)]
    )
    if "class" not in fields:
        raise PointCloudFileError(
            path,
            "holds no 'class' field: not written by skpcd identify (name the "
            "field of the predicted classes)",
        )
    codes = _integer_codes(path, "class", fields["class"])
    if path.suffix.lower() in _LAS:
        table = {0: "unclassified", **read_class_names(path)}
    else:
        table = {-1: "unclassified", **_side_names(path)}
    unknown = sorted(set(np.unique(codes).tolist()) - set(table))
    if unknown:
        raise PointCloudFileError(
            path, f"class codes {unknown} have no name in the file's class names"
        )
    rename = {} if class_map is None else read_class_map(class_map).by_name
    keys = np.array(sorted(table))
    names = np.array([rename.get(table[k], table[k]) for k in keys], dtype=object)
    labels = names[np.searchsorted(keys, codes)]
    if "ground" in fields:
        labels[np.asarray(fields["ground"]) == 1] = rename.get("ground", "ground")
    return labels


def _side_names(path):
    """Class index -> name of ``PATH.classes.csv`` (skpcd identify's legend
    beside an output that is not LAS/LAZ)."""
    legend = path.with_name(f"{path.name}.classes.csv")
    if not legend.is_file():
        raise MissingFileError(
            legend, f"the class names of {path.name} (written by skpcd identify)"
        )
    with open(legend, newline="") as f:
        rows = list(csv.DictReader(f))
    try:
        return {int(r["class"]): r["name"] for r in rows if int(r["class"]) >= 0}
    except (KeyError, ValueError, TypeError):
        raise PointCloudFileError(
            legend, "not a legend of skpcd identify (columns class, name)"
        ) from None


def labelled_scan_paths(paths):
    """The scans named by files and folders, in order.

    A file is kept as it is. A folder gives its scans, sorted: in
    SemanticKITTI's layout, the ``.bin`` files of its ``velodyne/`` folder
    (a sequence folder, whose ``calib.txt`` and ``poses.txt`` are not
    scans) or of every ``*/velodyne/`` below it (the ``sequences/``
    folder), each with its ``.label``; otherwise the files of a point-cloud
    extension in it (a ``.bin`` only with a ``.label`` beside it or in
    ``../labels/``).

    Parameters
    ----------
    paths : sequence of str or path-like
        Files and folders.

    Returns
    -------
    scans : list of pathlib.Path

    Raises
    ------
    MissingFileError
        If a path does not exist, or a folder holds no scan.
    """
    out = []
    for path in map(Path, map(os.fspath, paths)):
        if not path.exists():
            raise MissingFileError(path, "no such file or folder")
        if not path.is_dir():
            out.append(path)
            continue
        # SemanticKITTI's layout first: a sequence folder (velodyne/ beside
        # calib.txt, poses.txt...) or the folder of sequences
        found = [
            p
            for velodyne in sorted([path / "velodyne", *path.glob("*/velodyne")])
            if velodyne.is_dir()
            for p in sorted(velodyne.glob("*.bin"))
            if _has_label(p)
        ]
        if not found:
            found = [
                p
                for p in sorted(path.iterdir())
                if p.is_file()
                and p.suffix.lower() in SUPPORTED_EXTENSIONS
                and not p.name.startswith(".")
                and (p.suffix.lower() != ".bin" or _has_label(p))
            ]
        if not found:
            raise MissingFileError(path, "holds no labelled scan")
        out += found
    return out


def _has_label(path):
    try:
        _label_file(path)
    except MissingFileError:
        return False
    return True
