"""Saving and loading fitted models, without running code from the file.

A model file is one small container (see :ref:`models`)::

    16 bytes   signature  b"\\x89SKPCD-MODEL\\r\\n\\x1a\\n"
    8 bytes    header length n, unsigned little endian
    n bytes    header: a JSON object (format, serializer, versions, metadata,
               payload size and SHA-256)
    32 bytes   SHA-256 of the 24 + n bytes above
    ...        payload: the estimator serialised by skops (default) or joblib

:func:`load_model` checks the signature, the sizes, both checksums, the type
of every header field and the library versions before it deserialises
anything; a skops payload is then rebuilt only if every type it names that
skops does not trust by itself is in ``TRUSTED_TYPES``, and its structure
is checked: the node indices of its decision trees, which scikit-learn would
follow out of bounds, and the sizes its parts share (features, outputs and
classes of trees and their ensembles, ``classes_`` against ``n_classes_``,
the width of each pipeline step against the next). A joblib payload, and
the bare joblib pickles that skpcd wrote before this format, run code from
the file when loaded: they need ``trust_pickle=True``.
"""

import contextvars
import hashlib
import importlib
import io
import itertools
import json
import os
import platform
import re
import struct
import sys
import zipfile
from pathlib import Path

import joblib
import numpy as np
import sklearn
import sklearn.utils
from sklearn.base import BaseEstimator

from skpcd import __version__
from skpcd.exceptions import (
    IncompatibleModelError,
    MissingFileError,
    PointCloudFileError,
    UntrustedModelError,
)
from skpcd.io._atomic import atomic_path

__all__ = ["TRUSTED_TYPES", "load_model", "save_model"]

_FORMAT = "skpcd-model"
_FORMAT_VERSION = 2  # 1: a bare joblib pickle of a dict (before the container)
_SERIALIZERS = ("skops", "joblib")
_MAGIC = b"\x89SKPCD-MODEL\r\n\x1a\n"
_LENGTH = struct.Struct("<Q")
_PREFIX = len(_MAGIC) + _LENGTH.size
_DIGEST = 32  # bytes of a SHA-256
_MAX_HEADER = 16 * 2**20

#: The types a skops model file may name, beyond those skops trusts by itself
#: (builtins, NumPy arrays and dtypes, SciPy sparse matrices, every public
#: scikit-learn estimator): skpcd's estimators, scikit-learn's decision tree
#: storage (checked after loading, see :func:`load_model`), its fitted
#: calibrators (the temperature of the shipped street model), NumPy's
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
    "skpcd.features._improved.ImprovedPFHTransformer",
    "skpcd.features._overall.OverallDescriptor",
    "skpcd.features._pfh.FPFHTransformer",
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

# first bytes of what joblib.dump writes: a pickle (protocol 2 to 5), or
# one compressed by zlib, gzip, bz2, xz, lzma or lz4, or joblib's old "ZF"
_PICKLE_STARTS = (
    *(bytes([0x80, p]) for p in range(2, 6)),
    b"\x78\x01",
    b"\x78\x5e",
    b"\x78\x9c",
    b"\x78\xda",
    b"\x1f\x8b",
    b"BZh",
    b"\xfd7zXZ",
    b"]\x00\x00",
    b"\x04\x22\x4d\x18",
    b"ZF",
)


def _versions():

    return {
        "skpcd": __version__,
        "scikit-learn": sklearn.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
    }


def _release(version):
    """``major.minor`` of a version string."""
    return ".".join(str(version).split(".")[:2])


def _type_name(obj):
    cls = type(obj)
    return f"{cls.__module__}.{cls.__qualname__}"


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _pack(header, payload):
    """The bytes of a model file: signature, header, its digest, payload."""
    text = json.dumps(header, sort_keys=True, default=_json_default).encode()
    head = _MAGIC + _LENGTH.pack(len(text)) + text
    return head + hashlib.sha256(head).digest() + payload


def _serialise(model, format):
    if format == "joblib":
        buffer = io.BytesIO()
        joblib.dump(model, buffer)
        return buffer.getvalue(), "joblib"

    import skops

    skops_io = _skops_io()

    try:
        # deflated: the JSON schema of a 300-tree forest shrinks 14-fold
        payload = skops_io.dumps(model, compression=zipfile.ZIP_DEFLATED)
    except Exception as exc:
        raise TypeError(
            f"cannot save a {type(model).__name__} in the skops format "
            f"({type(exc).__name__}: {exc}); save it with format='joblib' "
            "(loading it then needs trust_pickle=True)"
        ) from exc
    return payload, f"skops {skops.__version__}"


