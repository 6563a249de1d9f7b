"""The approximate (pynndescent) paths of BagOfFeatures, CaseBasedClassifier
and the model files, in one module.

pynndescent compiles its index for minutes on a cold numba cache and for
about a minute on a warm one, once per process. The suite runs with
``--dist loadfile``, so that one worker pays it, for every test here; the
folder's name puts the module first, so that it does not end the run alone.
All are marked slow: the README's test command leaves them out, CI runs them
in a second step (``-m slow``).
"""

import pickle

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from sklearn.base import clone
from sklearn.cluster import KMeans, MiniBatchKMeans

from skpcd.classification import CaseBasedClassifier
from skpcd.encoding import BagOfFeatures
from skpcd.io import load_model, save_model
from skpcd.utils.estimator_checks import check_ragged_estimator

pytestmark = pytest.mark.slow


def test_ragged_checks_of_the_approximate_assignment(dales_pfh):
    pfh, _ = dales_pfh
    # NaN rows and an empty cloud among them, as PFHTransformer can emit
    X = [*pfh[:7], np.empty((0, 125), np.float32)]
    bof = BagOfFeatures(n_words=20, assignment="approximate", random_state=0)
    check_ragged_estimator(bof, X)


def _one_hot_words(bof, descs):
    """The word of each descriptor, through transform of one-row clouds."""
    return bof.transform([row[None] for row in descs]).argmax(axis=1)


# real PFH only: on the synthetic objects' PFH (many repeated descriptors)
# MiniBatchKMeans leaves repeated words (289 distinct of 300), so 12 % of the
# queries get another word at the same distance (97 % of the differences are
# such ties) and the counts split between the copies
@pytest.mark.parametrize("labelled_objects", ["dales"], indirect=True)
def test_approximate_assignment_agrees_with_exact_on_real_pfh(dales_pfh):
    pfh, _ = dales_pfh
    rows = np.vstack(pfh)
    rows = rows[~np.isnan(rows).any(axis=1)]
    queries = rows[np.random.default_rng(0).choice(len(rows), 3000, replace=False)]
    params = {"n_words": 300, "norm": None, "random_state": 0, "max_descriptors": 6000}
    params["clusterer"] = MiniBatchKMeans(batch_size=1024, n_init=1, max_iter=20)
    exact = BagOfFeatures(assignment="exact", **params).fit(pfh)
    approx = BagOfFeatures(assignment="approximate", **params).fit(pfh)
    assert (exact.assignment_, approx.assignment_) == ("exact", "approximate")
    np.testing.assert_array_equal(exact.vocabulary_, approx.vocabulary_)
    want, got = _one_hot_words(exact, queries), _one_hot_words(approx, queries)
    agreement = np.mean(want == got)
    assert agreement >= 0.98, agreement
    # where they differ, the approximate word is nearly as close
    v = exact.vocabulary_.astype(np.float64)
    d_exact = np.linalg.norm(queries - v[want], axis=1)
    d_approx = np.linalg.norm(queries - v[got], axis=1)
    assert (d_approx >= d_exact - 1e-3).all()
    assert d_approx.sum() <= 1.01 * d_exact.sum()
    # and the counts of whole clouds barely move
    a, e = approx.transform(pfh), exact.transform(pfh)
    assert np.minimum(a, e).sum() / e.sum() >= 0.98


def test_auto_assignment_threshold(monkeypatch):
    # the documented threshold, then the rule at a small threshold (fitting
    # 2047 words to check it took 114 s)
    assert BagOfFeatures._APPROXIMATE_MIN_WORDS == 2048
    monkeypatch.setattr(BagOfFeatures, "_APPROXIMATE_MIN_WORDS", 16)
    rng = np.random.default_rng(0)
    X = [rng.normal(size=(300, 3)), rng.normal(size=(100, 3))]
    quick = KMeans(n_init=1, max_iter=1, init="random")
    for n_words, want in [(15, "exact"), (16, "approximate")]:
        bof = BagOfFeatures(n_words, clusterer=quick, random_state=0).fit(X)
        assert bof.assignment_ == want
    assert hasattr(bof, "_index")
    exact = bof.set_params(assignment="exact").fit(X)
    assert exact.assignment_ == "exact" and not hasattr(exact, "_index")


