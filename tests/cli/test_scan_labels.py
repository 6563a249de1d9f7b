"""``skpcd fit SCANS --labels-from FIELD`` and ``skpcd score-scan`` on real
sweeps labelled point by point (SemanticKITTI and PandaSet), and the
objects ``objects_from_labelled_scans`` cuts from them."""

import csv
import json
import re
import shutil

import laspy
import numpy as np
import pytest

from skpcd.cli import main
from skpcd.datasets import objects_from_labelled_scans
from skpcd.io import (
    read_point_cloud,
    read_point_labels,
    read_predicted_labels,
    write_point_cloud,
)

TRAIN = ["semantickitti_05_000000.laz", "semantickitti_07_000000.laz"]
TEST = "semantickitti_04_000000.laz"
STREET_MAP = (
    "code,name\n0,ignore\n1,ignore\n10,car\n252,car\n18,car\n13,car\n20,car\n"
    "30,person\n254,person\n31,person\n40,ground\n44,ground\n48,ground\n"
    "49,ground\n60,ground\n72,ground\n50,building\n51,fence\n52,other\n"
    "70,vegetation\n71,vegetation\n80,pole\n81,traffic_sign\n99,other\n"
    "facade,building\n"
)


@pytest.fixture(scope="module")
def fitted(real_labelled, tmp_path_factory):
    """A model fitted on two real SemanticKITTI sweeps, the third sweep
    labelled by it, and the class map."""
    folder = tmp_path_factory.mktemp("scan_labels")
    (folder / "map.csv").write_text(STREET_MAP)
    scans = [str(real_labelled(n)) for n in TRAIN]
    model, out = folder / "kitti.skpcd", folder / "labelled.laz"
    status = main(
        [
            "fit",
            *scans,
            "--labels-from",
            "semantic",
            "--class-map",
            str(folder / "map.csv"),
            "-o",
            str(model),
            "--quiet",
        ]
    )
    assert status == 0
    test = real_labelled(TEST)
    assert (
        main(["identify", str(test), "--model", str(model), "-o", str(out), "--quiet"])
        == 0
    )
    return folder, model, out, test


def test_fit_says_what_it_cut(real_labelled, tmp_path, capsys):
    (tmp_path / "map.csv").write_text(STREET_MAP)
    main(
        [
            "fit",
            str(real_labelled(TRAIN[0])),
            "--labels-from",
            "semantic",
            "--class-map",
            str(tmp_path / "map.csv"),
            "-o",
            str(tmp_path / "m.skpcd"),
        ]
    )
    out = capsys.readouterr().out
    assert "objects   " in out and " by instance, " in out and "purity median" in out
    assert "left out" in out and (tmp_path / "m.skpcd").is_file()


def _score_semantic(folder, out, *extra):
    """``skpcd score-scan`` of the labelled sweep against its ``semantic``
    dimension, through the street map; the command's status."""
    argv = ["score-scan", str(out), "--truth", "semantic", "--map"]
    return main([*argv, str(folder / "map.csv"), *map(str, extra)])


def test_identify_then_score_scan(fitted, capsys):
    folder, _, out, test = fitted
    report = folder / "report.json"
    assert _score_semantic(folder, out, "-o", report) == 0
    text = capsys.readouterr().out
    assert "mIoU" in text and "confusion matrix, share of each true class" in text
    numbers = json.loads(report.read_text())
    pooled = numbers["pooled"]
    truth = read_point_labels(test, "semantic", class_map=folder / "map.csv")
    assert pooled["n_points"] == int((~truth.ignored).sum())
    assert set(pooled["classes"]) == set(np.unique(truth.labels)) - {"ignore"}
    # a model of the same sensor labels the ground and the cars of another
    # sweep (measured: 0.97 and 0.25; cars by chance would be 0.02)
    assert pooled["iou"]["ground"] > 0.8 and pooled["iou"]["car"] > 0.15
    assert pooled["miou"] == pytest.approx(np.mean(list(pooled["iou"].values())))
    # the same through the CSV report
    assert _score_semantic(folder, out, "-o", folder / "r.csv", "--quiet") == 0
    rows = list(csv.DictReader(open(folder / "r.csv")))
    car = next(r for r in rows if r["class"] == "car" and r["scan"] != "(pooled)")
    assert float(car["iou"]) == pytest.approx(pooled["iou"]["car"], abs=1e-6)


