"""Bag of features: a vocabulary of local descriptors, and word counts per segment.

:class:`BagOfFeatures` clusters the local descriptors of the training clouds
(a bounded random sample of them) into ``n_words`` visual words, then
encodes each cloud as the histogram of the words its descriptors fall
nearest to. Word assignment is exact (blocked brute force) for small
vocabularies and approximate (pynndescent) for large ones.
"""

import typing
from numbers import Integral

import numpy as np
from sklearn.base import (
    BaseEstimator,
    ClassNamePrefixFeaturesOutMixin,
    TransformerMixin,
    _fit_context,
    clone,
)
from sklearn.cluster import KMeans
from sklearn.metrics import pairwise_distances_argmin
from sklearn.preprocessing import normalize
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.random import sample_without_replacement
from sklearn.utils.validation import check_is_fitted
from threadpoolctl import threadpool_limits

from skpcd.utils import check_point_clouds
from skpcd.utils._parallel import effective_threads, map_batches

__all__ = ["BagOfFeatures"]

# Rows of descriptors assigned to words at once (bounds the temporary copies).
_BATCH_ROWS = 1 << 15


def _check_descriptors(X):
    """The descriptor arrays of X as a list, all of one width.

    Empty arrays and NaN values are allowed (they are undefined
    descriptors); infinite values are not.
    """
    if isinstance(X, np.ndarray) and X.dtype != object and X.ndim == 2:
        raise ValueError(
            f"X is a single 2-D array of shape {X.shape}; BagOfFeatures expects "
            "a sequence of descriptor arrays, one per cloud (as "
            "PFHTransformer().transform(clouds) returns). For the descriptors "
            "of one cloud, wrap it: [descriptors], as for a lone [cloud]."
        )
    if isinstance(X, (list, tuple)) or (
        isinstance(X, np.ndarray) and X.dtype == object
    ):
        for i, d in enumerate(X):
            if np.ndim(d) != 2:
                raise ValueError(
                    f"X[{i}] must be a 2-D array of shape (n_descriptors, "
                    f"n_features), got an object with {np.ndim(d)} dimension(s)."
                )
    descs = check_point_clouds(
        X,
        min_points=0,
        n_columns=(1, None),
        ensure_all_finite=False,
    )
    width = descs[0].shape[1]
    for i, d in enumerate(descs):
        if d.shape[1] != width:
            raise ValueError(
                f"X[{i}] has {d.shape[1]} features but X[0] has {width}: every "
                "descriptor array must have the same width."
            )
        if d.size:
            # squared distances to the words must not overflow (inf - inf
            # is NaN, and the nearest word then silently wrong)
            top = max(np.fmax.reduce(d, axis=None), -np.fmin.reduce(d, axis=None))
            limit = np.sqrt(np.finfo(d.dtype).max / width) / 4
            if np.isfinite(top) and top > limit:
                raise ValueError(
                    f"X[{i}] has a value of magnitude {top:.3g}; {d.dtype} "
                    f"descriptors of {width} features must stay below "
                    f"{limit:.3g} for their squared distances not to overflow."
                )
    return descs


def _defined_mask(d, i):
    """True for the rows of ``d`` without NaN; infinite values are refused."""
    bad = ~np.isfinite(d)
    if not bad.any():
        return None
    undefined = bad.any(axis=1)
    if np.isinf(d[undefined]).any():
        raise ValueError(
            f"X[{i}] has infinite values; only NaN rows (undefined descriptors) "
            "are allowed."
        )
    return ~undefined


def _batches(descs, n_rows):
    """Blocks of defined descriptors, ``(first_segment, segment_ids, block)``.

    Consecutive arrays are stacked up to about ``n_rows`` rows; a larger
    array is cut into pieces. Undefined (NaN) rows are left out.
    """
    parts, ids, size, first = [], [], 0, 0
    for i, d in enumerate(descs):
        mask = _defined_mask(d, i)
        if mask is not None:
            d = d[mask]
        for lo in range(0, len(d), n_rows):
            piece = d[lo : lo + n_rows]
            if size + len(piece) > n_rows and parts:
                yield first, np.concatenate(ids), np.concatenate(parts)
                parts, ids, size = [], [], 0
            if not parts:
                first = i
            parts.append(piece)
            ids.append(np.full(len(piece), i - first, dtype=np.intp))
            size += len(piece)
    if parts:
        yield first, np.concatenate(ids), np.concatenate(parts)


