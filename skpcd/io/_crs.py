"""The coordinate reference system of a LAS/LAZ file and the length of its
coordinate unit, read from its VLRs (no pyproj)."""

import re
import struct
import typing

from skpcd.io._las_reader import read_vlr_records

__all__ = [
    "GEOGRAPHIC_KEY",
    "PROJECTED_KEY",
    "USER_DEFINED",
    "LinearUnit",
    "geo_keys",
    "linear_unit",
    "read_las_crs",
]

# GeoTIFF keys of the GeoKeyDirectory VLR that name a CRS by its EPSG code
PROJECTED_KEY, GEOGRAPHIC_KEY = 3072, 2048
# ProjLinearUnitsGeoKey: the unit of the projected coordinates
_LINEAR_UNITS_KEY = 3076
# "user-defined" in GeoTIFF: no EPSG code
USER_DEFINED = 32767

_WKT = ("LASF_Projection", 2112)
_GEO_KEYS = ("LASF_Projection", 34735)

# EPSG codes of the length units a projected CRS uses, and their length in
# metres (EPSG 9001 metre, 9002 international foot, 9003 US survey foot)
_EPSG_UNITS = {
    9001: ("metre", 1.0),
    9002: ("foot", 0.3048),
    9003: ("US survey foot", 1200 / 3937),
}
# a unit of a WKT that measures angles, not lengths
_ANGULAR = ("degree", "radian", "grad", "gon", "arc-second", "arc-minute")
# UNIT["name", factor] (WKT1) and LENGTHUNIT["name", factor] (WKT2)
_WKT_UNIT = re.compile(
    r'\b(?:LENGTH)?UNIT\[\s*"(?P<name>[^"]*)"\s*,\s*(?P<factor>[0-9.eE+-]+)'
)


class LinearUnit(typing.NamedTuple):
    """What :func:`linear_unit` returns (a named tuple).

    Attributes
    ----------
    name : str
        The unit's name as the file gives it ("metre", "foot", "US survey
        foot"...).
    metres : float
        The length of one unit in metres.
    source : str
        Where it was read: "WKT VLR" or "GeoKeys VLR".
    """

    name: str
    metres: float
    source: str


def geo_keys(data):
    """The keys of a GeoKeyDirectory record whose value is held in the
    record itself: ``{key id: value}``."""
    if len(data) < 8:
        return {}
    values = struct.unpack(f"<{len(data) // 2}H", data[: len(data) // 2 * 2])
    found = {}
    for i in range(values[3]):
        key = values[4 + 4 * i : 8 + 4 * i]
        if len(key) < 4:
            break
        key_id, location, _, value = key
        if location == 0:
            found[key_id] = value
    return found


def _records(path):
    return {
        (user.rstrip("\0"), record): data
        for user, record, data in read_vlr_records(path)
    }


def _wkt_text(records):
    data = records.get(_WKT)
    if not data:
        return None
    return data.split(b"\0", 1)[0].decode("utf-8", "replace").strip() or None


def read_las_crs(path):
    """The coordinate reference system of a LAS/LAZ file, from its VLRs.

    Parameters
    ----------
    path : str or path-like
        A LAS or LAZ file.

    Returns
    -------
    crs : str or None
        The OGC WKT of the "OGC Coordinate System WKT" record
        (``LASF_Projection`` 2112) if the file has one, else ``EPSG:code``
        from the GeoTIFF keys (``LASF_Projection`` 34735: the projected,
        else the geographic CRS), else None.
    """
    records = _records(path)
    text = _wkt_text(records)
    if text:
        return text
    keys = geo_keys(records.get(_GEO_KEYS, b""))
    for key_id in (PROJECTED_KEY, GEOGRAPHIC_KEY):
        code = keys.get(key_id)
        if code and code != USER_DEFINED:
            return f"EPSG:{code}"
    return None


def linear_unit(path):
    """The length unit of the horizontal coordinates of a LAS/LAZ file.

    Read from the first length unit of the WKT record (the projected CRS's;
    angular units are skipped), else from the ``ProjLinearUnitsGeoKey``
    (3076) of the GeoTIFF keys. State-plane scans of the United States are
    often in feet: PDAL's and laspy's ``autzen`` files are in international
    feet.

    Parameters
    ----------
    path : str or path-like
        A LAS or LAZ file.

    Returns
    -------
    unit : LinearUnit or None
        The unit, or None when the file names none (no CRS, a geographic
        CRS, or a unit code this function does not know).

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> import laspy
    >>> from skpcd.io import linear_unit
    >>> header = laspy.LasHeader(point_format=6, version="1.4")
    >>> las = laspy.LasData(header)
    >>> las.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(
    ...     'PROJCS["NAD83 / Oregon GIC Lambert (ft)",GEOGCS["NAD83",'
    ...     'UNIT["degree",0.0174532925199433]],UNIT["foot",0.3048]]'))
    >>> las.x = las.y = las.z = np.zeros(1)
    >>> path = os.path.join(tempfile.mkdtemp(), "scan_in_feet.las")
    >>> las.write(path)
    >>> linear_unit(path)
    LinearUnit(name='foot', metres=0.3048, source='WKT VLR')
    """
    records = _records(path)
    text = _wkt_text(records)
    if text:
        for match in _WKT_UNIT.finditer(text):
            name = match["name"]
            if name.lower() in _ANGULAR:
                continue
            try:
                metres = float(match["factor"])
            except ValueError:
                continue
            if metres > 0:
                return LinearUnit(name, metres, "WKT VLR")
    code = geo_keys(records.get(_GEO_KEYS, b"")).get(_LINEAR_UNITS_KEY)
    if code in _EPSG_UNITS:
        name, metres = _EPSG_UNITS[code]
        return LinearUnit(name, metres, "GeoKeys VLR")
    return None
