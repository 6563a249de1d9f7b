"""write_labelled_scan and read_class_names: a labelled copy that loses nothing."""

import hashlib
import json

import laspy
import numpy as np
import pytest

from skpcd.exceptions import MissingFileError, NonFiniteWarning, PointCloudFileError
from skpcd.io import (
    read_class_names,
    read_point_cloud,
    write_labelled_scan,
    write_point_cloud,
)

NAMES = ["building", "street_lamp", "a very long class name", "unknown"]
FORMATS = [(3, "1.2"), (6, "1.4")]


def _scan(path, point_format=6, version="1.4", n=3000, seed=0):
    """A scan as a survey delivers it: ASPRS classes with flags, a float
    extra dimension, a VLR of its own (and an EVLR in LAS 1.4)."""
    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.add_extra_dims(
        [laspy.ExtraBytesParams("reflectance", "float32", description="dB")]
    )
    header.scales = [0.001, 0.001, 0.001]
    header.offsets = [430000.0, 5400000.0, 100.0]
    header.vlrs.append(laspy.VLR("survey", 7, "flight", b"\x01\x02\x03 line 12"))
    las = laspy.LasData(header)
    las.x = rng.uniform(430000, 430100, n)
    las.y = rng.uniform(5400000, 5400100, n)
    las.z = rng.uniform(100, 130, n)
    las.intensity = rng.integers(0, 65535, n)
    las.classification = rng.choice([1, 2, 3, 5, 6, 9, 17], n)
    las.synthetic = rng.random(n) < 0.2
    las.withheld = rng.random(n) < 0.1
    las.return_number = rng.integers(1, 4, n)
    las.number_of_returns = np.full(n, 3)
    las.gps_time = rng.uniform(0, 1e5, n)
    las.reflectance = rng.normal(size=n).astype(np.float32)
    if point_format == 3:
        las.red = rng.integers(0, 65535, n)
    if version == "1.4":
        las.evlrs = laspy.vlrs.vlrlist.VLRList(
            [laspy.VLR("survey", 8, "trajectory", b"t" * 100)]
        )
    las.write(str(path))
    return las


def _labels(n, seed=1, n_classes=len(NAMES)):
    rng = np.random.default_rng(seed)
    segment = rng.integers(-1, 40, n)
    class_index = np.where(segment >= 0, rng.integers(0, n_classes, n), -1)
    score = np.where(segment >= 0, rng.random(n), np.nan)
    ground = (segment < 0) & (rng.random(n) < 0.7)
    return {
        "segment": segment,
        "class_index": class_index,
        "score": score,
        "ground": ground,
    }


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize(("point_format", "version"), FORMATS)
@pytest.mark.parametrize("src_ext", [".las", ".laz"])
@pytest.mark.parametrize("out_ext", [".las", ".laz"])
def test_las_copy_keeps_every_point_and_dimension(
    tmp_path, point_format, version, src_ext, out_ext
):
    source = tmp_path / f"scan{src_ext}"
    original = _scan(source, point_format, version)
    n = len(original.points)
    labels = _labels(n)
    out = tmp_path / f"labelled{out_ext}"
    write_labelled_scan(
        source,
        out,
        class_names=NAMES,
        score_name="probability",
        chunk_size=700,
        classes_into="extra",
        **labels,
    )
    got = laspy.read(str(out))
    assert got.header.point_count == n
    assert got.header.version == original.header.version
    assert got.header.point_format.id == point_format
    np.testing.assert_array_equal(got.header.scales, original.header.scales)
    np.testing.assert_array_equal(got.header.offsets, original.header.offsets)
    # every raw field of the input, bit for bit, except the classification
    raw_class = "classification" if point_format >= 6 else "raw_classification"
    for name in original.points.array.dtype.names:
        if name != raw_class:
            assert np.array_equal(
                got.points.array[name], original.points.array[name]
            ), name
    ground = labels["ground"]
    assert np.array_equal(got.classification[ground], np.full(ground.sum(), 2))
    assert np.array_equal(got.classification[~ground], original.classification[~ground])
    for flag in ("synthetic", "withheld", "key_point"):
        assert np.array_equal(got[flag], original[flag]), flag
    assert got.reflectance.dtype == np.float32
    # the new dimensions
    extra = list(got.point_format.extra_dimension_names)
    assert extra == ["reflectance", "segment", "class", "probability", "ground"]
    assert got["segment"].dtype == np.int32
    assert np.array_equal(got["segment"], labels["segment"])
    index = labels["class_index"]
    assert got["class"].dtype == np.uint8
    assert np.array_equal(got["class"], np.where(index >= 0, index + 64, 0))
    assert got["probability"].dtype == np.float32
    np.testing.assert_array_equal(
        got["probability"], labels["score"].astype(np.float32)
    )
    assert np.array_equal(got["ground"], ground.astype(np.uint8))
    # described in the Extra Bytes VLR
    (eb,) = got.header.vlrs.get("ExtraBytesVlr")
    descriptions = {
        s.format_name(): s.description.rstrip(b"\0").decode()
        for s in eb.extra_bytes_structs
    }
    assert descriptions["reflectance"] == "dB"
    assert descriptions["class"] == "class code 64+j (0: none)"
    assert descriptions["segment"] == "segment id (-1: none)"
    assert descriptions["probability"] == "probability (NaN: none)"
    # the class names: full ones back, truncated ones in the lookup VLR
    assert read_class_names(out) == {64 + j: c for j, c in enumerate(NAMES)}
    (lookup,) = got.header.vlrs.get("ClassificationLookupVlr")
    assert lookup.lookups[64] == "building"
    assert lookup.lookups[66] == "a very long cla"  # 15 characters
    (names,) = [v for v in got.header.vlrs if v.user_id == "skpcd"]
    record = json.loads(names.record_data)
    assert record["dimensions"]["score"] == "probability"
    assert record["classes"]["65"] == "street_lamp"
    # the source's own VLR and EVLR
    (own,) = [v for v in got.header.vlrs if v.user_id == "survey"]
    assert own.record_id == 7 and own.record_data == b"\x01\x02\x03 line 12"
    if version == "1.4":
        assert [(e.user_id, e.record_id) for e in got.evlrs] == [("survey", 8)]
        assert got.evlrs[0].record_data == b"t" * 100


