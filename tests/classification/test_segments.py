"""identify_segments: batched prediction of a scene's segments."""

import numpy as np
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import FunctionTransformer
from sklearn.tree import DecisionTreeClassifier

from skpcd.classification import identify_segments
from skpcd.segmentation._members import spread_to_points


def _height(clouds):
    return [[np.ptp(c[:, 2]), len(c)] for c in clouds]


def _data(seed=0, n=40):
    rng = np.random.default_rng(seed)
    clouds = [rng.random((int(rng.integers(5, 60)), 3)) * [1, 1, rng.uniform(0.2, 5)]
              for _ in range(n)]  # fmt: skip
    labels = ["tall" if np.ptp(c[:, 2]) > 2 else "low" for c in clouds]
    return clouds, labels


def test_the_answers_do_not_depend_on_the_batches():
    clouds, labels = _data()
    model = make_pipeline(
        FunctionTransformer(_height), DecisionTreeClassifier(random_state=0)
    )
    model.fit(clouds, labels)
    kinds = ["object"] * len(clouds)
    kinds[3] = "facade"
    segments = [(c, {}) for c in clouds]
    whole = identify_segments(model, segments, kinds=kinds, batch_points=10**9)
    for batch_points in (1, 37, 500):
        parts = identify_segments(
            model, segments, kinds=kinds, batch_points=batch_points
        )
        np.testing.assert_array_equal(parts[0], whole[0])
        np.testing.assert_array_equal(parts[2], whole[2])
        np.testing.assert_array_equal(parts[3], whole[3])
    pred, kind, score, sizes = whole
    assert pred[3] == "facade" and np.isnan(score[3]) and kind == "probability"
    expected = model.predict([c for i, c in enumerate(clouds) if i != 3])
    np.testing.assert_array_equal(np.delete(pred, 3), expected)
    np.testing.assert_array_equal(sizes, [len(c) for c in clouds])


def test_spread_to_points_in_chunks_equals_the_lookup():
    rng = np.random.default_rng(1)
    labels = rng.integers(-1, 7, 1000)
    values = rng.random(7)
    out = spread_to_points(labels, values, np.nan, np.empty(1000), chunk=33)
    expected = np.where(labels >= 0, values[np.maximum(labels, 0)], np.nan)
    np.testing.assert_array_equal(out, expected)
