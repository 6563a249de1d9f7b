"""``skpcd simulate`` (a folder that ``skpcd fit`` reads as it is), ``skpcd
predict --n-jobs`` and ``skpcd score -o``: the round trip simulate -> fit
-> predict -> score."""

import csv
import json

import numpy as np
import pytest

from skpcd.cli import main
from skpcd.cli._evaluate import simulated_data
from skpcd.cli._model import with_n_jobs
from skpcd.io import read_segments

N_PER_CLASS = 6


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A simulated folder (urban, 6 per class, seed 3) and the model that
    ``skpcd fit`` wrote from it."""
    root = tmp_path_factory.mktemp("simulate")
    objects, model = root / "objects", root / "model.skpcd"
    argv = ["simulate", "-o", str(objects), "--n-per-class", str(N_PER_CLASS)]
    assert main([*argv, "--random-state", "3", "--quiet"]) == 0
    assert main(["fit", str(objects), "-o", str(model), "--quiet"]) == 0
    return root, objects, model


def test_simulate_writes_what_fit_reads(fitted):
    _, objects, _ = fitted
    clouds, labels, _ = simulated_data("urban", N_PER_CLASS, random_state=3)
    read, y, names = read_segments(objects, objects / "labels.csv")
    assert len(read) == len(clouds) == 5 * N_PER_CLASS
    assert names == [f"object_{i:04d}.ply" for i in range(len(clouds))]
    assert list(y) == [str(v) for v in labels]
    for a, b in zip(read, clouds):
        np.testing.assert_array_equal(a, b)
    with open(objects / "labels.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["file", "label"] and len(rows) == 1 + len(clouds)
    assert sorted(p.name for p in objects.iterdir()) == sorted([*names, "labels.csv"])


def test_predict_n_jobs_gives_the_same_answers(fitted, capsys):
    root, objects, model = fitted
    outs = []
    for n_jobs in ("1", "2"):
        out = root / f"pred_{n_jobs}.csv"
        argv = ["predict", str(model), str(objects), "-o", str(out)]
        assert main([*argv, "--n-jobs", n_jobs, "--overwrite"]) == 0
        outs.append(out.read_text())
    assert outs[0] == outs[1]
    rows = list(csv.DictReader(outs[0].splitlines()))
    truth = dict(csv.reader((objects / "labels.csv").open()))
    # the training objects themselves: a forest answers nearly all right
    right = np.mean([truth[r["file"]] == r["label"] for r in rows])
    assert len(rows) == 5 * N_PER_CLASS and right >= 0.9
    capsys.readouterr()


def test_with_n_jobs_reaches_every_part():
    from skpcd.classification import RejectUnknown, make_named_pipeline

    clouds, labels, _ = simulated_data("urban", 3, random_state=0)
    pipe = make_named_pipeline("default", n_jobs=2)
    model = RejectUnknown(pipe).fit(clouds, labels)
    with_n_jobs(model, 1)
    fitted = model.estimator_
    assert fitted is not pipe  # a fitted clone, not a parameter
    for est in (model.estimator, fitted):
        params = est.get_params(deep=True)
        jobs = {k: v for k, v in params.items() if k.endswith("n_jobs")}
        assert jobs and set(jobs.values()) == {1}
    assert fitted.named_steps["randomforestclassifier"].n_jobs == 1


@pytest.mark.parametrize("ext", [".csv", ".json", ".txt"])
def test_score_writes_the_report(fitted, capsys, ext):
    root, objects, model = fitted
    out = root / f"score{ext}"
    argv = ["score", str(model), str(objects), "-o", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    accuracy = float(printed.split("accuracy  ")[1].split()[0])
    truth = dict(csv.reader((objects / "labels.csv").open()))
    if ext == ".csv":
        rows = list(csv.DictReader(out.open()))
        assert list(rows[0]) == ["file", "label", "predicted", "probability"]
        assert [r["file"] for r in rows] == [f"object_{i:04d}.ply" for i in range(30)]
        assert all(truth[r["file"]] == r["label"] for r in rows)
        right = np.mean([r["label"] == r["predicted"] for r in rows])
        assert right == pytest.approx(accuracy, abs=1e-4)
        assert all(0 < float(r["probability"]) <= 1 for r in rows)
    elif ext == ".json":
        report = json.loads(out.read_text())
        assert report["accuracy"] == pytest.approx(accuracy, abs=1e-4)
        assert report["n_segments"] == 30
        assert report["classes"] == sorted(set(truth.values()) - {"label"})
        assert np.sum(report["confusion_matrix"]) == 30
        assert report["per_class"]["car"]["support"] == N_PER_CLASS
    else:
        text = out.read_text()
        assert text.startswith("accuracy  ") and "confusion matrix" in text
        assert text.strip() in printed
    # never replaced without asking; --quiet then prints nothing
    before = out.read_bytes()
    with pytest.raises(SystemExit, match="--overwrite"):
        main(argv)
    assert out.read_bytes() == before
    assert main([*argv, "--overwrite", "--quiet"]) == 0
    assert capsys.readouterr().out == ""


def test_score_output_refusals(fitted):
    root, objects, model = fitted
    argv = ["score", str(model), str(objects), "-o"]
    with pytest.raises(SystemExit, match="inside"):
        main([*argv, str(objects / "scores.csv")])
    with pytest.raises(SystemExit, match="is an input file"):
        main([*argv, str(model), "--overwrite"])
    with pytest.raises(SystemExit, match="does not exist"):
        main([*argv, str(root / "nowhere" / "s.csv")])
    assert not (objects / "scores.csv").exists()


def test_simulate_output_folder(tmp_path, capsys):
    out = tmp_path / "objs"
    argv = ["simulate", "-o", str(out), "--n-per-class", "1", "--format", "xyz"]
    assert main(argv) == 0
    assert "written   5 objects of 5 classes" in capsys.readouterr().out
    first = sorted(p.name for p in out.iterdir())
    with pytest.raises(SystemExit, match="not empty; pass --overwrite"):
        main(argv)
    assert main([*argv[:-1], "npy", "--overwrite", "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        n.replace(".xyz", ".npy") for n in first
    ]
    # what skpcd did not write is never deleted
    (out / "notes.txt").write_text("mine")
    with pytest.raises((SystemExit, FileExistsError)) as e:
        assert main([*argv, "--overwrite"]) == 1
        raise SystemExit(capsys.readouterr().err)
    assert "notes.txt" in str(e.value)
    assert (out / "notes.txt").read_text() == "mine"
    with pytest.raises(SystemExit, match="--n-per-class must be at least 1"):
        main(["simulate", "-o", str(tmp_path / "new"), "--n-per-class", "0"])
    (tmp_path / "file").write_text("x")
    with pytest.raises(SystemExit, match="not a folder"):
        main(["simulate", "-o", str(tmp_path / "file")])
    assert not (tmp_path / "new").exists()
