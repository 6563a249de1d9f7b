"""Scans labelled point by point: LAS dimensions and their class names,
scalar fields of other formats, SemanticKITTI ``.bin`` + ``.label``, class
maps, and the errors of each."""

import re

import laspy
import numpy as np
import pytest

from skpcd.exceptions import MissingFileError, PointCloudFileError
from skpcd.io import (
    labelled_scan_paths,
    read_class_map,
    read_point_cloud,
    read_point_labels,
    write_point_cloud,
)
from skpcd.io._point_labels import SEMANTICKITTI_NAMES

KITTI = "semantickitti_04_000000.laz"
PANDASET = "pandaset_001_00.laz"


def _las(path, classification, *, lookup=None, extra=None, n=None):
    """A LAS file of ``n`` points with this classification, an optional
    Classification Lookup VLR (code -> name) and extra dimensions."""
    n = len(classification)
    las = laspy.create(point_format=6, file_version="1.4")
    rng = np.random.default_rng(0)
    for name, values in (extra or {}).items():
        las.add_extra_dim(laspy.ExtraBytesParams(name, values.dtype))
    xyz = rng.uniform(0, 10, (n, 3))
    las.header.scales = [0.001] * 3
    las.x, las.y, las.z = xyz.T
    las.classification = classification
    for name, values in (extra or {}).items():
        setattr(las, name, values)
    if lookup:
        data = b"".join(
            bytes([c]) + t.encode().ljust(15, b"\0") for c, t in lookup.items()
        )
        las.vlrs.append(laspy.VLR("LASF_Spec", 0, "Classification Lookup", data))
    las.write(path)
    return path


def test_las_classification_named_by_lookup_then_asprs(tmp_path):
    path = _las(
        tmp_path / "s.las",
        np.array([2, 6, 6, 70, 5], np.uint8),
        lookup={70: "kerb", 6: "house"},
    )
    scan = read_point_labels(path)
    assert scan.labels.tolist() == [
        "ground",
        "house",
        "house",
        "kerb",
        "high vegetation",
    ]
    assert scan.codes.tolist() == [2, 6, 6, 70, 5]
    assert scan.instances is None and not scan.ignored.any()


def test_extra_dimension_and_instances(tmp_path):
    semantic = np.array([10, 10, 30, 0], np.uint16)
    objects = np.array([1, 1, 2, 0], np.uint32)
    path = _las(
        tmp_path / "s.las",
        np.zeros(4, np.uint8),
        extra={"semantic": semantic, "instance": objects},
    )
    scan = read_point_labels(path, "semantic")
    assert scan.labels.tolist() == ["10", "10", "30", "0"]
    assert scan.instances.tolist() == [1, 1, 2, 0]  # "auto": the instance field
    assert read_point_labels(path, "semantic", instances=None).instances is None
    mapped = read_point_labels(path, "semantic", class_map="semantickitti")
    assert mapped.labels.tolist() == ["car", "car", "person", "ignore"]
    assert mapped.ignored.tolist() == [False, False, False, True]


def test_cloudcompare_ply_scalar_field(tmp_path):
    """CloudCompare saves a painted class as a float scalar field."""
    path = tmp_path / "painted.ply"
    values = np.array([2.0, 6.0, 6.0, 5.0], np.float32)
    write_point_cloud(path, np.eye(4, 3), fields={"scalar_Classification": values})
    (tmp_path / "map.csv").write_text("code,name\n2,ground\n6,building\n5,ignore\n")
    scan = read_point_labels(
        path, "scalar_Classification", class_map=tmp_path / "map.csv"
    )
    assert scan.labels.tolist() == ["ground", "building", "building", "ignore"]
    write_point_cloud(tmp_path / "bad.ply", np.eye(2, 3), fields={"f": [0.5, 1.0]})
    with pytest.raises(
        PointCloudFileError, match=r"bad\.ply: field 'f' holds non-integer"
    ):
        read_point_labels(tmp_path / "bad.ply", "f")


def test_missing_field_names_the_file_and_what_it_has(tmp_path):
    path = tmp_path / "c.ply"
    write_point_cloud(path, np.eye(3), fields={"intensity": [1, 2, 3]})
    with pytest.raises(
        PointCloudFileError, match=r"c\.ply: no field 'label'.*intensity"
    ):
        read_point_labels(path, "label")


def test_class_map_by_name_and_errors(tmp_path):
    path = _las(tmp_path / "s.las", np.array([2, 5, 4, 1], np.uint8))
    (tmp_path / "m.csv").write_text(
        "high vegetation,tree\nmedium vegetation,tree\n1,ignore\n"
    )
    assert read_point_labels(path, class_map=tmp_path / "m.csv").labels.tolist() == [
        "ground",
        "tree",
        "tree",
        "ignore",
    ]
    bad = {
        "big.csv": ("300,x\n", "class code 300 cannot occur: the field holds 0 to 255"),
        "neg.csv": ("-2,x\n", "line 1: class code -2 is negative"),
        "float.csv": ("2.5,x\n", "line 1: class code '2.5' is not an integer"),
        "twice.csv": ("2,a\n2,b\n", "line 2: 2 is mapped twice"),
        "three.csv": ("2,a,b\n", "line 1: expected 'code,name'"),
        "empty.csv": ("code,name\n", "the class map has no code,name row"),
    }
    for name, (text, message) in bad.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(PointCloudFileError, match=re.escape(f"{name}: {message}")):
            read_point_labels(path, class_map=tmp_path / name)
    with pytest.raises(MissingFileError, match=r"nothere\.csv"):
        read_class_map(tmp_path / "nothere.csv")