def test_pickled_approximate_encoder_gives_same_output(dales_pfh):
    pfh, _ = dales_pfh
    bof = BagOfFeatures(n_words=50, assignment="approximate", random_state=0)
    bof.fit(pfh[:10])
    again = pickle.loads(pickle.dumps(bof))
    np.testing.assert_array_equal(again.transform(pfh), bof.transform(pfh))


# The case-based approximate tests run on DALES only.
@pytest.mark.parametrize("labelled_objects", ["dales"], indirect=True)
def test_approximate_recall_on_dales(dales_cases):
    X, labels, _ = dales_cases
    train = np.arange(len(X)) % 4 != 0
    params = {"volume_column": 0, "w1": 0.3, "threshold": None}
    exact = CaseBasedClassifier(**params).fit(X[train], labels[train])
    approx = CaseBasedClassifier(
        **params, algorithm="approximate", n_candidates=5, random_state=0
    ).fit(X[train], labels[train])
    assert approx.algorithm_ == "approximate"
    assert all(index is not None for *_, index in approx._indexes)
    Q = X[~train]
    s_exact, i_exact = exact.retrieve(Q, n_cases=5)
    s_approx, i_approx = approx.retrieve(Q, n_cases=5)
    top1 = (i_exact[:, 0] == i_approx[:, 0]).mean()
    top5 = np.mean([len(set(a) & set(b)) / 5 for a, b in zip(i_exact, i_approx)])
    assert top1 >= 0.95
    assert top5 >= 0.9
    # candidates are cases: never more similar than the exact best
    assert (s_approx <= s_exact + 1e-12).all()
    cs_exact, cs_approx = exact.class_similarity(Q), approx.class_similarity(Q)
    assert (cs_approx <= cs_exact + 1e-12).all()
    assert (approx.predict(Q) == exact.predict(Q)).mean() >= 0.95
    # pickle and clone round trips
    again = pickle.loads(pickle.dumps(approx))
    assert_array_equal(again.retrieve(Q, n_cases=5)[1], i_approx)
    refit = clone(approx).fit(X[train], labels[train])
    assert_array_equal(refit.retrieve(Q, n_cases=5)[1], i_approx)


@pytest.mark.parametrize("labelled_objects", ["dales"], indirect=True)
def test_auto_switch(dales_cases, monkeypatch):
    from skpcd.classification import _case_based

    X, labels, _ = dales_cases
    assert CaseBasedClassifier().fit(X, labels).algorithm_ == "exact"
    monkeypatch.setattr(_case_based, "AUTO_APPROXIMATE", 100)
    model = CaseBasedClassifier(n_candidates=5).fit(X, labels)
    assert model.algorithm_ == "approximate"


@pytest.mark.parametrize("which", ["bag", "cases"])
def test_approximate_indexes_are_saved_and_rebuilt(tmp_path, which):
    # before: skops could not store the pynndescent indexes (TypeError:
    # cannot pickle 'generator' object)
    from skpcd.classification import CaseBasedClassifier
    from skpcd.encoding import BagOfFeatures

    rng = np.random.default_rng(0)
    if which == "bag":
        X = [rng.normal(size=(200, 4)) for _ in range(6)]
        model = BagOfFeatures(
            40, assignment="approximate", random_state=0, n_jobs=1
        ).fit(X)
        query, answer = X, model.transform
    else:
        X = np.abs(rng.normal(size=(120, 9)))
        y = np.repeat(["a", "b"], 60)
        model = CaseBasedClassifier(
            algorithm="approximate", n_candidates=10, n_jobs=1, random_state=0
        ).fit(X, y)
        query, answer = X, model.decision_function
    want = answer(query)
    save_model(model, tmp_path / "m.skpcd")
    again = load_model(tmp_path / "m.skpcd")
    fresh = pickle.loads(pickle.dumps(model))
    for other in (again, fresh):
        method = getattr(other, answer.__name__)
        np.testing.assert_array_equal(method(query), want)
    np.testing.assert_array_equal(answer(query), want)  # the original still works
