"""Checks for estimators whose X is a ragged sequence of point clouds.

scikit-learn's common checks feed 2-D arrays and skip estimators tagged
``two_d_array=False``, so they say nothing about skpcd's transformers. These
checks fill that gap: each takes an estimator, a list of clouds and
optionally labels, and raises ``AssertionError`` on failure.
"""

import pickle

import numpy as np
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

__all__ = ["check_ragged_estimator", "ragged_checks"]


def _output(estimator, X):
    if hasattr(estimator, "transform"):
        return estimator.transform(X)
    if hasattr(estimator, "predict"):
        return estimator.predict(X)
    raise AssertionError(
        f"{type(estimator).__name__} has neither transform nor predict"
    )


def _assert_same(a, b, msg):
    if isinstance(a, np.ndarray) and a.dtype != object:
        np.testing.assert_array_equal(a, b, err_msg=msg)
        return
    assert len(a) == len(b), f"{msg}: lengths {len(a)} != {len(b)}"
    for i, (u, v) in enumerate(zip(a, b)):
        np.testing.assert_array_equal(u, v, err_msg=f"{msg} (item {i})")


def _fit(estimator, X, y):
    return estimator.fit(X) if y is None else estimator.fit(X, y)


def check_fit_returns_self_and_output_length(estimator, X, y=None):
    """``fit`` returns the estimator and the output has one item per cloud."""
    est = clone(estimator)
    assert _fit(est, X, y) is est, "fit must return self"
    out = _output(est, X)
    assert len(out) == len(X), f"{len(out)} outputs for {len(X)} clouds"


def check_not_fitted(estimator, X, y=None):
    """An estimator that needs fitting raises NotFittedError before fit."""
    est = clone(estimator)
    if not est.__sklearn_tags__().requires_fit:
        return
    try:
        _output(est, X)
    except NotFittedError:
        return
    raise AssertionError("using an unfitted estimator must raise NotFittedError")


def check_fit_idempotent(estimator, X, y=None):
    """Fitting twice gives the same outputs as fitting once."""
    est = clone(estimator)
    first = _output(_fit(est, X, y), X)
    second = _output(_fit(est, X, y), X)
    _assert_same(first, second, "fit is not idempotent")


def check_pickle_round_trip(estimator, X, y=None):
    """A pickled and reloaded fitted estimator gives identical outputs."""
    est = _fit(clone(estimator), X, y)
    again = pickle.loads(pickle.dumps(est))
    _assert_same(_output(est, X), _output(again, X), "pickling changes the output")


def check_cloud_permutation(estimator, X, y=None):
    """Permuting the clouds at transform time permutes the outputs."""
    est = _fit(clone(estimator), X, y)
    out = _output(est, X)
    order = np.random.default_rng(0).permutation(len(X))
    permuted = _output(est, [X[i] for i in order])
    _assert_same(
        [out[i] for i in order], list(permuted), "outputs depend on cloud order"
    )
    _assert_same(
        list(_output(est, X[:2])), [out[0], out[1]], "a prefix gives other outputs"
    )


def check_container_types(estimator, X, y=None):
    """A list, a tuple and a 1-D object array of clouds give the same result."""
    est = _fit(clone(estimator), X, y)
    obj = np.empty(len(X), dtype=object)
    for i, cloud in enumerate(X):
        obj[i] = cloud
    ref = _output(est, list(X))
    _assert_same(ref, _output(est, tuple(X)), "tuple input differs from list input")
    _assert_same(ref, _output(est, obj), "object-array input differs from list input")


def check_read_only_input(estimator, X, y=None):
    """Read-only clouds (as joblib's memmaps are) are accepted and unchanged."""
    frozen = []
    for cloud in X:
        c = np.array(cloud, copy=True)
        c.flags.writeable = False
        frozen.append(c)
    est = _fit(clone(estimator), frozen, y)
    _assert_same(_output(est, X), _output(est, frozen), "read-only input differs")
    for a, b in zip(X, frozen):
        np.testing.assert_array_equal(a, b)


def check_lone_array_refused(estimator, X, y=None):
    """A single 2-D array as X is refused with the 'wrap it' message."""
    est = _fit(clone(estimator), X, y)
    try:
        _output(est, np.asarray(X[0]))
    except ValueError as exc:
        assert "[cloud]" in str(exc), f"unhelpful message: {exc}"
        return
    raise AssertionError("a lone 2-D array must be refused")


def check_n_jobs_invariance(estimator, X, y=None):
    """``n_jobs=1`` and ``n_jobs=2`` give identical results."""
    if "n_jobs" not in estimator.get_params():
        return
    one = _output(_fit(clone(estimator).set_params(n_jobs=1), X, y), X)
    two = _output(_fit(clone(estimator).set_params(n_jobs=2), X, y), X)
    _assert_same(one, two, "n_jobs changes the output")


def ragged_checks():
    """The ragged-input checks, in the order they run.

    Returns
    -------
    checks : list of callable
        Functions ``check(estimator, X, y=None)``.
    """
    return [
        check_fit_returns_self_and_output_length,
        check_not_fitted,
        check_fit_idempotent,
        check_pickle_round_trip,
        check_cloud_permutation,
        check_container_types,
        check_read_only_input,
        check_lone_array_refused,
        check_n_jobs_invariance,
    ]


def check_ragged_estimator(estimator, X, y=None):
    """Run every ragged-input check on one estimator.

    Parameters
    ----------
    estimator : estimator instance
        An unfitted skpcd (or compatible) estimator taking a list of clouds.
    X : list of ndarray of shape (n_points_i, 3+)
        At least two clouds to fit and transform or predict.
    y : array-like of shape (n_clouds,), default=None
        Labels, for supervised estimators.

    Raises
    ------
    AssertionError
        From the first check that fails, naming what went wrong.

    Examples
    --------
    >>> from skpcd.datasets import make_point_clouds
    >>> from skpcd.features import ShapeFeatures
    >>> from skpcd.utils.estimator_checks import check_ragged_estimator
    >>> check_ragged_estimator(ShapeFeatures(), make_point_clouds(4, random_state=0))
    """
    for check in ragged_checks():
        check(estimator, X, y)
