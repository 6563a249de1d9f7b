"""A real-format scan through the CLI: a LAS file with ASPRS classes and an
extra dimension through segment, fit (default and case-based), identify
(in memory and tiled) and predict."""

import csv

import laspy
import numpy as np
import pytest

from skpcd.cli import main
from skpcd.io import read_class_names, write_point_cloud


def _las_scene(path, random_state=0):
    """Synthetic urban objects on a terrain as a LAS 1.4 file (point format
    6) with ASPRS classes and a float32 ``reflectance`` extra dimension."""
    from skpcd.datasets import make_urban_objects
    from skpcd.segmentation import make_scene

    clouds, labels = make_urban_objects(n_per_class=2, random_state=random_state)
    points, truth = make_scene(clouds, gap=3.0, random_state=random_state)
    rng = np.random.default_rng(random_state)
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = points.min(axis=0)
    header.scales = [0.001] * 3
    header.add_extra_dims([laspy.ExtraBytesParams("reflectance", np.float32)])
    las = laspy.LasData(header)
    las.x, las.y, las.z = points.T
    las.classification = np.where(truth < 0, 2, rng.choice([1, 5, 6], len(points)))
    las.intensity = rng.integers(0, 65535, len(points))
    las.reflectance = rng.normal(size=len(points)).astype(np.float32)
    las.write(path)
    return laspy.read(path), truth, labels


def _train(folder, classes=None):
    from skpcd.datasets import make_urban_objects

    clouds, labels = make_urban_objects(n_per_class=6, random_state=1)
    folder.mkdir()
    rows = ["file,label"]
    for i, (c, y) in enumerate(zip(clouds, labels)):
        if classes is None or y in classes:
            write_point_cloud(folder / f"{i:03d}.xyz", c)
            rows.append(f"{i:03d}.xyz,{y}")
    (folder / "labels.csv").write_text("\n".join(rows))


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    root = tmp_path_factory.mktemp("models")
    _train(root / "all")
    _train(root / "cars", classes={"car"})
    default, cases = root / "default.joblib", root / "cases.joblib"
    assert main(["fit", str(root / "all"), "-o", str(default), "--quiet"]) == 0
    argv = ["fit", str(root / "cars"), "-o", str(cases), "--pipeline", "case-based"]
    assert main([*argv, "--quiet"]) == 0
    return {"default": default, "case-based": cases}


def _identify(scene, model, out, *extra):
    argv = ["identify", str(scene), "--model", str(model), "-o", str(out)]
    return main([*argv, "--eps", "1.0", "--min-size", "30", "--quiet", *extra])


@pytest.mark.parametrize("pipeline", ["default", "case-based"])
def test_identify_keeps_every_dimension_of_the_scan(tmp_path, models, pipeline):
    # before: the case-based model crashed with KeyError 'unknown', and the
    # default one wrote classification 0 everywhere and lost reflectance
    scene = tmp_path / "scene.las"
    source, truth, _ = _las_scene(scene)
    out = tmp_path / "labelled.laz"
    assert _identify(scene, models[pipeline], out) == 0
    las = laspy.read(out)
    assert len(las.points) == len(source.points)
    for dim in source.point_format.dimension_names:
        if dim != "classification":
            np.testing.assert_array_equal(las[dim], source[dim], err_msg=dim)
    ground = np.asarray(las["ground"]).astype(bool)
    assert ground[truth < 0].mean() > 0.95
    np.testing.assert_array_equal(las.classification[ground], 2)
    # the classes went into classification; the input's is kept beside
    np.testing.assert_array_equal(las["original_classification"], source.classification)
    segment, code = np.asarray(las["segment"]), np.asarray(las["class"])
    assert segment.max() >= 5 and ((segment < 0) == (code == 0)).all()
    names = read_class_names(out)  # the codes of the class dimension
    legend = list(csv.DictReader(open(f"{out}.classes.csv")))
    rows = [r for r in legend if int(r["class"]) >= 0]
    # the side file names the codes of classification, as its lookup does,
    # and apart those of the class dimension
    assert {int(r["class_code"]): r["name"] for r in rows} == names
    (table,) = [
        v for v in las.vlrs if isinstance(v, laspy.vlrs.known.ClassificationLookupVlr)
    ]
    lookup = dict(table.lookups)
    # (unknown is ASPRS 1, unclassified; the lookup names 1 and 2 as ASPRS)
    assert {
        int(r["classification"]): r["name"][:15] for r in rows if r["name"] != "unknown"
    } == {c: lookup[c] for c in lookup if c not in (1, 2)}
    by_code = {int(r["class_code"]): int(r["classification"]) for r in rows}
    segmented = segment >= 0
    assert [by_code[c] for c in code[segmented]] == las.classification[
        segmented
    ].tolist()
    assert set(np.unique(code[segmented])) <= set(names)
    score = "similarity" if pipeline == "case-based" else "probability"
    assert np.isfinite(las[score][segment >= 0]).all()
    if pipeline == "case-based":  # trained on cars only: the rest is unknown
        answered = {names[c] for c in np.unique(code[segment >= 0])}
        assert "unknown" in answered and answered <= {"car", "unknown"}