def save_model(model, path, *, metadata=None, overwrite=False, format="skops"):
    """Save a fitted estimator to a file, with the library versions.

    Read more in the :ref:`User Guide <models>`.

    Parameters
    ----------
    model : estimator
        Any fitted scikit-learn compatible estimator or pipeline.
    path : str or path-like
        The file to write (``.skpcd`` by convention; the format is told by
        the file's content, not by its name).
    metadata : dict, default=None
        Extra information kept beside the model (for example the training
        folder and the classes), returned by :func:`load_model` with
        ``return_info=True``. It is stored as JSON: strings, numbers,
        booleans, None, lists and dicts with string keys (NumPy scalars and
        arrays are converted).
    overwrite : bool, default=False
        Replace an existing file; otherwise an existing file raises
        :class:`FileExistsError` and is left untouched.
    format : {"skops", "joblib"}, default="skops"
        How the estimator is serialised. ``"skops"``: with
        :func:`skops.io.dumps`, loaded without running code from the file.
        ``"joblib"``: a pickle, for estimators skops cannot serialise;
        :func:`load_model` then needs ``trust_pickle=True``. Both are
        wrapped in the same checksummed container.

    Returns
    -------
    path : pathlib.Path
        The file written.

    Raises
    ------
    FileExistsError
        If the file exists and ``overwrite`` is False.
    TypeError
        If the metadata is not JSON serialisable, or skops cannot serialise
        the model (the message suggests ``format="joblib"``).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from sklearn.dummy import DummyClassifier
    >>> from skpcd.io import load_model, save_model
    >>> model = DummyClassifier().fit([[0], [1]], ["a", "b"])
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "model.skpcd"
    >>> _ = save_model(model, path, metadata={"data": "toy"})
    >>> load_model(path).predict([[0]]).shape
    (1,)
    """
    if format not in _SERIALIZERS:
        raise ValueError(f"format must be 'skops' or 'joblib', got {format!r}")
    path = Path(os.fspath(path))
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: exists; pass overwrite=True to replace it")
    metadata = dict(metadata or {})
    try:
        json.dumps(metadata, default=_json_default)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"metadata must be JSON serialisable: {exc}") from exc
    payload, library = _serialise(model, format)
    versions = _versions()
    name, _, version = library.partition(" ")
    if version:
        versions[name] = version
    header = {
        "format": _FORMAT,
        "format_version": _FORMAT_VERSION,
        "serializer": format,
        "estimator": _type_name(model),
        "versions": versions,
        "metadata": metadata,
        "payload_size": len(payload),
        "payload_sha256": hashlib.sha256(payload).hexdigest(),
    }
    data = _pack(header, payload)
    # written beside the target and renamed when whole
    with atomic_path(path, overwrite=overwrite) as tmp:
        tmp.write_bytes(data)
    return path


def _bit_distance(a, b):
    return sum(bin(x ^ y).count("1") for x, y in zip(a, b))


def _looks_like_pickle(head):
    return head.startswith(_PICKLE_STARTS)


def _pickle_refused(path, what):
    return UntrustedModelError(
        path,
        f"{what}: loading it runs code stored in the file, so skpcd does not "
        "load it by default; if you trust where it comes from, load it with "
        "trust_pickle=True (skpcd commands: --trust-pickle), or refit and save "
        "it again in the default skops format",
    )


