"""A handful of real labels, completed by simulated objects of the same classes."""

import inspect
import numbers
import typing

import numpy as np
from sklearn.base import (
    BaseEstimator,
    ClassifierMixin,
    MetaEstimatorMixin,
    _fit_context,
    clone,
)
from sklearn.metrics import balanced_accuracy_score
from sklearn.utils import check_random_state, get_tags
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.metaestimators import available_if
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import _num_samples, check_is_fitted

from skpcd.classification._street import make_street_pipeline
from skpcd.classification._wrapped import _WrappedClassifierMixin
from skpcd.datasets import STREET_OBJECT_CLASSES, make_street_objects

__all__ = ["AUGMENT_SCANNERS", "SimulationAugmented", "simulate_objects"]

#: The scan patterns ``SimulationAugmented(scanner="auto")`` chooses from.
AUGMENT_SCANNERS = ("spinning", "mobile")


def simulate_objects(classes, n_per_class, scanner, seed, n_jobs=None, traffic=True):
    """``n_per_class`` randomised simulated objects of each class, centred:
    the training objects of the street model and of SimulationAugmented
    (``benchmarks/bench_sim_to_real.py`` measured each setting on real
    scans)."""
    clouds, labels = make_street_objects(
        n_per_class,
        classes=classes,
        scanner=scanner,
        randomise=True,
        min_points=20,
        segment_length=80.0,
        traffic=traffic,
        random_state=seed,
        n_jobs=n_jobs,
    )
    return [c - c.mean(axis=0) for c in clouds], np.asarray(labels, dtype=object)


def _fit_weighted(estimator, X, y, sample_weight):
    """Fit with per-sample weights given to the final step of a pipeline, or
    repeat the weighted samples when the estimator takes no weights."""
    final = estimator.steps[-1] if hasattr(estimator, "steps") else (None, estimator)
    name, step = final
    if _takes_weight(step):
        key = "sample_weight" if name is None else f"{name}__sample_weight"
        return estimator.fit(X, y, **{key: sample_weight})
    repeat = np.maximum(np.rint(sample_weight).astype(np.int64), 1)
    index = np.repeat(np.arange(len(y)), repeat)
    return estimator.fit(_take(X, index), np.asarray(y)[index])


def _take(X, index):
    """The samples ``index`` of an array or of a list of clouds."""
    return [X[i] for i in index] if isinstance(X, list) else X[index]


def _takes_weight(estimator):
    """Whether ``estimator.fit`` takes ``sample_weight`` (a meta-estimator
    passing its ``**fit_params`` on, such as RejectUnknown, asks its own)."""
    params = inspect.signature(estimator.fit).parameters
    if "sample_weight" in params:
        return True
    inner = getattr(estimator, "estimator", None)
    kwargs = any(p.kind is p.VAR_KEYWORD for p in params.values())
    return kwargs and inner is not None and _takes_weight(inner)


