"""What a model payload must pass before skpcd trusts it.

:func:`from_skops` rebuilds a skops payload trusting only the types skops
trusts by itself (the scikit-learn estimators among them found by the same
rule, for the types the payload names) and those in ``TRUSTED_TYPES``;
:func:`import_skops_io` imports skops without its list of every
scikit-learn estimator. :func:`check_trees` then checks the structure of
the loaded model, whatever its serializer: the node indices of its decision trees, which
scikit-learn would follow out of bounds, and the sizes its parts share
(features, outputs and classes of trees and their ensembles, ``classes_``
against ``n_classes_``, the width of each pipeline step against the next).
The container that holds the payload is read and checked by
:mod:`skpcd.io._model`.
"""

import contextvars
import importlib
import io
import itertools
import re
import sys
import zipfile

import numpy as np
import sklearn
import sklearn.utils
from sklearn.base import BaseEstimator

from skpcd.exceptions import PointCloudFileError, UntrustedModelError

__all__ = ["TRUSTED_TYPES", "check_trees", "from_skops", "import_skops_io"]


#: The types a skops model file may name, beyond those skops trusts by itself
#: (builtins, NumPy arrays and dtypes, SciPy sparse matrices, every public
#: scikit-learn estimator): skpcd's estimators, scikit-learn's decision tree
#: storage (checked after loading, see :func:`~skpcd.io.load_model`), its
#: fitted calibrators (the temperature of the shipped street model), NumPy's
#: polynomial (:class:`~skpcd.segmentation.AutoEpsDBSCAN` keeps its fitted
#: curve as one), and the splitters and default scorer that a fitted
#: :class:`~sklearn.model_selection.GridSearchCV` keeps. None of them runs
#: code named by the file when it is rebuilt.
TRUSTED_TYPES = (
    "numpy.polynomial.polynomial.Polynomial",
    "sklearn.calibration._CalibratedClassifier",
    "sklearn.calibration._TemperatureScaling",
    "sklearn.metrics._scorer._PassthroughScorer",
    "sklearn.model_selection._split.KFold",
    "sklearn.model_selection._split.StratifiedKFold",
    "sklearn.tree._tree.Tree",
    "skpcd.classification._augmented.SimulationAugmented",
    "skpcd.classification._case_based.CaseBasedClassifier",
    "skpcd.classification._reject.RejectUnknown",
    "skpcd.classification._two_step.TwoStepClassifier",
    "skpcd.encoding._bag.BagOfFeatures",
    "skpcd.features._fpfh.FPFHTransformer",
    "skpcd.features._improved.ImprovedPFHTransformer",
    "skpcd.features._overall.OverallDescriptor",
    "skpcd.features._pfh.PFHTransformer",
    "skpcd.features._shape.ShapeFeatures",
    "skpcd.features._vertical.VerticalProfile",
    "skpcd.preprocessing._normals.NormalEstimator",
    "skpcd.preprocessing._outliers.RadiusOutlierFilter",
    "skpcd.preprocessing._outliers.StatisticalOutlierFilter",
    "skpcd.preprocessing._sampling.GridSampler",
    "skpcd.segmentation._clusters.EuclideanClusters",
    "skpcd.segmentation._dbscan.AutoEpsDBSCAN",
    "skpcd.segmentation.ground._filter.GroundFilter",
    "skpcd.segmentation.ground._terrain.Terrain",
)


def _not_allowed(untrusted, trusted):
    allowed = set(TRUSTED_TYPES).union(trusted)
    return sorted(
        t for t in untrusted if t not in allowed and not _sklearn_estimator(t)
    )


# skops, when imported, lists every public scikit-learn estimator (the types
# it trusts by default) with sklearn.utils.all_estimators, which imports every
# module of scikit-learn: about 1 s of CPU, a third of loading the street
# model. skpcd imports skops without that list and, for a file it loads,
# trusts the scikit-learn types that file names which the same rule accepts
# (_sklearn_estimator, asked of those types only): the trusted set is the
# one skops would use, built for the few types at hand. For everyone else
# in the process, skops' list is made as skops makes it, on its first use.
_OWN_LOAD = contextvars.ContextVar("skpcd_own_skops_load", default=False)


