import subprocess
import sys

import numpy as np
import pytest

from skpcd.cli import format_report, main
from skpcd.io import write_point_cloud


def test_info(tmp_path, capsys):
    path = tmp_path / "grid.ply"
    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(4.0), [1.0]), -1).reshape(-1, 3)
    write_point_cloud(path, 0.5 * g, fields={"intensity": np.arange(20.0)})
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "points    20" in out
    assert "fields    x y z intensity" in out
    assert "x         [0.0000, 2.0000]" in out
    assert "spacing   0.5000" in out


def test_info_bad_file_is_a_clean_error(tmp_path, capsys):
    path = tmp_path / "bad.xyz"
    path.write_text("1 2\n")
    assert main(["info", str(path)]) == 1
    err = capsys.readouterr().err
    assert "error" in err and str(path) in err and "Traceback" not in err


def test_evaluate_folder(tmp_path, capsys, labelled_folder):
    labelled_folder(tmp_path)
    assert main(["evaluate", str(tmp_path), "--folds", "3", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "30 segments, 5 classes" in out
    assert "precision" in out and "recall" in out
    assert "confusion matrix" in out
    for cls in ("building", "car", "fence", "pole", "tree"):
        assert cls in out


def test_evaluate_needs_enough_segments_per_class(tmp_path):
    for i in range(4):
        write_point_cloud(
            tmp_path / f"{i}.xyz", np.random.default_rng(i).normal(size=(20, 3))
        )
    (tmp_path / "labels.csv").write_text("0.xyz,a\n1.xyz,a\n2.xyz,b\n3.xyz,b\n")
    with pytest.raises(SystemExit, match="fewer than --folds 5"):
        main(["evaluate", str(tmp_path)])


def test_evaluate_street_data(capsys):
    argv = ["evaluate", "--data", "street", "--n-per-class", "3", "--folds", "2"]
    assert main([*argv, "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "data      street: street furniture from simulated mobile scans" in out
    assert "30 segments, 10 classes" in out
    for cls in ("street_light", "traffic_sign", "pedestrian_signal", "tree", "car"):
        assert cls in out
    assert "compiling" not in err  # --quiet (see tests/utils/test_compile.py)


def test_evaluate_urban_n_per_class(capsys):
    argv = ["evaluate", "--data", "urban", "--n-per-class", "4", "--folds", "2"]
    assert main([*argv, "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "data      urban: embedded synthetic urban objects" in out
    assert "20 segments, 5 classes" in out


@pytest.mark.parametrize(
    "options", [["--data", "street"], ["--n-per-class", "5"]], ids=["data", "n"]
)
def test_evaluate_simulated_data_options_need_no_folder(tmp_path, options):
    with pytest.raises(SystemExit, match="do not apply with a FOLDER"):
        main(["evaluate", str(tmp_path), *options])


def test_evaluate_n_per_class_must_be_positive():
    with pytest.raises(SystemExit, match="--n-per-class must be at least 1"):
        main(["evaluate", "--n-per-class", "0"])


def test_format_report_confusion_matrix():
    text = format_report(
        np.array(["a", "a", "b"]), np.array(["a", "b", "b"]), [1.0, 0.5]
    )
    assert "accuracy  0.7500 +/- 0.2500 over 2 folds" in text
    lines = text.splitlines()
    header = lines.index("confusion matrix (rows: true, columns: predicted)")
    assert lines[header + 2].split() == ["a", "1", "1"]
    assert lines[header + 3].split() == ["b", "0", "1"]


def test_console_entry_point_default_data_quiet_when_not_a_tty():
    proc = subprocess.run(
        [sys.executable, "-m", "skpcd", "evaluate", "--folds", "2"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "embedded synthetic urban objects" in proc.stdout
    assert "accuracy" in proc.stdout
    assert proc.stderr == ""  # no progress bar when not on a terminal


def test_fit_predict_describe_round_trip(tmp_path, capsys, labelled_folder):
    import csv

    train, test = tmp_path / "train", tmp_path / "test"
    labelled_folder(train, n_per_class=8, random_state=1)
    truth = labelled_folder(test, n_per_class=4, random_state=2)
    (test / "labels.csv").unlink()  # predict needs no labels
    model = tmp_path / "model.joblib"
    assert main(["fit", str(train), "-o", str(model)]) == 0  # --quiet: silent
    assert "40 segments, 5 classes" in capsys.readouterr().out
    out = tmp_path / "pred.csv"
    assert main(["predict", str(model), str(test), "-o", str(out), "--quiet"]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [r["file"] for r in rows] == [f"{i:03d}.xyz" for i in range(20)]
    probability = np.array([float(r["probability"]) for r in rows])
    assert ((probability > 0) & (probability <= 1)).all()
    accuracy = np.mean([r["label"] == y for r, y in zip(rows, truth)])
    assert accuracy >= 0.8  # synthetic classes are well separated

    npz = tmp_path / "d.npz"
    args = ["describe", str(train), "-o", str(npz), "--quiet", "--local", "fpfh"]
    assert main([*args, "--descriptors", "shape,overall,fpfh_mean"]) == 0
    d = np.load(npz)
    assert d["names"].tolist() == [f"{i:03d}.xyz" for i in range(40)]
    assert len(d["labels"]) == 40
    assert d["shape"].shape[0] == d["overall"].shape[0] == 40
    assert d["fpfh_mean"].shape == (40, 33)
    assert len(d["shape_columns"]) == d["shape"].shape[1]
    assert d["fpfh_offsets"][-1] == len(d["fpfh"]) and d["fpfh"].shape[1] == 33


def test_case_based_pipeline_fit_predict_gives_similarities(
    tmp_path, capsys, labelled_folder
):
    import csv

    from skpcd.io import load_model

    train, test = tmp_path / "train", tmp_path / "test"
    labelled_folder(train, n_per_class=8, random_state=1)
    truth = labelled_folder(test, n_per_class=4, random_state=2)
    model = tmp_path / "model.joblib"
    args = ["fit", str(train), "-o", str(model), "--pipeline", "case-based"]
    assert main([*args, "--quiet"]) == 0
    assert load_model(model)[-1].threshold == 0.8
    out = tmp_path / "pred.csv"
    assert main(["predict", str(model), str(test), "-o", str(out), "--quiet"]) == 0
    rows = list(csv.DictReader(out.open()))
    similarity = np.array([float(r["similarity"]) for r in rows])
    assert "probability" not in rows[0]
    assert ((similarity >= -1) & (similarity <= 1)).all()
    labels = np.array([r["label"] for r in rows])
    # below the paper's threshold a segment is "unknown", never a class
    assert (labels[similarity < 0.8] == "unknown").all()
    assert (labels[similarity >= 0.8] != "unknown").all()
    known = labels != "unknown"
    # 40 synthetic cases: about half the answers pass 0.8, 7 of those 9 right
    assert known.sum() >= 5
    assert np.mean(labels[known] == np.asarray(truth)[known]) >= 0.6
    capsys.readouterr()
    assert main(["evaluate", str(train), "--pipeline", "case-based", "--quiet"]) == 0
    assert "case-based: improved FPFH" in capsys.readouterr().out


def test_outputs_are_never_overwritten_without_asking(
    tmp_path, capsys, labelled_folder
):
    labelled_folder(tmp_path / "seg", n_per_class=3)
    model = tmp_path / "model.joblib"
    model.write_text("precious")
    with pytest.raises(SystemExit, match="exists; pass --overwrite"):
        main(["fit", str(tmp_path / "seg"), "-o", str(model)])
    assert model.read_text() == "precious"
    npz = tmp_path / "d.npz"
    npz.write_text("precious")
    with pytest.raises(SystemExit, match="exists"):
        main(["describe", str(tmp_path / "seg"), "-o", str(npz)])
    assert npz.read_text() == "precious"


def test_describe_unknown_descriptor(tmp_path, labelled_folder):
    labelled_folder(tmp_path, n_per_class=1)
    with pytest.raises(SystemExit, match=r"unknown descriptor.*bogus"):
        main(["describe", str(tmp_path), "-o", str(tmp_path / "x.npz"),
              "--descriptors", "shape,bogus"])  # fmt: skip


def test_predict_with_a_bad_model_file_is_a_clean_error(
    tmp_path, capsys, labelled_folder
):
    labelled_folder(tmp_path / "seg", n_per_class=1)
    bad = tmp_path / "model.joblib"
    bad.write_bytes(b"not a pickle")
    out = tmp_path / "p.csv"
    assert main(["predict", str(bad), str(tmp_path / "seg"), "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "not a model file" in err and "Traceback" not in err
    assert not out.exists()


# --- skpcd segment / skpcd identify -------------------------------------------


def test_segment_writes_one_file_per_segment_and_a_summary(
    tmp_path, capsys, scene_file
):
    import csv

    from skpcd.io import read_point_cloud, read_segments

    scene = tmp_path / "scene.ply"
    points, truth, _ = scene_file(scene)
    out = tmp_path / "segs"
    args = ["segment", str(scene), "-o", str(out), "--eps", "1.0", "--min-size", "30"]
    # SMRF: on this rolling synthetic terrain CSF leaves a few ground points
    # at the foot of the pole and a fence (the segments must be pure here)
    args += ["--ground", "aerial"]
    assert main([*args, "--keep-fields"]) == 0
    assert "segments  10 " in capsys.readouterr().out
    rows = list(csv.DictReader((out / "segments.csv").open()))
    assert len(rows) == 10
    assert {r["type"] for r in rows} == {"object"}  # no facade, no wire here
    clouds, _, names = read_segments(str(out / "*.ply"))
    assert names == [r["file"] for r in rows]
    for row, cloud in zip(rows, clouds):
        assert int(row["n_points"]) == len(cloud)
        np.testing.assert_allclose(
            [float(row[f"extent_{c}"]) for c in "xyz"], np.ptp(cloud, axis=0), atol=1e-3
        )
    # every segment is one object, whole above the ground threshold
    first, extras = read_point_cloud(out / rows[0]["file"], fields=["intensity"])
    objects = truth[extras["intensity"].astype(int)]
    assert len(np.unique(objects)) == 1 and objects[0] >= 0
    np.testing.assert_allclose(
        first, points[extras["intensity"].astype(int)], atol=1e-4
    )
    # never overwritten without asking; other formats on demand
    before = (out / rows[0]["file"]).read_bytes()
    with pytest.raises(SystemExit, match="--overwrite"):
        main(args)
    assert (out / rows[0]["file"]).read_bytes() == before
    assert main([*args, "--overwrite", "--quiet", "--format", "xyz"]) == 0
    assert capsys.readouterr().out == ""
    assert len(list(out.glob("*.xyz"))) == 10


def test_identify_writes_the_labelled_scene(
    tmp_path, capsys, labelled_folder, scene_file
):
    import csv

    from skpcd.io import read_point_cloud

    labelled_folder(tmp_path / "train", n_per_class=8)
    model = tmp_path / "model.joblib"
    assert main(["fit", str(tmp_path / "train"), "-o", str(model), "--quiet"]) == 0
    scene = tmp_path / "scene.pcd"
    points, truth, labels = scene_file(scene, random_state=3)
    out = tmp_path / "labelled.ply"
    args = ["identify", str(scene), "--model", str(model), "-o", str(out)]
    assert main([*args, "--eps", "1.0", "--min-size", "30"]) == 0
    assert "classes   " in capsys.readouterr().out
    xyz, f = read_point_cloud(out, fields=["segment", "class", "ground", "probability"])
    np.testing.assert_allclose(xyz, points, atol=1e-3)
    segment, cls = f["segment"].astype(int), f["class"].astype(int)
    assert ((segment < 0) == (cls < 0)).all()
    assert f["ground"][truth == -1].mean() > 0.99
    legend = list(csv.DictReader((tmp_path / "labelled.ply.classes.csv").open()))
    names = {int(r["class"]): r["name"] for r in legend}
    assert names[-1] == "(no segment)"
    assert sorted(v for k, v in names.items() if k >= 0) == sorted(set(labels))
    # the synthetic objects are told apart: most segments get their class
    right = []
    for s in range(segment.max() + 1):
        objects, counts = np.unique(truth[segment == s], return_counts=True)
        right.append(names[cls[segment == s][0]] == labels[objects[counts.argmax()]])
    assert np.mean(right) >= 0.8
    p = f["probability"][segment >= 0]
    assert ((p > 0) & (p <= 1)).all()
    with pytest.raises(SystemExit, match="exists; pass --overwrite"):
        main(args)


def test_segment_eps_scale_sets_the_estimated_radius(tmp_path, capsys, scene_file):
    import re

    scene = tmp_path / "scene.ply"
    scene_file(scene)
    eps = {}
    for scale in ("1", "2.5"):
        out = tmp_path / f"segs{scale}"
        args = ["segment", str(scene), "-o", str(out), "--eps-scale", scale]
        assert main(args) == 0
        printed = capsys.readouterr().out
        eps[scale] = float(re.search(r"eps ([0-9.]+)\)", printed).group(1))
    assert eps["2.5"] == pytest.approx(2.5 * eps["1"], abs=2e-3)


def test_segment_and_identify_bad_inputs(tmp_path, capsys):
    assert main(["segment", str(tmp_path / "missing.ply"), "-o", str(tmp_path)]) == 1
    assert "error" in capsys.readouterr().err
    bad = tmp_path / "bad.xyz"
    bad.write_text("0 0 0\n")
    model = tmp_path / "model.joblib"
    model.write_text("not a model")
    out = tmp_path / "o.ply"
    assert main(["identify", str(bad), "--model", str(model), "-o", str(out)]) == 1
    assert not out.exists()
    with pytest.raises(SystemExit, match="not a folder"):
        main(["segment", str(bad), "-o", str(bad)])


# --- bad arguments of fit, predict, describe and evaluate ------------------------


@pytest.mark.parametrize("command", ["fit", "describe", "predict"])
def test_output_folder_problems_are_found_before_any_work(
    tmp_path, command, labelled_folder
):
    # before: a FileNotFoundError/IsADirectoryError after fitting or computing
    # the descriptors (describe also left a .tmp.npz behind)
    labelled_folder(tmp_path / "seg", n_per_class=1)
    model = tmp_path / "model.joblib"
    model.write_text("never read")
    first = {"predict": [str(model)]}.get(command, [])
    for out, message in [
        (
            tmp_path / "missing" / "out.x",
            "the folder .*missing of out.x does not exist",
        ),
        (tmp_path / "seg", "is a folder; give a file name"),
    ]:
        argv = [command, *first, str(tmp_path / "seg"), "-o", str(out), "--quiet"]
        with pytest.raises(SystemExit, match=message):
            main([*argv, "--overwrite"])
    assert not (tmp_path / "missing").exists()
    assert not list((tmp_path / "seg").glob(".*"))


def test_predict_never_writes_over_its_model(tmp_path, labelled_folder):
    labelled_folder(tmp_path / "seg", n_per_class=1)
    model = tmp_path / "model.joblib"
    model.write_text("precious")
    with pytest.raises(SystemExit, match="is an input file"):
        main(["predict", str(model), str(tmp_path / "seg"), "-o",
              str(tmp_path / "." / "model.joblib"), "--overwrite"])  # fmt: skip
    assert model.read_text() == "precious"


def test_predict_with_a_model_that_is_not_a_cloud_classifier(tmp_path, labelled_folder):
    from sklearn.linear_model import LogisticRegression

    from skpcd.io import save_model

    labelled_folder(tmp_path / "seg", n_per_class=1)
    out = tmp_path / "p.csv"
    # a saved object without predict: was AttributeError: 'dict' object ...
    save_model({"a": 1}, tmp_path / "dict.joblib")
    with pytest.raises(SystemExit, match="holds a dict, not a fitted model"):
        main(["predict", str(tmp_path / "dict.joblib"), str(tmp_path / "seg"),
              "-o", str(out)])  # fmt: skip
    # a model of 2-D features, given clouds: was numpy's inhomogeneous shape
    lr = LogisticRegression().fit([[0.0, 1], [1, 0]], ["a", "b"])
    save_model(lr, tmp_path / "lr.joblib")
    with pytest.raises(
        SystemExit, match=r"cannot label these segments \(LogisticRegression"
    ):
        main(["predict", str(tmp_path / "lr.joblib"), str(tmp_path / "seg"),
              "-o", str(out)])  # fmt: skip
    assert not out.exists()


def test_describe_bad_descriptor_options(tmp_path, labelled_folder):
    labelled_folder(tmp_path, n_per_class=1)
    out = tmp_path / "d.npz"
    # was: an .npz holding the names only
    with pytest.raises(SystemExit, match="no descriptor asked for"):
        main(["describe", str(tmp_path), "-o", str(out), "--descriptors", ","])
    # was: InvalidParameterError raised from the transformer
    with pytest.raises(SystemExit, match="improved_pfh: The 'n_neighbors'"):
        main(["describe", str(tmp_path), "-o", str(out), "--quiet",
              "--descriptors", "improved_pfh", "--n-neighbors", "0"])  # fmt: skip
    with pytest.raises(SystemExit, match="pfh: The 'n_neighbors'"):
        main(["describe", str(tmp_path), "-o", str(out), "--quiet", "--descriptors",
              "shape", "--local", "pfh", "--n-neighbors", "1"])  # fmt: skip
    assert not out.exists()


@pytest.mark.parametrize(
    "options", [["--folds", "1"], ["--folds", "0"], ["--repeats", "0"]]
)
def test_evaluate_needs_two_folds_and_a_repeat(tmp_path, options, capsys):
    # was: a ValueError from scikit-learn's splitter after the data were read
    with pytest.raises(SystemExit, match="--folds must be at least 2"):
        main(["evaluate", str(tmp_path), "--quiet", *options])
    assert capsys.readouterr().out == ""


def test_fit_without_labels_names_the_fit_command(tmp_path):
    with pytest.raises(SystemExit, match=r"^skpcd fit: .* has no labels.csv"):
        main(["fit", str(tmp_path), "-o", str(tmp_path / "m.joblib")])


def test_one_class_is_refused_where_it_means_nothing(tmp_path, capsys):
    # was: "accuracy 1.0000" from evaluate, and a default model labelling
    # every segment with the one class
    from skpcd.datasets import make_urban_objects

    clouds, _ = make_urban_objects(n_per_class=1, random_state=0)
    for i, c in enumerate(clouds):
        write_point_cloud(tmp_path / f"{i}.xyz", c)
    (tmp_path / "labels.csv").write_text(
        "\n".join(f"{i}.xyz,tree" for i in range(len(clouds)))
    )
    with pytest.raises(SystemExit, match="every segment is labelled 'tree'"):
        main(["evaluate", str(tmp_path), "--folds", "2", "--quiet"])
    model = tmp_path / "m.joblib"
    with pytest.raises(SystemExit, match="label at least 2 classes"):
        main(["fit", str(tmp_path), "-o", str(model), "--quiet"])
    assert not model.exists()
    # a case-based library of one class answers it or "unknown"
    args = ["fit", str(tmp_path), "-o", str(model), "--pipeline", "case-based"]
    assert main(args) == 0  # not --quiet: its summary says it
    assert "1 classes" in capsys.readouterr().out


@pytest.mark.parametrize("command", ["fit", "describe", "predict"])
def test_outputs_never_replace_the_inputs_even_with_overwrite(
    tmp_path, command, labelled_folder
):
    # was: labels.csv replaced by the model (fit), a segment file replaced
    # by the predictions or the descriptors
    seg = tmp_path / "seg"
    labelled_folder(seg, n_per_class=1)
    model = tmp_path / "model.joblib"
    model.write_text("never read")
    first = [str(model)] if command == "predict" else []
    targets = [seg / "labels.csv"] if command != "predict" else []
    if command != "fit":
        targets.append(seg / "000.xyz")
    for out in targets:
        before = out.read_bytes()
        argv = [command, *first, str(seg), "-o", str(out), "--overwrite", "--quiet"]
        if command == "predict":  # the model is checked after the segments
            from sklearn.dummy import DummyClassifier

            from skpcd.io import save_model

            save_model(DummyClassifier().fit([[0]], ["a"]), model, overwrite=True)
        with pytest.raises(SystemExit, match="is an input file"):
            main(argv)
        assert out.read_bytes() == before


@pytest.mark.parametrize("command", ["fit", "describe", "predict", "evaluate"])
def test_an_unreadable_segment_is_a_clean_error_naming_it(
    tmp_path, capsys, command, labelled_folder
):
    seg = tmp_path / "seg"
    labelled_folder(seg, n_per_class=1)
    (seg / "002.xyz").write_text("1 2\n3 4\n")  # two columns: not a cloud
    model = tmp_path / "model.joblib"
    if command == "predict":
        from sklearn.dummy import DummyClassifier

        from skpcd.io import save_model

        save_model(DummyClassifier().fit([[0]], ["a"]), model)
    out = tmp_path / "out"
    argv = {
        "fit": ["fit", str(seg), "-o", str(out)],
        "describe": ["describe", str(seg), "-o", str(out)],
        "predict": ["predict", str(model), str(seg), "-o", str(out)],
        "evaluate": ["evaluate", str(seg), "--folds", "2"],
    }[command]
    assert main([*argv, "--quiet"]) == 1
    err = capsys.readouterr().err
    assert f"skpcd {command}: error: " in err and "002.xyz" in err
    assert not out.exists()


def test_identify_refuses_bad_output_places_before_any_work(tmp_path, capsys):
    scene = tmp_path / "scene.xyz"
    np.savetxt(scene, np.random.default_rng(0).uniform(0, 10, (50, 3)))
    original = scene.read_bytes()
    model = tmp_path / "model.joblib"
    model.write_bytes(b"not read: the output is refused first")
    cases = {
        str(tmp_path / "missing" / "out.ply"): "does not exist",
        str(tmp_path): "is a folder",
        str(scene): "is an input file",
    }
    for out, message in cases.items():
        with pytest.raises(SystemExit, match=message):
            main(
                [
                    "identify",
                    str(scene),
                    "--model",
                    str(model),
                    "-o",
                    out,
                    "--overwrite",
                    "--quiet",
                ]
            )
    assert scene.read_bytes() == original
    assert model.read_bytes() == b"not read: the output is refused first"


# --- out of core (--tile-size) and on a Dask cluster (--scheduler) -------------


def _tree_bytes(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.mark.parametrize("ext", [".las", ".ply"])
def test_segment_tiled_writes_the_untiled_files(tmp_path, capsys, ext, scene_file):
    scene = tmp_path / f"scene{ext}"
    scene_file(scene, random_state=2)
    args = ["segment", str(scene), "--eps", "1.0", "--min-size", "30", "--quiet"]
    # tiles take an SMRF ground preset and no structures (else refused)
    args += ["--ground", "aerial", "--no-structures"]
    assert main([*args, "-o", str(tmp_path / "whole"), "--keep-fields"]) == 0
    tiled = [*args, "-o", str(tmp_path / "tiles"), "--keep-fields"]
    assert main([*tiled, "--tile-size", "12"]) == 0
    whole = _tree_bytes(tmp_path / "whole")
    assert len(whole) > 5
    assert _tree_bytes(tmp_path / "tiles") == whole  # no temporary file left
    # the folder of segments can be described as is (segments.csv is skipped)
    npz = tmp_path / "d.npz"
    desc = ["describe", str(tmp_path / "tiles"), "-o", str(npz), "--quiet"]
    assert main([*desc, "--descriptors", "shape"]) == 0
    with np.load(npz) as d:
        # the folder holds segments.csv and segmentation.json besides
        assert d["shape"].shape[0] == len(whole) - 2
    with pytest.raises(SystemExit, match="2 \\* eps"):
        main([*tiled, "--overwrite", "--tile-size", "12", "--tile-buffer", "1"])


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip(
        "distributed", reason="the dask extra is not installed (skpcd[dask])"
    )
    with (
        distributed.LocalCluster(
            n_workers=2, processes=True, threads_per_worker=1, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        yield cluster.scheduler_address, client


def test_scheduler_gives_the_local_outputs(
    tmp_path, cluster, labelled_folder, scene_file
):
    from distributed import get_task_stream

    address, client = cluster
    scene = tmp_path / "scene.ply"
    scene_file(scene, random_state=2)
    seg = ["segment", str(scene), "--eps", "1.0", "--min-size", "30", "--quiet"]
    seg += ["--tile-size", "12", "--ground", "none", "--no-structures"]
    labelled_folder(tmp_path / "train", n_per_class=3)
    outputs = {}
    for where, extra in (("local", []), ("dask", ["--scheduler", address])):
        out = tmp_path / where
        out.mkdir()
        plys = str(out / "segs" / "*.ply")
        model = str(out / "m.joblib")
        with get_task_stream(client) as stream:
            assert main([*seg, "-o", str(out / "segs"), *extra]) == 0
            fit = ["fit", str(tmp_path / "train"), "-o", model, "--quiet"]
            assert main([*fit, "--pipeline", "case-based", *extra]) == 0
            desc = ["describe", plys, "-o", str(out / "d.npz"), "--quiet"]
            assert main([*desc, "--descriptors", "shape,improved_fpfh", *extra]) == 0
            pred = ["predict", model, plys, "-o", str(out / "p.csv"), "--quiet"]
            assert main([*pred, *extra]) == 0
        assert (len(stream.data) > 0) == (where == "dask")  # ran on the workers
        with np.load(out / "d.npz") as npz:
            outputs[where] = (
                _tree_bytes(out / "segs"),
                {k: npz[k] for k in npz.files},
                (out / "p.csv").read_bytes(),
            )
    local, dask = outputs["local"], outputs["dask"]
    assert dask[0] == local[0] and len(local[0]) >= 4
    assert dask[1].keys() == local[1].keys()
    for k in local[1]:
        np.testing.assert_array_equal(dask[1][k], local[1][k])
    assert dask[2] == local[2]


def test_scheduler_unreachable_or_missing(tmp_path, monkeypatch, labelled_folder):
    import skpcd.cli._common

    pytest.importorskip("distributed")
    labelled_folder(tmp_path / "seg", n_per_class=1)
    monkeypatch.setattr(skpcd.cli._common, "SCHEDULER_TIMEOUT", 1)
    args = ["describe", str(tmp_path / "seg"), "-o", str(tmp_path / "d.npz")]
    with pytest.raises(SystemExit, match="cannot reach the Dask scheduler at tcp"):
        main([*args, "--scheduler", "tcp://127.0.0.1:9"])
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(SystemExit, match="pip install 'skpcd\\[dask\\]'"):
        main([*args, "--scheduler", "tcp://127.0.0.1:9"])
    assert not (tmp_path / "d.npz").exists()


def test_predict_without_a_model_uses_the_shipped_street_model(
    tmp_path, capsys, street_folder
):
    from skpcd.classification import STREET_MODEL_CLASSES

    labels = street_folder(tmp_path / "seg")
    out = tmp_path / "pred.csv"
    assert main(["predict", str(tmp_path / "seg"), "-o", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("no model given, using the shipped street model street-") == 1
    rows = [line.split(",") for line in out.read_text().splitlines()[1:]]
    assert len(rows) == len(labels)
    assert {r[1] for r in rows} <= set(STREET_MODEL_CLASSES)
    # the two-path form and --model name the model; three paths are refused
    with pytest.raises(SystemExit, match="expected \\[MODEL\\] FOLDER"):
        main(["predict", "a", "b", "c", "-o", str(tmp_path / "p2.csv")])


def test_identify_without_a_model_uses_the_shipped_street_model(
    tmp_path, capsys, scene_file
):
    scene_file(tmp_path / "scene.ply", n_per_class=1)
    out = tmp_path / "labelled.ply"
    argv = ["identify", str(tmp_path / "scene.ply"), "-o", str(out), "--quiet"]
    assert main([*argv, "--ground", "aerial"]) == 0
    assert "using the shipped street model" in capsys.readouterr().err
    legend = (tmp_path / "labelled.ply.classes.csv").read_text()
    assert out.exists() and "person" in legend and "street_light" in legend


def test_fit_simulate_adds_simulated_objects(tmp_path, capsys, street_folder):
    from skpcd.classification import SimulationAugmented
    from skpcd.io import load_model

    street_folder(tmp_path / "seg", n_per_class=2)
    model_path = tmp_path / "m.skpcd"
    argv = ["fit", str(tmp_path / "seg"), "-o", str(model_path)]
    assert main([*argv, "--simulate", "2", "--scanner", "spinning"]) == 0
    out = capsys.readouterr().out
    assert "simulated 4 objects of car, person (spinning pattern)" in out
    model = load_model(model_path)
    assert isinstance(model, SimulationAugmented) and model.n_simulated_ == 4
    with pytest.raises(SystemExit, match="--simulate must be at least 1"):
        main([*argv, "--overwrite", "--simulate", "0"])