class BagOfFeatures(ClassNamePrefixFeaturesOutMixin, TransformerMixin, BaseEstimator):
    """Bag of features: word counts of local descriptors per cloud.

    :meth:`fit` pools the local descriptors of all clouds (e.g. the PFH of
    every point), draws at most ``max_descriptors`` of them at random and
    clusters them into ``n_words`` words with ``clusterer`` (k-means by
    default): the cluster centres are the vocabulary. :meth:`transform`
    assigns each descriptor of a cloud to its nearest word (Euclidean
    distance) and returns one row of word counts per cloud, optionally
    weighted by inverse document frequency and normalised.

    Parameters
    ----------
    n_words : int, default=30
        Vocabulary size, the number of output columns. It sets the
        ``n_clusters`` of the clusterer (whose own value is ignored), so
        ``bagoffeatures__n_words`` can be tuned in a grid search.
    clusterer : estimator, default=None
        The vocabulary learner, cloned in :meth:`fit`: an estimator with an
        ``n_clusters`` parameter that learns ``cluster_centers_``
        (:class:`~sklearn.cluster.KMeans`,
        :class:`~sklearn.cluster.MiniBatchKMeans`,
        :class:`~sklearn.cluster.BisectingKMeans`). None means
        ``KMeans(n_init=1)``. If its ``random_state`` is None it is seeded
        from ``random_state``. Its parameters can be tuned as
        ``clusterer__<name>``.
    max_descriptors : int or None, default=20_000
        At most this many defined descriptors, drawn uniformly at random
        without replacement over all clouds, are clustered; None clusters
        them all. Word counts always use every descriptor. 20 000 is 200
        descriptors per word at 100 words and keeps k-means to seconds (on
        the DALES objects, 100 000 PFH took about a minute per 100-word
        vocabulary); raise it for vocabularies of thousands of words.
    norm : {"l1", "l2"} or None, default="l1"
        Normalisation of each row after the idf weighting: word
        frequencies (``"l1"``), unit Euclidean length (``"l2"``) or raw
        counts (None, the paper's encoding). An all-zero row stays zero.
    use_idf : bool, default=False
        Weight the counts by the inverse document frequency of each word
        over the training clouds, as
        :class:`~sklearn.feature_extraction.text.TfidfTransformer` with
        ``smooth_idf=True``: ``idf = ln((1 + n) / (1 + df)) + 1``, ``n``
        the number of clouds and ``df`` the number of them with the word.
        ``use_idf=True, norm="l2"`` is the usual tf-idf.
    assignment : {"auto", "exact", "approximate"}, default="auto"
        How descriptors find their nearest word. ``"exact"``: blocked brute
        force (scikit-learn's
        :func:`~sklearn.metrics.pairwise_distances_argmin`).
        ``"approximate"``: a pynndescent index over the vocabulary, built in
        :meth:`fit`. ``"auto"`` is exact for ``n_words`` below 2048 words
        and approximate from 2048 on, where the index becomes faster than
        brute force on PFH-like descriptors (see Notes).
    random_state : int, RandomState instance or None, default=None
        Seeds the descriptor sample, the clusterer (when its own
        ``random_state`` is None) and the approximate index. Pass an int for
        reproducible results.
    n_jobs : int, default=None
        Threads for the exact word assignment (the clustering and the
        approximate queries run on one thread, so that the output does not
        depend on the thread count); None means 1, -1 all cores. Under a
        backend chosen with :func:`joblib.parallel_config` (e.g.
        ``"dask"``), the word counts are computed in batches of clouds (a
        descriptor counts as a point), run at once (None: the backend's),
        each on the cores left to its task.

    Attributes
    ----------
    vocabulary_ : ndarray of shape (n_words, ``n_features_in_``)
        The words: the cluster centres learned by ``clusterer_``.
    clusterer_ : estimator
        The fitted clone of ``clusterer``.
    idf_ : ndarray of shape (n_words,)
        Inverse document frequencies; only when ``use_idf=True``.
    assignment_ : {"exact", "approximate"}
        The word assignment in use.
    n_descriptors_ : int
        Defined descriptors (rows without NaN) seen in :meth:`fit`.
    n_undefined_ : int
        Rows with NaN left out in :meth:`fit`.
    n_features_in_ : int
        Width of the descriptors.

    Read more in the :ref:`User Guide <identification>`.

    See Also
    --------
    skpcd.features.PFHTransformer : Local descriptors to encode.
    skpcd.features.FPFHTransformer : Faster local descriptors.
    sklearn.feature_extraction.text.TfidfTransformer : The same weighting of
        word counts for text.

    Notes
    -----
    **Undefined descriptors.** Rows containing NaN (what the local
    descriptor transformers emit with ``undefined="nan"``) are undefined:
    they are neither clustered nor counted, and ``n_undefined_`` says how
    many :meth:`fit` skipped. A cloud without any defined descriptor (empty,
    or all NaN) gets an all-zero row under every ``norm``. Infinite values
    are an error, and so are values whose squared distances would overflow
    (above about 1e153 for float64, 1e18 for float32).

    **Word assignment.** Exact assignment costs
    ``n_descriptors * n_words * n_features`` operations (as matrix products,
    in blocks of 32768 rows); the approximate one searches a k-nearest-
    neighbour graph of the words, whose cost grows roughly with the
    logarithm of ``n_words``. On the 883k PFH (125 bins) of 400 DALES
    objects with two threads, brute force took about as long as the index
    around 2000 words and several times longer at 16k words; the index
    agreed with exact search on over 99% of the descriptors. Below the
    threshold exact assignment is both faster and exact. Ties go to the
    lower word index.

    The clustering runs on one thread (scikit-learn's k-means sums the
    partial centres of its threads in an order that depends on their
    number: the vocabulary would differ in its last bits with ``n_jobs``),
    and so do the approximate queries (pynndescent's parallel batch search
    shares one random state between its threads); the exact assignment
    uses ``n_jobs`` threads.

    The encoding follows He et al. [2]_ (section 3.2.2): k-means over the
    PFH of every point (k = 6 neighbours, 125 bins), then the count of the
    descriptors of a segment assigned to each centre, with vocabularies of
    15, 30, 50 and 100 words (30 retained). ``norm=None`` gives their raw
    counts.

    References
    ----------
    .. [1] G. Csurka, C. Dance, L. Fan, J. Willamowski, C. Bray, "Visual
       categorization with bags of keypoints", ECCV Workshop on Statistical
       Learning in Computer Vision, 2004.
    .. [2] H. He, K. Khoshelham, C. Fraser, "A two-step classification
       approach to distinguishing similar objects in mobile lidar point
       clouds", ISPRS Annals IV-2/W4, 2017.

    Examples
    --------
    >>> from skpcd.datasets import make_point_clouds
    >>> from skpcd.encoding import BagOfFeatures
    >>> from skpcd.features import PFHTransformer
    >>> clouds = make_point_clouds(4, n_points=60, random_state=0)
    >>> pfh = PFHTransformer(n_neighbors=8).fit_transform(clouds)
    >>> bof = BagOfFeatures(n_words=5, random_state=0).fit(pfh)
    >>> bof.vocabulary_.shape
    (5, 125)
    >>> words = bof.transform(pfh)
    >>> words.shape, words.sum(axis=1).round(6).tolist()
    ((4, 5), [1.0, 1.0, 1.0, 1.0])
    >>> bof.get_feature_names_out()[:2].tolist()
    ['bagoffeatures0', 'bagoffeatures1']
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        "n_words": [Interval(Integral, 1, None, closed="left")],
        "clusterer": [HasMethods(["fit", "get_params", "set_params"]), None],
        "max_descriptors": [Interval(Integral, 1, None, closed="left"), None],
        "norm": [StrOptions({"l1", "l2"}), None],
        "use_idf": ["boolean"],
        "assignment": [StrOptions({"auto", "exact", "approximate"})],
        "random_state": ["random_state"],
        "n_jobs": [Integral, None],
    }

    # "auto" assignment is approximate from this many words on.
    _APPROXIMATE_MIN_WORDS = 2048
    # Approximate queries: the nearest of k words found, searched with epsilon
    # (0.2: 99.5 % of 3000 real PFH (k=6) get the exact word among 300, 98.0 %
    # with 0.1, for 15 % more query time).
    _QUERY_K = 4
    _QUERY_EPSILON = 0.2

    def __init__(
        self,
        n_words=30,
        *,
        clusterer=None,
        max_descriptors=20_000,
        norm="l1",
        use_idf=False,
        assignment="auto",
        random_state=None,
        n_jobs=None,
    ):
        self.n_words = n_words
        self.clusterer = clusterer
        self.max_descriptors = max_descriptors
        self.norm = norm
        self.use_idf = use_idf
        self.assignment = assignment
        self.random_state = random_state
        self.n_jobs = n_jobs

    def _sample(self, descs, rng):
        """The defined descriptors, or a random sample of them, stacked."""
        masks = [_defined_mask(d, i) for i, d in enumerate(descs)]
        sizes = np.array(
            [len(d) if m is None else int(m.sum()) for d, m in zip(descs, masks)]
        )
        n_rows = sum(len(d) for d in descs)
        self.n_descriptors_ = int(sizes.sum())
        self.n_undefined_ = n_rows - self.n_descriptors_
        if self.n_descriptors_ == 0:
            raise ValueError(
                f"X has no defined descriptor: {len(descs)} array(s), {n_rows} "
                "row(s), all empty or NaN."
            )
        if self.n_descriptors_ < self.n_words:
            raise ValueError(
                f"X has {self.n_descriptors_} defined descriptor(s), fewer than "
                f"n_words={self.n_words}."
            )
        m = self.max_descriptors
        if m is None or m >= self.n_descriptors_:
            picks = None
        else:
            picks = np.sort(
                sample_without_replacement(self.n_descriptors_, m, random_state=rng)
            )
        starts = np.concatenate([[0], np.cumsum(sizes)])
        parts = []
        for i, (d, mask) in enumerate(zip(descs, masks)):
            rows = np.arange(len(d)) if mask is None else np.flatnonzero(mask)
            if picks is not None:
                lo, hi = np.searchsorted(picks, starts[i : i + 2])
                rows = rows[picks[lo:hi] - starts[i]]
            parts.append(d[rows])
        dtype = np.result_type(*[d.dtype for d in descs])
        return np.concatenate(parts).astype(dtype, copy=False)

    def _fit_vocabulary(self, sample, rng):
        clusterer = KMeans(n_init=1) if self.clusterer is None else self.clusterer
        clusterer = clone(clusterer)
        params = clusterer.get_params(deep=False)
        if "n_clusters" not in params:
            raise ValueError(
                f"clusterer must have an n_clusters parameter (KMeans, "
                f"MiniBatchKMeans...); {type(clusterer).__name__} has none."
            )
        clusterer.set_params(n_clusters=self.n_words)
        seed = rng.randint(np.iinfo(np.int32).max)
        if "random_state" in params and params["random_state"] is None:
            clusterer.set_params(random_state=seed)
        # one OpenMP thread: scikit-learn's k-means sums the partial centres
        # of its threads in an order that depends on their number, so the
        # vocabulary (and with it the words near ties) would depend on n_jobs
        with threadpool_limits(1, user_api="openmp"):
            clusterer.fit(sample)
        centers = getattr(clusterer, "cluster_centers_", None)
        want = (self.n_words, sample.shape[1])
        if centers is None or np.shape(centers) != want:
            got = "none" if centers is None else np.shape(centers)
            raise ValueError(
                f"the fitted clusterer must have cluster_centers_ of shape {want}, "
                f"got {got}."
            )
        self.clusterer_ = clusterer
        self.vocabulary_ = np.asarray(centers)
        return seed

    def __getstate__(self):
        # the pynndescent index holds generators that skops (and some
        # pickle protocols) cannot store; it is rebuilt from the vocabulary
        # and its seed on first use, the same graph (one thread)
        state = super().__getstate__()
        if "_index" in state:
            state["_index"] = None
        return state

    def _build_index(self, seed):
        """The pynndescent index over the words, for approximate assignment."""
        from pynndescent import NNDescent

        words = np.ascontiguousarray(self.vocabulary_, dtype=np.float32)
        index = NNDescent(
            words,
            metric="euclidean",
            n_neighbors=min(30, max(len(words) - 1, 1)),
            random_state=seed,
            n_jobs=1,  # one thread: the graph does not depend on n_jobs
            # serial queries: pynndescent's parallel batch search shares one
            # random state between its threads (candidates drawn to fill a
            # small leaf), so its answers would depend on the thread count
            parallel_batch_queries=False,
        )
        index.prepare()
        return index

    def _assign(self, block, n_jobs):
        """Word index of each row of ``block``, on ``n_jobs`` threads."""
        n_threads = effective_threads(n_jobs)
        if self.assignment_ == "exact":
            with threadpool_limits(n_threads, user_api="openmp"):
                return pairwise_distances_argmin(
                    block.astype(self.vocabulary_.dtype, copy=False),
                    self.vocabulary_,
                )
        k = min(self._QUERY_K, len(self.vocabulary_))
        if getattr(self, "_index", None) is None:  # unpickled: rebuilt once
            self._index = self._build_index(self._index_seed)
        indices = self._index.query(
            np.ascontiguousarray(block, dtype=np.float32),
            k=k,
            epsilon=self._QUERY_EPSILON,
            return_distances=False,
        )
        return indices[:, 0].astype(np.intp)

    def _counts(self, descs):
        """Word counts of each descriptor array, batches of arrays on the
        joblib backend chosen by the caller, if any."""
        return map_batches(self._counts_batch, descs, self.n_jobs)

    def _counts_batch(self, descs, n_jobs):
        """Word counts of a batch of descriptor arrays, one row each."""
        n_words = len(self.vocabulary_)
        counts = np.zeros((len(descs), n_words))
        for first, ids, block in _batches(descs, _BATCH_ROWS):
            words = self._assign(block, n_jobs)
            n_seg = int(ids[-1]) + 1
            flat = np.bincount(ids * n_words + words, minlength=n_seg * n_words)
            counts[first : first + n_seg] += flat.reshape(n_seg, n_words)
        return counts

    def _weight(self, counts):
        if self.use_idf:
            counts = counts * self.idf_
        if self.norm is not None:
            counts = normalize(counts, norm=self.norm, copy=False)
        return counts

    def _fit(self, X, with_counts):
        descs = _check_descriptors(X)
        rng = check_random_state(self.random_state)
        sample = self._sample(descs, rng)
        seed = self._fit_vocabulary(sample, rng)
        del sample
        self.n_features_in_ = descs[0].shape[1]
        self._n_features_out = self.n_words
        approximate = self.assignment == "approximate" or (
            self.assignment == "auto" and self.n_words >= self._APPROXIMATE_MIN_WORDS
        )
        self.assignment_ = "approximate" if approximate else "exact"
        if approximate:
            self._index_seed = seed
            self._index = self._build_index(seed)
        elif hasattr(self, "_index"):
            del self._index
        counts = None
        if self.use_idf or with_counts:
            counts = self._counts(descs)
        if self.use_idf:
            df = np.count_nonzero(counts, axis=0)
            self.idf_ = np.log((1.0 + len(descs)) / (1.0 + df)) + 1.0
        elif hasattr(self, "idf_"):
            del self.idf_
        return counts

    @_fit_context(prefer_skip_nested_validation=False)
    def fit(self, X, y=None):
        """Learn the vocabulary (and the idf weights) from the descriptors.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_descriptors_i, n_features)
            One array of local descriptors per cloud, e.g. the output of
            :meth:`skpcd.features.PFHTransformer.transform`. Rows with NaN
            are skipped; arrays may be empty.
        y : None
            Ignored.

        Returns
        -------
        self : object
            The fitted encoder.
        """
        self._fit(X, with_counts=False)
        return self

    @_fit_context(prefer_skip_nested_validation=False)
    def fit_transform(self, X, y=None):
        """Fit, then encode the same clouds (assigning their words once).

        Parameters
        ----------
        X : sequence of ndarray of shape (n_descriptors_i, n_features)
            One array of local descriptors per cloud.
        y : None
            Ignored.

        Returns
        -------
        X_new : ndarray of shape (n_clouds, n_words)
            The encoding of each cloud, as :meth:`transform` returns it.
        """
        return self._weight(self._fit(X, with_counts=True))

    def transform(self, X):
        """Encode each cloud as (weighted, normalised) word counts.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_descriptors_i, n_features)
            One array of local descriptors per cloud, as wide as in
            :meth:`fit`. Rows with NaN are not counted.

        Returns
        -------
        X_new : ndarray of shape (n_clouds, n_words)
            Row i counts the descriptors of cloud i nearest to each word,
            weighted by ``idf_`` when ``use_idf`` and normalised by
            ``norm``; float64.
        """
        check_is_fitted(self)
        descs = _check_descriptors(X)
        if descs[0].shape[1] != self.n_features_in_:
            raise ValueError(
                f"X has {descs[0].shape[1]} features, but BagOfFeatures is "
                f"expecting {self.n_features_in_} features as input."
            )
        return self._weight(self._counts(descs))

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.allow_nan = True
        return tags