class _EstimatorNames(list):
    """skops' list of scikit-learn estimator type names (its
    ``SKLEARN_ESTIMATOR_TYPE_NAMES``), made as skops makes it on first use;
    empty in skpcd's own loads, which give those types in ``trusted``.
    skops only adds it to another list; reading it fills it too."""

    filled = False

    def _fill(self):
        if not self.filled:
            from skops.io._utils import get_type_name

            names = (get_type_name(cls) for _, cls in sklearn.utils.all_estimators())
            self[:] = [name for name in names if name.startswith("sklearn.")]
            self.filled = True
        return self

    def __add__(self, other):
        if _OWN_LOAD.get():
            return list(other)
        return list.__add__(self._fill(), other)

    def __iter__(self):
        return list.__iter__(self._fill())

    def __len__(self):
        return list.__len__(self._fill())

    def __contains__(self, item):
        return list.__contains__(self._fill(), item)

    def __getitem__(self, index):
        return list.__getitem__(self._fill(), index)


def import_skops_io():
    """``skops.io``, imported without its list of every scikit-learn
    estimator (see ``_EstimatorNames``) when skpcd is the first to import it."""
    if "skops.io" in sys.modules:
        return sys.modules["skops.io"]
    every = sklearn.utils.all_estimators
    sklearn.utils.all_estimators = lambda *args, **kwargs: []
    try:
        import skops.io
        from skops.io import _general, _trusted_types
    finally:
        sklearn.utils.all_estimators = every
    names = getattr(_trusted_types, "SKLEARN_ESTIMATOR_TYPE_NAMES", None)
    if names == [] and getattr(_general, "SKLEARN_ESTIMATOR_TYPE_NAMES", None) is names:
        lazy = _EstimatorNames()
        _trusted_types.SKLEARN_ESTIMATOR_TYPE_NAMES = lazy
        _general.SKLEARN_ESTIMATOR_TYPE_NAMES = lazy
    elif isinstance(names, list) and not names:  # another layout: made now
        names[:] = _EstimatorNames()._fill()
    return skops.io


# What sklearn.utils.all_estimators leaves out: modules with a part of these
# names (its _MODULE_TO_IGNORE).
_NOT_WALKED = {
    "tests", "externals", "setup", "conftest", "experimental", "estimator_checks",
}  # fmt: skip


def _sklearn_estimator(name):
    """Whether the type ``name`` is one that skops trusts by default: a
    class that sklearn.utils.all_estimators lists (a public, non-abstract
    subclass of BaseEstimator exported under its name by a public module of
    scikit-learn), found through the public package above the module that
    defines it. Imports only that public module, as all_estimators would."""
    module, _, qualname = str(name).rpartition(".")
    parts = module.split(".")
    if (
        parts[0] != "sklearn"
        or not qualname.isidentifier()
        or qualname.startswith("_")
        or not all(part.isidentifier() for part in parts)
    ):
        return False
    public = parts[: next((i for i, p in enumerate(parts) if p.startswith("_")), None)]
    if _NOT_WALKED.intersection(public):
        return False
    try:
        cls = getattr(importlib.import_module(".".join(public)), qualname, None)
    except ImportError:
        return False
    return (
        isinstance(cls, type)
        and cls.__module__ == module
        and cls.__qualname__ == qualname
        and issubclass(cls, BaseEstimator)
        and qualname != "BaseEstimator"
        and not getattr(cls, "__abstractmethods__", None)
    )


_NAMED = re.compile(rb'"__module__":\s*"(sklearn(?:\.\w+)+)"|"__class__":\s*"(\w+)"')


def _sklearn_estimators_named(payload):
    """The scikit-learn estimator types (see :func:`_sklearn_estimator`)
    that a skops payload may name: every pair of a scikit-learn module and
    a class name found in its schema that is one."""
    with zipfile.ZipFile(io.BytesIO(payload)) as archive:
        schema = archive.read("schema.json")
    modules, classes = set(), set()
    for module, cls in _NAMED.findall(schema):
        (modules.add(module.decode()) if module else classes.add(cls.decode()))
    pairs = (f"{m}.{c}" for m in sorted(modules) for c in sorted(classes))
    return [name for name in pairs if _sklearn_estimator(name)]