def test_several_scans_are_pooled(fitted, tmp_path, capsys):
    """Two scans: one line each, and scores over all their points (here the
    same scan twice: the IoU of one, twice the points)."""
    folder, _, out, _ = fitted
    copy = tmp_path / "copy.laz"
    copy.write_bytes(out.read_bytes())
    report = tmp_path / "two.json"
    argv = ["score-scan", str(out), str(copy), "--truth", "semantic", "--map"]
    assert main([*argv, str(folder / "map.csv"), "-o", str(report), "--quiet"]) == 0
    numbers = json.loads(report.read_text())
    one, two = numbers["scans"]
    assert one["iou"] == two["iou"] == numbers["pooled"]["iou"]
    assert numbers["pooled"]["n_points"] == 2 * one["n_points"]
    assert numbers["pooled"]["confusion"] == (2 * np.array(one["confusion"])).tolist()


def test_round_trip_scores_one(fitted, capsys):
    """identify -> score-scan against a truth file holding the prediction
    itself: IoU 1 for every class present."""
    folder, _, out, _ = fitted
    pred = read_predicted_labels(out)
    names, codes = np.unique(pred, return_inverse=True)
    points = read_point_cloud(out)
    truth = folder / "own.ply"
    write_point_cloud(truth, points, fields={"label": codes.astype(np.int32)})
    (folder / "own.csv").write_text("".join(f"{k},{n}\n" for k, n in enumerate(names)))
    status = main(
        [
            "score-scan",
            str(out),
            "--truth",
            str(truth),
            "--truth-from",
            "label",
            "--map",
            str(folder / "own.csv"),
            "-o",
            str(folder / "own.json"),
        ]
    )
    assert status == 0
    pooled = json.loads((folder / "own.json").read_text())["pooled"]
    assert set(pooled["classes"]) == set(names) and len(names) >= 4
    assert all(v == 1.0 for v in pooled["iou"].values()) and pooled["accuracy"] == 1


