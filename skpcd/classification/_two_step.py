"""Two-step classification: groups of similar classes first, then within groups.

He et al. (2017) classify mobile LiDAR segments in two steps: lamp posts,
street lights and traffic signs are merged into one "mixed pole" class while
a first classifier separates vehicle, tree and mixed pole; a second
classifier, trained on the pole-like segments only, tells the three apart.
:class:`TwoStepClassifier` implements this for any pair of scikit-learn
classifiers and any grouping of the labels.
"""

import typing
import warnings
from numbers import Integral, Number, Real

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, _fit_context, clone
from sklearn.metrics import confusion_matrix
from sklearn.model_selection import StratifiedKFold, check_cv, cross_val_predict
from sklearn.utils import get_tags
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.metaestimators import available_if
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import (
    _check_sample_weight,
    check_is_fitted,
    has_fit_parameter,
    validate_data,
)

__all__ = ["TwoStepClassifier"]

_LABEL_COLLECTIONS = (list, tuple, set, frozenset, np.ndarray)


def _check_name(value, what):
    """Labels and group names are strings or numbers (hashable scalars)."""
    if not isinstance(value, (str, Number, np.generic)):
        raise ValueError(
            f"groups: each {what} must be a string or a number, got "
            f"{type(value).__name__} {value!r}"
        )


def _label_to_group(groups):
    """Normalise ``groups`` to a dict ``{label: group}`` (explicit labels only)."""
    if groups is None:
        return {}
    values = list(groups.values())
    is_collection = [isinstance(v, _LABEL_COLLECTIONS) for v in values]
    if not any(is_collection):
        for label, group in groups.items():
            _check_name(label, "label")
            _check_name(group, f"group of label {label!r}")
        return dict(groups)
    if not all(is_collection):
        raise ValueError(
            "groups must be either {label: group} or {group: [labels, ...]}; "
            "got a dict mixing both (some values are lists of labels, some not)"
        )
    mapping = {}
    for group, labels in groups.items():
        _check_name(group, "group")
        if isinstance(labels, np.ndarray):
            labels = labels.ravel().tolist()
        labels = list(labels)
        if not labels:
            raise ValueError(f"group {group!r} lists no labels")
        for label in labels:
            _check_name(label, f"label of group {group!r}")
            if label in mapping and mapping[label] != group:
                raise ValueError(
                    f"label {label!r} is in two groups, {mapping[label]!r} and "
                    f"{group!r}"
                )
            mapping[label] = group
    return mapping


def _group_structure(groups, classes):
    """Group names (in order of their first class) and each class's group index.

    Classes absent from ``groups`` form a group of their own, named by the
    class label. Labels of ``groups`` absent from ``classes`` are dropped
    with a warning.
    """
    mapping = _label_to_group(groups)
    present = classes.tolist()
    unknown = [label for label in mapping if label not in set(present)]
    if unknown:
        warnings.warn(
            f"labels {unknown!r} of groups do not occur in y; they are ignored "
            "in this fit (they cannot be predicted)",
            UserWarning,
            stacklevel=4,
        )
    explicit = set(mapping.values())
    names, index, class_group = [], {}, np.empty(len(present), dtype=np.intp)
    for i, label in enumerate(present):
        if label in mapping:
            name = mapping[label]
        elif label in explicit:
            raise ValueError(
                f"class {label!r} is in no group, so it forms its own group "
                f"named {label!r}, but groups already has a group named "
                f"{label!r}; rename that group or assign the class"
            )
        else:
            name = label
        if name not in index:
            index[name] = len(names)
            names.append(name)
        class_group[i] = index[name]
    group_names = np.empty(len(names), dtype=object)
    group_names[:] = names
    return group_names, class_group


def _merge_confused(classes, confusion, threshold):
    """``{label: group}`` merging every class pair confused more than ``threshold``.

    ``confusion[i, j]`` is the fraction of the samples of class ``i``
    predicted as class ``j``. Classes ``i`` and ``j`` are linked when their
    symmetric confusion rate ``(confusion[i, j] + confusion[j, i]) / 2``
    exceeds ``threshold``; the groups are the connected components of these
    links (union-find, i.e. single-linkage agglomeration). A group of several
    classes is named by its labels joined with "+", in the order of
    ``classes``; a class alone keeps no entry (it is its own group).
    """
    n = len(classes)
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    rate = (confusion + confusion.T) / 2
    for i in range(n):
        for j in range(i + 1, n):
            if rate[i, j] > threshold:
                a, b = root(i), root(j)
                if a != b:
                    parent[max(a, b)] = min(a, b)
    members = {}
    for i in range(n):
        members.setdefault(root(i), []).append(i)
    names = classes.tolist()
    taken = {str(c) for c in names}
    mapping = {}
    for rows in members.values():
        if len(rows) < 2:
            continue
        name = "+".join(str(names[i]) for i in rows)
        while name in taken:  # a class already bears that name
            name += "'"
        mapping.update({names[i]: name for i in rows})
    return mapping