def from_skops(path, payload, trusted):
    """The estimator of a skops payload, rebuilt from trusted types only.

    Parameters
    ----------
    path : pathlib.Path
        The model file, named in the errors.
    payload : bytes
        The payload of the container, its checksum verified.
    trusted : list of str
        The type names the caller trusts beyond ``TRUSTED_TYPES``.

    Returns
    -------
    model : estimator
        The rebuilt estimator, its structure not yet checked (see
        :func:`check_trees`).

    Raises
    ------
    UntrustedModelError
        If the payload names types that are not trusted (listed).
    PointCloudFileError
        If skops cannot rebuild the payload.
    """
    skops_io = import_skops_io()
    from skops.io.exceptions import UntrustedTypesFoundException

    token = _OWN_LOAD.set(True)
    try:
        known = _sklearn_estimators_named(payload)
        return skops_io.loads(payload, trusted=[*TRUSTED_TYPES, *trusted, *known])
    except UntrustedTypesFoundException:
        refused = _not_allowed(skops_io.get_untrusted_types(data=payload), trusted)
        raise UntrustedModelError(
            path,
            f"the model names types that skpcd does not trust: {', '.join(refused)}; "
            "nothing was loaded. If you trust the file, pass them as "
            "load_model(..., trusted=[...])",
            types=refused,
        ) from None
    except Exception as exc:  # checksummed, so crafted: any failure is corruption
        raise PointCloudFileError(
            path,
            f"cannot rebuild the model from its skops data ({type(exc).__name__}: "
            f"{exc})",
        ) from exc
    finally:
        _OWN_LOAD.reset(token)


def _check_tree(path, tree, owner, classifier):
    """Node indices that scikit-learn follows without bounds checks, and the
    sizes the tree shares with ``owner`` (the estimator that calls it):
    features, outputs and, for a ``classifier`` tree, classes."""
    n = tree.node_count

    def bad(problem):
        return PointCloudFileError(
            path, f"corrupt model: a decision tree of {n} nodes {problem}"
        )

    if n < 1 or tree.capacity != n:
        raise bad(f"has storage for {tree.capacity}")
    if tree.n_features < 1 or tree.n_outputs < 1:
        raise bad(f"has {tree.n_features} features and {tree.n_outputs} outputs")
    left, right, feature = tree.children_left, tree.children_right, tree.feature
    leaf = left == -1
    if not np.array_equal(leaf, right == -1):
        raise bad("has nodes with one child")
    node = np.arange(n)[~leaf]
    inner = [left[~leaf], right[~leaf]]
    if any(((c <= node) | (c >= n)).any() for c in inner):
        raise bad("has children out of range or before their parent")
    if ((feature[~leaf] < 0) | (feature[~leaf] >= tree.n_features)).any():
        raise bad(f"splits on features outside 0..{tree.n_features - 1}")
    expected = getattr(owner, "n_features_in_", None)
    if isinstance(expected, (int, np.integer)) and tree.n_features != expected:
        raise bad(f"expects {tree.n_features} features, its estimator {expected}")
    if not np.isfinite(tree.value).all():
        raise bad("has leaf values that are not finite")
    outputs = getattr(owner, "n_outputs_", None)
    if isinstance(outputs, (int, np.integer)) and tree.n_outputs != outputs:
        raise bad(f"has {tree.n_outputs} outputs, its estimator {outputs}")
    classes = _class_counts(owner) if classifier else None
    if classes is not None and tree.n_classes.tolist() != classes:
        raise bad(
            f"tells {tree.n_classes.tolist()} classes, its estimator "
            f"{classes} (n_classes_)"
        )


def _class_counts(est):
    """The number of classes of each output that a classifier's
    ``n_classes_`` gives, as a list; None without one."""
    n = getattr(est, "n_classes_", None)
    if isinstance(n, (int, np.integer)):
        return [int(n)]
    if isinstance(n, (list, np.ndarray)) and all(
        isinstance(v, (int, np.integer)) for v in np.ravel(n).tolist()
    ):
        return [int(v) for v in np.ravel(n).tolist()]
    return None


def _check_classes(path, est, attrs):
    """A classifier's ``classes_`` as many as its ``n_classes_`` (one array
    per output when there are several)."""
    counts, classes = _class_counts(est), attrs.get("classes_")
    if counts is None or classes is None:
        return
    per_output = (
        [classes] if len(counts) == 1 and isinstance(classes, np.ndarray) else classes
    )
    sizes = [len(c) if isinstance(c, np.ndarray) else None for c in per_output]
    if sizes != counts:
        raise PointCloudFileError(
            path,
            f"corrupt model: its {type(est).__name__} has {sizes} classes_ but "
            f"n_classes_ says {counts}",
        )


