"""``skpcd identify ... --inventory objects.gpkg|.geojson|.csv``: one row per
object (class, base position, size, pole lean...), in the scan's CRS."""

import sys
from pathlib import Path

from skpcd.cli._common import CommandError, check_output

# ground points read at a time when the scene is streamed (--tile-size)
_CHUNK = 1_000_000


def add_inventory_option(parser):
    parser.add_argument(
        "--inventory",
        metavar="FILE",
        help="also write one row per object: id, class, confidence, x, y, z of "
        "the ground under its base, height, width, length, heading, points, and "
        "for poles their lean and the height of what they carry; .gpkg (needs "
        "pip install 'skpcd[gis]') or .geojson in the scan's CRS, or .csv",
    )


def check_inventory(args, command, inputs):
    """The ``--inventory`` file checked before any work, or None."""
    from skpcd.io._inventory import check_inventory_path

    if args.inventory is None:
        return None
    out = check_output(args.inventory, args, command, inputs=inputs)
    if out.resolve() == Path(args.output).resolve():
        raise CommandError(command, f"--inventory {out} is the output file")
    try:
        check_inventory_path(out)
    except ValueError as exc:
        raise CommandError(command, str(exc)) from exc
    return out


def measuring(segments, geometries):
    """``segments`` passed through, the geometry of each appended to
    ``geometries`` on the way (one pass over the segments)."""
    from skpcd.segmentation._inventory import segment_geometry

    for seg, fields in segments:
        geometries.append(segment_geometry(seg, pole=True))
        yield seg, fields


def _ground(args, points, result):
    """The :class:`GroundHeight` of the scan's ground points (streamed in
    chunks when the scene was, each chunk reduced to its cells first)."""
    import numpy as np

    from skpcd.segmentation._inventory import GroundHeight
    from skpcd.segmentation.tiling._spill import iter_chunks

    if points is not None:
        return GroundHeight().fit(points[result.ground])
    cells, start = [], 0
    for xyz in iter_chunks(args.scene, _CHUNK):
        mask = np.asarray(result.ground[start : start + len(xyz)], dtype=bool)
        start += len(xyz)
        part = GroundHeight().fit(xyz[mask])
        centres = (part.cells_ + 0.5) * part.cell
        cells.append(np.column_stack([centres, part.heights_]))
    return GroundHeight().fit(np.vstack(cells) if cells else np.empty((0, 3)))


def write_inventory_of(args, out, geometries, pred, score, points, result):
    """Write the inventory of the identified segments to ``out``."""
    from skpcd.io._crs import read_las_crs
    from skpcd.io._inventory import write_inventory
    from skpcd.segmentation._inventory import object_inventory

    table = object_inventory(
        geometries, pred, score, ground=_ground(args, points, result)
    )
    crs = None
    if Path(args.scene).suffix.lower() in (".las", ".laz"):
        crs = read_las_crs(args.scene)
    write_inventory(out, table, crs=crs, overwrite=args.overwrite)
    if not args.quiet:
        where = f"CRS {crs if len(crs or '') < 40 else crs[:37] + '...'}"
        print(
            f"inventory {out}: {len(pred)} objects ("
            + (where if crs else "no CRS in the scan")
            + ")",
            file=sys.stdout,
        )
