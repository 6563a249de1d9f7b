"""The shipped street model and its pipeline."""

import os
from pathlib import Path

import numpy as np
import pytest

import skpcd
from skpcd.classification import (
    STREET_MODEL_CLASSES,
    STREET_MODEL_PATH,
    _street,
    load_street_model,
    make_street_pipeline,
)
from skpcd.datasets import make_street_objects
from skpcd.exceptions import IncompatibleModelError
from skpcd.io import save_model

REAL = Path(
    os.environ.get(
        "SKPCD_REAL_MOBILE_DIR",
        Path(__file__).resolve().parents[3] / "shared/data/real_mobile",
    )
)


@pytest.fixture(scope="module")
def shipped():
    return load_street_model(return_info=True)


def test_shipped_model_is_small_versioned_and_simulated_only(shipped):
    model, info = shipped
    assert STREET_MODEL_PATH.stat().st_size < 8 * 2**20
    assert set(STREET_MODEL_CLASSES) <= set(model.classes_)
    meta = info["metadata"]
    assert meta["model_version"].startswith("street-")
    assert "no real scan" in meta["data"]
    # rebuilt for every release (benchmarks/build_street_model.py)
    assert meta["skpcd_release"] == skpcd.__version__
    assert [name for name, _ in model.steps] == ["sample", "features", "classifier"]


def test_shipped_model_recognises_simulated_objects_it_did_not_see(shipped):
    """Cars and people of a seed it was not trained on. (Tall furniture is
    left out: an HDL-64E looks at most 2 degrees up and sees the lower
    metres of a street light, which are a pole's.)"""
    model, _ = shipped
    clouds, labels = make_street_objects(
        4,
        classes=["car", "person"],
        scanner="spinning",
        min_points=20,
        random_state=12345,
    )
    assert (model.predict(clouds) == labels).mean() >= 0.75


def test_unknown_threshold(shipped):
    clouds, _ = make_street_objects(
        1, classes=["car"], scanner="spinning", min_points=20, random_state=3
    )
    assert load_street_model(unknown_threshold=1.0).predict(clouds).tolist() == [
        "unknown"
    ]
    assert load_street_model(unknown_threshold=None).predict(clouds)[0] != "unknown"
    with pytest.raises(ValueError, match="unknown_threshold must be a probability"):
        load_street_model(unknown_threshold=1.5)


def test_a_model_that_answers_differently_is_refused(tmp_path, monkeypatch):
    """The probe check: a model file whose stored answers match loads, one
    whose answers differ (as after a scikit-learn change) is refused."""
    clouds, labels = make_street_objects(
        2,
        classes=["car", "person"],
        scanner="spinning",
        min_points=20,
        random_state=9,
    )
    model = make_street_pipeline().set_params(classifier__estimator__n_estimators=5)
    model.fit(clouds, labels)
    probe = [np.round(c[:60], 3) for c in clouds]
    meta = {
        "model_version": "street-test",
        "probe": {
            "clouds": [c.tolist() for c in probe],
            "proba": model.predict_proba(probe).tolist(),
        },
    }
    good = save_model(model, tmp_path / "good.skpcd", metadata=meta)
    monkeypatch.setattr(_street, "STREET_MODEL_PATH", good)
    assert load_street_model().classes_.tolist() == ["car", "person"]
    meta["probe"]["proba"] = np.roll(meta["probe"]["proba"], 1, axis=1).tolist()
    bad = save_model(model, tmp_path / "bad.skpcd", metadata=meta)
    monkeypatch.setattr(_street, "STREET_MODEL_PATH", bad)
    with pytest.raises(IncompatibleModelError, match=r"build_street_model\.py"):
        load_street_model()


def test_sampling_makes_density_matter_less():
    """The same simulated objects thinned to a third describe closer to
    the originals after the pipeline's grid sampling than without it."""
    clouds, _ = make_street_objects(
        2, classes=["car", "tree"], scanner="spinning", min_points=50, random_state=8
    )
    rng = np.random.default_rng(0)
    thin = [c[rng.random(len(c)) < 0.33] for c in clouds]
    sampled = make_street_pipeline()[:2]
    plain = make_street_pipeline()[1:2]

    def gap(steps):
        a, b = steps.fit_transform(clouds), steps.fit_transform(thin)
        return np.nanmean(np.abs(a - b) / (np.abs(a) + np.abs(b) + 1e-9))

    assert gap(sampled) < gap(plain)


@pytest.mark.skipif(not (REAL / "objects").is_dir(), reason=f"no real scans at {REAL}")
def test_shipped_model_on_real_car_mounted_scans(shipped):
    """The documented zero-shot figure on real PandaSet/KITTI objects
    (benchmarks/results/few_shot_objects.txt) holds."""
    from skpcd.io import read_segments

    clouds, labels, _ = read_segments(REAL / "objects", REAL / "objects/labels.csv")
    keep = np.isin(labels, ["car", "person", "traffic_sign"])
    pred = shipped[0].predict([c for c, k in zip(clouds, keep) if k])
    truth = np.asarray(labels)[keep]
    recall = [np.mean(pred[truth == c] == c) for c in np.unique(truth)]
    assert np.mean(recall) >= 0.6
