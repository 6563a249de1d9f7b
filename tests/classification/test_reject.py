import csv

import numpy as np
import pytest
from sklearn.ensemble import RandomForestClassifier
from sklearn.linear_model import LogisticRegression
from sklearn.tree import DecisionTreeClassifier

from skpcd.classification import (
    CaseBasedClassifier,
    RejectUnknown,
    make_default_pipeline,
    predict_with_confidence,
)
from skpcd.datasets import make_urban_objects

X = np.array([[0.0], [0.1], [0.2], [1.0], [1.1], [1.2]])


def _forest():
    return RandomForestClassifier(n_estimators=50, random_state=0)


def test_rejects_below_the_threshold_only():
    model = RejectUnknown(_forest(), threshold=0.9).fit(X, list("aaabbb"))
    proba = model.predict_proba([[0.05], [0.6], [1.15]])
    pred = model.predict([[0.05], [0.6], [1.15]])
    assert pred.tolist() == ["a", "unknown", "b"]
    assert proba[1].max() < 0.9 <= proba[0].max()
    np.testing.assert_array_equal(model.classes_, ["a", "b"])


def test_threshold_none_and_zero_never_reject():
    inner = _forest().fit(X, list("aaabbb"))
    query = np.linspace(-1, 2, 31)[:, None]
    for t in (None, 0.0):
        model = RejectUnknown(_forest(), threshold=t).fit(X, list("aaabbb"))
        np.testing.assert_array_equal(model.predict(query), inner.predict(query))


@pytest.mark.parametrize(
    ("y", "unknown_label", "expected"),
    [
        ([0, 0, 0, 1, 1, 1], None, -1),  # as CaseBasedClassifier
        ([-1, -1, -1, 1, 1, 1], None, -2),
        ([0, 0, 0, 1, 1, 1], "none", "none"),
        (list("aaabbb"), None, "unknown"),
        (list("aaabbb"), "other", "other"),
    ],
)
def test_unknown_label_like_the_case_based_classifier(y, unknown_label, expected):
    model = RejectUnknown(_forest(), threshold=1.0, unknown_label=unknown_label)
    pred = model.fit(X, y).predict([[0.6]])
    assert pred.tolist() == [expected] and model.unknown_label_ == expected
    if unknown_label is None:
        cases = CaseBasedClassifier(threshold=0.8).fit(np.c_[X, X**2 + 1], y)
        assert cases.unknown_label_ == expected


def test_unknown_label_must_not_be_a_class():
    with pytest.raises(ValueError, match="is a training class"):
        RejectUnknown(_forest(), unknown_label="a").fit(X, list("aaabbb"))


def test_needs_predict_proba():
    from sklearn.svm import LinearSVC

    with pytest.raises(ValueError, match="predict_proba"):
        RejectUnknown(LinearSVC()).fit(X, list("aaabbb"))


def test_default_pipeline_with_unknown_and_its_confidence():
    clouds, labels = make_urban_objects(n_per_class=6, random_state=0)
    keep = labels != "pole"  # a class never seen in training
    model = make_default_pipeline(unknown_threshold=0.6)
    model.set_params(rejectunknown__estimator__n_estimators=30)
    model.fit([c for c, k in zip(clouds, keep) if k], labels[keep])
    assert isinstance(model[-1], RejectUnknown)
    pred, kind, score = predict_with_confidence(model, clouds)
    assert kind == "probability"
    np.testing.assert_array_equal(pred, model.predict(clouds))
    # the answer is "unknown" exactly where the best probability is low
    assert ((pred == "unknown") == (score < 0.6)).all()
    assert "pole" not in set(pred)
    assert set(pred) <= {*labels[keep], "unknown"}


def test_the_confidence_of_a_rejecting_model_takes_one_prediction(monkeypatch):
    # the forest's probabilities, the costliest step of identify on a sweep,
    # are computed once for the answer and its confidence
    model = RejectUnknown(_forest(), threshold=0.9).fit(X, list("aaabbb"))
    calls = []
    real = RejectUnknown.predict_proba
    monkeypatch.setattr(
        RejectUnknown, "predict_proba", lambda self, X: calls.append(1) or real(self, X)
    )
    pred, kind, score = predict_with_confidence(model, X)
    assert len(calls) == 1
    np.testing.assert_array_equal(pred, model.predict(X))
    assert kind == "probability"
    assert ((pred == "unknown") == (score < 0.9)).all()


def test_cli_predict_writes_unknown(tmp_path, capsys):
    from skpcd.cli import main
    from skpcd.io import save_model, write_point_cloud

    clouds, labels = make_urban_objects(n_per_class=5, random_state=0)
    model = make_default_pipeline(unknown_threshold=1.0)  # rejects any doubt
    model.set_params(rejectunknown__estimator__n_estimators=20)
    model.fit(clouds, labels)
    path = tmp_path / "model.skpcd"
    save_model(model, path)
    folder = tmp_path / "seg"
    folder.mkdir()
    new, _ = make_urban_objects(n_per_class=2, random_state=1)
    for i, c in enumerate(new):
        write_point_cloud(folder / f"{i:02d}.xyz", c)
    out = tmp_path / "pred.csv"
    assert main(["predict", str(path), str(folder), "-o", str(out), "--quiet"]) == 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == len(new)
    probability = np.array([float(r["probability"]) for r in rows])
    got = np.array([r["label"] for r in rows])
    assert ((got == "unknown") == (probability < 1.0)).all()
    assert set(got) <= {*labels, "unknown"}


def test_meta_estimator_clones_and_delegates():
    inner = LogisticRegression()
    model = RejectUnknown(inner, threshold=0.5).fit(X, list("aaabbb"))
    assert model.estimator_ is not inner and not hasattr(inner, "classes_")
    assert model.n_features_in_ == 1
    tree = RejectUnknown(DecisionTreeClassifier(random_state=0)).fit(
        X, [1] * 3 + [2] * 3
    )
    assert tree.predict([[0.0], [1.2]]).tolist() == [1, 2]
