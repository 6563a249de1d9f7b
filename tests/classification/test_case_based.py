import pickle
import warnings

import numpy as np
import pytest
import sklearn
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.calibration import CalibratedClassifierCV
from sklearn.model_selection import GridSearchCV, StratifiedKFold

from skpcd.classification import (
    CaseBasedClassifier,
    case_similarity,
    make_case_based_pipeline,
)
from skpcd.features import ImprovedPFHTransformer, OverallDescriptor


def _reference(a, b, w1=0.5, volume=True):
    """One pair, from the paper's formulas and the documented conventions."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    s_r = 1.0
    if volume:
        (va, *a), (vb, *b) = a, b
        a, b = np.asarray(a), np.asarray(b)
        s_r = 1 - abs(va - vb) / max(va, vb) if max(va, vb) > 0 else 1.0
    peaks = (a != 0) | (b != 0)
    x, y = a[peaks], b[peaks]
    if not a.any() or not b.any():
        s_a = 0.0
    elif np.ptp(x) == 0 or np.ptp(y) == 0:
        s_a = float(np.ptp(x) == np.ptp(y) == 0)
    else:
        s_a = np.corrcoef(x, y)[0, 1]
    return w1 * s_r + (1 - w1) * s_a if volume else s_a


def _cases(n, n_bins=12, seed=0):
    """Sparse histograms with a volume in column 0, and degenerate rows."""
    rng = np.random.default_rng(seed)
    H = rng.integers(0, 20, (n, n_bins)) * (rng.random((n, n_bins)) < 0.4)
    H[0] = 0  # no peak
    H[1] = 0
    H[1, 3] = 7  # one peak
    H[2] = 0
    H[2, [3, 5]] = 4  # flat over two peaks
    H[3] = H[2] * 3  # the same peaks, scaled
    V = rng.uniform(0, 50, n)
    V[:2] = 0
    return np.column_stack([V, H]).astype(float)


def test_similarity_tiny_oracle():
    # S_r = 2 / 4; over the first four dimensions (the last is 0 in both)
    # the deviations from the means (25, 25) are (-15, -25, 5, 35) and
    # (-25, -5, 5, 25): S_a = 1400 / sqrt(2100 * 1300)
    a = [2.0, 10, 0, 30, 60, 0]
    b = [4.0, 0, 20, 30, 50, 0]
    s_a = 1400 / np.sqrt(2100 * 1300)
    got = case_similarity([a], [b], w1=0.25, volume_column=0)
    assert_allclose(got, [[0.25 * 0.5 + 0.75 * s_a]], rtol=1e-12)
    # the zero dimension is left out: the plain correlation differs
    assert abs(np.corrcoef(a[1:], b[1:])[0, 1] - s_a) > 0.01
    model = CaseBasedClassifier(w1=0.25, volume_column=0).fit([b], ["b"])
    assert_allclose(model.class_similarity([a]), [[0.25 * 0.5 + 0.75 * s_a]])
    # the same histograms without a volume column: S_a alone
    assert_allclose(case_similarity([a[1:]], [b[1:]]), [[s_a]], rtol=1e-12)


@pytest.mark.parametrize("volume", [True, False])
def test_similarity_matches_reference(volume):
    X = _cases(40)
    if not volume:
        X = X[:, 1:]
    col = 0 if volume else None
    got = case_similarity(X, X[:25], w1=0.3, volume_column=col)
    want = [[_reference(a, b, 0.3, volume) for b in X[:25]] for a in X]
    assert_allclose(got, want, atol=1e-12)
    assert_allclose(got[:25], got[:25].T, atol=1e-12)


def test_undefined_terms():
    X = _cases(4)
    sim = case_similarity(X, X, w1=0.5, volume_column=0)
    assert sim[0, 0] == 0.5  # volumes 0 and 0: S_r = 1; no peak: S_a = 0
    assert sim[0, 1] == 0.5
    assert sim[0, 2] == 0  # volumes 0 and V > 0: S_r = 0
    assert sim[1, 1] == 1.0  # one peak, itself
    v2, v3 = X[2:4, 0]
    # the same two peaks, each flat over them: S_a = 1
    assert_allclose(sim[2, 3], 0.5 * min(v2, v3) / max(v2, v3) + 0.5)
    H = np.array([[5.0, 0, 0], [0, 5, 0], [1, 2, 3], [2, 2, 2], [0, 0, 0]])
    s = case_similarity(H, H)
    assert s[0, 1] == -1  # (5, 0) and (0, 5) over two peaks
    assert s[2, 3] == 0  # one flat over the peaks: undefined, 0
    assert s[3, 3] == 1  # flat: equal up to scale to itself
    assert_array_equal(s[4], 0)  # an all-zero histogram resembles nothing
    assert_allclose(np.diag(s)[:4], 1)


def test_flat_cases_with_same_peaks_are_alike():
    X = _cases(4)
    sim = case_similarity(X[2:4], X[2:4], w1=0.0, volume_column=0)
    assert_allclose(sim, 1.0)


def test_predict_follows_the_best_case_and_the_threshold():
    X = _cases(60, seed=1)
    y = np.repeat(["pole", "tree", "car"], 20)
    model = CaseBasedClassifier(volume_column=0, w1=0.4, threshold=0.9).fit(X, y)
    Q = _cases(30, seed=2)
    S = case_similarity(Q, X, w1=0.4, volume_column=0)
    best = S.max(axis=1)
    want = np.where(best >= 0.9, y[S.argmax(axis=1)], "unknown")
    assert 0 < (want == "unknown").sum() < len(Q)
    assert_array_equal(model.predict(Q), want)
    cs = model.class_similarity(Q)
    for k, c in enumerate(model.classes_):
        assert_allclose(cs[:, k], S[:, y == c].max(axis=1))
    assert_array_equal(model.decision_function(Q), cs)
    assert_array_equal(model.classes_, ["car", "pole", "tree"])


def test_unknown_label_defaults_and_types():
    X = _cases(20, seed=3)[:, 1:]
    Q = -X[::-1]  # anti-correlated: all unknown at threshold 0.99
    y = np.arange(20) % 2
    model = CaseBasedClassifier(threshold=0.99).fit(X, y)
    assert model.unknown_label_ == -1
    pred = model.predict(Q)
    assert pred.dtype.kind == "i" and (pred == -1).any()
    assert_array_equal(model.classes_, [0, 1])
    assert CaseBasedClassifier().fit(X, 2 * y - 1).unknown_label_ == -2
    assert CaseBasedClassifier().fit(X, y + 3.0).unknown_label_ == -1
    model = CaseBasedClassifier(threshold=0.99, unknown_label="?").fit(X, y)
    assert set(model.predict(Q).tolist()) <= {"?", 0, 1}
    assert "?" in model.predict(Q).tolist()
    with pytest.raises(ValueError, match="is a training class"):
        CaseBasedClassifier(unknown_label=1).fit(X, y)
    # no threshold, no unknown: the label may then be a class
    model = CaseBasedClassifier(threshold=None, unknown_label=1).fit(X, y)
    assert set(model.predict(Q).tolist()) <= {0, 1}
    assert model.predict(Q).dtype == model.classes_.dtype


def test_binary_decision_function_and_ties():
    X = np.array([[1.0, 2, 3], [1, 2, 3], [3, 2, 1]])
    model = CaseBasedClassifier(threshold=None).fit(X, ["b", "a", "c"])
    # cases 0 and 1 tie: the first class of classes_ ("a") wins
    assert model.predict([[2.0, 4, 6]]).tolist() == ["a"]
    sim, ind = model.retrieve([[2.0, 4, 6]], n_cases=3)
    assert ind.tolist() == [[0, 1, 2]]  # ties in training order
    assert_allclose(sim, [[1, 1, -1]])
    binary = CaseBasedClassifier().fit(X[1:], ["a", "c"])
    Q = np.array([[1.0, 2, 4], [4, 2, 1]])
    cs = binary.class_similarity(Q)
    assert_allclose(binary.decision_function(Q), cs[:, 1] - cs[:, 0])
    assert binary.predict(Q).tolist() == ["a", "c"]


def test_retrieve_equals_sorted_similarities():
    X = _cases(50, seed=4)
    model = CaseBasedClassifier(volume_column=0).fit(X, np.arange(50) % 3)
    Q = _cases(7, seed=5)
    sim, ind = model.retrieve(Q, n_cases=6)
    S = case_similarity(Q, X, volume_column=0)
    assert_array_equal(ind, np.argsort(-S, axis=1, kind="stable")[:, :6])
    assert_allclose(sim, np.take_along_axis(S, ind, axis=1))
    for bad in (0, 51, 2.0):
        with pytest.raises(ValueError, match="n_cases"):
            model.retrieve(Q, n_cases=bad)


def test_small_working_memory_gives_the_same_result():
    X = _cases(300, seed=6)
    model = CaseBasedClassifier(volume_column=0).fit(X, np.arange(300) % 4)
    Q = _cases(90, seed=7)
    want = model.class_similarity(Q), model.retrieve(Q, 4)
    with sklearn.config_context(working_memory=0.05):  # blocks of ~2 rows
        assert len(model._blocks(len(Q), 80 * 300)) > 10
        got = model.class_similarity(Q), model.retrieve(Q, 4)
    assert_array_equal(got[0], want[0])
    assert_array_equal(got[1][1], want[1][1])


def test_volume_column_rules():
    X = _cases(10, seed=8)
    y = np.arange(10) % 2
    last = np.roll(X, -1, axis=1)  # the volume in the last column
    a = CaseBasedClassifier(volume_column=0).fit(X, y).class_similarity(X)
    b = CaseBasedClassifier(volume_column=-1).fit(last, y).class_similarity(last)
    assert_allclose(a, b)
    neg = X.copy()
    neg[3, 0] = -1
    with pytest.raises(ValueError, match="must not be negative"):
        CaseBasedClassifier(volume_column=0).fit(neg, y)
    model = CaseBasedClassifier(volume_column=0).fit(X, y)
    with pytest.raises(ValueError, match="must not be negative"):
        model.predict(neg)
    with pytest.raises(ValueError, match="out of range"):
        CaseBasedClassifier(volume_column=13).fit(X, y)
    with pytest.raises(ValueError, match="feature"):
        CaseBasedClassifier(volume_column=0).fit(X[:, :1], y)
    nan = X.copy()
    nan[2, 4] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        CaseBasedClassifier().fit(nan, y)
    with pytest.raises(ValueError, match="NaN"):
        model.predict(nan)
    # float32 input gives the float64 answer
    f32 = X.astype(np.float32)
    assert_allclose(model.class_similarity(f32), model.class_similarity(X))


def test_calibrated_probabilities():
    X = _cases(60, seed=9)[:, 1:]
    y = (X[:, :6].sum(axis=1) > X[:, 6:].sum(axis=1)).astype(int)
    model = CalibratedClassifierCV(CaseBasedClassifier(threshold=None), cv=3)
    proba = model.fit(X, y).predict_proba(X)
    assert proba.shape == (60, 2)
    assert_allclose(proba.sum(axis=1), 1)


def test_pipeline_layout(dales_cases):
    X, _, clouds = dales_cases
    assert_allclose(X[:, 0], OverallDescriptor().fit_transform(clouds)[:, 9])
    H = ImprovedPFHTransformer(undefined="zero").fit_transform(clouds)
    assert_allclose(X[:, 1:], H)
    plain = make_case_based_pipeline(volume=False, threshold=None)
    assert plain[-1].volume_column is None
    with pytest.raises(TypeError, match="volume_column"):
        make_case_based_pipeline(volume_column=1)


def test_grid_search_on_dales_clouds(dales_cases):
    _, labels, clouds = dales_cases
    pick = np.arange(len(clouds)) % 3 == 0
    clouds = [c for c, k in zip(clouds, pick) if k]
    labels = labels[pick]
    grid = GridSearchCV(
        make_case_based_pipeline(),
        {
            "casebasedclassifier__w1": [0.0, 0.5],
            "casebasedclassifier__threshold": [None, 0.95],
        },
        cv=StratifiedKFold(3, shuffle=True, random_state=0),
    )
    grid.fit(clouds, labels)
    scores = grid.cv_results_["mean_test_score"]
    assert grid.best_params_["casebasedclassifier__threshold"] is None
    assert scores.max() > 0.5  # five classes: chance is 0.2
    model = pickle.loads(pickle.dumps(grid.best_estimator_))
    assert_array_equal(model.predict(clouds), grid.predict(clouds))


# -- bad input and properties ----------------------------------------------------


@pytest.mark.parametrize(
    ("A", "B", "kw", "message"),
    [
        ([[1.0, np.nan, 2]], [[1.0, 2, 3]], {}, "A contains NaN"),
        ([[1.0, 2, 3]], [[1.0, np.inf, 3]], {}, "B contains infinity"),
        ([[1.0, 2, 3]], [[1.0, 2]], {}, "A has 3 columns and B has 2"),
        ([1.0, 2, 3], [1.0, 2, 3], {}, "Expected 2D array"),
        (np.ones((2, 2, 2)), np.ones((2, 2, 2)), {}, "dim 3"),
        (np.empty((0, 3)), [[1.0, 2, 3]], {}, "0 sample"),
        ([[1.0]], [[2.0]], {"volume_column": 0}, "minimum of 2"),
        ([[1.0, 2, 3]], [[2.0, 1, 1]], {"volume_column": 5}, "out of range"),
        ([[1.0, 2, 3]], [[2.0, 1, 1]], {"volume_column": 0, "w1": 3}, "w1"),
        ([[1.0, 2, 3]], [[2.0, 1, 1]], {"volume_column": 0, "w1": -1}, "w1"),
    ],
)
def test_case_similarity_rejects_bad_input(A, B, kw, message):
    # before: NaN for NaN/inf, a silently wrapped volume_column, w1 = 3
    # giving 1.5, and matmul/einsum/AxisError messages for bad shapes
    with pytest.raises(ValueError, match=message):
        case_similarity(A, B, **kw)


def test_extreme_magnitudes_give_the_correlation_of_the_scaled_histograms():
    # the sums of squares overflowed (NaN) or underflowed (a wrong 1.0)
    want = case_similarity([[1.0, 2, 0]], [[1.0, 3, 1]])
    assert_allclose(want, [[np.sqrt(3) / 2]])
    for scale in (1e-200, 1e200):
        a, b = [[scale, 2 * scale, 0]], [[scale, 3 * scale, scale]]
        assert_allclose(case_similarity(a, b), want, rtol=1e-12)
        model = CaseBasedClassifier(threshold=None).fit(b, ["b"])
        assert_allclose(model.class_similarity(a), want, rtol=1e-12)


def test_unknown_label_must_be_a_scalar_and_uint_classes_do_not_wrap():
    from sklearn.utils._param_validation import InvalidParameterError

    X = _cases(10, seed=3)[:, 1:]
    y = np.arange(10) % 2
    # a list was broadcast into the predictions: [1], a training class
    with pytest.raises(InvalidParameterError, match="unknown_label"):
        CaseBasedClassifier(unknown_label=[1], threshold=0.99).fit(X, y)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # was: overflow in scalar subtract
        model = CaseBasedClassifier(threshold=0.99).fit(X, y.astype(np.uint8))
    assert model.unknown_label_ == -1
    assert (model.predict(-X) == -1).any()


_hist = st.lists(
    st.lists(st.one_of(st.just(0.0), st.floats(0.5, 100.0)), min_size=5, max_size=5),
    min_size=1,
    max_size=6,
)


@settings(max_examples=60, deadline=None)
@given(a=_hist, b=_hist, scale=st.floats(1e-3, 1e3))
def test_case_similarity_properties(a, b, scale):
    A, B = np.array(a), np.array(b)
    S = case_similarity(A, B)
    assert ((S >= -1) & (S <= 1)).all()
    assert_allclose(case_similarity(B, A), S.T, atol=1e-12)  # symmetric
    # a histogram scaled by a positive factor is as similar to every case
    assert_allclose(case_similarity(scale * A, B), S, atol=1e-9)
    V = np.column_stack([np.arange(len(A)) * scale, A])
    W = np.column_stack([np.arange(len(B)) + 1.0, B])
    SV = case_similarity(V, W, w1=0.3, volume_column=0)
    assert ((SV >= -1) & (SV <= 1)).all()
    assert_allclose(case_similarity(W, V, w1=0.3, volume_column=0), SV.T, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(4, 12),
    threshold=st.sampled_from([None, 0.0, 0.8]),
)
def test_predictions_do_not_depend_on_the_order_of_the_cases(seed, n, threshold):
    rng = np.random.default_rng(seed)
    X = _cases(n, n_bins=6, seed=seed)
    y = rng.choice(["a", "b", "c"], n)
    Q = _cases(5, n_bins=6, seed=seed + 1)
    perm = rng.permutation(n)
    params = {"volume_column": 0, "w1": 0.3, "threshold": threshold}
    model = CaseBasedClassifier(**params).fit(X, y)
    shuffled = CaseBasedClassifier(**params).fit(X[perm], y[perm])
    # class similarities are maxima over each class: the order cannot matter
    assert_array_equal(shuffled.class_similarity(Q), model.class_similarity(Q))
    # ties between classes go to the first of classes_, sorted either way
    assert_array_equal(shuffled.predict(Q), model.predict(Q))
    # retrieve: the same ranked similarities, of the same cases
    s1, i1 = model.retrieve(Q, n_cases=n)
    s2, i2 = shuffled.retrieve(Q, n_cases=n)
    assert_array_equal(s1, s2)
    assert_array_equal(np.sort(perm[i2], axis=1), np.sort(i1, axis=1))


def test_one_class_library_answers_the_class_or_unknown():
    X = _cases(12, seed=10)[:, 1:]
    model = CaseBasedClassifier(threshold=0.9).fit(X, ["lamp"] * 12)
    assert_array_equal(model.classes_, ["lamp"])
    Q = np.vstack([X[5:7], -X[5:7]])  # two known cases, two anti-correlated
    assert model.predict(Q).tolist() == ["lamp", "lamp", "unknown", "unknown"]
    assert model.decision_function(Q).shape == (4, 1)
    always = CaseBasedClassifier(threshold=None).fit(X, ["lamp"] * 12)
    assert always.predict(Q).tolist() == ["lamp"] * 4


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_centred_unit_rows_order_neighbours_as_the_correlation(seed):
    # the approximate search's Euclidean index over these rows finds the
    # neighbours by correlation: squared distance = 2 * (1 - r)
    from skpcd.classification._case_based import _centred_unit_rows

    rng = np.random.default_rng(seed)
    H = np.abs(rng.normal(size=(30, 20))) * rng.integers(0, 2, size=(30, 20))
    H[1:, 0] += 1.0  # no other row constant
    H[0] = 3.0  # a constant row: zero, at distance 1 from every unit row
    U = _centred_unit_rows(H).astype(np.float64)
    d2 = ((U[:, None, :] - U[None, :, :]) ** 2).sum(-1)
    r = np.corrcoef(H[1:])
    assert_allclose(d2[1:, 1:], 2 * (1 - r), atol=1e-5)
    assert_allclose(U[0], 0.0)