@pytest.mark.parametrize("ext", [".las", ".laz"])
def test_chunk_size_does_not_change_the_file(tmp_path, ext):
    source = tmp_path / f"scan{ext}"
    n = 60_000  # more than one LAZ chunk of 50 000 points
    _scan(source, n=n)
    labels = _labels(n)
    digests = set()
    for chunk_size in (7_001, 60_000, 10**6):
        out = tmp_path / f"out{chunk_size}{ext}"
        write_labelled_scan(
            source, out, class_names=NAMES, chunk_size=chunk_size, **labels
        )
        digests.add(_digest(out))
    assert len(digests) == 1


def test_memmap_inputs_give_the_same_file(tmp_path):
    source = tmp_path / "scan.las"
    n = 5000
    _scan(source, n=n)
    labels = _labels(n)
    write_labelled_scan(source, tmp_path / "a.las", class_names=NAMES, **labels)
    maps = {}
    for name, values in labels.items():
        maps[name] = np.memmap(
            tmp_path / f"{name}.dat", dtype=values.dtype, mode="w+", shape=(n,)
        )
        maps[name][:] = values
        maps[name].flush()
        maps[name] = np.memmap(
            tmp_path / f"{name}.dat", dtype=values.dtype, mode="r", shape=(n,)
        )
    write_labelled_scan(
        source, tmp_path / "b.las", class_names=NAMES, chunk_size=999, **maps
    )
    assert _digest(tmp_path / "a.las") == _digest(tmp_path / "b.las")


def test_relabelling_an_output_replaces_its_dimensions(tmp_path):
    source = tmp_path / "scan.laz"
    original = _scan(source)
    n = len(original.points)
    first = tmp_path / "first.laz"
    write_labelled_scan(
        source,
        first,
        class_names=NAMES,
        score_name="similarity",
        classes_into="extra",
        **_labels(n),
    )
    labels = _labels(n, seed=5, n_classes=2)
    second = tmp_path / "second.las"
    write_labelled_scan(
        first,
        second,
        class_names=["car", "tree"],
        segment=labels["segment"],
        class_index=labels["class_index"],
        score=labels["score"],
        score_name="similarity",
        classes_into="extra",
    )
    got = laspy.read(str(second))
    extra = list(got.point_format.extra_dimension_names)
    # the old ground dimension is an input dimension now (no ground given)
    assert extra == ["reflectance", "ground", "segment", "class", "similarity"]
    assert np.array_equal(got["segment"], labels["segment"])
    assert read_class_names(second) == {64: "car", 65: "tree"}
    assert len([v for v in got.header.vlrs if v.user_id == "skpcd"]) == 1
    assert len(got.header.vlrs.get("ClassificationLookupVlr")) == 1
    assert np.array_equal(got.reflectance, original.reflectance)
    # without ground, classification is the input's
    assert np.array_equal(got.classification, laspy.read(str(first)).classification)


