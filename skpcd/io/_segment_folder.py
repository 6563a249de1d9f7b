"""The folder of a segmented scene: one point-cloud file per segment,
``segments.csv`` (what each file holds) and ``segmentation.json`` (what the
run chose). Written whole or not at all; read back by
:func:`~skpcd.io.read_segments`, which checks that it holds one whole run.
"""

import csv
import glob
import json
import os
import re
import warnings
from pathlib import Path

import numpy as np

from skpcd.exceptions import MissingFileError, PointCloudFileError, SkippedFilesWarning
from skpcd.io._api import (
    _FORMATS,
    SUPPORTED_EXTENSIONS,
    check_regular_file,
    read_point_cloud,
    write_point_cloud,
)
from skpcd.io._atomic import atomic_folder
from skpcd.io._las_writer import write as write_las
from skpcd.utils._progress import progress

__all__ = [
    "SEGMENTATION_METADATA",
    "SEGMENTS_SUMMARY",
    "SEGMENT_FORMATS",
    "check_segment_run",
    "is_segment_run_file",
    "read_labels",
    "read_segments",
    "write_segment_folder",
]

# the formats of the segment files
SEGMENT_FORMATS = ("ply", "pcd", "las", "laz", "xyz", "txt", "csv", "npy")
# the file names of the segments, and the summary
_SEGMENT_FILE = re.compile(r"segment_\d{4,}\.[a-z]+")
SEGMENTS_SUMMARY = "segments.csv"
# what the run chose: the scan kind, the ground filter, eps (JSON)
SEGMENTATION_METADATA = "segmentation.json"
_SUMMARY_COLUMNS = ["file", "segment", "type", "n_points"] + [
    f"{a}_{c}" for a in ("min", "max", "extent") for c in "xyz"
]


def is_segment_run_file(name):
    """Whether ``name`` is an entry that :func:`write_segment_folder`
    writes (a segment file, the summary or the metadata)."""
    return name in (SEGMENTS_SUMMARY, SEGMENTATION_METADATA) or bool(
        re.fullmatch(rf"segment_\d{{4,}}\.({'|'.join(SEGMENT_FORMATS)})", name)
    )


def _bounds(points):
    """``points.min(axis=0), points.max(axis=0)`` of an ``(n, 3)`` array,
    column by column (five times faster than across the rows); a zero among
    them, whose sign the order of the comparisons decides when the column
    holds both 0.0 and -0.0, is taken from the reduction across the rows."""
    lo = np.array([points[:, j].min() for j in range(points.shape[1])])
    hi = np.array([points[:, j].max() for j in range(points.shape[1])])
    if not (lo.all() and hi.all()):
        lo, hi = points.min(axis=0), points.max(axis=0)
    return lo, hi


