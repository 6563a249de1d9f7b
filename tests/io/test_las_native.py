"""LAS/LAZ as the native format: laspy and lazrs are core dependencies, LAS
outputs carry the source's header through (version, point format, scales,
offsets, CRS) as PDAL's ``forward=all`` does, and predicted classes can go
into ``classification`` with ASPRS codes. On real files of the laspy test
data (tests/data/las/README.md)."""

import re
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest
import tomllib

from skpcd.cli import main
from skpcd.io import read_class_names, write_labelled_scan
from skpcd.io._class_codes import classification_codes
from skpcd.io._las_reader import read, read_las_header
from skpcd.io._las_structure import import_laspy
from skpcd.io._las_writer import write

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
AUTZEN = DATA / "las" / "autzen_trim.laz"  # LAS 1.2, format 3, GeoKeys + WKT
EVLR = DATA / "las" / "1_4_w_evlr.laz"  # LAS 1.4, format 6, WKT, an EVLR
COPC = DATA / "copc" / "simple.copc.laz"
LASZIP = ("laszip encoded", 22204)


def _records(header):
    return [
        (v.user_id, v.record_id, bytes(v.record_data_bytes()))
        for v in header.vlrs
        if (v.user_id, v.record_id) != LASZIP
    ]


def _raw(las):
    """Each point record of ``las`` as bytes (one void value per point)."""
    array = np.ascontiguousarray(las.points.array)
    return array.view(np.dtype((np.void, array.dtype.itemsize)))


# -- 1. LAS/LAZ needs no extra ------------------------------------------------


def test_laspy_and_lazrs_are_core_dependencies():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    names = {re.split(r"[<>=!~\[ ;]", d)[0].lower() for d in project["dependencies"]}
    assert {"laspy", "lazrs"} <= names
    # the extra stays, so that pip install 'skpcd[las]' still works
    assert "las" in project["optional-dependencies"]


def test_no_code_path_gives_the_las_extra_as_a_hint(monkeypatch):
    sources = list((ROOT / "skpcd").rglob("*.py"))
    hinted = [p.name for p in sources if "skpcd[las]" in p.read_text()]
    assert hinted == []
    monkeypatch.setitem(sys.modules, "laspy", None)  # laspy not importable
    with pytest.raises(ImportError) as info:
        import_laspy()
    assert "laspy" in str(info.value) and "[las]" not in str(info.value)


# -- 3. the source's header carried through -----------------------------------


def test_write_with_a_header_keeps_it_bit_for_bit(tmp_path):
    header = read_las_header(AUTZEN)
    fields, _ = read(AUTZEN)
    take = np.arange(0, len(fields["x"]), 9)
    out = tmp_path / "part.las"
    write(out, {k: v[take] for k, v in fields.items()}, header=header)
    got, source = laspy.read(out), laspy.read(AUTZEN)
    assert str(got.header.version) == "1.2" and got.header.point_format.id == 3
    np.testing.assert_array_equal(got.header.scales, source.header.scales)
    np.testing.assert_array_equal(got.header.offsets, source.header.offsets)
    assert _records(got.header) == _records(source.header)  # GeoKeys and WKT
    assert list(got.point_format.extra_dimension_names) == []
    assert np.array_equal(_raw(got), _raw(source)[take])


def test_write_with_a_copc_header_leaves_the_copc_records_out(tmp_path):
    fields, _ = read(COPC)
    out = tmp_path / "copy.laz"
    write(out, fields, header=read_las_header(COPC))
    got = laspy.read(out)
    assert [v.user_id for v in got.header.vlrs] == ["LASF_Projection"]
    assert got.header.point_format.id == 7 and len(got.points) == 1065


def test_write_with_a_header_moves_the_offset_only_for_points_beyond_it(tmp_path):
    header = read_las_header(AUTZEN)
    far = {"x": np.array([3e7, 3e7 + 1.25]), "y": np.zeros(2), "z": np.ones(2)}
    out = tmp_path / "far.las"
    write(out, far, header=header)  # 3e7 / 0.01 is beyond 32 bits
    got = laspy.read(out)
    assert got.header.scales[0] == 0.01 and got.header.offsets[1] == 0
    np.testing.assert_allclose(got.x, far["x"])


def test_segment_files_carry_the_header_of_the_scan(tmp_path):
    # before: LAS 1.4 format 7, scale 0.0001, the CRS lost and
    # scan_angle_rank an extra dimension beside scan_angle
    out = tmp_path / "segs"
    argv = ["segment", str(AUTZEN), "-o", str(out), "--format", "las"]
    options = ["--keep-fields", "--ground", "none", "--eps", "2.5", "--min-size", "300"]
    assert main([*argv, *options, "--quiet"]) == 0
    source = laspy.read(AUTZEN)
    files = sorted(out.glob("segment_*.las"))
    assert len(files) >= 2
    records = _raw(source)
    for path in files:
        got = laspy.read(path)
        assert str(got.header.version) == "1.2", path.name
        assert got.header.point_format.id == 3
        np.testing.assert_array_equal(got.header.scales, [0.01, 0.01, 0.01])
        np.testing.assert_array_equal(got.header.offsets, source.header.offsets)
        assert _records(got.header) == _records(source.header)
        assert "scan_angle_rank" in got.point_format.standard_dimension_names
        assert list(got.point_format.extra_dimension_names) == []
        # every point record is one of the scan's, bit for bit
        assert np.isin(_raw(got), records).all()


