"""What the header of a LAS/LAZ file says, as ``pdal info`` and ``lasinfo``
show it: LAS version, point format, scales and offsets, CRS, VLRs and extra
dimensions; with the points' classification and return numbers, their
histograms. ``skpcd info`` prints it."""

import re

import numpy as np

from skpcd.io._class_codes import ASPRS_NAMES
from skpcd.io._crs import GEOGRAPHIC_KEY, PROJECTED_KEY, USER_DEFINED
from skpcd.io._las_reader import read_las_header

__all__ = ["describe_las"]

_GEO_KEYS = ("LASF_Projection", 34735)
_GEO_ASCII = ("LASF_Projection", 34737)
_WKT = ("LASF_Projection", 2112)
_LOOKUP = ("LASF_Spec", 0)


def _wkt_name(wkt):
    """The name of the outermost CRS of a WKT string (WKT1 or WKT2)."""
    found = re.match(r'\s*[A-Z_]+\[\s*"([^"]*)"', wkt)
    return found.group(1) if found else None


def _crs_from_vlrs(header):
    """The CRS read from the VLRs alone (no pyproj): the WKT VLR's name and
    text, else the EPSG code of the GeoKeys and their ASCII parameters."""
    for vlr in [*header.vlrs, *(header.evlrs or ())]:
        if (vlr.user_id, vlr.record_id) == _WKT and hasattr(vlr, "string"):
            wkt = vlr.string.rstrip("\0")
            return {"name": _wkt_name(wkt), "epsg": None, "wkt": wkt, "from": "WKT VLR"}
    keys = {}
    ascii_text = None
    for vlr in header.vlrs:
        if (vlr.user_id, vlr.record_id) == _GEO_KEYS:
            keys = {k.id: k.value_offset for k in getattr(vlr, "geo_keys", ())}
        elif (vlr.user_id, vlr.record_id) == _GEO_ASCII:
            ascii_text = "".join(getattr(vlr, "strings", ())).strip("|\0 ") or None
    if not keys:
        return None
    code = keys.get(PROJECTED_KEY, keys.get(GEOGRAPHIC_KEY))
    epsg = code if code not in (None, 0, USER_DEFINED) else None
    name = ascii_text or (f"EPSG:{epsg}" if epsg else None)
    return {"name": name, "epsg": epsg, "wkt": None, "from": "GeoKeys VLR"}


def _crs(header):
    try:
        parsed = header.parse_crs()  # imports pyproj
    except ImportError:
        crs = _crs_from_vlrs(header)
        if crs is not None:
            crs["from"] += "; pyproj not installed"
        return crs
    except Exception:  # a CRS pyproj cannot parse: what the VLRs say
        parsed = None
    if parsed is None:
        crs = _crs_from_vlrs(header)
        if crs is not None:
            crs["from"] += "; pyproj cannot parse it"
        return crs
    return {
        "name": parsed.name,
        "epsg": parsed.to_epsg(),
        "wkt": parsed.to_wkt(),
        "from": "pyproj (header.parse_crs)",
    }


def _vlr(vlr):
    return {
        "user_id": vlr.user_id,
        "record_id": int(vlr.record_id),
        "description": vlr.description.rstrip("\0"),
        "bytes": len(vlr.record_data_bytes()),
    }


def _histogram(values, names=None):
    codes, counts = np.unique(np.asarray(values), return_counts=True)
    out = []
    for code, count in zip(codes.tolist(), counts.tolist(), strict=True):
        row = {"code": int(code), "points": int(count)}
        if names is not None:
            row["name"] = names.get(int(code), "")
        out.append(row)
    return out


def describe_las(path, fields=None):
    """What the header of a LAS/LAZ file says, and the histograms of its
    points' classes and returns.

    Parameters
    ----------
    path : str or path-like
        A ``.las`` or ``.laz`` file.
    fields : dict of str to ndarray, default=None
        The points' dimensions as :func:`~skpcd.io.read_point_cloud` returns
        them with ``fields="all"``; the ``classification`` and
        ``return_number`` histograms come from them (none without).

    Returns
    -------
    description : dict
        ``version``, ``point_format``, ``record_length``, ``n_points``,
        ``compressed``, ``scales``, ``offsets``, ``mins``, ``maxs`` (the
        header's bounds), ``system_identifier``, ``generating_software``,
        ``creation_date``, ``crs`` (None, or ``name``, ``epsg``, ``wkt`` and
        ``from``: pyproj's reading of the CRS VLRs when pyproj is installed,
        else the WKT VLR's text or the GeoKeys' EPSG code), ``vlrs`` and
        ``evlrs`` (``user_id``, ``record_id``, ``description``, ``bytes``),
        ``extra_dimensions`` (``name``, ``type``, ``description``),
        ``classification`` (``code``, ``name``, ``points``: the names of the
        file's Classification Lookup VLR, else the ASPRS ones) and
        ``returns`` (``code``: the return number, ``points``).

    Raises
    ------
    MissingFileError
        If the file does not exist.
    PointCloudFileError
        If it is not a readable LAS/LAZ file.
    """
    header = read_las_header(path)
    fmt = header.point_format
    lookup = dict(ASPRS_NAMES)
    for vlr in header.vlrs:
        if (vlr.user_id, vlr.record_id) == _LOOKUP and hasattr(vlr, "lookups"):
            lookup.update({int(k): v for k, v in vlr.lookups.items()})
    extra = []
    for dim in fmt.extra_dimensions:
        kind = str(np.dtype(dim.dtype).base) if dim.dtype is not None else "bytes"
        if dim.num_elements > 1:
            kind += f"[{dim.num_elements}]"
        extra.append(
            {"name": dim.name, "type": kind, "description": dim.description.strip()}
        )
    fields = fields or {}
    date = header.creation_date
    return {
        "version": str(header.version),
        "point_format": int(fmt.id),
        "record_length": int(fmt.size),
        "n_points": int(header.point_count),
        "compressed": str(path).lower().endswith(".laz"),
        "scales": [float(s) for s in header.scales],
        "offsets": [float(o) for o in header.offsets],
        "mins": [float(v) for v in header.mins],
        "maxs": [float(v) for v in header.maxs],
        "system_identifier": header.system_identifier.rstrip("\0"),
        "generating_software": header.generating_software.rstrip("\0"),
        "creation_date": None if date is None else date.isoformat(),
        "crs": _crs(header),
        "vlrs": [_vlr(v) for v in header.vlrs],
        "evlrs": [_vlr(v) for v in header.evlrs or ()],
        "extra_dimensions": extra,
        "classification": (
            _histogram(fields["classification"], lookup)
            if "classification" in fields
            else []
        ),
        "returns": (
            _histogram(fields["return_number"]) if "return_number" in fields else []
        ),
    }