def _check_header(path, header):
    """Every field of a container header, type-checked."""

    def bad(problem):
        return PointCloudFileError(path, f"corrupt model file header: {problem}")

    if not isinstance(header, dict):
        raise bad(f"expected a JSON object, found {type(header).__name__}")
    if header.get("format") != _FORMAT:
        raise bad(f"format is {header.get('format')!r}, not {_FORMAT!r}")
    version = header.get("format_version")
    if type(version) is not int:
        raise bad(f"format_version is {version!r}, not an integer")
    if version > _FORMAT_VERSION:
        raise IncompatibleModelError(
            path,
            f"model file format {version}, newer than this skpcd reads "
            f"({_FORMAT_VERSION}); upgrade skpcd",
        )
    if version != _FORMAT_VERSION:
        raise bad(f"format_version {version} is not a container version")
    if header.get("serializer") not in _SERIALIZERS:
        raise bad(f"serializer is {header.get('serializer')!r}, not skops or joblib")
    size = header.get("payload_size")
    if type(size) is not int or size < 0:
        raise bad(f"payload_size is {size!r}, not a byte count")
    digest = header.get("payload_sha256")
    if not (
        isinstance(digest, str)
        and len(digest) == 2 * _DIGEST
        and all(c in "0123456789abcdef" for c in digest)
    ):
        raise bad(f"payload_sha256 is {digest!r}, not a SHA-256 in hex")
    versions = header.get("versions")
    if not (
        isinstance(versions, dict)
        and all(isinstance(v, str) for v in versions.values())
        and all(isinstance(versions.get(k), str) for k in ("skpcd", "scikit-learn"))
    ):
        raise bad(
            f"versions is {versions!r}, not a mapping of library names to "
            "version strings with skpcd and scikit-learn"
        )
    if not isinstance(header.get("metadata"), dict):
        raise bad(f"metadata is {header.get('metadata')!r}, not a JSON object")
    if not isinstance(header.get("estimator", ""), str):
        raise bad(f"estimator is {header.get('estimator')!r}, not a string")


def _check_versions(path, saved):
    current = _versions()
    for lib in ("skpcd", "scikit-learn"):
        if _release(saved[lib]) != _release(current[lib]):
            raise IncompatibleModelError(
                path,
                f"written with {lib} {saved[lib]}, this is {lib} "
                f"{current[lib]}; refit the model with this version (or load "
                "it with check_versions=False at your own risk)",
            )


def _read_container(path, fh, size, *, trust_pickle, check_versions):
    """The header and payload of a container, both checksums verified."""
    prefix = fh.read(_PREFIX)
    if len(prefix) < _PREFIX:
        raise PointCloudFileError(path, "truncated model file (no header length)")
    (length,) = _LENGTH.unpack(prefix[len(_MAGIC) :])
    if length > _MAX_HEADER or _PREFIX + length + _DIGEST > size:
        raise PointCloudFileError(
            path,
            f"corrupt or truncated model file: it declares a header of {length} "
            f"bytes and holds {size} bytes in all",
        )
    text = fh.read(length)
    digest = fh.read(_DIGEST)
    if hashlib.sha256(prefix + text).digest() != digest:
        raise PointCloudFileError(
            path, "corrupt model file: the header does not match its checksum"
        )
    try:
        header = json.loads(text.decode("utf-8"))
    except (ValueError, RecursionError) as exc:  # includes UnicodeDecodeError
        raise PointCloudFileError(
            path, f"corrupt model file header: not JSON ({exc})"
        ) from exc
    _check_header(path, header)
    start = _PREFIX + length + _DIGEST
    if size != start + header["payload_size"]:
        raise PointCloudFileError(
            path,
            f"corrupt or truncated model file: the header declares a payload of "
            f"{header['payload_size']} bytes, the file holds {size - start}",
        )
    if header["serializer"] == "joblib" and not trust_pickle:
        raise _pickle_refused(path, "the model is a joblib pickle")
    if check_versions:
        _check_versions(path, header["versions"])
    sha = hashlib.sha256()
    chunks = []
    for chunk in iter(lambda: fh.read(2**20), b""):
        sha.update(chunk)
        chunks.append(chunk)
    if sha.hexdigest() != header["payload_sha256"]:
        raise PointCloudFileError(
            path,
            "corrupt model file: the model data do not match their checksum "
            f"(SHA-256 {sha.hexdigest()}, the header says "
            f"{header['payload_sha256']})",
        )
    return header, b"".join(chunks)


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


def _skops_io():
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


def _from_skops(path, payload, trusted):
    skops_io = _skops_io()
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


def _from_joblib(path, source):

    try:
        return joblib.load(source)
    except Exception as exc:  # any unpickling failure means "not a model file"
        raise PointCloudFileError(
            path, f"not a model file written by skpcd ({type(exc).__name__}: {exc})"
        ) from exc


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


def _check_trees(path, model):
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