def test_lookup_entries_below_64_are_kept(tmp_path):
    source = tmp_path / "scan.las"
    header = laspy.LasHeader(point_format=6, version="1.4")
    lookup = laspy.vlrs.known.ClassificationLookupVlr()
    lookup[2] = "ground"
    lookup[6] = "building"
    lookup[70] = "old"
    header.vlrs.append(lookup)
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.arange(3.0), np.arange(3.0), np.arange(3.0)
    las.write(str(source))
    out = tmp_path / "out.las"
    write_labelled_scan(
        source,
        out,
        segment=[0, 1, -1],
        class_index=[0, 1, -1],
        class_names="ab",
        classes_into="extra",
    )
    (got,) = laspy.read(str(out)).header.vlrs.get("ClassificationLookupVlr")
    assert got.lookups == {2: "ground", 6: "building", 64: "a", 65: "b"}


def test_keep_fields_false_drops_the_extra_dimensions(tmp_path):
    source = tmp_path / "scan.las"
    original = _scan(source, n=100)
    out = tmp_path / "out.las"
    write_labelled_scan(
        source,
        out,
        class_names=NAMES,
        keep_fields=False,
        classes_into="extra",
        **_labels(100),
    )
    got = laspy.read(str(out))
    assert list(got.point_format.extra_dimension_names) == [
        "segment",
        "class",
        "score",
        "ground",
    ]
    assert np.array_equal(got.intensity, original.intensity)


def test_read_class_names_falls_back_to_the_lookup_vlr(tmp_path):
    path = tmp_path / "lookup.las"
    header = laspy.LasHeader(point_format=6, version="1.4")
    lookup = laspy.vlrs.known.ClassificationLookupVlr()
    lookup[2] = "ground"
    lookup[64] = "pole"
    header.vlrs.append(lookup)
    las = laspy.LasData(header)
    las.x, las.y, las.z = [0.0], [0.0], [0.0]
    las.write(str(path))
    assert read_class_names(path) == {64: "pole"}
    plain = tmp_path / "plain.las"
    write_point_cloud(plain, np.zeros((2, 3)))
    assert read_class_names(plain) == {}
    with pytest.raises(PointCloudFileError, match="not a LAS/LAZ file"):
        read_class_names(tmp_path / "x.ply")


@pytest.mark.parametrize("out_ext", [".ply", ".xyz"])
def test_las_source_to_another_format(tmp_path, out_ext):
    source = tmp_path / "scan.las"
    original = _scan(source, n=500)
    labels = _labels(500)
    out = tmp_path / f"labelled{out_ext}"
    write_labelled_scan(
        source, out, class_names=NAMES, score_name="probability", **labels
    )
    points, fields = read_point_cloud(out, fields="all")
    assert np.allclose(points[:, 0], original.x)
    assert np.array_equal(fields["segment"], labels["segment"])
    assert np.array_equal(fields["class"], labels["class_index"])
    np.testing.assert_allclose(
        fields["probability"], labels["score"].astype(np.float32), rtol=1e-6
    )
    assert np.array_equal(fields["ground"], labels["ground"])
    np.testing.assert_allclose(fields["reflectance"], original.reflectance, rtol=1e-6)
    expected = np.where(labels["ground"], 2, original.classification)
    assert np.array_equal(fields["classification"], expected)
    if out_ext == ".ply":
        assert fields["segment"].dtype == np.int32
        assert fields["class"].dtype == np.int32
        assert fields["ground"].dtype == np.uint8


def test_other_source_to_las_gets_the_las_layout(tmp_path):
    source = tmp_path / "scan.ply"
    points = np.random.default_rng(0).uniform(0, 10, (50, 3))
    write_point_cloud(source, points, fields={"intensity": np.arange(50.0)})
    labels = _labels(50)
    out = tmp_path / "out.laz"
    write_labelled_scan(source, out, class_names=NAMES, classes_into="extra", **labels)
    got = laspy.read(str(out))
    index = labels["class_index"]
    assert np.array_equal(got["class"], np.where(index >= 0, index + 64, 0))
    assert np.array_equal(got["segment"], labels["segment"])
    assert np.array_equal(got.classification, np.where(labels["ground"], 2, 0))
    assert np.array_equal(got.intensity, np.arange(50))
    assert read_class_names(out) == {64 + j: c for j, c in enumerate(NAMES)}


