"""Case-based identification of segments (Wang et al., 2023, section 3.4)."""

import contextlib
import functools
import typing
from numbers import Integral, Real

import numpy as np
from sklearn import get_config
from sklearn.base import BaseEstimator, ClassifierMixin, _fit_context
from sklearn.compose import ColumnTransformer
from sklearn.pipeline import FeatureUnion, Pipeline, make_pipeline
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_array, check_is_fitted, validate_data
from threadpoolctl import threadpool_limits

from skpcd.classification._unknown import best_or_unknown, unknown_label_for
from skpcd.features import ImprovedPFHTransformer, OverallDescriptor
from skpcd.features._overall import OVERALL_NAMES
from skpcd.utils._parallel import effective_threads, map_batches, task_threads

__all__ = ["CaseBasedClassifier", "case_similarity", "make_case_based_pipeline"]

# Above this many cases, algorithm="auto" searches the approximate index.
AUTO_APPROXIMATE = 20_000
# A case whose variance over the peak dimensions is below this fraction of its
# sum of squares is constant there (the correlation is undefined).
_CONSTANT_RTOL = 1e-9
# Bytes of the temporaries of one (query, case) pair, for blocks of queries
# sized by scikit-learn's ``working_memory``.
_PAIR_BYTES = 8 * 10
# Rows of every matrix product of histograms (see _rows_dot).
_DOT_ROWS = 64


def _centred_unit_rows(H):
    """Rows minus their mean, scaled to unit length, as float32.

    Between such rows the squared Euclidean distance is ``2 * (1 - r)``,
    ``r`` the correlation of the original rows: the neighbours by
    correlation, searched with pynndescent's Euclidean index (compiled once
    and cached on disk; its correlation index compiles a search function
    for every index built, seconds each). Constant rows stay zero.
    """
    centred = H - H.mean(axis=1, keepdims=True)
    norm = np.linalg.norm(centred, axis=1, keepdims=True)
    return np.ascontiguousarray(
        np.divide(centred, norm, out=np.zeros_like(centred), where=norm > 0),
        dtype=np.float32,
    )


def _split(X, volume_column):
    """The volumes (or None) and the histograms, as float64.

    Each histogram is divided by its largest absolute value: the
    correlation does not change, and neither its sums of squares overflow
    (values above 1e154) nor underflow (below 1e-154).
    """
    X = np.asarray(X, dtype=np.float64)
    if volume_column is None:
        volume, H = None, X
    else:
        col = volume_column % X.shape[1]
        volume = X[:, col].copy()
        if (volume < 0).any():
            raise ValueError(
                f"column {volume_column} holds the volumes and must not be "
                f"negative; got {volume.min()} (set volume_column=None to use no "
                "volume)"
            )
        H = np.delete(X, col, axis=1)
    scale = np.abs(H).max(axis=1, initial=0.0, keepdims=True)
    return volume, H / np.where(scale > 0, scale, 1.0)


def _rows_dot(A, B):
    """``A @ B``, each row the same whatever the rows of ``A`` around it.

    BLAS rounds a product differently with its shape: NumPy hands one row
    to ``gemv``, and OpenBLAS multiplies small products with other kernels
    than large ones. The rows of ``A`` are therefore multiplied in chunks
    of exactly ``_DOT_ROWS`` (the last one padded with zeros): every call
    has the same shape, and a row's result does not depend on its place in
    a chunk (checked for 3 to 20 000 cases of 33 to 343 features, on 1 and
    2 BLAS threads). A query then gets the same similarities alone, in a
    block or in a batch run elsewhere.
    """
    n = len(A)
    out = np.empty((n, B.shape[1]))
    for lo in range(0, n, _DOT_ROWS):
        chunk = A[lo : lo + _DOT_ROWS]
        if len(chunk) < _DOT_ROWS:
            pad = np.zeros((_DOT_ROWS - len(chunk), A.shape[1]), dtype=A.dtype)
            chunk = np.concatenate([chunk, pad])
        out[lo : lo + _DOT_ROWS] = (chunk @ B)[: n - lo]
    return out


def _blas_limit():
    """At most the task's threads for BLAS inside a dispatched batch."""
    n = task_threads()
    if n is None:
        return contextlib.nullcontext()
    return threadpool_limits(n, user_api="blas")