def test_score_scan_warns_when_no_class_is_shared(fitted, capsys):
    """The scan's own codes against skpcd's names: every IoU 0, said in one
    line; the original classification kept by identify gets ASPRS names."""
    _, _, out, _ = fitted
    assert main(["score-scan", str(out), "--truth", "semantic", "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search("no true class .* is a predicted class", err[0])
    truth = read_point_labels(out, "original_classification")
    assert set(truth.labels) == {"never classified"}  # the sweep's classification is 0


def _fails(capsys, pattern, argv):
    """The command ends with a one-line error matching ``pattern`` (status 1
    for a file at fault, SystemExit for a command that cannot run)."""
    try:
        status = main(argv)
    except SystemExit as exc:
        message = str(exc)
    else:
        assert status == 1
        message = capsys.readouterr().err
    assert re.search(pattern, message), message
    assert len(message.strip().splitlines()) == 1


def test_score_scan_errors(fitted, real_labelled, tmp_path, capsys):
    folder, _, out, _ = fitted
    other = real_labelled("semantickitti_05_000000.laz")
    _fails(
        capsys,
        r"05_000000\.laz: holds 126956 points but "
        r"the prediction .*labelled\.laz holds 124231",
        ["score-scan", str(out), "--truth", str(other), "--truth-from", "semantic"],
    )
    _fails(
        capsys,
        r"labelled\.laz: no field 'semantik'",
        ["score-scan", str(out), "--truth", "semantik"],
    )
    _fails(
        capsys,
        "class 'bicycle' has no true point",
        [
            "score-scan",
            str(out),
            "--truth",
            "semantic",
            "--map",
            str(folder / "map.csv"),
            "--classes",
            "car,bicycle",
        ],
    )
    _fails(
        capsys,
        "1 PRED but 2 TRUTH files",
        ["score-scan", str(out), "--truth", str(other), str(other)],
    )
    _fails(
        capsys,
        "--labels names the labels of a folder",
        ["fit", str(other), "--labels", "x.csv", "-o", str(tmp_path / "m")],
    )
    _fails(
        capsys,
        "--min-purity must be within 0 and 1",
        ["fit", str(other), "--min-purity", "2", "-o", str(tmp_path / "m")],
    )
    # nothing was written by the failures
    assert not list(tmp_path.iterdir())


def test_objects_cut_by_instance_and_segment(real_labelled):
    path = real_labelled(TRAIN[1])
    found = objects_from_labelled_scans(
        [path], "semantic", class_map="semantickitti", min_purity=0.8
    )
    las = laspy.read(path)
    instance = np.asarray(las.instance)
    by_instance = found.cut == "instance"
    assert by_instance.sum() >= 10 and (~by_instance).sum() >= 10
    # an object with an id is exactly the points of that id
    xyz = np.column_stack([las.x, las.y, las.z])
    objects = {
        tuple(np.sort(xyz[instance == i], axis=0).ravel()): i
        for i in np.unique(instance[instance > 0])
    }
    cut = [c for c, i in zip(found.clouds, by_instance) if i]
    assert all(tuple(np.sort(c, axis=0).ravel()) in objects for c in cut)
    assert (found.purity >= 0.8).all() and (found.n_points >= 50).all()
    assert not set(found.labels) & {"road", "sidewalk", "terrain", "parking"}
    assert {"car", "building", "vegetation"} <= set(found.labels)
    assert (found.scan == 0).all() and found.left_out["ground"] > 0
    clouds, labels = objects_from_labelled_scans(
        [path], "semantic", class_map="semantickitti", return_X_y=True
    )
    assert len(clouds) == len(labels) >= len(found.clouds)


def test_fit_reads_a_semantickitti_folder(real_labelled, tmp_path, capsys):
    """``skpcd fit sequences/`` with SemanticKITTI's layout: the .bin scans
    and their .label files, the built-in map."""
    las = laspy.read(real_labelled(TRAIN[0]))
    seq = tmp_path / "sequences" / "05"
    (seq / "velodyne").mkdir(parents=True)
    (seq / "labels").mkdir()
    xyz = np.column_stack([las.x, las.y, las.z, np.zeros(len(las.x))])
    xyz.astype("<f4").tofile(seq / "velodyne" / "000000.bin")
    instance = np.asarray(las.instance, np.uint32)
    raw = np.where(instance > 0, instance, np.asarray(las.semantic, np.uint32))
    raw.astype("<u4").tofile(seq / "labels" / "000000.label")
    shutil.copy(seq / "velodyne" / "000000.bin", tmp_path / "lonely.bin")
    assert (
        main(
            [
                "fit",
                str(tmp_path / "sequences"),
                "--class-map",
                "semantickitti",
                "-o",
                str(tmp_path / "m.skpcd"),
            ]
        )
        == 0
    )
    assert "from 1 scans" in capsys.readouterr().out
    _fails(
        capsys,
        r"lonely\.label: no \.label file",
        ["fit", str(tmp_path / "lonely.bin"), "-o", str(tmp_path / "n.skpcd")],
    )


@pytest.mark.slow
def test_fit_scans_with_simulation(real_labelled, tmp_path, capsys):
    """``--simulate`` completes the objects of labelled scans as it does a
    folder's: simulated objects of the classes the simulator knows."""
    (tmp_path / "map.csv").write_text(STREET_MAP)
    status = main(
        [
            "fit",
            str(real_labelled(TRAIN[0])),
            "--labels-from",
            "semantic",
            "--class-map",
            str(tmp_path / "map.csv"),
            "--simulate",
            "2",
            "--scanner",
            "spinning",
            "-o",
            str(tmp_path / "m.skpcd"),
        ]
    )
    assert status == 0
    out = capsys.readouterr().out
    simulated = next(line for line in out.splitlines() if line.startswith("simulated"))
    assert "car" in simulated and "traffic_sign" in simulated
