"""The inventory of ``skpcd identify --inventory``: the geometry of each
object (base, size, heading, a pole's lean and what it carries), the ground
under it, and the files (GeoPackage, GeoJSON, CSV) read back with a GIS
library in the scan's CRS."""

import csv
import json
import math
import struct
import sys

import laspy
import numpy as np
import pytest

from skpcd.cli import main
from skpcd.exceptions import PointCloudFileError
from skpcd.io._crs import read_las_crs
from skpcd.io._inventory import check_inventory_path, write_inventory
from skpcd.segmentation._inventory import (
    INVENTORY_COLUMNS,
    GroundHeight,
    object_inventory,
    segment_geometry,
)

pyogrio = pytest.importorskip("pyogrio")

EPSG = 25832  # ETRS89 / UTM zone 32N
# a street of the simulator, moved to where that CRS's coordinates are
OFFSET = np.array([690_000.0, 5_335_000.0, 400.0])


def _pole(lean_deg=0.0, azimuth_deg=0.0, carried_at=None, n=1500, seed=0):
    """Points of a pole 6 m high of radius 0.06 m leaning ``lean_deg`` towards
    ``azimuth_deg``, with a plate 0.6 m wide from ``carried_at`` to 0.5 m
    higher (measured along the pole)."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, 6, n)
    a = rng.uniform(0, 2 * np.pi, n)
    shaft = np.column_stack([0.06 * np.cos(a), 0.06 * np.sin(a), t])
    parts = [shaft]
    if carried_at is not None:
        u = rng.uniform(-0.3, 0.3, n // 2)
        h = rng.uniform(carried_at, carried_at + 0.5, n // 2)
        parts.append(np.column_stack([u, np.full(n // 2, 0.08), h]))
    points = np.vstack(parts)
    lean, az = np.radians(lean_deg), np.radians(azimuth_deg)
    # tilt about the horizontal axis perpendicular to the azimuth
    tilt = np.array([np.sin(lean) * np.cos(az), np.sin(lean) * np.sin(az)])
    points[:, :2] += np.outer(points[:, 2], tilt)
    points[:, 2] *= np.cos(lean)
    return points + np.array([10.0, 20.0, 3.0])


def test_pole_lean_and_carried_height():
    g = segment_geometry(
        _pole(lean_deg=5.0, azimuth_deg=30.0, carried_at=2.2), pole=True
    )
    assert abs(g["lean"] - 5.0) < 0.5
    assert abs(g["carried_height"] - 2.2 * math.cos(math.radians(5))) < 0.12
    assert abs(g["x"] - 10.0) < 0.1 and abs(g["y"] - 20.0) < 0.1
    upright = segment_geometry(_pole(carried_at=3.0, seed=1), pole=True)
    assert upright["lean"] < 0.7
    assert abs(upright["carried_height"] - 3.0) < 0.12
    bare = segment_geometry(_pole(lean_deg=2.0, seed=2), pole=True)
    assert abs(bare["lean"] - 2.0) < 0.5
    assert math.isnan(bare["carried_height"])
    # not measured as a pole
    assert math.isnan(segment_geometry(_pole(seed=3))["lean"])


def test_footprint_of_a_rotated_box():
    rng = np.random.default_rng(0)
    box = rng.uniform([-2.0, -0.9, 0.0], [2.0, 0.9, 1.5], (3000, 3))
    angle = np.radians(30.0)  # long side 30 degrees anticlockwise from +x
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    box[:, :2] = box[:, :2] @ rot.T
    g = segment_geometry(box)
    assert abs(g["length"] - 4.0) < 0.05 and abs(g["width"] - 1.8) < 0.05
    # 30 degrees from east is 60 degrees clockwise from north
    assert abs(g["heading"] - 60.0) < 1.0
    np.testing.assert_allclose(g["centre"], [0.0, 0.0], atol=0.05)


def test_base_on_the_ground_under_the_object():
    rng = np.random.default_rng(1)
    xy = rng.uniform(0, 30, (20000, 2))
    ground = np.column_stack([xy, 0.05 * xy[:, 0] + 100.0])
    # a sign whose plate hangs from 2 m: its lowest point is off the ground
    plate = np.column_stack(
        [rng.uniform(9.7, 10.3, 300), np.full(300, 5.0), rng.uniform(102.5, 103.0, 300)]
    )
    pole = _pole(carried_at=2.0, seed=4) + np.array([0, 0, 97.5])  # on z 100.5
    geoms = [segment_geometry(plate, pole=True), segment_geometry(pole, pole=True)]
    table = object_inventory(
        geoms, ["traffic_sign", "pole"], [0.4, 0.9], ground=GroundHeight().fit(ground)
    )
    np.testing.assert_allclose(table["z"], [100.5, 100.5], atol=0.05)
    np.testing.assert_allclose(table["height"], [2.5, 6.0], atol=0.05)
    assert abs(table["carried_height"][1] - 2.0) < 0.12
    assert table["class"].tolist() == ["traffic_sign", "pole"]
    # without ground: the base is the lowest point
    alone = object_inventory(geoms, ["traffic_sign", "car"])
    np.testing.assert_allclose(alone["z"][0], 102.5, atol=0.01)
    assert math.isnan(alone["lean"][1])  # a car is not measured as a pole


def _geokeys(epsg):
    """A GeoKeyDirectory record naming a projected CRS by its EPSG code."""
    keys = [1, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, epsg]
    return struct.pack(f"<{len(keys)}H", *keys)


def _street_las(path, crs_record):
    from skpcd.datasets import make_street_scene

    scene = make_street_scene(30, scanner="spinning", random_state=3)
    points = scene.points + OFFSET
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = points.min(axis=0)
    header.scales = [0.001] * 3
    las = laspy.LasData(header)
    las.x, las.y, las.z = points.T
    if crs_record is not None:
        record_id, data = crs_record
        las.vlrs.append(
            laspy.VLR(user_id="LASF_Projection", record_id=record_id, record_data=data)
        )
    las.write(path)
    return points, scene.labels == "ground"


@pytest.fixture(scope="module")
def street(tmp_path_factory):
    folder = tmp_path_factory.mktemp("inventory")
    scan = folder / "street.las"
    points, is_ground = _street_las(scan, (34735, _geokeys(EPSG)))
    return folder, scan, points, is_ground


def test_read_las_crs(street, tmp_path):
    _, scan, _, _ = street
    assert read_las_crs(scan) == f"EPSG:{EPSG}"
    text = 'PROJCS["ETRS89 / UTM zone 32N",AUTHORITY["EPSG","25832"]]'
    other = tmp_path / "wkt.las"
    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.x, las.y, las.z = np.zeros((3, 5))
    las.vlrs.append(
        laspy.VLR(
            user_id="LASF_Projection", record_id=2112, record_data=text.encode() + b"\0"
        )
    )
    las.write(other)
    assert read_las_crs(other) == text
    plain = tmp_path / "plain.las"
    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.x, las.y, las.z = np.zeros((3, 5))
    las.write(plain)
    assert read_las_crs(plain) is None


def test_identify_writes_an_inventory_in_the_scan_crs(street):
    folder, scan, points, is_ground = street
    out, inv = folder / "out.las", folder / "objects.gpkg"
    argv = ["identify", str(scan), "-o", str(out), "--inventory", str(inv)]
    assert main([*argv, "--quiet"]) == 0
    info = pyogrio.read_info(inv)
    assert info["geometry_type"] == "Point Z"
    assert info["crs"] == f"EPSG:{EPSG}"
    segments = laspy.read(out).segment
    assert info["features"] == int(segments.max()) + 1
    meta, _, geometry, fields = pyogrio.raw.read(inv)
    columns = dict(zip(meta["fields"], fields))
    assert set(columns) == set(INVENTORY_COLUMNS) - {"x", "y", "z"}
    np.testing.assert_array_equal(
        np.sort(columns["n_points"]), np.sort(np.bincount(segments[segments >= 0]))
    )
    xyz = np.array([struct.unpack("<ddd", g[-24:]) for g in geometry])
    # each base lies on the simulated ground under it
    from scipy.spatial import cKDTree

    ground = points[is_ground]
    _, near = cKDTree(ground[:, :2]).query(xyz[:, :2], k=20)
    below = np.median(ground[near, 2], axis=1)
    assert np.median(np.abs(xyz[:, 2] - below)) < 0.1
    assert (columns["height"] > 0).all()


def test_identify_without_inventory_measures_nothing(street, monkeypatch):
    """The geometry of the segments (a convex hull each) is computed only
    for an inventory."""
    from skpcd.segmentation import _inventory

    measured = []
    real = _inventory.segment_geometry
    monkeypatch.setattr(
        _inventory,
        "segment_geometry",
        lambda *a, **k: measured.append(1) or real(*a, **k),
    )
    folder, scan, _, _ = street
    argv = ["identify", str(scan), "-o", str(folder / "plain.las"), "--quiet"]
    assert main(argv) == 0
    assert not measured
    argv += ["--overwrite", "--inventory", str(folder / "measured.csv")]
    assert main(argv) == 0
    assert measured


def test_csv_inventory_and_refusals(street, tmp_path, monkeypatch):
    table = object_inventory(
        [segment_geometry(_pole(carried_at=2.0)), segment_geometry(_pole(seed=5))],
        ["pole", "car"],
        [0.9, np.nan],
    )
    out = tmp_path / "objects.csv"
    write_inventory(out, table)
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["class"] for r in rows] == ["pole", "car"]
    assert {"x", "y", "z"} <= set(rows[0])
    assert rows[1]["confidence"] == "" and rows[1]["lean"] == ""
    assert abs(float(rows[0]["x"]) - 10.0) < 0.1
    with pytest.raises(FileExistsError):
        write_inventory(out, table)
    # the format from the extension, checked before any work
    _, scan, _, _ = street
    with pytest.raises(SystemExit, match=r"objects\.shp: .*\.gpkg, \.geojson"):
        main(
            [
                "identify",
                str(scan),
                "-o",
                str(tmp_path / "o.las"),
                "--inventory",
                str(tmp_path / "objects.shp"),
            ]
        )
    assert not (tmp_path / "o.las").exists()
    monkeypatch.setitem(sys.modules, "pyogrio", None)
    with pytest.raises(PointCloudFileError, match=r"skpcd\[gis\]"):
        check_inventory_path(tmp_path / "objects.gpkg")


@pytest.mark.slow
def test_tiled_identify_finds_the_same_ground(street):
    """--tile-size streams the scene: the ground under the objects is then
    gathered chunk by chunk, and agrees with the scene read whole."""
    folder, scan, _, _ = street
    rows = {}
    for name, extra in (("whole.csv", []), ("tiled.csv", ["--tile-size", "15"])):
        out = folder / f"out_{name}.las"
        inv = folder / name
        argv = ["identify", str(scan), "-o", str(out), "--inventory", str(inv)]
        assert main([*argv, *extra, "--quiet", "--overwrite"]) == 0
        with open(inv, newline="") as fh:
            rows[name] = np.array(
                [[float(r[k]) for k in ("x", "y", "z")] for r in csv.DictReader(fh)]
            )
    from scipy.spatial import cKDTree

    whole, tiled = rows["whole.csv"], rows["tiled.csv"]
    dist, near = cKDTree(whole[:, :2]).query(tiled[:, :2])
    # the same objects found both ways (the structures step may cut some
    # differently in tiles)
    same = dist < 0.05
    assert same.sum() >= 10
    np.testing.assert_allclose(tiled[same, 2], whole[near[same], 2], atol=0.05)


def test_a_wkt_crs_is_written_as_gdal_reads_it(tmp_path):
    wkt = (
        'PROJCS["ETRS89 / UTM zone 32N",GEOGCS["ETRS89",DATUM["European_Terrestrial_'
        'Reference_System_1989",SPHEROID["GRS 1980",6378137,298.257222101]],'
        'PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],'
        'PROJECTION["Transverse_Mercator"],PARAMETER["latitude_of_origin",0],'
        'PARAMETER["central_meridian",9],PARAMETER["scale_factor",0.9996],'
        'PARAMETER["false_easting",500000],PARAMETER["false_northing",0],'
        'UNIT["metre",1],AUTHORITY["EPSG","25832"]]'
    )
    table = object_inventory([segment_geometry(_pole())], ["pole"], [0.7])
    for name in ("objects.geojson", "objects.gpkg"):
        write_inventory(tmp_path / name, table, crs=wkt)
        assert pyogrio.read_info(tmp_path / name)["crs"] == f"EPSG:{EPSG}"
    # an EPSG code: the crs member as GDAL reads it
    write_inventory(tmp_path / "epsg.geojson", table, crs=f"EPSG:{EPSG}")
    doc = json.loads((tmp_path / "epsg.geojson").read_text())
    assert doc["crs"]["properties"]["name"] == f"urn:ogc:def:crs:EPSG::{EPSG}"
    assert pyogrio.read_info(tmp_path / "epsg.geojson")["crs"] == f"EPSG:{EPSG}"
    assert doc["features"][0]["geometry"]["type"] == "Point"
    # WGS 84 is GeoJSON's own: no crs member
    write_inventory(tmp_path / "wgs84.geojson", table, crs="EPSG:4326")
    assert "crs" not in json.loads((tmp_path / "wgs84.geojson").read_text())


def test_cars_of_a_real_sweep_measured_from_the_ground(real_sweeps, tmp_path):
    """PandaSet sweep (Pandar64), cars labelled by boxes: the inventory gives
    car sizes (height from the ground under the car, also where the segment
    lacks its wheels, length and width of the footprint)."""
    scan = next(p for p in real_sweeps if p.name == "pandaset_000200.las")
    out, inv = tmp_path / "out.las", tmp_path / "objects.csv"
    argv = ["identify", str(scan), "-o", str(out), "--inventory", str(inv)]
    assert main([*argv, "--quiet"]) == 0
    las = laspy.read(out)
    segment = np.asarray(las.segment).astype(int)
    semantic = np.asarray(las.semantic).astype(int)
    z = np.asarray(las.z)
    with open(inv, newline="") as fh:
        rows = {int(r["id"]): r for r in csv.DictReader(fh)}
    cars = []
    for i, row in rows.items():
        mine = segment == i
        if mine.sum() >= 300 and (semantic[mine] == 10).mean() > 0.9:  # car
            cars.append(
                [float(row[k]) for k in ("z", "height", "length", "width")]
                + [z[mine].min()]
            )
    cars = np.array(cars)
    assert len(cars) >= 6
    base, height, length, width, lowest = cars.T
    assert (base <= lowest + 1e-6).all()  # on the ground, not above it
    assert (lowest - base).max() > 0.3  # some segments lack the wheels ...
    assert np.mean((height > 1.2) & (height < 2.2)) >= 0.8  # ... yet car heights
    assert np.mean((length > 3.0) & (length < 5.5)) >= 0.7
    assert np.mean((width > 1.2) & (width < 2.2)) >= 0.8