def _stats(H):
    """Per histogram: its peak indicator, peak count, sum and sum of squares."""
    peaks = (H != 0).astype(np.float64)
    return peaks, peaks.sum(axis=1), H.sum(axis=1), np.einsum("ij,ij->i", H, H)


def _combine(xy, shared, q, c, w1):
    """Similarity from the cross products of a query (``q``) and a case (``c``).

    ``xy`` and ``shared`` are the dot products of the histograms and of their
    peak indicators; ``q`` and ``c`` are ``(volume, n_peaks, sum, sum of
    squares)``, each broadcast against ``xy``. The Pearson correlation over
    the union of the two peak sets needs nothing else: outside its own
    peaks a histogram is zero, so its sums over the union are its sums over
    all dimensions, and only the union's size depends on the pair.
    """
    vq, kq, sq, qq = q
    vc, kc, sc, qc = c
    n = kq + kc - shared
    cov = n * xy - sq * sc
    var_q = n * qq - sq * sq
    var_c = n * qc - sc * sc
    flat_q = var_q <= _CONSTANT_RTOL * n * qq
    flat_c = var_c <= _CONSTANT_RTOL * n * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        s = cov / np.sqrt(var_q * var_c)
    np.clip(s, -1.0, 1.0, out=s)
    # both flat over the same peaks: equal up to scale; one flat: undefined
    s = np.where(flat_q | flat_c, np.where(flat_q & flat_c, 1.0, 0.0), s)
    s = np.where((kq == 0) | (kc == 0), 0.0, s)
    if vq is None:
        return s
    lo, hi = np.minimum(vq, vc), np.maximum(vq, vc)
    with np.errstate(invalid="ignore", divide="ignore"):
        s_r = np.where(hi > 0, lo / np.where(hi > 0, hi, 1.0), 1.0)
    return w1 * s_r + (1.0 - w1) * s


def case_similarity(A, B, *, w1=0.5, volume_column=None):
    """Similarity of every case of ``A`` with every case of ``B``.

    ``w1 * S_r + (1 - w1) * S_a`` (Wang et al., 2023, equations 1-3):
    ``S_r = 1 - |V_i - V_j| / max(V_i, V_j)`` compares the volumes and
    ``S_a`` is the Pearson correlation of the two histograms over the
    dimensions where either is non-zero (the paper's peaks).

    Parameters
    ----------
    A : array-like of shape (n_a, n_features)
        Cases, one per row: a histogram and, when ``volume_column`` is
        given, a volume.
    B : array-like of shape (n_b, n_features)
        Cases, in the same layout.
    w1 : float, default=0.5
        Weight of the volume term; the histogram's is ``1 - w1``. Ignored
        when ``volume_column`` is None.
    volume_column : int, default=None
        Column of the volumes (non-negative); None: no volume, the
        similarity is ``S_a``.

    Returns
    -------
    similarity : ndarray of shape (n_a, n_b)
        Between -1 and 1. See :class:`CaseBasedClassifier` for the
        undefined cases.

    Raises
    ------
    ValueError
        If ``A`` or ``B`` is not 2-D, is empty or holds NaN or infinite
        values, if their widths differ, if ``volume_column`` is out of range
        or a volume is negative, or if ``w1`` is not in [0, 1].

    Examples
    --------
    >>> from skpcd.classification import case_similarity
    >>> a = [[2.0, 10, 0, 30, 60, 0]]
    >>> b = [[4.0, 0, 20, 30, 50, 0]]
    >>> round(float(case_similarity(a, b, w1=0.5, volume_column=0)[0, 0]), 4)
    0.6737
    """
    if not (isinstance(w1, Real) and 0 <= w1 <= 1):
        raise ValueError(f"w1 must be a number from 0 to 1, got {w1!r}")
    min_features = 1 if volume_column is None else 2
    kw = {"dtype": np.float64, "ensure_min_features": min_features}
    A = check_array(A, input_name="A", **kw)
    B = check_array(B, input_name="B", **kw)
    if A.shape[1] != B.shape[1]:
        raise ValueError(
            f"A has {A.shape[1]} columns and B has {B.shape[1]}: the cases must "
            "have the same layout"
        )
    if volume_column is not None:
        if not isinstance(volume_column, Integral):
            raise TypeError(
                f"volume_column must be an int or None, got {volume_column!r}"
            )
        if not -A.shape[1] <= volume_column < A.shape[1]:
            raise ValueError(
                f"volume_column={volume_column} is out of range for cases with "
                f"{A.shape[1]} columns"
            )
    va, Ha = _split(A, volume_column)
    vb, Hb = _split(B, volume_column)
    pa, *sa = _stats(Ha)
    pb, *sb = _stats(Hb)
    q = (None if va is None else va[:, None], *(s[:, None] for s in sa))
    c = (None if vb is None else vb[None, :], *(s[None, :] for s in sb))
    return _combine(_rows_dot(Ha, Hb.T), pa @ pb.T, q, c, w1)


