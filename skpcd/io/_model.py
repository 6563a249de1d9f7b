"""Saving and loading fitted models, with the versions that made them.

A model file is a joblib pickle of a dictionary: the estimator, the skpcd,
scikit-learn, numpy and Python versions it was fitted with, and free-form
metadata (what it was trained on). Pickles are only safe to load with the
library versions that wrote them, so :func:`load_model` refuses a file
written by another skpcd or scikit-learn release (major.minor) with a message
naming both versions, unless asked to try anyway.
"""

import os
import platform
from pathlib import Path

from skpcd.exceptions import (
    IncompatibleModelError,
    MissingFileError,
    PointCloudFileError,
)
from skpcd.io._atomic import atomic_path

__all__ = ["load_model", "save_model"]

_FORMAT = "skpcd-model"
_FORMAT_VERSION = 1


def _versions():
    import numpy
    import sklearn

    from skpcd import __version__

    return {
        "skpcd": __version__,
        "scikit-learn": sklearn.__version__,
        "numpy": numpy.__version__,
        "python": platform.python_version(),
    }


def _release(version):
    """``major.minor`` of a version string."""
    return ".".join(str(version).split(".")[:2])


def save_model(model, path, *, metadata=None, overwrite=False):
    """Save a fitted estimator to a file, with the library versions.

    Parameters
    ----------
    model : estimator
        Any fitted scikit-learn compatible estimator or pipeline.
    path : str or path-like
        The file to write (``.joblib`` by convention).
    metadata : dict, default=None
        Extra information kept beside the model (for example the training
        folder and the classes), returned by :func:`load_model` with
        ``return_info=True``.
    overwrite : bool, default=False
        Replace an existing file; otherwise an existing file raises
        :class:`FileExistsError` and is left untouched.

    Returns
    -------
    path : pathlib.Path
        The file written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from sklearn.dummy import DummyClassifier
    >>> from skpcd.io import load_model, save_model
    >>> model = DummyClassifier().fit([[0], [1]], ["a", "b"])
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "model.joblib"
    >>> _ = save_model(model, path, metadata={"data": "toy"})
    >>> load_model(path).predict([[0]]).shape
    (1,)
    """
    import joblib

    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: exists; pass overwrite=True to replace it")
    payload = {
        "format": _FORMAT,
        "format_version": _FORMAT_VERSION,
        "versions": _versions(),
        "metadata": dict(metadata or {}),
        "model": model,
    }
    # write beside the target, then rename: a failed dump never leaves a
    # half-written file in place of a good one
    with atomic_path(path, overwrite=overwrite) as tmp:
        joblib.dump(payload, tmp)
    return path


def load_model(path, *, return_info=False, check_versions=True):
    """Load a model written by :func:`save_model`.

    Parameters
    ----------
    path : str or path-like
        The model file.
    return_info : bool, default=False
        Also return the versions and metadata stored with the model.
    check_versions : bool, default=True
        Refuse a model written by another skpcd or scikit-learn release
        (major.minor differs). ``False`` loads it anyway, at your own risk:
        unpickled estimators may then fail or answer differently.

    Returns
    -------
    model : estimator
        The fitted estimator.
    info : dict
        Only with ``return_info=True``: ``{"versions": ..., "metadata": ...}``.

    Raises
    ------
    MissingFileError
        If the file does not exist.
    PointCloudFileError
        If the file is not a model written by :func:`save_model`.
    IncompatibleModelError
        If it was written by an incompatible skpcd or scikit-learn version.

    Notes
    -----
    Loading a pickle runs code from the file: only load models you trust.
    """
    import joblib

    path = Path(os.fspath(path))
    if not path.is_file():
        what = "is a directory, not a file" if path.is_dir() else "no such file"
        raise MissingFileError(path, what)
    try:
        payload = joblib.load(path)
    except Exception as exc:  # any unpickling failure means "not a model file"
        raise PointCloudFileError(
            path, f"not a model file written by skpcd ({type(exc).__name__}: {exc})"
        ) from exc
    if not (isinstance(payload, dict) and payload.get("format") == _FORMAT):
        raise PointCloudFileError(path, "not a model file written by skpcd.save_model")
    saved = payload.get("versions", {})
    if check_versions:
        current = _versions()
        for lib in ("skpcd", "scikit-learn"):
            if _release(saved.get(lib)) != _release(current[lib]):
                raise IncompatibleModelError(
                    path,
                    f"written with {lib} {saved.get(lib)}, this is {lib} "
                    f"{current[lib]}; refit the model with this version (or load "
                    "it with check_versions=False at your own risk)",
                )
    model = payload["model"]
    if return_info:
        return model, {"versions": saved, "metadata": payload.get("metadata", {})}
    return model
