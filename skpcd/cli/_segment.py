"""``skpcd segment SCENE -o FOLDER`` and ``skpcd identify SCENE --model M -o OUT``."""

import sys
import time
from pathlib import Path

import numpy as np

from skpcd.cli._common import CommandError
from skpcd.cli._segmentation_options import add_segmentation_options

KINDS = ("object", "facade", "wire")
# The choice of --format, written out (as SEGMENT_FORMATS of
# skpcd.io._segment_folder has it, tests/cli/test_startup.py checks) so that
# building the parser loads no library.
SEGMENT_FORMATS = ("ply", "pcd", "las", "laz", "xyz", "txt", "csv", "npy")


def add_parser(sub):
    seg = sub.add_parser(
        "segment",
        help="cut a scene into segments, one file each",
        description="Remove the ground (CSF or SMRF), take facades and overhead "
        "wires out as segments of their own, cluster the rest (DBSCAN with "
        "automatic eps, or Euclidean clusters) and split clusters at vertical "
        "trunks, keep segments within the size range and write one file per "
        "segment plus segments.csv (type: object, facade or wire; points and "
        "extents of each) into the output folder. The folder is filled under a "
        "temporary name and swapped in when whole; --overwrite replaces an "
        "earlier run's folder, never files skpcd did not write.",
    )
    seg.add_argument("scene", help="a point-cloud file (.ply .pcd .las .laz .xyz ...)")
    seg.add_argument("-o", "--output", required=True, help="output folder")
    seg.add_argument(
        "--format",
        default="ply",
        choices=SEGMENT_FORMATS,
        help="format of the segment files (default ply)",
    )
    add_segmentation_options(seg)
    seg.set_defaults(func=run_segment)

    return seg


def segment_file(args, command, fields=None):
    """Read SCENE and segment it; returns ``(points, extras, result)``.

    With ``--tile-size`` the scene is not read here (segment_scene streams
    it tile by tile): ``points`` is None and ``extras`` empty. Otherwise
    ``result`` covers every point of the file (non-finite ones: no segment,
    not ground), in file order."""
    from skpcd.segmentation import segment_scene
    from skpcd.utils._progress import stage

    check_method(args, command)
    tiled = args.tile_size is not None
    unit = _unit_of(args)
    finite = None
    ground = None if args.ground == "none" else args.ground
    if ground == "from-file":
        from skpcd.segmentation.ground import ClassifiedGround

        ground = ClassifiedGround(args.ground_codes)
    if tiled:
        points, extras, source, rings = None, {}, args.scene, None
    else:
        want = "all" if fields or args.ground == "from-file" else None
        with stage(f"reading {Path(args.scene).name}"):
            points, extras, rings = _read_scene(args, want)
        finite = np.isfinite(points).all(axis=1)
        source = points if finite.all() else points[finite]
        if rings is not None:
            rings = rings[finite]
        if args.ground == "from-file":  # the flags of the points read
            ground = ground.flags_of(args.scene, extras)[finite]
            extras = extras if fields else {}
    tiling = (
        {"tile_size": args.tile_size, "tile_buffer": args.tile_buffer} if tiled else {}
    )
    start = time.perf_counter()
    try:
        result = segment_scene(
            source,
            ground=ground,
            sensor=args.sensor,
            rings=rings,
            method=args.method,
            eps=args.eps,
            eps_scale=args.eps_scale,
            min_samples=args.min_samples,
            min_cluster_size=args.min_size,
            max_cluster_size=args.max_size,
            random_state=args.random_state,
            n_jobs=args.n_jobs,
            structures=args.structures,
            unit=unit.metres,
            **tiling,
        )
    except ValueError as exc:
        raise CommandError(command, str(exc)) from exc
    if finite is not None and not finite.all():
        labels = np.full(len(points), -1, dtype=result.labels.dtype)
        ground = np.zeros(len(points), dtype=bool)
        labels[finite], ground[finite] = result.labels, result.ground
        result = result._replace(labels=labels, ground=ground)
    if unit.metres != 1.0 and not args.quiet:
        print(
            f"skpcd {command}: coordinates in {unit.name} ({unit.metres:.6g} m, "
            f"{unit.source}): segmented in metres (--unit to choose)",
            file=sys.stderr,
        )
    if result.scan is not None and not args.quiet:
        print(
            f"skpcd {command}: {result.scan.summary()}: "
            f"ground {result.ground_filter!r} (--ground to choose)",
            file=sys.stderr,
        )
    if result.sensor_from == "above the origin" and not args.quiet:
        x, y, z = result.sensor
        print(
            f"skpcd {command}: the origin of the sweep is on the ground, not at "
            f"its sensor: rays from ({x:.6g}, {y:.6g}, {z:.6g}), 1.85 m above the "
            "ground under it (--sensor X Y Z to give it)",
            file=sys.stderr,
        )
    if not args.quiet:
        labels = result.labels
        print(
            f"scene     {args.scene}: {len(labels)} points, "
            f"{int(result.ground.sum())} ground"
        )
        eps = _finite(result.eps)  # None: no radius (range-image)
        metres = f" = {eps * result.unit:.3f} m" if eps and result.unit != 1 else ""
        print(
            f"segments  {result.n_segments} ({args.method}"
            + ("" if eps is None else f", eps {eps:.3f}{metres}")
            + "); "
            f"{int(((labels < 0) & ~result.ground).sum())} points in none "
            f"({time.perf_counter() - start:.1f} s)"
        )
        kinds = np.asarray(result.kinds if result.kinds is not None else [])
        if (kinds != "object").any():
            print(
                "types     "
                + ", ".join(f"{int((kinds == k).sum())} {k}" for k in KINDS)
            )
    return points, extras, result