def load_model(
    path, *, return_info=False, check_versions=True, trust_pickle=False, trusted=None
):
    """Load a model written by :func:`save_model`.

    Read more in the :ref:`User Guide <models>`.

    Parameters
    ----------
    path : str or path-like
        The model file.
    return_info : bool, default=False
        Also return the versions and metadata stored with the model.
    check_versions : bool, default=True
        Refuse a model written by another skpcd or scikit-learn release
        (major.minor differs). ``False`` loads it anyway, at your own risk:
        the estimators may then fail or answer differently.
    trust_pickle : bool, default=False
        Also load pickles: a model saved with ``format="joblib"`` and the
        bare joblib files skpcd wrote before its model container.
        **Unpickling runs code stored in the file**: a file from someone else
        can do anything your account can. Without it such a file raises
        :class:`~skpcd.exceptions.UntrustedModelError` and nothing from it
        runs. A skops model is never unpickled, with or without this flag.
    trusted : list of str, default=None
        More type names (as the error lists them) that a skops model may
        hold besides skops' own trusted types and ``TRUSTED_TYPES``.

    Returns
    -------
    model : estimator
        The fitted estimator.
    info : dict
        Only with ``return_info=True``: ``{"versions": ..., "metadata": ...,
        "format": "skops" | "joblib" | "joblib-bare"}``.

    Raises
    ------
    MissingFileError
        If the file does not exist.
    PointCloudFileError
        If the file is not a model written by :func:`save_model`, is
        truncated or corrupt (a checksum differs), or its header fields have
        the wrong types.
    UntrustedModelError
        If it is a pickle and ``trust_pickle`` is False, or a skops model
        naming types outside the allow-list (named in the message).
    IncompatibleModelError
        If it was written by an incompatible skpcd or scikit-learn version.

    Notes
    -----
    For a skops model (the default of :func:`save_model`) the signature,
    sizes, both SHA-256 checksums, the header fields and the versions are
    checked before the estimator is rebuilt; skops then imports and builds
    only types it trusts or that are listed in ``TRUSTED_TYPES`` (or
    ``trusted``), without calling any function named by the file. Before
    the model is returned its structure is checked: decision trees for node
    indices out of range and non-finite leaf values; trees against the
    estimator that calls them (features, outputs, classes); ``classes_``
    against ``n_classes_``; a fitted ensemble for at least one estimator;
    each pipeline step's output width (its ``get_feature_names_out``)
    against the next step's ``n_features_in_``. A model that fails raises
    :class:`~skpcd.exceptions.PointCloudFileError` naming the problem, where
    it would otherwise fail in ``predict`` or answer wrong classes.
    """
    path = Path(os.fspath(path))
    if not path.is_file():
        what = "is a directory, not a file" if path.is_dir() else "no such file"
        raise MissingFileError(path, what)
    trusted = [str(t) for t in (trusted or ())]
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        head = fh.read(len(_MAGIC))
        fh.seek(0)
        if head == _MAGIC:
            header, payload = _read_container(
                path, fh, size, trust_pickle=trust_pickle, check_versions=check_versions
            )
            kind = header["serializer"]
            if kind == "skops":
                model = _from_skops(path, payload, trusted)
            else:
                model = _from_joblib(path, io.BytesIO(payload))
            saved, metadata = header["versions"], header["metadata"]
        elif _looks_like_pickle(head):
            if not trust_pickle:
                raise _pickle_refused(path, "the model is a bare joblib pickle")
            model, saved, metadata = _bare_joblib(path, _from_joblib(path, fh))
            if check_versions:
                _check_versions(path, saved)
            kind = "joblib-bare"
        elif len(head) == len(_MAGIC) and _bit_distance(head, _MAGIC) <= 4:
            raise PointCloudFileError(
                path, "corrupt model file: its signature is damaged"
            )
        else:
            raise PointCloudFileError(
                path, "not a model file written by skpcd.save_model"
            )
    _check_trees(path, model)
    if return_info:
        return model, {"versions": saved, "metadata": metadata, "format": kind}
    return model


def _bare_joblib(path, payload):
    """The model, versions and metadata of a format-1 file (a joblib dict)."""
    if not (isinstance(payload, dict) and payload.get("format") == _FORMAT):
        raise PointCloudFileError(path, "not a model file written by skpcd.save_model")
    saved = payload.get("versions")
    if not (
        isinstance(saved, dict)
        and all(isinstance(saved.get(k), str) for k in ("skpcd", "scikit-learn"))
    ):
        raise PointCloudFileError(
            path,
            f"corrupt model file: versions is {saved!r}, not a mapping with the "
            "skpcd and scikit-learn versions",
        )
    metadata = payload.get("metadata", {})
    if not isinstance(metadata, dict):
        raise PointCloudFileError(
            path, f"corrupt model file: metadata is {type(metadata).__name__}"
        )
    if "model" not in payload:
        raise PointCloudFileError(path, "corrupt model file: it holds no model")
    return payload["model"], saved, metadata