def _width(step):
    """Number of columns a fitted transformer gives, from its
    ``get_feature_names_out`` (no data goes through it); None when it does
    not tell."""
    names = getattr(step, "get_feature_names_out", None)
    if names is None:
        return None
    try:
        return len(names())
    except Exception:  # a transformer that cannot tell without data
        return None


def _check_pipeline(path, pipe):
    """Each step of a pipeline expects as many columns as the step before
    it gives."""
    steps = [s for _, s in pipe.steps if s is not None and not isinstance(s, str)]
    for before, after in itertools.pairwise(steps):
        expected = getattr(after, "n_features_in_", None)
        if not isinstance(expected, (int, np.integer)):
            continue
        given = _width(before)
        if given is not None and given != expected:
            raise PointCloudFileError(
                path,
                f"corrupt model: its {type(before).__name__} gives {given} "
                f"features but the {type(after).__name__} after it expects "
                f"{expected}",
            )


_OURS = ("sklearn.", "skpcd.")


def _module(obj):
    return getattr(type(obj), "__module__", None) or ""


def _flat(items):
    """The items of a list or array of estimators, nested one level at most
    (gradient boosting keeps a 2-D array of trees)."""
    for item in items.ravel().tolist() if isinstance(items, np.ndarray) else items:
        if isinstance(item, (list, tuple, np.ndarray)):
            yield from (item.ravel().tolist() if isinstance(item, np.ndarray) else item)
        else:
            yield item


def check_trees(path, model):
    """Check the structure of ``model``: every decision tree reachable from
    it, the classes of its classifiers and the widths of its pipelines.

    scikit-learn indexes the node arrays of its trees without bounds checks,
    so a file with wrong indices would crash or hang ``predict``; a forest
    hands its trees its own input unchecked, so they must expect as many
    features, outputs and classes as it does. A classifier whose
    ``classes_`` and ``n_classes_`` disagree, a fitted ensemble without
    estimators, or a pipeline step that gives another number of features
    than the next one expects would load and then fail in ``predict`` with
    a scikit-learn error, or answer wrong classes.
    """
    # loaded here: scikit-learn's tree module takes a quarter of a second to import
    from sklearn.tree._tree import Tree

    # a model holding a pipeline has loaded scikit-learn's pipeline module
    pipeline = getattr(sys.modules.get("sklearn.pipeline"), "Pipeline", ())

    seen, pipelines = set(), []
    stack = [(model, None)]
    while stack:
        obj, owner = stack.pop()
        if id(obj) in seen or isinstance(obj, (str, bytes, int, float, type)):
            continue
        seen.add(id(obj))
        if isinstance(obj, Tree):
            _check_tree(path, obj, owner, classifier=True)
        elif isinstance(obj, np.ndarray):
            if obj.dtype.hasobject:
                stack.extend((item, owner) for item in obj.ravel().tolist())
        elif isinstance(obj, dict):
            stack.extend((item, owner) for item in obj.values())
        elif isinstance(obj, (list, tuple, set, frozenset)):
            stack.extend((item, owner) for item in obj)
        elif isinstance(obj, BaseEstimator) or _module(obj).startswith(_OURS):
            attrs = vars(obj) if hasattr(obj, "__dict__") else {}
            stack.extend((item, obj) for item in attrs.values())
            _check_classes(path, obj, attrs)
            if isinstance(obj, pipeline):
                pipelines.append(obj)
            subs = attrs.get("estimators_")
            if "n_features_in_" in attrs and isinstance(subs, list) and not subs:
                raise PointCloudFileError(
                    path, f"corrupt model: its fitted {type(obj).__name__} holds "
                    "no estimators"
                )  # fmt: skip
            if (
                "n_features_in_" in attrs
                and isinstance(subs, (list, tuple, np.ndarray))
                and "estimators_features_" not in attrs  # bagging: feature subsets
            ):
                for sub in _flat(subs):
                    tree = getattr(sub, "tree_", None)
                    if isinstance(tree, Tree):
                        _check_tree(path, tree, obj, hasattr(sub, "classes_"))
    # last: the widths are asked of the steps, whose trees are now checked
    for pipe in pipelines:
        _check_pipeline(path, pipe)
