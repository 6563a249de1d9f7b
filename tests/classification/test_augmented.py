"""SimulationAugmented: real labels completed by simulated objects of their classes."""

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.datasets import make_classification
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import GridSearchCV
from sklearn.tree import DecisionTreeClassifier

from skpcd.classification import SimulationAugmented, make_street_pipeline
from skpcd.datasets import make_street_objects


def _small_pipeline():
    return make_street_pipeline().set_params(classifier__estimator__n_estimators=20)


@pytest.fixture(scope="module")
def real():
    """Stand-ins for a user's few labelled segments: two cars, two people
    (a spinning sensor, another seed than any simulation below) and two
    segments of a class the simulator does not know."""
    clouds, labels = make_street_objects(
        2, classes=["car", "person"], scanner="spinning", min_points=20, random_state=5
    )
    rng = np.random.default_rng(0)
    kiosks = [rng.uniform([0, 0, 0], [2, 2, 2.5], size=(200, 3)) for _ in range(2)]
    return [*clouds, *kiosks], np.array([*labels, "kiosk", "kiosk"])


def test_adds_simulated_objects_of_the_known_classes(real):
    X, y = real
    model = SimulationAugmented(
        _small_pipeline(), n_per_class=3, scanner="spinning", random_state=0
    ).fit(X, y)
    assert model.simulated_classes_ == ["car", "person"]
    assert model.n_simulated_ == 6 and model.scanner_ == "spinning"
    assert sorted(model.classes_.tolist()) == ["car", "kiosk", "person"]
    assert model.predict(X).shape == (6,)
    assert model.predict_proba(X).shape == (6, 3)
    # the forest saw 6 real + 6 simulated objects
    forest = model.estimator_[-1].estimator_
    assert forest.n_features_in_ > 0 and len(forest.estimators_) == 20


def test_auto_keeps_the_pattern_that_labels_the_real_objects_best(real):
    X, y = real
    model = SimulationAugmented(_small_pipeline(), n_per_class=3, random_state=0)
    model.fit(X, y)
    assert set(model.scanner_scores_) == {"spinning", "mobile"}
    assert model.scanner_ == max(model.scanner_scores_, key=model.scanner_scores_.get)


class _WeightSpy(DecisionTreeClassifier):
    """Records the weights fit receives."""

    def fit(self, X, y, sample_weight=None):
        self.seen_weight_ = sample_weight
        return super().fit(X, y, sample_weight=sample_weight)


def test_real_objects_weigh_real_weight_times_a_simulated_one(real):
    X, y = real
    pipe = _small_pipeline()
    pipe.steps[-1] = ("classifier", _WeightSpy(random_state=0))
    model = SimulationAugmented(
        pipe, n_per_class=2, scanner="spinning", real_weight=7.0, random_state=0
    ).fit(X, y)
    w = model.estimator_[-1].seen_weight_
    assert w.tolist() == [7.0] * len(y) + [1.0] * model.n_simulated_


def test_without_weights_real_objects_are_repeated():
    from skpcd.classification._augmented import _fit_weighted

    class NoWeights(DecisionTreeClassifier):
        def fit(self, X, y):
            self.n_seen_ = len(y)
            return super().fit(X, y)

    X, y = make_classification(20, random_state=0)
    model = _fit_weighted(NoWeights(), X, y, np.r_[np.full(10, 3.0), np.ones(10)])
    assert model.n_seen_ == 40


def test_labels_the_simulator_does_not_know_fit_the_estimator_alone():
    X, y = make_classification(60, random_state=0)
    model = SimulationAugmented(LogisticRegression()).fit(X, y)
    assert model.n_simulated_ == 0 and model.scanner_ is None
    plain = LogisticRegression().fit(X, y)
    np.testing.assert_allclose(model.predict_proba(X), plain.predict_proba(X))


def test_grid_search_and_clone():
    X, y = make_classification(60, random_state=0)
    search = GridSearchCV(
        SimulationAugmented(LogisticRegression()),
        {"real_weight": [1.0, 5.0], "estimator__C": [0.1, 1.0]},
        cv=3,
    ).fit(X, y)
    assert set(search.best_params_) == {"real_weight", "estimator__C"}
    assert clone(search.best_estimator_).get_params()["real_weight"] in (1.0, 5.0)


def test_bad_input_is_a_clear_error():
    with pytest.raises(ValueError, match="3 samples but y has 2"):
        SimulationAugmented(LogisticRegression()).fit(np.zeros((3, 2)), [0, 1])
    with pytest.raises(ValueError, match="scanner"):
        SimulationAugmented(scanner="lidar").fit(np.zeros((3, 2)), [0, 1, 0])