# -- 4. the classes in classification -----------------------------------------


def test_classification_codes_are_asprs_then_stable_user_codes():
    names = ["Building", "bush", "car", "kiosk", "pole", "tree", "wire", "unknown"]
    assert classification_codes(names) == [6, 4, 64, 76, 65, 5, 14, 1]
    # skpcd's own names keep their code whatever the other classes
    assert classification_codes(["pole"]) == [65]
    assert classification_codes(["kiosk", "bench"]) == [76, 77]
    assert classification_codes(["kiosk"], {"kiosk": 200}) == [200]
    with pytest.raises(ValueError, match="0 to 255"):
        classification_codes(["car"], {"car": 300})


def _labels(n, n_classes, seed=0):
    rng = np.random.default_rng(seed)
    segment = rng.integers(-1, 30, n)
    index = np.where(segment >= 0, segment % n_classes, -1)
    ground = (segment < 0) & (rng.random(n) < 0.5)
    return {"segment": segment, "class_index": index, "ground": ground}


def test_classes_go_into_classification_of_a_legacy_scan(tmp_path):
    # before: classification held only the ground; the lookup VLR named the
    # codes 64+ of the class dimension, which classification did not hold
    names = ["building", "car", "kiosk", "tree"]
    n = laspy.open(AUTZEN).header.point_count
    labels = _labels(n, len(names))
    out = tmp_path / "labelled.laz"
    write_labelled_scan(AUTZEN, out, class_names=names, chunk_size=40_000, **labels)
    got, source = laspy.read(out), laspy.read(AUTZEN)
    # codes above 31 need the LAS 1.4 counterpart of format 3
    assert str(got.header.version) == "1.4" and got.header.point_format.id == 7
    assert got.header.global_encoding.wkt  # the CRS read from the WKT VLR
    codes = np.array([1, 6, 64, 76, 5])[labels["class_index"] + 1]
    codes[labels["ground"]] = 2
    np.testing.assert_array_equal(got.classification, codes)
    np.testing.assert_array_equal(got["original_classification"], source.classification)
    (lookup,) = got.header.vlrs.get("ClassificationLookupVlr")
    assert lookup.lookups == {
        1: "unclassified",
        2: "ground",
        5: "tree",
        6: "building",
        64: "car",
        76: "kiosk",
    }
    assert set(np.unique(got.classification)) <= set(lookup.lookups)
    for dim in ("intensity", "gps_time", "red", "return_number", "point_source_id"):
        np.testing.assert_array_equal(got[dim], source[dim], err_msg=dim)
    np.testing.assert_array_equal(
        got.scan_angle, np.round(source.scan_angle_rank / 0.006)
    )
    np.testing.assert_array_equal(got.header.scales, source.header.scales)
    got_crs = [
        r for r in _records(got.header) if r[0] != "LASF_Spec" and r[0] != "skpcd"
    ]
    assert got_crs == _records(source.header)
    assert read_class_names(out) == {64: "building", 65: "car", 66: "kiosk", 67: "tree"}


def test_asprs_classes_keep_the_legacy_format(tmp_path):
    names = ["building", "tree"]
    n = laspy.open(AUTZEN).header.point_count
    out = tmp_path / "labelled.las"
    write_labelled_scan(AUTZEN, out, class_names=names, **_labels(n, 2))
    got = laspy.read(out)
    assert str(got.header.version) == "1.2" and got.header.point_format.id == 3
    assert set(np.unique(got.classification)) <= {1, 2, 5, 6}


def test_extra_keeps_the_format_and_classification(tmp_path):
    names = ["car", "pole"]
    n = laspy.open(AUTZEN).header.point_count
    labels = _labels(n, 2)
    out = tmp_path / "labelled.las"
    write_labelled_scan(AUTZEN, out, class_names=names, classes_into="extra", **labels)
    got, source = laspy.read(out), laspy.read(AUTZEN)
    assert str(got.header.version) == "1.2" and got.header.point_format.id == 3
    keep = ~labels["ground"]
    np.testing.assert_array_equal(got.classification[keep], source.classification[keep])
    assert "original_classification" not in got.point_format.dimension_names
    with pytest.raises(ValueError, match="classes_into"):
        write_labelled_scan(
            AUTZEN,
            tmp_path / "x.las",
            class_names=names,
            classes_into="class",
            **labels,
        )


def test_classes_into_classification_of_a_las_14_scan_with_an_evlr(tmp_path):
    names = ["ground", "pole", "wire"]
    n = laspy.open(EVLR).header.point_count
    labels = _labels(n, 3, seed=2)
    out = tmp_path / "labelled.las"
    write_labelled_scan(EVLR, out, class_names=names, chunk_size=300, **labels)
    got, source = laspy.read(out), laspy.read(EVLR)
    assert got.header.point_format.id == 6
    assert [(e.user_id, e.record_id) for e in got.header.evlrs] == [("pylastest", 42)]
    codes = np.array([1, 2, 65, 14])[labels["class_index"] + 1]
    codes[labels["ground"]] = 2
    np.testing.assert_array_equal(got.classification, codes)
    np.testing.assert_array_equal(got.X, source.X)
    # relabelling an output keeps the first input's classification
    again = tmp_path / "again.las"
    write_labelled_scan(out, again, class_names=["car"], **_labels(n, 1, seed=3))
    np.testing.assert_array_equal(
        laspy.read(again)["original_classification"], source.classification
    )