def check_method(args, command):
    """Refuse, before any work, options that --method does not take."""
    if args.method == "range-image" and args.tile_size is not None:
        raise CommandError(
            command,
            "--method range-image segments one sweep in memory; it does not "
            "take --tile-size",
        )


def _read_scene(args, want):
    """``(points, extras, rings)`` of SCENE, non-finite points kept;
    ``rings``: with --method range-image, the ring of each point when the
    file has them (see :func:`~skpcd.segmentation._scene.rings_of`), else
    None."""
    from skpcd.io._api import read_fields
    from skpcd.segmentation._scene import RING_FIELDS, rings_of

    if args.method != "range-image":
        read = read_fields(args.scene, want, nonfinite="keep")
        return (*(read if want else (read, {})), None)
    points, extras = read_fields(
        args.scene, want, nonfinite="keep", optional=[RING_FIELDS]
    )
    return points, extras if want else {}, rings_of(extras)


def _finite(value):
    """``value``, or None when it is NaN (no radius: JSON has no NaN)."""
    return None if value is None or np.isnan(value) else float(value)


def _unit_of(args):
    """The unit of the coordinates: ``--unit``, or with auto the unit of
    a LAS/LAZ scene's CRS (a :class:`~skpcd.io.LinearUnit`)."""
    from skpcd.io import LinearUnit, linear_unit

    if args.unit != "auto":
        return LinearUnit("unit", float(args.unit), "--unit")
    found = linear_unit(args.scene) if is_las(args.scene) else None
    return found if found is not None else LinearUnit("metre", 1.0, "default")


def segment_clouds(args, points, extras, result, folder, *, fields=True):
    """``(points, fields)`` of each segment, in order (the fields only with
    ``fields`` and ``--keep-fields``), with a progress bar (writing them for
    segment, classifying them for identify)."""
    from skpcd.segmentation._members import iter_segment_points, segment_members
    from skpcd.utils._progress import progress

    if points is None:  # tiled: gathered in one pass over the scene
        each = iter_segment_points(
            args.scene,
            result.labels,
            result.n_segments,
            fields=fields and args.keep_fields,
            folder=folder,
        )
    else:
        each = (
            (points[idx], {name: values[idx] for name, values in extras.items()})
            for idx in segment_members(result.labels, result.n_segments)
        )
    desc = "writing" if args.command == "segment" else "classifying"
    return progress(each, total=result.n_segments, desc=desc)


def _metadata(args, result):
    """What ``segmentation.json`` holds: the scene, the scan kind found,
    the ground filter and the radius used, the options given."""
    import skpcd

    scan = result.scan
    return {
        "scene": str(args.scene),
        "skpcd": skpcd.__version__,
        "scan": None if scan is None else {k: getattr(scan, k) for k in scan._fields},
        "ground": args.ground if result.ground_filter is None else result.ground_filter,
        "method": args.method,
        "sensor": None if result.sensor is None else list(result.sensor),
        "sensor_from": result.sensor_from,
        "eps": _finite(result.eps),
        "eps_given": args.eps is not None,
        "unit_metres": result.unit,
        "structures": bool(args.structures),
        "min_size": args.min_size,
        "max_size": args.max_size,
        "n_segments": result.n_segments,
        "n_ground": int(result.ground.sum()),
    }


def run_segment(args):
    from skpcd.exceptions import MissingFileError
    from skpcd.io._atomic import check_folder_output, check_writable
    from skpcd.io._segment_folder import (
        SEGMENTS_SUMMARY,
        is_segment_run_file,
        write_segment_folder,
    )

    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise CommandError("segment", f"{out} exists and is not a folder")
    if not Path(args.scene).exists():
        raise MissingFileError(args.scene, "no such file")
    if Path(args.scene).resolve().is_relative_to(out.resolve()):
        raise CommandError(
            "segment", f"the scene {args.scene} is inside the output folder {out}"
        )
    if out.is_dir() and any(out.iterdir()) and not args.overwrite:
        raise CommandError(
            "segment",
            f"{out} is not empty; pass --overwrite to replace an earlier run's "
            "segments (files skpcd did not write are never deleted)",
        )
    check_folder_output(out, overwrite=True, owned=is_segment_run_file)
    check_writable(out)
    points, extras, result = segment_file(
        args, "segment", "all" if args.keep_fields else None
    )
    n = result.n_segments
    kinds = result.kinds if result.kinds is not None else np.full(n, "object", object)
    try:
        write_segment_folder(
            out,
            lambda scratch: segment_clouds(args, points, extras, result, scratch),
            n_segments=n,
            kinds=kinds,
            format=args.format,
            metadata=_metadata(args, result),
            overwrite=args.overwrite,
            las_header=_las_header(args),
        )
    except ValueError as exc:  # a field the format cannot hold
        raise CommandError("segment", str(exc)) from exc
    if not args.quiet:
        print(f"written   {n} {args.format} files and {SEGMENTS_SUMMARY} -> {out}")
    return 0


def is_las(path):
    return Path(path).suffix.lower() in (".las", ".laz")


def _las_header(args):
    """The header of a LAS/LAZ scene, which LAS/LAZ segment files carry."""
    if not (is_las(args.scene) and args.format in ("las", "laz")):
        return None
    from skpcd.io._las_reader import read_las_header

    return read_las_header(args.scene)