class SimulationAugmented(
    _WrappedClassifierMixin, MetaEstimatorMixin, ClassifierMixin, BaseEstimator
):
    """Train on a few real labelled segments plus simulated ones of their classes.

    A model fitted on a handful of real objects per class has seen too few
    of them; one fitted on simulated objects alone meets a scanner, a
    street and objects it did not see. ``fit(X, y)`` does both: for every
    class of ``y`` that the street simulator knows
    (:data:`~skpcd.datasets.STREET_OBJECT_CLASSES`: ``"car"``,
    ``"person"``, ``"pole"``, ``"tree"``, ``"traffic_sign"``...), it adds
    ``n_per_class`` simulated objects (:func:`~skpcd.datasets.make_street_objects`
    with ``randomise=True`` and ``traffic=True``), each real object counting
    ``real_weight``
    times a simulated one, and fits a clone of ``estimator`` on the union.
    Classes the simulator does not know are learnt from the real objects
    alone.

    Read more in the :ref:`User Guide <own_scans>`.

    Parameters
    ----------
    estimator : estimator or None, default=None
        The classifier to fit; None means
        :func:`~skpcd.classification.make_street_pipeline` (taking a list
        of clouds). Its final step should accept ``sample_weight`` (a
        random forest does); otherwise each real object is repeated
        ``round(real_weight)`` times.
    n_per_class : int, default=30
        Simulated objects added per simulated class.
    scanner : {"auto", "spinning", "mobile", "ugv"}, default="auto"
        The scan pattern of the simulated objects, its numbers randomised
        per street (:func:`~skpcd.datasets.make_street_objects`).
        ``"auto"`` simulates the classes with each pattern of
        ``AUGMENT_SCANNERS`` (spinning multi-beam sensors, profilers), fits
        ``estimator`` on each simulated set alone and keeps the pattern
        whose model labels the real ``X`` best (balanced accuracy): the
        pattern that matches the user's scanner by measurement.
    real_weight : float, default=5.0
        Weight of each real object relative to a simulated one.
    random_state : int, RandomState instance or None, default=None
        Seeds the simulation.
    n_jobs : int, default=None
        Threads for the simulation; None means 1, -1 all cores.

    Attributes
    ----------
    estimator_ : estimator
        The fitted clone of ``estimator``.
    classes_ : ndarray of shape (n_classes,)
        The classes of ``y``.
    simulated_classes_ : list of str
        The classes that got simulated objects.
    scanner_ : str or None
        The pattern used (None when no class was simulated).
    scanner_scores_ : dict
        With ``scanner="auto"``: the balanced accuracy on the real ``X`` of
        the simulation-only model of each pattern.
    n_simulated_ : int
        Simulated objects added.

    See Also
    --------
    load_street_model : A model fitted on simulated streets alone.
    make_street_pipeline : The default ``estimator``.

    Notes
    -----
    With no class the simulator knows (numeric labels, say), ``fit`` adds
    nothing and fits ``estimator`` on ``X`` and ``y`` alone, unweighted:
    this is how the estimator passes scikit-learn's checks on 2-D data.

    Examples
    --------
    >>> from skpcd.classification import SimulationAugmented
    >>> from skpcd.datasets import make_street_objects
    >>> real, y = make_street_objects(
    ...     2, classes=["car", "person"], scanner="spinning", min_points=20,
    ...     random_state=1,
    ... )
    >>> model = SimulationAugmented(
    ...     n_per_class=3, scanner="spinning", random_state=0
    ... ).fit(real, y)
    >>> model.n_simulated_, model.predict(real).shape
    (6, (4,))
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "estimator": [HasMethods(["fit", "predict"]), None],
        "n_per_class": [Interval(numbers.Integral, 1, None, closed="left")],
        "scanner": [StrOptions({"auto", "spinning", "mobile", "ugv"})],
        "real_weight": [Interval(numbers.Real, 0, None, closed="neither")],
        "random_state": ["random_state"],
        "n_jobs": [numbers.Integral, None],
    }

    def __init__(
        self,
        estimator=None,
        *,
        n_per_class=30,
        scanner="auto",
        real_weight=5.0,
        random_state=None,
        n_jobs=None,
    ):
        self.estimator = estimator
        self.n_per_class = n_per_class
        self.scanner = scanner
        self.real_weight = real_weight
        self.random_state = random_state
        self.n_jobs = n_jobs

    def _base(self):
        if self.estimator is not None:
            return clone(self.estimator)
        return make_street_pipeline(n_jobs=self.n_jobs)

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y):
        """Simulate objects of the classes of ``y`` and fit on both.

        Parameters
        ----------
        X : list of array-like
            The real training samples (clouds for the default estimator).
        y : array-like of shape (n_samples,)
            Their labels.

        Returns
        -------
        self : SimulationAugmented
            The fitted meta-estimator.
        """
        if y is None:
            raise ValueError(
                "SimulationAugmented requires y to be passed, but the target y is None"
            )
        if not hasattr(X, "shape") and not hasattr(X, "__array__"):
            X = list(X)
        n = _num_samples(X)
        if n != _num_samples(y):
            raise ValueError(f"X has {n} samples but y has {_num_samples(y)} labels")
        check_classification_targets(y)
        y = np.asarray(y)
        known = [c for c in np.unique(y).tolist() if c in STREET_OBJECT_CLASSES]
        self.simulated_classes_ = [str(c) for c in known]
        self.scanner_, self.scanner_scores_, self.n_simulated_ = None, {}, 0
        weight = np.full(len(y), float(self.real_weight))
        if not known:  # nothing to weigh the real objects against
            return self._adopt(self._base().fit(X, y))
        seed = int(check_random_state(self.random_state).randint(2**31 - 1))
        candidates = AUGMENT_SCANNERS if self.scanner == "auto" else (self.scanner,)
        pools = {
            s: simulate_objects(
                self.simulated_classes_, self.n_per_class, s, seed, self.n_jobs
            )
            for s in candidates
        }
        if len(pools) > 1:
            self.scanner_scores_ = {s: self._transfer(pools[s], X, y) for s in pools}
            scanner = max(pools, key=lambda s: self.scanner_scores_[s])
        else:
            scanner = candidates[0]
        sim_X, sim_y = pools[scanner]
        self.scanner_, self.n_simulated_ = scanner, len(sim_y)
        both_y = np.concatenate([y.astype(object), sim_y])
        weights = np.concatenate([weight, np.ones(len(sim_y))])
        return self._adopt(_fit_weighted(self._base(), [*X, *sim_X], both_y, weights))

    def _transfer(self, pool, X, y):
        """Balanced accuracy on the real objects of a model of ``pool`` alone."""
        sim_X, sim_y = pool
        model = self._base().fit(sim_X, sim_y)
        keep = np.isin(y, np.unique(sim_y))
        pred = model.predict(_take(X, np.flatnonzero(keep)))
        return float(balanced_accuracy_score(y[keep].astype(object), pred))

    def predict(self, X):
        """The class of each sample.

        Parameters
        ----------
        X : list of array-like
            The samples.

        Returns
        -------
        y : ndarray of shape (n_samples,)
            Predicted labels.
        """
        check_is_fitted(self)
        return self.estimator_.predict(X)

    # the wrapped estimator's, when the estimator has them
    predict_proba = available_if(lambda self: hasattr(self._base(), "predict_proba"))(
        _WrappedClassifierMixin.predict_proba
    )

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        if self.estimator is not None:
            tags.input_tags = get_tags(self.estimator).input_tags
        else:
            tags.input_tags.two_d_array = False
        tags.target_tags.required = True
        return tags
