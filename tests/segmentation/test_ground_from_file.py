"""The ground a scan already carries (``ground="from-file"``,
``--ground from-file``): on a real sweep whose classification marks the
ground skpcd computed, the segments are those of computing it, in memory,
in tiles and from the CLI."""

import warnings
from pathlib import Path

import laspy
import numpy as np
import pytest

from skpcd.cli import main
from skpcd.exceptions import PointCloudFileError, SegmentationWarning
from skpcd.io import read_point_cloud, read_segments, write_point_cloud
from skpcd.segmentation import segment_scene
from skpcd.segmentation.ground import ClassifiedGround

SWEEP = Path("/work/shared/data/real_mobile/scans/pandaset_000200.las")
pytestmark = pytest.mark.skipif(not SWEEP.exists(), reason="real sweeps not here")


def _classified_copy(path, classification):
    """The sweep with its classification replaced (every other dimension,
    the header and its VLRs as they were)."""
    las = laspy.read(SWEEP)
    las.classification = classification
    las.write(path)
    return path


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """The sweep segmented with the ground computed (SMRF, "mobile"), and
    copies whose classification holds that ground: as class 2 (1 elsewhere),
    and split between classes 2 and 8."""
    folder = tmp_path_factory.mktemp("from_file")
    computed = segment_scene(SWEEP, ground="mobile", structures=False)
    assert 10_000 < computed.ground.sum() < len(computed.ground) - 10_000
    cls = np.where(computed.ground, 2, 1).astype(np.uint8)
    split = cls.copy()
    ground = np.flatnonzero(computed.ground)
    split[ground[::2]] = 8
    return {
        "computed": computed,
        "class2": _classified_copy(folder / "class2.las", cls),
        "split": _classified_copy(folder / "split.las", split),
        "folder": folder,
    }


def _same(a, b):
    np.testing.assert_array_equal(a.ground, b.ground)
    np.testing.assert_array_equal(a.labels, b.labels)
    assert a.eps == b.eps
    assert a.n_segments > 20


def test_from_file_gives_the_segments_of_the_computed_ground(sweep):
    got = segment_scene(sweep["class2"], ground="from-file", structures=False)
    _same(got, sweep["computed"])
    assert got.ground_filter == "from-file"


def test_from_file_on_tiles_gives_the_same_segments(sweep):
    got = segment_scene(
        sweep["class2"], ground="from-file", structures=False, tile_size=30
    )
    _same(got, sweep["computed"])
    assert got.ground_filter == "from-file"


def test_from_file_with_the_structures_step(sweep):
    computed = segment_scene(SWEEP, ground="mobile")
    got = segment_scene(sweep["class2"], ground="from-file")
    _same(got, computed)
    assert list(got.kinds) == list(computed.kinds)


def test_other_ground_codes(sweep):
    both = ClassifiedGround(codes=(8, 2))
    assert both.codes == (2, 8)
    _same(
        segment_scene(sweep["split"], ground=both, structures=False), sweep["computed"]
    )
    tiled = segment_scene(sweep["split"], ground=both, structures=False, tile_size=30)
    _same(tiled, sweep["computed"])
    # class 2 alone is half the ground
    half = segment_scene(sweep["split"], ground="from-file", structures=False)
    assert half.ground.sum() == (sweep["computed"].ground.sum() + 1) // 2


def test_ground_flags_given_outright(sweep):
    points = read_point_cloud(SWEEP)
    flags = sweep["computed"].ground
    _same(segment_scene(points, ground=flags, structures=False), sweep["computed"])
    tiled = segment_scene(points, ground=flags, structures=False, tile_size=30)
    _same(tiled, sweep["computed"])
    assert tiled.ground_filter is None


def test_a_scan_without_classification_is_one_clear_error(tmp_path):
    path = tmp_path / "plain.xyz"
    write_point_cloud(path, np.random.default_rng(0).uniform(0, 10, (200, 3)))
    for tiling in ({}, {"tile_size": 5.0}):
        with pytest.raises(PointCloudFileError, match="no classification field") as e:
            segment_scene(path, ground="from-file", structures=False, **tiling)
        assert str(path) in str(e.value) and "\n" not in str(e.value)