def test_nonfinite_points_of_the_source(tmp_path):
    source = tmp_path / "scan.xyz"
    points = np.arange(15.0).reshape(5, 3)
    points[1, 2] = np.nan
    write_point_cloud(source, points)
    segment = np.array([0, 1, 1, -1, 2])
    index = np.array([0, 1, 1, -1, 0])
    # one value per point of the file: the NaN point keeps its labels
    out = tmp_path / "all.ply"
    write_labelled_scan(
        source, out, segment=segment, class_index=index, class_names=NAMES
    )
    got, fields = read_point_cloud(out, fields=["segment"], nonfinite="keep")
    assert np.isnan(got[1, 2]) and fields["segment"].tolist() == [0, 1, 1, -1, 2]
    # one value per finite point (what read_point_cloud returns by default)
    out = tmp_path / "finite.ply"
    write_labelled_scan(
        source,
        out,
        segment=segment[[0, 2, 3, 4]],
        class_index=index[[0, 2, 3, 4]],
        class_names=NAMES,
        score=[0.5, 0.6, 0.7, 0.8],
        ground=[0, 0, 1, 0],
    )
    got, fields = read_point_cloud(out, fields="all", nonfinite="keep")
    assert len(got) == 5
    assert fields["segment"].tolist() == [0, -1, 1, -1, 2]
    assert fields["class"].tolist() == [0, -1, 1, -1, 0]
    assert np.isnan(fields["score"][1]) and fields["ground"].tolist() == [0, 0, 0, 1, 0]
    # LAS cannot store the NaN point: left out, with a warning
    out = tmp_path / "out.las"
    with pytest.warns(NonFiniteWarning, match="1 of 5 points"):
        write_labelled_scan(
            source, out, segment=segment, class_index=index, class_names=NAMES
        )
    got = laspy.read(str(out))
    assert got["segment"].tolist() == [0, 1, -1, 2]


def test_errors(tmp_path):
    source = tmp_path / "scan.las"
    _scan(source, n=10)
    labels = _labels(10)
    out = tmp_path / "out.las"

    def write(**changes):
        kwargs = {"class_names": NAMES, **labels, **changes}
        write_labelled_scan(kwargs.pop("source", source), out, **kwargs)

    with pytest.raises(
        ValueError,
        match=r"scan\.las: segment has 9 values but the "
        r"scan has 10 points",
    ):
        write(segment=labels["segment"][:9])
    with pytest.raises(ValueError, match=r"ground has 11 values .* 10 points"):
        write(ground=np.zeros(11, bool))
    with pytest.raises(ValueError, match="at most 192"):
        write(class_names=[f"c{j}" for j in range(193)])
    with pytest.raises(ValueError, match="class_index values must be -1"):
        write(class_index=np.full(10, len(NAMES)))
    with pytest.raises(ValueError, match="segment values must be -1"):
        write(segment=np.full(10, -2))
    with pytest.raises(ValueError, match="standard LAS dimension"):
        write(score_name="intensity")
    with pytest.raises(ValueError, match="clashes"):
        write(score_name="segment")
    with pytest.raises(ValueError, match="ground must be boolean"):
        write(ground=np.full(10, 3))
    with pytest.raises(ValueError, match="segment must have a numeric dtype"):
        write(segment=np.full(10, 0.5))
    with pytest.raises(ValueError, match="chunk_size must be a positive integer"):
        write(chunk_size=0)
    with pytest.raises(MissingFileError):
        write(source=tmp_path / "missing.las")
    with pytest.raises(PointCloudFileError, match="unknown point-cloud extension"):
        write_labelled_scan(source, tmp_path / "out.foo", class_names=NAMES, **labels)
    assert not out.exists()
    # an error in a later chunk: no partial output
    late = labels["class_index"].copy()
    late[-1] = 99
    with pytest.raises(ValueError, match="class_index values"):
        write(class_index=late, chunk_size=3)
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == [
        "scan.las"
    ]
    # the source is never the output, even with overwrite
    for same in (source, tmp_path / "." / "scan.las"):
        with pytest.raises(ValueError, match="the output is the source"):
            write_labelled_scan(
                source, same, class_names=NAMES, overwrite=True, **labels
            )
    write()
    with pytest.raises(FileExistsError):
        write()
    write(overwrite=True)
