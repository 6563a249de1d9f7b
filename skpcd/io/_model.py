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

This module writes and reads the container; what the payload must pass
before it is trusted (``TRUSTED_TYPES``, the skops loading and the checks
of the model's structure) is in :mod:`skpcd.io._model_checks`.
"""

import hashlib
import io
import json
import os
import platform
import struct
import zipfile
from pathlib import Path

import joblib
import numpy as np
import sklearn

from skpcd import __version__
from skpcd.exceptions import (
    IncompatibleModelError,
    MissingFileError,
    PointCloudFileError,
    UntrustedModelError,
)
from skpcd.io._atomic import atomic_path
from skpcd.io._model_checks import (
    TRUSTED_TYPES,
    check_trees,
    from_skops,
    import_skops_io,
)

__all__ = ["TRUSTED_TYPES", "load_model", "save_model"]

_FORMAT = "skpcd-model"
_FORMAT_VERSION = 2  # 1: a bare joblib pickle of a dict (before the container)
_SERIALIZERS = ("skops", "joblib")
_MAGIC = b"\x89SKPCD-MODEL\r\n\x1a\n"
_LENGTH = struct.Struct("<Q")
_PREFIX = len(_MAGIC) + _LENGTH.size
_DIGEST = 32  # bytes of a SHA-256
_MAX_HEADER = 16 * 2**20

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

    skops_io = import_skops_io()

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


def _from_joblib(path, source):

    try:
        return joblib.load(source)
    except Exception as exc:  # any unpickling failure means "not a model file"
        raise PointCloudFileError(
            path, f"not a model file written by skpcd ({type(exc).__name__}: {exc})"
        ) from exc


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
                model = from_skops(path, payload, trusted)
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
    check_trees(path, model)
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
