import numpy as np
from sklearn.ensemble import RandomForestClassifier
from sklearn.model_selection import StratifiedKFold, cross_val_predict

from skpcd.classification import (
    PIPELINES,
    RejectUnknown,
    make_default_pipeline,
    make_named_pipeline,
)
from skpcd.features import PFHTransformer, ShapeFeatures, VerticalProfile


def test_default_pipeline_content():
    model = make_default_pipeline(random_state=3, n_jobs=2)
    union, forest = model[0], model[-1]
    kinds = [type(t) for _, t in union.transformer_list]
    assert kinds == [ShapeFeatures, VerticalProfile, PFHTransformer]
    pfh = union.transformer_list[2][1]
    assert (pfh.n_neighbors, pfh.pooling, pfh.n_jobs) == (10, "mean", 2)
    assert isinstance(forest, RandomForestClassifier)
    assert (forest.n_estimators, forest.random_state, forest.n_jobs) == (300, 3, 2)
    assert forest.class_weight is None
    assert "vertical" in PIPELINES["default"]
    assert type(make_named_pipeline("default")[-1]) is RandomForestClassifier


def test_unknown_threshold_wraps_the_forest():
    model = make_default_pipeline(unknown_threshold=0.4, random_state=1)
    last = model[-1]
    assert isinstance(last, RejectUnknown) and last.threshold == 0.4
    assert isinstance(last.estimator, RandomForestClassifier)
    assert last.estimator.random_state == 1
    model.set_params(rejectunknown__estimator__n_estimators=7)
    assert last.estimator.n_estimators == 7


def _furniture(rng, kind):
    """A 4-7 m pole seen from one side: bare, with an arm and a lamp at the
    top, or with a plate somewhere along it; ground clutter at the foot."""
    height = rng.uniform(4, 7)
    n = 400
    angle = rng.uniform(0, np.pi, n)
    z = rng.uniform(0, height, n)
    parts = [np.c_[0.08 * np.cos(angle), 0.08 * np.sin(angle), z]]
    if kind == "street_light":
        t = rng.uniform(0, rng.uniform(1.0, 2.5), 150)
        parts.append(np.c_[t, np.zeros(150), height + rng.normal(0, 0.03, 150)])
    elif kind == "sign":
        z0 = rng.uniform(1.5, height - 0.8)
        parts.append(
            np.c_[
                rng.uniform(-0.35, 0.35, 200),
                np.full(200, 0.1),
                rng.uniform(z0, z0 + 0.7, 200),
            ]
        )
    parts.append(np.c_[rng.uniform(-0.6, 0.6, (60, 2)), rng.uniform(0, 0.15, 60)])
    pts = np.vstack(parts) + rng.normal(0, 0.01, (sum(map(len, parts)), 3))
    a = rng.uniform(0, 2 * np.pi)
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    return pts @ rot.T + rng.uniform(-100, 100, 3)


def test_default_tells_pole_like_furniture_apart():
    rng = np.random.default_rng(0)
    kinds = ["pole", "street_light", "sign"] * 12
    clouds = [_furniture(rng, k) for k in kinds]
    y = np.array(kinds)
    model = make_default_pipeline().set_params(randomforestclassifier__n_estimators=50)
    pred = cross_val_predict(
        model, clouds, y, cv=StratifiedKFold(3, shuffle=True, random_state=0)
    )
    for k in set(kinds):
        assert np.mean(pred[y == k] == k) >= 0.8, k