def test_identify_tiled_writes_the_same_file_content(tmp_path, models):
    scene = tmp_path / "scene.las"
    _las_scene(scene)
    whole, tiled = tmp_path / "whole.las", tmp_path / "tiled.las"
    smrf = ("--ground", "aerial", "--no-structures")  # what tiles take
    assert _identify(scene, models["default"], whole, *smrf) == 0
    assert _identify(scene, models["default"], tiled, *smrf, "--tile-size", "15") == 0
    a, b = laspy.read(whole), laspy.read(tiled)
    for dim in a.point_format.dimension_names:
        np.testing.assert_array_equal(a[dim], b[dim], err_msg=dim)
    assert read_class_names(whole) == read_class_names(tiled)


def test_identify_side_file_is_named_after_the_whole_output(tmp_path, models):
    # before: -o labelled.ply was refused because labelled_classes.csv
    # existed from an earlier -o labelled.las
    scene = tmp_path / "scene.las"
    _las_scene(scene)
    for name in ("labelled.las", "labelled.ply"):
        assert _identify(scene, models["default"], tmp_path / name) == 0
        assert (tmp_path / f"{name}.classes.csv").is_file()
    with pytest.raises(SystemExit, match="exists; pass --overwrite"):
        _identify(scene, models["default"], tmp_path / "labelled.ply")
    out = tmp_path / "labelled.ply"
    assert _identify(scene, models["default"], out, "--overwrite") == 0
    with pytest.raises(SystemExit, match="is an input file"):
        _identify(scene, models["default"], scene, "--overwrite")


def test_identify_keep_fields_in_other_formats(tmp_path, models):
    from skpcd.io import read_point_cloud

    scene = tmp_path / "scene.las"
    source, _, _ = _las_scene(scene)
    out = tmp_path / "labelled.ply"
    assert _identify(scene, models["default"], out, "--keep-fields") == 0
    _, fields = read_point_cloud(out, fields="all")
    np.testing.assert_array_equal(fields["reflectance"], source.reflectance)
    assert {"segment", "class", "ground", "probability"} <= set(fields)


def test_an_interrupted_identify_leaves_nothing(tmp_path, models, monkeypatch):
    import skpcd.io

    scene = tmp_path / "scene.las"
    _las_scene(scene)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(skpcd.io, "write_labelled_scan", interrupted)
    out = tmp_path / "labelled.las"
    assert _identify(scene, models["default"], out) == 130
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.las"]


def test_segment_and_predict_a_las_scene(tmp_path, models):
    scene = tmp_path / "scene.las"
    source, _, _ = _las_scene(scene)
    segs = tmp_path / "segs"
    argv = ["segment", str(scene), "-o", str(segs), "--eps", "1.0", "--min-size", "30"]
    assert main([*argv, "--format", "las", "--keep-fields", "--quiet"]) == 0
    first = laspy.read(segs / "segment_0000.las")
    assert set(source.point_format.extra_dimension_names) <= set(
        first.point_format.extra_dimension_names
    )
    out = tmp_path / "p.csv"
    assert main(["predict", str(models["default"]), str(segs), "-o", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == len(list(segs.glob("segment_*.las")))