class CaseBasedClassifier(ClassifierMixin, BaseEstimator):
    """Identify a segment by its most similar known case (Wang et al., 2023).

    The case library is the training set. The similarity of two cases
    ``i`` and ``j`` is ``w1 * S_r + (1 - w1) * S_a``: ``S_r = 1 - |V_i -
    V_j| / max(V_i, V_j)`` compares their volumes (the overall descriptor),
    ``S_a`` is the Pearson correlation of their histograms (the detailed
    descriptor, e.g. the improved PFH) over the dimensions where either
    histogram is non-zero. A segment gets the class of the most similar
    case, or ``unknown_label`` when no case is at least ``threshold``
    similar.

    Read more in the :ref:`User Guide <case_based>`.

    Parameters
    ----------
    w1 : float, default=0.5
        Weight of the volume term, between 0 and 1; the histogram's weight
        is ``w2 = 1 - w1``. The paper leaves both to the user. Ignored when
        ``volume_column`` is None. Tune it: on the DALES objects an inner
        cross-validation chose ``w1`` between 0.005 and 0.1, and 0.5 cost
        8 to 16 points of accuracy (:ref:`identification`).
    volume_column : int, default=None
        Column of X holding the volumes (negative indices count from the
        end); the other columns are the histogram. None: every column is
        the histogram and the similarity is ``S_a`` alone (as ``w1=0``).
        :func:`make_case_based_pipeline` puts the volume in column 0.
    threshold : float or None, default=0.8
        Least similarity for an answer (the paper's 0.8); a segment whose
        best similarity is lower is ``unknown_label``. None: always answer.
    unknown_label : str, int, float or None, default=None
        The prediction for segments like no case. None: ``"unknown"`` for
        string or object labels; for numeric ones ``-1``, or one less than
        the smallest class when that is below 0 (``-2`` for classes -1 and
        1). A given label must not be a training class.
    algorithm : {"auto", "exact", "approximate"}, default="auto"
        ``"exact"`` compares each query with every case (blocks of queries
        times cases, in NumPy). ``"approximate"`` asks a pynndescent index
        per class for candidates and compares the query with those only.
        ``"auto"``: approximate above 20000 cases.
    n_candidates : int, default=30
        Candidates per class from the approximate index (at least twice
        the ``n_cases`` of :meth:`retrieve`), re-ranked by the exact
        similarity. More: better recall, slower queries.
    random_state : int, RandomState instance or None, default=None
        Seeds the approximate index.
    n_jobs : int, default=None
        Threads for building and querying the approximate index; None means
        1, -1 all cores. The exact search uses NumPy's BLAS threads. Under
        a backend chosen with :func:`joblib.parallel_config` (e.g.
        ``"dask"``), the queries of :meth:`predict`,
        :meth:`decision_function`, :meth:`class_similarity` and
        :meth:`retrieve` run in batches at once (None: the backend's), each
        on the cores left to its task.

    Attributes
    ----------
    classes_ : ndarray of shape (n_classes,)
        The training classes (never ``unknown_label``).
    unknown_label_ : str, int or float
        The label of unidentified segments.
    algorithm_ : {"exact", "approximate"}
        The search used.
    n_samples_fit_ : int
        Cases in the library.
    n_features_in_ : int
        Columns of X (volume included).
    feature_names_in_ : ndarray of shape (``n_features_in_``,)
        Column names, when X has string column names.

    See Also
    --------
    case_similarity : The similarity matrix of two sets of cases.
    make_case_based_pipeline : Descriptors and this classifier in one pipeline.
    sklearn.neighbors.KNeighborsClassifier : Nearest neighbours under a metric.

    Notes
    -----
    *Input.* X is 2-D, one row per segment: the histogram (any width) and,
    when ``volume_column`` is given, a column of non-negative volumes. A
    :class:`~sklearn.pipeline.FeatureUnion` of the volume of
    :class:`~skpcd.features.OverallDescriptor` and of
    :class:`~skpcd.features.ImprovedPFHTransformer` builds it from a list
    of clouds; :func:`make_case_based_pipeline` does so in one line.

    *Undefined terms.* ``S_r = 1`` when both volumes are 0. ``S_a`` is
    undefined when a histogram is constant over the union of the two peak
    sets (in particular when the union has one dimension); it is then 1
    when both are (the same peaks, equal up to scale) and 0 when only one
    is. An all-zero histogram (``ImprovedPFHTransformer(undefined="zero")``
    for a segment without normals) has ``S_a = 0`` with every case. NaN or
    infinite values and negative volumes raise a ValueError.

    *One class.* A library of one class is allowed: with a ``threshold``
    each segment is that class or ``unknown_label_`` (is it a lamp post or
    something else?); without one, always that class.

    *Scores.* :meth:`class_similarity` is each class's best similarity;
    :meth:`decision_function` is the same, or for two classes the second
    minus the first, as scikit-learn expects. They are not probabilities:
    wrap the classifier in :class:`~sklearn.calibration.CalibratedClassifierCV`
    for those. Ties go to the first class of ``classes_``.

    *Search.* The exact search costs two matrix products per block of
    queries (memory bounded by scikit-learn's ``working_memory``). The
    approximate one builds, per class, a pynndescent index under the plain
    correlation of the histograms (a Euclidean index over the histograms
    centred and scaled to unit length: the same order), takes
    ``n_candidates`` neighbours from it and, with a volume column, the
    ``n_candidates`` cases of nearest volume, and re-ranks them exactly:
    on a quarter of 200 DALES objects queried against the rest, the best
    case is the exact one for at least 95 % of the queries (checked by the
    test suite).

    References
    ----------
    .. [1] C. Wang, X. Xiong, X. Zhang, L. Liu, W. Tan, X. Liu, H. Yang, "A 3D
       Point Cloud Feature Identification Method Based on Improved Point
       Feature Histogram Descriptor", Electronics 12, 3736, 2023.

    Examples
    --------
    >>> from skpcd.classification import CaseBasedClassifier
    >>> X = [[8.0, 60, 30, 10, 0], [9.0, 55, 35, 10, 0],
    ...      [1.0, 0, 10, 30, 60], [1.2, 0, 15, 25, 60]]
    >>> y = ["lamp", "lamp", "tree", "tree"]
    >>> model = CaseBasedClassifier(volume_column=0).fit(X, y)
    >>> model.predict([[8.5, 58, 32, 10, 0], [50.0, 25, 25, 25, 25]]).tolist()
    ['lamp', 'unknown']
    >>> sim, ind = model.retrieve([[1.1, 0, 12, 28, 60]], n_cases=2)
    >>> ind.tolist(), sim.round(3).tolist()
    ([[3, 2]], [[0.955, 0.953]])
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "w1": [Interval(Real, 0, 1, closed="both")],
        "volume_column": [Integral, None],
        "threshold": [Interval(Real, -1, 1, closed="both"), None],
        "unknown_label": [str, Real, None],
        "algorithm": [StrOptions({"auto", "exact", "approximate"})],
        "n_candidates": [Interval(Integral, 1, None, closed="left")],
        "random_state": ["random_state"],
        "n_jobs": [Integral, None],
    }

    def __init__(
        self,
        *,
        w1=0.5,
        volume_column=None,
        threshold=0.8,
        unknown_label=None,
        algorithm="auto",
        n_candidates=30,
        random_state=None,
        n_jobs=None,
    ):
        self.w1 = w1
        self.volume_column = volume_column
        self.threshold = threshold
        self.unknown_label = unknown_label
        self.algorithm = algorithm
        self.n_candidates = n_candidates
        self.random_state = random_state
        self.n_jobs = n_jobs

    def _check_X(self, X, *, reset, y=None):
        min_features = 1 if self.volume_column is None else 2
        kw = {"dtype": (np.float64, np.float32), "ensure_min_features": min_features}
        if reset:
            X, y = validate_data(self, X, y, **kw)
            c = self.volume_column
            if c is not None and not -X.shape[1] <= c < X.shape[1]:
                raise ValueError(
                    f"volume_column={c} is out of range for X with {X.shape[1]} columns"
                )
            return X, y
        return validate_data(self, X, reset=False, **kw)

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y):
        """Store the cases (and index them for the approximate search).

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            The cases: histograms and, in ``volume_column``, volumes.
        y : array-like of shape (n_samples,)
            Their classes.

        Returns
        -------
        self : CaseBasedClassifier
            The fitted classifier.
        """
        X, y = self._check_X(X, reset=True, y=y)
        check_classification_targets(y)
        self.classes_, self._y = np.unique(y, return_inverse=True)
        self.unknown_label_ = unknown_label_for(
            self.classes_, self.unknown_label, answered=self.threshold is not None
        )
        volume, H = _split(X, self.volume_column)
        self._volume, self._H = volume, H
        peaks, *stats = _stats(H)
        self._peaks, self._stats = peaks, stats
        self.n_samples_fit_ = len(H)
        order = np.argsort(self._y, kind="stable")
        self._order = order
        self._starts = np.searchsorted(self._y[order], np.arange(len(self.classes_)))
        algorithm = self.algorithm
        if algorithm == "auto":
            many = self.n_samples_fit_ > AUTO_APPROXIMATE
            algorithm = "approximate" if many else "exact"
        self.algorithm_ = algorithm
        self._indexes = self._build_indexes() if algorithm == "approximate" else None
        return self

    def __getstate__(self):
        # the pynndescent indexes hold generators that skops cannot store;
        # they are rebuilt from the cases and the seeds on first use
        state = super().__getstate__()
        if state.get("_indexes") is not None:
            state["_indexes"] = None
        return state

    def _build_indexes(self):
        """Per class: its cases, their volume order and a pynndescent index."""
        from pynndescent import NNDescent

        rng = check_random_state(self.random_state)
        n_jobs = effective_threads(self.n_jobs)
        out = []
        for c in range(len(self.classes_)):
            cases = np.flatnonzero(self._y == c)
            seed = int(rng.randint(np.iinfo(np.int32).max))
            by_volume = None
            if self._volume is not None:
                by_volume = cases[np.argsort(self._volume[cases], kind="stable")]
            index = None
            if len(cases) > 2 * self.n_candidates:
                index = NNDescent(
                    _centred_unit_rows(self._H[cases]),
                    metric="euclidean",
                    n_neighbors=min(30, len(cases) - 1),
                    random_state=seed,
                    n_jobs=n_jobs,
                )
                index.prepare()
            out.append((cases, by_volume, index))
        return out

    def _blocks(self, n_queries, row_bytes):
        budget = get_config()["working_memory"] * 2**20
        step = int(min(max(budget // max(row_bytes, 1), 1), max(n_queries, 1)))
        return [slice(i, min(i + step, n_queries)) for i in range(0, n_queries, step)]

    def _query(self, X):
        """Split validated queries into volumes, histograms and statistics."""
        volume, H = _split(X, self.volume_column)
        peaks, *stats = _stats(H)
        return volume, H, peaks, stats

    def _exact(self, volume, H, peaks, stats):
        """Similarity of every query with every case, block by block."""
        c = (
            None if self._volume is None else self._volume[None, :],
            *(s[None, :] for s in self._stats),
        )
        for rows in self._blocks(len(H), _PAIR_BYTES * self.n_samples_fit_):
            q = (
                None if volume is None else volume[rows, None],
                *(s[rows, None] for s in stats),
            )
            xy = _rows_dot(H[rows], self._H.T)
            # exact whatever the shape: sums of 0 and 1
            shared = peaks[rows] @ self._peaks.T
            yield rows, _combine(xy, shared, q, c, self.w1)

    def _candidates(self, volume, H, m):
        """Candidate cases per query (duplicates possible), grouped by class.

        Returns the candidates ``(n_queries, n_columns)`` and the first
        column of each class.
        """
        cols, starts = [], []
        H32 = _centred_unit_rows(H)
        if self._indexes is None:  # unpickled: rebuilt once, the same graphs
            self._indexes = self._build_indexes()
        for cases, by_volume, index in self._indexes:
            starts.append(sum(a.shape[1] for a in cols))
            if index is None or len(cases) <= 2 * m:
                cols.append(np.broadcast_to(cases, (len(H), len(cases))))
                continue
            found, _ = index.query(H32, k=m)
            # pynndescent marks neighbours it could not find by -1
            found = np.where(found < 0, found[:, :1], found)
            cols.append(cases[found])
            if by_volume is not None:
                # the m cases of nearest volume lie in a window of 2m
                at = np.searchsorted(self._volume[by_volume], volume)
                lo = np.clip(at - m, 0, len(cases) - 2 * m)
                cols.append(by_volume[lo[:, None] + np.arange(2 * m)])
        return np.concatenate(cols, axis=1), np.asarray(starts)

    def _approximate(self, volume, H, peaks, stats, m):
        """Similarity of each query with its candidates, block by block."""
        cand, starts = self._candidates(volume, H, m)
        # per query: the gathered histograms and peaks, and the pair terms
        row_bytes = cand.shape[1] * (16 * H.shape[1] + _PAIR_BYTES)
        for rows in self._blocks(len(H), row_bytes):
            idx = cand[rows]
            xy = np.einsum("qd,qcd->qc", H[rows], self._H[idx])
            shared = np.einsum("qd,qcd->qc", peaks[rows], self._peaks[idx])
            q = (
                None if volume is None else volume[rows, None],
                *(s[rows, None] for s in stats),
            )
            c = (
                None if self._volume is None else self._volume[idx],
                *(s[idx] for s in self._stats),
            )
            yield rows, idx, starts, _combine(xy, shared, q, c, self.w1)

    def class_similarity(self, X):
        """The best similarity of each segment with the cases of each class.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            The segments, laid out as in :meth:`fit`.

        Returns
        -------
        similarity : ndarray of shape (n_samples, n_classes)
            Columns in the order of ``classes_``; between -1 and 1.
        """
        check_is_fitted(self)
        X = self._check_X(X, reset=False)
        return map_batches(
            self._class_similarity_batch, X, self.n_jobs, sizes=np.ones(len(X))
        )

    def _class_similarity_batch(self, X, n_jobs):
        """:meth:`class_similarity` of validated queries (a batch of them)."""
        with _blas_limit():
            return self._class_similarity(X)

    def _class_similarity(self, X):
        q = self._query(X)
        out = np.empty((len(X), len(self.classes_)))
        if self.algorithm_ == "exact":
            for rows, S in self._exact(*q):
                out[rows] = np.maximum.reduceat(S[:, self._order], self._starts, 1)
        else:
            for rows, _, starts, S in self._approximate(*q, self.n_candidates):
                out[rows] = np.maximum.reduceat(S, starts, axis=1)
        return out

    def decision_function(self, X):
        """Per-class best similarity (for two classes: second minus first).

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            The segments, laid out as in :meth:`fit`.

        Returns
        -------
        scores : ndarray of shape (n_samples, n_classes) or (n_samples,)
            :meth:`class_similarity`; with two classes the difference of
            its columns, positive for ``classes_[1]``.
        """
        s = self.class_similarity(X)
        return s[:, 1] - s[:, 0] if s.shape[1] == 2 else s

    def predict(self, X):
        """The class of the most similar case, or ``unknown_label_``.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            The segments, laid out as in :meth:`fit`.

        Returns
        -------
        y : ndarray of shape (n_samples,)
            A class of ``classes_``, or ``unknown_label_`` where the best
            similarity is below ``threshold``. Its dtype holds both (object
            when one is a string and the other a number).
        """
        s = self.class_similarity(X)
        return best_or_unknown(s, self.classes_, self.threshold, self.unknown_label_)

    def retrieve(self, X, n_cases=5):
        """The most similar cases of each segment, most similar first.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            The segments, laid out as in :meth:`fit`.
        n_cases : int, default=5
            Cases per segment, at most ``n_samples_fit_``.

        Returns
        -------
        similarity : ndarray of shape (n_samples, n_cases)
            Their similarities, decreasing; ties in the order of the
            training set.
        indices : ndarray of shape (n_samples, n_cases)
            Their rows in the training set (``y_train[indices]`` are their
            classes).
        """
        check_is_fitted(self)
        if not isinstance(n_cases, Integral) or not 1 <= n_cases <= self.n_samples_fit_:
            raise ValueError(
                f"n_cases must be an integer from 1 to {self.n_samples_fit_} "
                f"(the cases fitted), got {n_cases!r}"
            )
        X = self._check_X(X, reset=False)
        func = functools.partial(self._retrieve_batch, n_cases=n_cases)
        return map_batches(func, X, self.n_jobs, sizes=np.ones(len(X)))

    def _retrieve_batch(self, X, n_jobs, n_cases):
        """:meth:`retrieve` of validated queries (a batch of them)."""
        with _blas_limit():
            return self._retrieve(X, n_cases)

    def _retrieve(self, X, n_cases):
        q = self._query(X)
        sim = np.empty((len(X), n_cases))
        ind = np.empty((len(X), n_cases), dtype=np.intp)
        if self.algorithm_ == "exact":
            for rows, S in self._exact(*q):
                top = np.argsort(-S, axis=1, kind="stable")[:, :n_cases]
                ind[rows] = top
                sim[rows] = np.take_along_axis(S, top, axis=1)
            return sim, ind
        m = max(self.n_candidates, 2 * n_cases)
        for rows, idx, _, S in self._approximate(*q, m):
            # each case once (duplicates from the two candidate sources)
            first = np.argsort(idx, axis=1, kind="stable")
            idx = np.take_along_axis(idx, first, axis=1)
            S = np.take_along_axis(S, first, axis=1)
            S[:, 1:][idx[:, 1:] == idx[:, :-1]] = -np.inf
            top = np.argsort(-S, axis=1, kind="stable")[:, :n_cases]
            ind[rows] = np.take_along_axis(idx, top, axis=1)
            sim[rows] = np.take_along_axis(S, top, axis=1)
        return sim, ind


def _volume_only(box):

    column = OVERALL_NAMES.index("volume")
    return Pipeline(
        [
            ("overall", OverallDescriptor(box=box)),
            ("select", ColumnTransformer([("volume", "passthrough", [column])])),
        ]
    )


def make_case_based_pipeline(descriptor=None, *, volume=True, box="aabb", **params):
    """Descriptors of each cloud, then a :class:`CaseBasedClassifier`.

    With ``volume=True`` a :class:`~sklearn.pipeline.FeatureUnion` puts the
    segment's box volume (:class:`~skpcd.features.OverallDescriptor`) in
    column 0 and the histogram after it, and the classifier reads the
    volume from column 0. The steps are named ``featureunion`` (its parts
    ``volume`` and ``histogram``) and ``casebasedclassifier``, so a grid
    search tunes ``casebasedclassifier__w1`` or
    ``featureunion__histogram__n_neighbors``.

    Parameters
    ----------
    descriptor : transformer, default=None
        Turns a list of clouds into one histogram row per cloud; None means
        ``ImprovedPFHTransformer(undefined="zero")`` (the paper's
        improved PFH). ``PFHTransformer(pooling="mean")`` is the classic
        PFH averaged over the points.
    volume : bool, default=True
        Compare the volumes too; False: the histograms only.
    box : {"aabb", "obb_xy"}, default="aabb"
        The box whose volume is compared (see
        :class:`~skpcd.features.OverallDescriptor`).
    **params : dict
        Parameters of :class:`CaseBasedClassifier` (``w1``, ``threshold``,
        ``unknown_label``...), except ``volume_column``.

    Returns
    -------
    pipeline : sklearn.pipeline.Pipeline
        An unfitted pipeline taking a list of clouds.

    Examples
    --------
    >>> from skpcd.classification import make_case_based_pipeline
    >>> from skpcd.datasets import make_urban_objects
    >>> clouds, labels = make_urban_objects(n_per_class=6, random_state=0)
    >>> model = make_case_based_pipeline(threshold=None)
    >>> model.fit(clouds[::2], labels[::2]).predict(clouds[1::2]).shape
    (15,)
    """

    if "volume_column" in params:
        raise TypeError("volume_column is set by the volume parameter")
    if descriptor is None:
        descriptor = ImprovedPFHTransformer(undefined="zero")
    if not volume:
        return make_pipeline(descriptor, CaseBasedClassifier(**params))
    union = FeatureUnion([("volume", _volume_only(box)), ("histogram", descriptor)])
    return make_pipeline(union, CaseBasedClassifier(volume_column=0, **params))