def test_from_file_needs_a_file_and_flags_need_one_per_point():
    xyz = np.random.default_rng(0).uniform(0, 10, (50, 3))
    with pytest.raises(ValueError, match="the points are an array: pass the file"):
        segment_scene(xyz, ground="from-file")
    with pytest.raises(ValueError, match="hold 49 values for 50 points"):
        segment_scene(xyz, ground=np.zeros(49, dtype=bool))
    with pytest.raises(ValueError, match="hold 49 values for 50 points"):
        segment_scene(xyz, ground=np.zeros(49, dtype=bool), tile_size=5.0)
    with pytest.raises(ValueError, match="must be a boolean array"):
        segment_scene(xyz, ground=np.zeros(50))
    for bad in ([], [256], [-1], ["2"], 2.5):
        with pytest.raises(ValueError, match="ground codes must be integers"):
            ClassifiedGround(codes=bad)


def test_a_classification_without_those_codes_warns(tmp_path):
    path = tmp_path / "classified.ply"
    xyz = np.random.default_rng(0).uniform(0, 10, (300, 3))
    write_point_cloud(path, xyz, fields={"Classification": np.full(300, 1.0)})
    for tiling in ({}, {"tile_size": 5.0, "eps": 1.0}):
        with pytest.warns(SegmentationWarning, match="no point has classification 2"):
            seg = segment_scene(path, ground="from-file", structures=False, **tiling)
        assert not seg.ground.any()
    # PDAL's name, Classification (and its float type in PCD files), is found
    write_point_cloud(
        path, xyz, fields={"Classification": np.where(xyz[:, 2] < 1, 2.0, 1.0)},
        overwrite=True,
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error", SegmentationWarning)
        seg = segment_scene(path, ground="from-file", structures=False)
    np.testing.assert_array_equal(seg.ground, xyz[:, 2] < 1)


def test_cli_ground_from_file(sweep, capsys):
    folder = sweep["folder"]
    n_ground = int(sweep["computed"].ground.sum())
    n_seg = sweep["computed"].n_segments
    base = ["--no-structures", "--quiet", "--format", "xyz"]
    assert main(["segment", str(SWEEP), "-o", str(folder / "computed"),
                 "--ground", "mobile", *base]) == 0  # fmt: skip
    for name, extra in (
        ("mem", []),
        ("tiles", ["--tile-size", "30"]),
    ):
        out = folder / name
        argv = ["segment", str(sweep["split"]), "-o", str(out), "--ground",
                "from-file", "--ground-codes", "2,8", *base, *extra]  # fmt: skip
        assert main(argv) == 0
        clouds, _, names = read_segments(str(out / "*.xyz"))
        want, _, want_names = read_segments(str(folder / "computed" / "*.xyz"))
        assert len(clouds) == n_seg and names == want_names
        for a, b in zip(clouds, want):
            np.testing.assert_array_equal(a, b)
    capsys.readouterr()
    assert main(["segment", str(sweep["class2"]), "-o", str(folder / "c2"),
                 "--ground", "from-file", "--no-structures"]) == 0  # fmt: skip
    assert f"{n_ground} ground" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["segment", str(SWEEP), "-o", str(folder / "bad"), "--ground",
              "from-file", "--ground-codes", "2,x"])  # fmt: skip
    assert "expected classification codes 0 to 255" in capsys.readouterr().err


def test_cli_scan_without_classification(tmp_path, capsys):
    path = tmp_path / "plain.xyz"
    write_point_cloud(path, np.random.default_rng(0).uniform(0, 10, (200, 3)))
    for extra in ([], ["--tile-size", "5"]):
        argv = ["segment", str(path), "-o", str(tmp_path / "s"), "--ground",
                "from-file", *extra]  # fmt: skip
        try:  # a file error (exit 1) or a command error (SystemExit)
            assert main(argv) == 1
            message = capsys.readouterr().err
        except SystemExit as exc:
            message = str(exc.code)
        assert str(path) in message and "no classification field" in message
        assert len(message.strip().splitlines()) == 1
        assert not (tmp_path / "s").exists() or not any((tmp_path / "s").iterdir())