def write_segment_folder(
    folder,
    segments,
    *,
    n_segments,
    kinds,
    format,
    metadata,
    overwrite=False,
    las_header=None,
):
    """Write the segments of a scene into a folder, whole or not at all.

    Parameters
    ----------
    folder : path-like
        The output folder; filled under a temporary name beside it and
        renamed when whole.
    segments : callable
        ``segments(scratch)`` returns an iterable of ``(points, fields)``,
        one per segment in order (``fields`` a dict of per-point arrays, or
        empty); ``scratch`` is a folder inside the temporary output that it
        may use and that is removed with it.
    n_segments : int
        Number of segments (the width of the file numbers).
    kinds : sequence of str
        Type of each segment (object, facade, wire).
    format : str
        Extension of the segment files, one of ``SEGMENT_FORMATS``.
    metadata : dict
        What ``segmentation.json`` holds.
    overwrite : bool, default=False
        Replace an earlier run's folder (never files that a run did not
        write).
    las_header : laspy.LasHeader, default=None
        The header of a LAS/LAZ scene, which LAS/LAZ segment files carry
        through (version, point format, scales, offsets, CRS and other
        VLRs; see :func:`skpcd.io._las_writer.write`). Ignored for other
        formats.

    Returns
    -------
    n_written : int
        Number of segment files written.

    Raises
    ------
    ValueError
        If a segment's fields cannot be held by ``format``.
    """
    width = max(4, len(str(n_segments - 1)))
    rows = []
    with atomic_folder(folder, overwrite=overwrite, owned=is_segment_run_file) as tmp:
        for i, (seg, fields) in enumerate(segments(tmp)):
            name = f"segment_{i:0{width}d}.{format}"
            if las_header is not None and format in ("las", "laz"):
                xyz = {c: seg[:, j] for j, c in enumerate("xyz")}
                write_las(tmp / name, {**xyz, **fields}, header=las_header)
            else:
                write_point_cloud(tmp / name, seg, fields=fields or None)
            lo, hi = _bounds(seg)
            rows.append([name, i, kinds[i], len(seg), *lo, *hi, *(hi - lo)])
        with open(tmp / SEGMENTS_SUMMARY, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(_SUMMARY_COLUMNS)
            for row in rows:
                writer.writerow(row[:4] + [f"{v:.4f}" for v in row[4:]])
        with open(tmp / SEGMENTATION_METADATA, "w") as f:
            json.dump(metadata, f, indent=1)
    return len(rows)


def check_segment_run(folder, names):
    """A folder written by :func:`write_segment_folder` holds one whole run:
    exactly the segment files its ``segments.csv`` lists, and no segment
    file without it."""
    if not os.path.isdir(folder):
        return
    summary = Path(folder) / SEGMENTS_SUMMARY
    written = {n for n in names if _SEGMENT_FILE.fullmatch(n)}
    if not summary.is_file():
        if written:
            raise PointCloudFileError(
                folder,
                f"{len(written)} segment_NNNN files but no {SEGMENTS_SUMMARY}: the "
                "output of an interrupted skpcd segment run? Segment the scene again",
            )
        return
    with open(summary, newline="", encoding="utf-8") as fh:
        listed = {row["file"] for row in csv.DictReader(fh) if row.get("file")}
    extra, missing = sorted(written - listed), sorted(listed - set(names))
    if extra or missing:
        raise PointCloudFileError(
            folder,
            f"does not hold the run its {SEGMENTS_SUMMARY} describes ("
            + ", ".join(
                f"{len(v)} {w}: {', '.join(v[:3])}"
                for v, w in ((extra, "not listed"), (missing, "missing"))
                if v
            )
            + "); segment the scene again into an empty folder",
        )


def _natural_key(name):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _list_files(folder_or_glob, labels_path):
    source = os.fspath(folder_or_glob)
    if os.path.isdir(source):
        files = [
            p
            for p in Path(source).iterdir()
            if p.is_file()
            and not p.name.startswith(".")
            and p.suffix.lower() in _FORMATS
            and p.name not in ("labels.csv", SEGMENTS_SUMMARY)
        ]
        root = Path(source)
    else:
        files = [
            Path(p) for p in glob.glob(source, recursive=True) if os.path.isfile(p)
        ]
        if not files and not glob.has_magic(source):
            raise MissingFileError(source, "no such file or folder")
        root = (
            Path(os.path.commonpath([str(p.parent) for p in files])) if files else None
        )
    if labels_path is not None:
        files = [p for p in files if p.resolve() != Path(labels_path).resolve()]
    if not files:
        raise PointCloudFileError(
            source,
            "no point-cloud file found (extensions: "
            + ", ".join(SUPPORTED_EXTENSIONS)
            + ").",
        )
    names = [p.relative_to(root).as_posix() for p in files]
    order = sorted(range(len(files)), key=lambda i: _natural_key(names[i]))
    return [files[i] for i in order], [names[i] for i in order]


def read_labels(path):
    """The labels of a folder of segments: a CSV file of ``file,label`` rows.

    Parameters
    ----------
    path : str or path-like
        The labels file; a first row ``file,label`` is a header and skipped,
        blank rows are skipped.

    Returns
    -------
    path : Path
        The file, checked to be a regular file.
    mapping : dict of str to str
        File name (as written, relative to the folder) to label.

    Raises
    ------
    PointCloudFileError
        If the file is empty, a row does not have two columns, or a file is
        given two labels.
    """
    path = check_regular_file(path)
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [row for row in csv.reader(fh) if row and any(c.strip() for c in row)]
    if not rows:
        raise PointCloudFileError(path, "the labels file is empty.")
    if [c.strip().lower() for c in rows[0]][:2] == ["file", "label"]:
        rows = rows[1:]
    mapping = {}
    for lineno, row in enumerate(rows, start=1):
        if len(row) != 2:
            raise PointCloudFileError(
                path, f"row {lineno} has {len(row)} columns; expected 'file,label'."
            )
        name, label = row[0].strip(), row[1].strip()
        if name in mapping and mapping[name] != label:
            raise PointCloudFileError(path, f"file {name!r} is labelled twice.")
        mapping[name] = label
    return path, mapping


def read_segments(
    folder_or_glob,
    labels=None,
    *,
    fields=None,
    nonfinite="drop",
    verbose=False,
    errors="raise",
):
    """Read a folder of segmented objects, one file per object.

    Read more in the :ref:`User Guide <io>`.

    Parameters
    ----------
    folder_or_glob : str or path-like
        A folder (every file with a supported extension in it, not
        recursively, except hidden files (names starting with ``.``),
        ``labels.csv`` and ``segments.csv``, the summary written by
        ``skpcd segment``) or a glob pattern such
        as ``"scans/**/*.ply"``.
    labels : str or path-like, default=None
        A CSV file of ``file,label`` rows (a ``file,label`` header line is
        optional). File names are relative to the folder (or to the common
        folder of the glob matches). Every file read must be labelled and
        every labelled file must exist.
    fields : None, "all" or list of str, default=None
        Extra per-point fields, as in :func:`read_point_cloud`; when given,
        each cloud is ``(points, extras)``.
    nonfinite : {"drop", "keep", "raise"}, default="drop"
        Policy for NaN or infinite coordinates, as in
        :func:`read_point_cloud`.
    verbose : bool, default=False
        Show a progress bar on standard error (only on a terminal).
    errors : {"raise", "skip"}, default="raise"
        What to do with a file that cannot be read as a point cloud (a
        stray ``notes.txt``): raise, or leave it out (with its label) and
        name every skipped file in one
        :class:`~skpcd.exceptions.SkippedFilesWarning`.

    Returns
    -------
    clouds : list of ndarray of shape (n_points_i, 3)
        One cloud per file.
    labels : ndarray of str of shape (n_clouds,) or None
        The label of each cloud, or None without a labels file.
    names : list of str
        The file names, relative to the folder; the order of all three is
        the natural sort of these names (``2.xyz`` before ``10.xyz``).

    Raises
    ------
    MissingFileError
        If the folder, the labels file, or a file it names does not exist.
    PointCloudFileError
        If no point-cloud file is found, a file is not labelled, any file
        cannot be read (see :func:`read_point_cloud`) and ``errors`` is
        ``"raise"``, or a folder written by ``skpcd segment`` does not
        hold exactly the segments its ``segments.csv`` lists (an interrupted
        or mixed run).
    """
    if errors not in ("raise", "skip"):
        raise ValueError(f"errors must be 'raise' or 'skip', got {errors!r}")
    labels_path, mapping = (None, None) if labels is None else read_labels(labels)
    files, names = _list_files(folder_or_glob, labels_path)
    if mapping is not None:
        unknown = sorted(set(mapping) - set(names), key=_natural_key)
        if unknown:
            shown = ", ".join(unknown[:10]) + (" ..." if len(unknown) > 10 else "")
            raise MissingFileError(
                labels_path,
                f"{len(unknown)} labelled file(s) not found in "
                f"{folder_or_glob}: {shown}",
            )
        unlabelled = [n for n in names if n not in mapping]
        if unlabelled:
            shown = ", ".join(unlabelled[:10]) + (
                " ..." if len(unlabelled) > 10 else ""
            )
            raise PointCloudFileError(
                labels_path, f"{len(unlabelled)} file(s) have no label: {shown}"
            )
    check_segment_run(folder_or_glob, names)
    show = None if verbose else False
    clouds, kept, skipped = [], [], []
    for f, name in zip(progress(files, desc="reading", enabled=show), names):
        try:
            clouds.append(read_point_cloud(f, fields=fields, nonfinite=nonfinite))
        except PointCloudFileError as exc:
            if errors == "raise" or isinstance(exc, MissingFileError):
                raise
            skipped.append(f"{name} ({exc.problem})")
            continue
        kept.append(name)
    if skipped:
        if not kept:
            raise PointCloudFileError(
                folder_or_glob, f"no file could be read: {'; '.join(skipped[:5])}"
            )
        warnings.warn(
            f"{folder_or_glob}: skipped {len(skipped)} file(s) that are not point "
            f"clouds: {'; '.join(skipped[:10])}"
            + (" ..." if len(skipped) > 10 else ""),
            SkippedFilesWarning,
            stacklevel=2,
        )
    y = None if mapping is None else np.array([mapping[n] for n in kept])
    return clouds, y, kept