def _kitti_layout(root, real_labelled, names):
    """Real sweeps written as SemanticKITTI ships them: sequences/NN/velodyne
    and labels; returns the points and raw labels of each."""
    out = []
    for k, name in enumerate(names):
        las = laspy.read(real_labelled(name))
        seq = root / "sequences" / f"{k:02d}"
        (seq / "velodyne").mkdir(parents=True)
        (seq / "labels").mkdir()
        xyz = np.column_stack([las.x, las.y, las.z]).astype(np.float32)
        cloud = np.column_stack([xyz, np.asarray(las.intensity) / 65535]).astype("<f4")
        cloud.tofile(seq / "velodyne" / "000000.bin")
        instance = np.asarray(las.instance, np.uint32)
        raw = np.where(instance > 0, instance, np.asarray(las.semantic, np.uint32))
        raw.astype("<u4").tofile(seq / "labels" / "000000.label")
        out.append((xyz, np.asarray(las.semantic), instance))
    return out


def test_semantickitti_bin_and_label_real(tmp_path, real_labelled):
    truth = _kitti_layout(
        tmp_path, real_labelled, [KITTI, "semantickitti_05_000000.laz"]
    )
    for name in ("calib.txt", "poses.txt", "times.txt"):  # as SemanticKITTI has
        (tmp_path / "sequences" / "01" / name).write_text("0 0 0\n")
    scans = labelled_scan_paths([tmp_path / "sequences"])
    assert [p.relative_to(tmp_path).as_posix() for p in scans] == [
        "sequences/00/velodyne/000000.bin",
        "sequences/01/velodyne/000000.bin",
    ]
    assert labelled_scan_paths([tmp_path / "sequences" / "01"]) == scans[1:]
    for path, (xyz, semantic, instance) in zip(scans, truth):
        scan = read_point_labels(path)
        np.testing.assert_array_equal(scan.points, xyz.astype(np.float64))
        np.testing.assert_array_equal(scan.codes, semantic)
        expected = np.array([SEMANTICKITTI_NAMES[c] for c in semantic], object)
        np.testing.assert_array_equal(scan.labels, expected)
        np.testing.assert_array_equal(scan.instances, instance)
        assert len(np.unique(instance[instance > 0])) >= 5  # cars, people...
    points, extras = read_point_cloud(scans[0], fields=["intensity"])
    assert points.shape == truth[0][0].shape and extras["intensity"].max() <= 1


def test_kitti_bin_round_trip(tmp_path):
    """x, y, z and intensity as float32 records; nothing else fits."""
    xyz = np.array([[1.5, -2.25, 0.125], [3.0, 4.0, -1.75]])
    write_point_cloud(tmp_path / "s.bin", xyz, fields={"intensity": [0.5, 0.25]})
    assert (tmp_path / "s.bin").stat().st_size == 32
    points, extras = read_point_cloud(tmp_path / "s.bin", fields=["intensity"])
    np.testing.assert_array_equal(points, xyz)
    np.testing.assert_array_equal(extras["intensity"], [0.5, 0.25])
    with pytest.raises(ValueError, match="holds x, y, z and intensity only"):
        write_point_cloud(tmp_path / "t.bin", xyz, fields={"label": [1, 2]})
    assert not (tmp_path / "t.bin").exists()


def test_label_length_must_match_its_scan(tmp_path):
    np.zeros((5, 4), "<f4").tofile(tmp_path / "a.bin")
    np.zeros(4, "<u4").tofile(tmp_path / "a.label")
    with pytest.raises(
        PointCloudFileError,
        match=r"a\.label: holds 4 labels but its scan a\.bin has 5 points",
    ):
        read_point_labels(tmp_path / "a.bin")
    (tmp_path / "b.bin").write_bytes(b"\0" * 17)
    with pytest.raises(
        PointCloudFileError, match=r"b\.bin: .*17 bytes are not a multiple of 16"
    ):
        read_point_cloud(tmp_path / "b.bin")
    np.zeros((2, 4), "<f4").tofile(tmp_path / "c.bin")
    with pytest.raises(MissingFileError, match=r"c\.label: no \.label file for"):
        read_point_labels(tmp_path / "c.bin")
    (tmp_path / "empty").mkdir()
    with pytest.raises(MissingFileError, match="empty: holds no labelled scan"):
        labelled_scan_paths([tmp_path / "empty"])


def test_real_sweeps_box_labels(real_sweeps):
    """The real_mobile sweeps: SemanticKITTI codes of their boxes in
    ``semantic``, one object per box in ``instance``."""
    for path in real_sweeps[:3]:
        las = laspy.read(path)
        scan = read_point_labels(path, "semantic", class_map="semantickitti")
        np.testing.assert_array_equal(scan.codes, np.asarray(las.semantic))
        np.testing.assert_array_equal(scan.instances, np.asarray(las.instance))
        assert (scan.ignored == (np.asarray(las.semantic) == 0)).all()
        assert {"car", "person"} & set(scan.labels)


def test_real_labelled_pandaset(real_labelled):
    scan = read_point_labels(
        real_labelled(PANDASET), "semantic", class_map="semantickitti"
    )
    counts = dict(zip(*np.unique(scan.labels, return_counts=True)))
    # the README's per-scan table: car 14378, building 26387, vegetation 14321
    assert (counts["car"], counts["building"], counts["vegetation"]) == (
        14378,
        26387,
        14321,
    )
    assert counts["ignore"] == 728 and scan.instances is not None