def _has_proba(estimator):
    return hasattr(estimator, "predict_proba")


def _sub_estimators_have_proba(self):
    """Whether the fitted (else the template) sub-estimators have predict_proba."""
    if hasattr(self, "coarse_estimator_"):
        coarse = self.coarse_estimator_
        return (coarse is None or _has_proba(coarse)) and all(
            _has_proba(est) for est in self.fine_estimators_.values()
        )
    fine = self.coarse_estimator if self.fine_estimator is None else self.fine_estimator
    return _has_proba(self.coarse_estimator) and _has_proba(fine)


class TwoStepClassifier(ClassifierMixin, BaseEstimator):
    """Classify into groups of similar classes, then within each group.

    Step one: a clone of ``coarse_estimator`` learns the group of each
    sample, the fine labels being mapped to groups by ``groups`` (for
    instance lamp post, street light and traffic sign to "pole-like").
    Step two: for each group holding more than one class of ``y``, a clone
    of ``fine_estimator`` is trained on the samples of that group only and
    tells its classes apart. Rare classes that resemble each other are then
    separated by a classifier that sees only them, instead of being drowned
    by the abundant classes (He et al., 2017).

    Read more in the :ref:`User Guide <identification>`.

    Parameters
    ----------
    coarse_estimator : classifier
        Learns the groups. Cloned in :meth:`fit` and trained on the group
        index of each sample (0, 1, ... in the order of :attr:`groups_`).
    fine_estimator : classifier, default=None
        Template of the within-group classifiers, cloned once per group with
        more than one class. None means a clone of ``coarse_estimator``.
    groups : dict, "auto" or None, default=None
        The grouping of the fine labels: "auto" to learn it in :meth:`fit`
        from the confusions of a one-step classifier (see
        ``group_threshold``), or a dict in either of two forms:

        - ``{label: group}``, e.g. ``{"lamp post": "pole", "street light":
          "pole", "traffic sign": "pole"}``;
        - ``{group: [label, ...]}``, e.g. ``{"pole": ["lamp post", "street
          light", "traffic sign"]}`` (values that are lists, tuples, sets or
          arrays select this form).

        A class of ``y`` that is in no group forms its own group, named by
        its label; None (or ``{}``) thus makes every class its own group, and
        the classifier reduces to ``coarse_estimator``. Labels of ``groups``
        that do not occur in ``y`` are ignored with a warning (a rare class
        can be missing from a cross-validation fold). A label in two groups,
        a group with no labels, or a class left out whose label is also the
        name of a group is an error.
    method : {"cascade", "proba"}, default="cascade"
        How :meth:`predict` decides.

        - "cascade": the paper's procedure. The coarse estimator's
          :meth:`predict` picks a group; the group's fine estimator's
          :meth:`predict` picks the class. Works with classifiers that have
          no ``predict_proba`` (e.g. ``SVC()``).
        - "proba": the class maximising :meth:`predict_proba`, i.e.
          p(group) * p(class | group). Needs ``predict_proba`` on both
          estimators.

        The two can differ: with p(group) = (0.6, 0.4) for groups {a, b} and
        {c}, and p(a | {a, b}) = 0.55, the cascade says a, while the
        probabilities (0.33, 0.27, 0.40) say c.
    group_threshold : float in [0, 1], default=0.1
        With ``groups="auto"``: classes ``i`` and ``j`` join one group when
        their symmetric confusion rate, the mean of the fraction of ``i``
        predicted as ``j`` and the fraction of ``j`` predicted as ``i``,
        exceeds this; groups are then merged transitively (single linkage).
        1 keeps every class apart (one step), 0 merges every pair confused
        at all. A parameter like any other, so a grid search can tune it.
        Ignored unless ``groups="auto"``.
    cv : int, cross-validation generator or iterable, default=3
        With ``groups="auto"``: the cross-validation giving the confusions,
        out-of-fold predictions of a clone of ``coarse_estimator`` trained on
        the fine labels. An int is the number of folds of a shuffled
        :class:`~sklearn.model_selection.StratifiedKFold` (fewer if no class
        has that many samples); other values (a splitter, an iterable of
        (train, test) index arrays, None for 5 folds) go through
        :func:`~sklearn.model_selection.check_cv`. Ignored unless
        ``groups="auto"``.
    random_state : int, RandomState instance or None, default=None
        Shuffles the folds of an int ``cv``; an int makes the learned groups
        reproducible (if the estimators are). Ignored unless
        ``groups="auto"``.

    Attributes
    ----------
    classes_ : ndarray of shape (n_classes,)
        The fine labels seen in :meth:`fit`, sorted (``np.unique(y)``); the
        columns of :meth:`predict_proba` follow this order.
    groups_ : ndarray of object of shape (n_groups,)
        The group names, in the order of their first class in ``classes_``.
        With ``groups="auto"`` a learned group of several classes is named by
        its labels joined with "+" (``"lamp+sign"``), a class alone by its
        label.
        The coarse estimator predicts indices into this array:
        ``groups_[coarse_estimator_.predict(X)]`` are the predicted groups.
    group_of_ : dict
        The group name of each class in ``classes_``.
    group_classes_ : dict
        For each group name, the ndarray of its classes (sorted).
    confusion_ : ndarray of shape (n_classes, n_classes)
        Only with ``groups="auto"``: the cross-validated confusions the groups
        were learned from; row ``i`` holds the fractions of class
        ``classes_[i]`` predicted as each class (rows sum to 1).
    coarse_estimator_ : classifier or None
        The fitted clone of ``coarse_estimator``, trained on group indices;
        None when all classes of ``y`` are in one group (step one has
        nothing to decide, the fine estimator alone classifies).
    fine_estimators_ : dict
        For each group with more than one class in ``y``, the fitted clone of
        the fine estimator trained on that group's samples only. Groups with
        one class (by definition, or because a training fold holds only one
        of its classes) have none: their class is decided by step one.
    n_features_in_ : int
        Number of features seen in :meth:`fit`.
    feature_names_in_ : ndarray of shape (``n_features_in_``,)
        Names of the features seen in :meth:`fit`, when X has string column
        names.

    See Also
    --------
    sklearn.multiclass.OneVsRestClassifier : Another meta-classifier over
        the labels.

    Notes
    -----
    :meth:`predict_proba` gives p(class) = p(group) p(class | group), with
    p(class | group) = 1 for a group with one class; each row sums to 1.
    With ``method="cascade"`` :meth:`predict` is not always the argmax of
    :meth:`predict_proba` (see ``method``).

    ``sample_weight`` is passed to both estimators (the fine ones get the
    weights of their group's samples); both must accept it in ``fit``
    (a :class:`~sklearn.pipeline.Pipeline` does not, under that name).

    X is validated as a 2-D array (sparse if both estimators accept sparse
    input, NaN if both allow it). To classify lists of clouds, put the
    descriptor steps before this classifier in a pipeline.

    ``groups="auto"`` replaces the paper's hand-made grouping by the one its
    argument suggests: classes that a one-step classifier confuses go
    together. It costs ``cv`` extra fits of ``coarse_estimator`` on the fine
    labels. Rare classes weigh as much as abundant ones in the rates (they
    are fractions of each class), so a rare class mostly taken for another
    joins it. Learning the groups does not guarantee a better classifier:
    when the confused classes stay confused within their group, the two
    steps only redistribute the errors (see the User Guide).

    References
    ----------
    .. [1] H. He, K. Khoshelham, C. Fraser, "A two-step classification
       approach to distinguishing similar objects in mobile lidar point
       clouds", ISPRS Annals IV-2/W4, 2017 (section 4.3).

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.linear_model import LogisticRegression
    >>> from sklearn.tree import DecisionTreeClassifier
    >>> from skpcd.classification._two_step import TwoStepClassifier
    >>> X = np.array([[0.0, 0], [0, 1], [1, 0], [1, 1], [5, 0], [5, 1]] * 5)
    >>> y = np.array(["lamp", "sign", "lamp", "sign", "tree", "tree"] * 5)
    >>> clf = TwoStepClassifier(
    ...     LogisticRegression(),
    ...     DecisionTreeClassifier(random_state=0),
    ...     groups={"pole": ["lamp", "sign"]},
    ... ).fit(X, y)
    >>> clf.groups_
    array(['pole', 'tree'], dtype=object)
    >>> list(clf.fine_estimators_)
    ['pole']
    >>> clf.predict([[0, 0], [0, 1], [5, 0]])
    array(['lamp', 'sign', 'tree'], dtype='<U4')
    >>> bool(np.allclose(clf.predict_proba(X).sum(axis=1), 1))
    True

    Groups learned from the confusions of the coarse estimator: "lamp" and
    "sign" overlap, "tree" stands apart.

    >>> rng = np.random.default_rng(0)
    >>> X = np.vstack([rng.normal(m, 1, (30, 2)) for m in (0, 0.3, 8)])
    >>> y = np.repeat(["lamp", "sign", "tree"], 30)
    >>> clf = TwoStepClassifier(
    ...     LogisticRegression(), groups="auto", group_threshold=0.2, random_state=0
    ... ).fit(X, y)
    >>> clf.groups_
    array(['lamp+sign', 'tree'], dtype=object)
    >>> clf.confusion_.round(1)[2]
    array([0., 0., 1.])
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "coarse_estimator": [HasMethods(["fit", "predict"])],
        "fine_estimator": [HasMethods(["fit", "predict"]), None],
        "groups": [dict, StrOptions({"auto"}), None],
        "method": [StrOptions({"cascade", "proba"})],
        "group_threshold": [Interval(Real, 0, 1, closed="both")],
        "cv": ["cv_object"],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        coarse_estimator,
        fine_estimator=None,
        *,
        groups=None,
        method="cascade",
        group_threshold=0.1,
        cv=3,
        random_state=None,
    ):
        self.coarse_estimator = coarse_estimator
        self.fine_estimator = fine_estimator
        self.groups = groups
        self.method = method
        self.group_threshold = group_threshold
        self.cv = cv
        self.random_state = random_state

    def _fine_template(self):
        if self.fine_estimator is None:
            return self.coarse_estimator
        return self.fine_estimator

    def _input_kwargs(self):
        """validate_data options: sparse/NaN input if both estimators take it."""
        tags = get_tags(self).input_tags
        return {
            "accept_sparse": ["csr", "csc"] if tags.sparse else False,
            "ensure_all_finite": not tags.allow_nan,
        }

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y, sample_weight=None):
        """Fit the coarse estimator on groups and one fine estimator per group.

        Parameters
        ----------
        X : {array-like, sparse matrix} of shape (n_samples, n_features)
            Training data, e.g. one descriptor row per segment.
        y : array-like of shape (n_samples,)
            Fine labels.
        sample_weight : array-like of shape (n_samples,), default=None
            Sample weights, passed to both estimators.

        Returns
        -------
        self : TwoStepClassifier
            The fitted classifier.
        """
        X, y = validate_data(self, X, y, **self._input_kwargs())
        check_classification_targets(y)
        fine_template = self._fine_template()
        if self.method == "proba" and not (
            _has_proba(self.coarse_estimator) and _has_proba(fine_template)
        ):
            raise ValueError(
                'method="proba" needs predict_proba on both estimators; use '
                'method="cascade" or estimators with predict_proba'
            )
        if sample_weight is not None:
            sample_weight = _check_sample_weight(sample_weight, X)
            for role, est in (
                ("coarse", self.coarse_estimator),
                ("fine", fine_template),
            ):
                if not has_fit_parameter(est, "sample_weight"):
                    raise ValueError(
                        f"sample_weight is not supported: the {role} estimator "
                        f"{type(est).__name__} does not accept it in fit"
                    )

        self.classes_, y_index = np.unique(y, return_inverse=True)
        if len(self.classes_) < 2:
            raise ValueError(
                f"y contains 1 class ({self.classes_[0]!r}); a classifier needs "
                "samples of at least 2 classes"
            )
        groups = self.groups
        if isinstance(groups, str):  # "auto"
            groups = self._learn_groups(X, y, y_index, sample_weight)
        self.groups_, self._class_group = _group_structure(groups, self.classes_)
        self.group_of_ = {
            c: self.groups_[g] for c, g in zip(self.classes_, self._class_group)
        }
        self.group_classes_ = {
            name: self.classes_[self._class_group == g]
            for g, name in enumerate(self.groups_)
        }

        y_group = self._class_group[y_index]
        weight = {} if sample_weight is None else {"sample_weight": sample_weight}
        self.coarse_estimator_ = None
        if len(self.groups_) > 1:
            self.coarse_estimator_ = clone(self.coarse_estimator)
            self.coarse_estimator_.fit(X, y_group, **weight)
        self.fine_estimators_ = {}
        for g, name in enumerate(self.groups_):
            if np.count_nonzero(self._class_group == g) < 2:
                continue
            rows = np.flatnonzero(y_group == g)
            weight = {}
            if sample_weight is not None:
                weight = {"sample_weight": sample_weight[rows]}
            self.fine_estimators_[name] = clone(fine_template).fit(
                X[rows], y[rows], **weight
            )
        return self

    def _learn_groups(self, X, y, y_index, sample_weight):
        """Groups from the confusions of a cross-validated one-step classifier."""
        counts = np.bincount(y_index)
        if isinstance(self.cv, Integral):
            n_splits = min(self.cv, int(counts.max()))
            cv = None
            if n_splits >= 2:
                cv = StratifiedKFold(
                    n_splits, shuffle=True, random_state=self.random_state
                )
        else:
            cv = check_cv(self.cv, y, classifier=True)
        if cv is None:
            warnings.warn(
                "groups='auto': every class has a single sample, too few for a "
                "cross-validation; every class is its own group",
                UserWarning,
                stacklevel=3,
            )
            self.confusion_ = np.eye(len(self.classes_))
            return {}
        params = {} if sample_weight is None else {"sample_weight": sample_weight}
        with warnings.catch_warnings():
            # a class rarer than the folds: its samples are predicted anyway
            warnings.filterwarnings("ignore", "The least populated class")
            pred = cross_val_predict(
                clone(self.coarse_estimator), X, y, cv=cv, params=params
            )
        confusion = confusion_matrix(y, pred, labels=self.classes_).astype(float)
        self.confusion_ = confusion / counts[:, None]
        return _merge_confused(self.classes_, self.confusion_, self.group_threshold)

    def _class_index(self, labels):
        return np.searchsorted(self.classes_, labels)

    def _cascade(self, X):
        if self.coarse_estimator_ is None:
            group = np.zeros(X.shape[0], dtype=np.intp)
        else:
            group = self.coarse_estimator_.predict(X)
        single = np.array(
            [
                np.flatnonzero(self._class_group == g)[0]
                for g in range(len(self.groups_))
            ]
        )
        out = single[group]
        for g, name in enumerate(self.groups_):
            if name in self.fine_estimators_:
                rows = np.flatnonzero(group == g)
                if len(rows):
                    pred = self.fine_estimators_[name].predict(X[rows])
                    out[rows] = self._class_index(pred)
        return out

    def predict(self, X):
        """Predict the fine class of each sample.

        Parameters
        ----------
        X : {array-like, sparse matrix} of shape (n_samples, n_features)
            The samples.

        Returns
        -------
        y_pred : ndarray of shape (n_samples,)
            Labels from ``classes_``: by the cascade of hard decisions, or by
            the largest combined probability, as ``method`` says.
        """
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, **self._input_kwargs())
        if self.method == "proba":
            index = np.argmax(self._proba(X), axis=1)
        else:
            index = self._cascade(X)
        return self.classes_.take(index)

    def _proba(self, X):
        group_proba = np.ones((X.shape[0], len(self.groups_)))
        if self.coarse_estimator_ is not None:
            group_proba[:, self.coarse_estimator_.classes_] = (
                self.coarse_estimator_.predict_proba(X)
            )
        proba = np.zeros((X.shape[0], len(self.classes_)))
        for g, name in enumerate(self.groups_):
            if name in self.fine_estimators_:
                fine = self.fine_estimators_[name]
                columns = self._class_index(fine.classes_)
                proba[:, columns] = group_proba[:, [g]] * fine.predict_proba(X)
            else:
                proba[:, self._class_group == g] = group_proba[:, [g]]
        return proba

    @available_if(_sub_estimators_have_proba)
    def predict_proba(self, X):
        """Class probabilities p(group) * p(class | group).

        Available when the coarse and fine estimators have ``predict_proba``.

        Parameters
        ----------
        X : {array-like, sparse matrix} of shape (n_samples, n_features)
            The samples.

        Returns
        -------
        proba : ndarray of shape (n_samples, n_classes)
            Columns in the order of ``classes_``; rows sum to 1.
        """
        check_is_fitted(self)
        X = validate_data(self, X, reset=False, **self._input_kwargs())
        return self._proba(X)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        fine = self._fine_template()
        sub = [get_tags(self.coarse_estimator), get_tags(fine)]
        tags.input_tags.sparse = all(t.input_tags.sparse for t in sub)
        tags.input_tags.allow_nan = all(t.input_tags.allow_nan for t in sub)
        return tags
