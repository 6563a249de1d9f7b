"""Scans in feet: the unit read from the CRS, segmentation in metres, the
tiled and in-memory runs alike, and --tile-size alone enough on a real
airborne tile (laspy's autzen_trim.laz, Oregon Lambert in international
feet)."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from skpcd.cli import main
from skpcd.exceptions import SegmentationWarning
from skpcd.io import LinearUnit, linear_unit, read_point_cloud, write_point_cloud
from skpcd.segmentation import segment_scene

DATA = Path(__file__).parents[1] / "data"
AUTZEN = DATA / "las" / "autzen_trim.laz"  # WKT and GeoKeys: foot (EPSG 9002)
GEOKEYS = DATA / "las" / "autzen_geokeys.las"  # GeoKeys only: foot
EVLR = DATA / "las" / "1_4_w_evlr.laz"  # WKT in an EVLR: US survey foot
UTM = DATA / "io" / "pdal" / "autzen-utm.las"  # UTM: metre


def test_the_unit_is_read_from_the_wkt_or_the_geokeys(tmp_path):
    assert linear_unit(AUTZEN) == LinearUnit("foot", 0.3048, "WKT VLR")
    assert linear_unit(GEOKEYS) == LinearUnit("foot", 0.3048, "GeoKeys VLR")
    us = linear_unit(EVLR)
    assert us.name == "US survey foot" and us.metres == pytest.approx(1200 / 3937)
    utm = linear_unit(UTM) if UTM.exists() else linear_unit(_utm(tmp_path))
    assert utm is None or utm.metres == 1.0
    plain = tmp_path / "plain.las"
    write_point_cloud(plain, np.zeros((3, 3)))
    assert linear_unit(plain) is None


def _utm(tmp_path):
    path = tmp_path / "utm.las"
    write_point_cloud(path, np.zeros((3, 3)))
    return path


def test_a_scan_in_feet_is_segmented_in_metres():
    xyz = read_point_cloud(AUTZEN)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SegmentationWarning)
        auto = segment_scene(AUTZEN, n_jobs=2)
    assert auto.unit == 0.3048
    metres = segment_scene(xyz * 0.3048, n_jobs=2)
    assert np.array_equal(auto.labels, metres.labels)
    assert np.array_equal(auto.ground, metres.ground)
    assert auto.eps == pytest.approx(metres.eps / 0.3048)
    # the segmentation page's figure: 4.9 m (16.2 ft)
    assert round(auto.eps * 0.3048, 1) == 4.9 and round(auto.eps, 1) == 16.2
    # the same array, said to be in feet, gives the same answer
    feet = segment_scene(xyz, unit=0.3048, n_jobs=2)
    assert np.array_equal(feet.labels, auto.labels) and feet.eps == auto.eps
    # no segment wider than an object of the tile: the widest, 140 m, is
    # the row of trees along the river
    assert max(_widths(xyz, auto.labels)) * 0.3048 <= 150.0
    # taken for metres, the ground presets are 3.28 times too small and the
    # automatic eps joins a segment as wide as the tile
    with pytest.warns(SegmentationWarning, match="joined a segment of 1139 x"):
        segment_scene(xyz, unit=1.0, n_jobs=2)


def _widths(xyz, labels):
    return [np.ptp(xyz[labels == s, :2], axis=0).max() for s in range(labels.max() + 1)]


def test_tile_size_alone_works_and_agrees_with_the_whole_scan(tmp_path, capsys):
    whole, tiled = tmp_path / "whole", tmp_path / "tiled"
    assert main(["segment", str(AUTZEN), "-o", str(whole), "--quiet"]) == 0
    # the default buffer (that of SMRF, 67.7 m) is too small for the
    # estimated eps with the structures step (8 eps): the scan is cut again
    assert main(
        ["segment", str(AUTZEN), "-o", str(tiled), "--tile-size", "200", "--quiet"]
    ) == 0  # fmt: skip
    a = json.loads((whole / "segmentation.json").read_text())
    b = json.loads((tiled / "segmentation.json").read_text())
    assert a["eps"] == pytest.approx(b["eps"], rel=1e-9)
    assert a["unit_metres"] == b["unit_metres"] == 0.3048
    assert a["n_ground"] == b["n_ground"]
    assert abs(a["n_segments"] - b["n_segments"]) <= 1


def test_a_buffer_too_small_is_refused_with_the_options_to_change(tmp_path, capsys):
    with pytest.raises(SystemExit) as refused:
        main([
            "segment", str(AUTZEN), "-o", str(tmp_path / "s"), "--tile-size", "200",
            "--tile-buffer", "70",
        ])  # fmt: skip
    err = str(refused.value.code)
    assert "\n" not in err and not (tmp_path / "s").exists()
    assert "--tile-buffer 70" in err and "pass --tile-buffer " in err
    assert "or --eps " in err and " eps=" not in err and "tile_buffer" not in err
    # the values it names are in feet, as the coordinates: both work
    need = float(err.split("pass --tile-buffer ")[1].split()[0])
    room = float(err.split("or --eps ")[1].split()[0])
    assert main([
        "segment", str(AUTZEN), "-o", str(tmp_path / "a"), "--tile-size", "200",
        "--tile-buffer", str(need), "--quiet",
    ]) == 0  # fmt: skip
    assert main([
        "segment", str(AUTZEN), "-o", str(tmp_path / "b"), "--tile-size", "200",
        "--tile-buffer", "70", "--eps", str(room), "--quiet",
    ]) == 0  # fmt: skip


def test_the_unit_option_is_checked_and_said(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["segment", str(AUTZEN), "-o", str(tmp_path / "s"), "--unit", "-1"])
    assert "--unit" in capsys.readouterr().err
    assert main(["segment", str(AUTZEN), "-o", str(tmp_path / "t")]) == 0
    err = capsys.readouterr().err
    assert "coordinates in foot (0.3048 m, WKT VLR): segmented in metres" in err
