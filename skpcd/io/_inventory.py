"""Writing an inventory of objects as a GIS point layer (GeoPackage, GeoJSON)
or a CSV table, in the coordinate reference system of the scan.

The inventory's columns are those of
:func:`skpcd.segmentation._inventory.object_inventory`; each row is a 3-D
point at the base of an object. The CRS is read from the scan's LAS VLRs
(:func:`skpcd.io.read_las_crs`).
"""

import csv
import json
import math
import struct
import warnings
from pathlib import Path

import numpy as np

from skpcd.exceptions import PointCloudFileError
from skpcd.io._atomic import atomic_path

__all__ = [
    "INVENTORY_FORMATS",
    "check_inventory_path",
    "write_inventory",
]

#: Extensions :func:`write_inventory` writes, and the format of each.
INVENTORY_FORMATS = {
    ".gpkg": "gpkg",
    ".geojson": "geojson",
    ".json": "geojson",
    ".csv": "csv",
}


def _is_wgs84(crs):
    return crs is not None and crs.upper() in ("EPSG:4326", "EPSG:4979", "OGC:CRS84")


def _value(v):
    """A JSON or CSV value: NaN as None, numpy scalars as Python ones."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _rows(inventory):
    columns = list(inventory)
    n = len(inventory[columns[0]]) if columns else 0
    for i in range(n):
        yield {c: _value(inventory[c][i]) for c in columns}


def _write_csv(tmp, inventory):
    with open(tmp, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(inventory))
        writer.writeheader()
        for row in _rows(inventory):
            writer.writerow({k: "" if v is None else v for k, v in row.items()})


def _geojson_crs(crs):
    """The ``crs`` member GDAL reads (GeoJSON 2008; RFC 7946 has no such
    member and assumes WGS 84 longitude, latitude)."""
    if crs.upper().startswith("EPSG:"):
        name = f"urn:ogc:def:crs:EPSG::{crs.split(':', 1)[1]}"
    else:
        name = crs
    return {"type": "name", "properties": {"name": name}}


def _write_geojson(tmp, inventory, crs):
    features = []
    for row in _rows(inventory):
        props = {k: v for k, v in row.items() if k not in ("x", "y", "z")}
        features.append(
            {
                "type": "Feature",
                "id": props["id"],
                "geometry": {
                    "type": "Point",
                    "coordinates": [row["x"], row["y"], row["z"]],
                },
                "properties": props,
            }
        )
    collection = {"type": "FeatureCollection", "features": features}
    if crs is not None and not _is_wgs84(crs):
        collection["crs"] = _geojson_crs(crs)
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(collection, fh, indent=1, allow_nan=False)


def _write_gpkg(tmp, inventory, crs):
    from pyogrio.raw import write

    x, y, z = (np.asarray(inventory[k], dtype=float) for k in ("x", "y", "z"))
    # well-known binary of 3-D points (ISO: type 1001, little-endian)
    geometry = np.array(
        [struct.pack("<BIddd", 1, 1001, *p) for p in zip(x, y, z)], dtype=object
    )
    fields = [k for k in inventory if k not in ("x", "y", "z")]
    data = []
    for k in fields:
        values = np.asarray(inventory[k])
        data.append(values.astype(str) if values.dtype == object else values)
    with warnings.catch_warnings():
        # no CRS in the scan: said by the command, not as a warning
        warnings.filterwarnings("ignore", message="'crs' was not provided")
        write(
            str(tmp),
            geometry,
            data,
            fields,
            driver="GPKG",
            geometry_type="Point Z",
            crs=crs,
            layer="objects",
        )


def check_inventory_path(path):
    """The format of an inventory file, checked before any work.

    Parameters
    ----------
    path : str or path-like
        The file to write.

    Returns
    -------
    format : {"gpkg", "geojson", "csv"}

    Raises
    ------
    ValueError
        If the extension is not one of ``INVENTORY_FORMATS``.
    PointCloudFileError
        If a GeoPackage is asked for and pyogrio is not installed.
    """
    path = Path(path)
    fmt = INVENTORY_FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise ValueError(
            f"{path}: an inventory is written as "
            + ", ".join(INVENTORY_FORMATS)
            + f", not {path.suffix or 'a file without extension'}"
        )
    if fmt == "gpkg":
        try:
            import pyogrio  # noqa: F401
        except ImportError:
            raise PointCloudFileError(
                path,
                "writing a GeoPackage needs pyogrio: pip install 'skpcd[gis]' "
                "(or write .geojson or .csv)",
            ) from None
    return fmt


def write_inventory(path, inventory, *, crs=None, overwrite=False):
    """Write an inventory of objects as a point layer or a table.

    Read more in the :ref:`User Guide <review>`.

    Parameters
    ----------
    path : str or path-like
        The file; its extension picks the format: ``.gpkg`` (GeoPackage, a
        layer ``objects`` of 3-D points; needs pyogrio: ``pip install
        'skpcd[gis]'``), ``.geojson`` or ``.json`` (GeoJSON, one Point
        feature per object, the columns as properties) or ``.csv`` (one row
        per object with ``x``, ``y``, ``z`` columns; no CRS).
    inventory : dict of str to array-like
        The columns, with at least ``id``, ``x``, ``y`` and ``z`` (as
        :func:`~skpcd.segmentation._inventory.object_inventory` returns).
    crs : str, default=None
        The coordinate reference system of the coordinates (``EPSG:code``
        or WKT; see :func:`~skpcd.io.read_las_crs`), written where the format holds
        one. GeoJSON (RFC 7946) assumes WGS 84 longitude, latitude: a
        projected CRS is written in the ``crs`` member of GeoJSON 2008,
        which GDAL and QGIS read.
    overwrite : bool, default=False
        Replace an existing file.

    Raises
    ------
    ValueError, PointCloudFileError
        As :func:`check_inventory_path`, before anything is written.
    """
    path = Path(path)
    fmt = check_inventory_path(path)
    with atomic_path(path, overwrite=overwrite) as tmp:
        if fmt == "csv":
            _write_csv(tmp, inventory)
        elif fmt == "geojson":
            _write_geojson(tmp, inventory, crs)
        else:
            _write_gpkg(tmp, inventory, crs)
