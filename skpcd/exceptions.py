"""Exceptions and warnings raised by skpcd.

Every problem with a file on disk raises :class:`PointCloudFileError` (a
:class:`ValueError`) or its subclass :class:`MissingFileError` (also a
:class:`FileNotFoundError`), and the message always starts with the path.
"""

__all__ = [
    "IncompatibleModelError",
    "MissingFileError",
    "NonFiniteWarning",
    "PointCloudFileError",
    "SegmentationWarning",
    "SkippedFilesWarning",
    "UntrustedModelError",
]


class PointCloudFileError(ValueError):
    """A point-cloud or labels file cannot be read as asked.

    Raised for unknown extensions, empty files, files without a valid point,
    wrong column counts, truncated or corrupt binary data and headers that
    disagree with the data.

    Parameters
    ----------
    path : str or path-like
        The file at fault. It is kept as the ``path`` attribute.
    problem : str
        What is wrong with it, in words.
    """

    def __init__(self, path, problem):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")

    def __reduce__(self):
        return (type(self), (self.path, self.problem))


class MissingFileError(PointCloudFileError, FileNotFoundError):
    """A file that was asked for, or named in a labels file, does not exist.

    It is both a :class:`PointCloudFileError` and a
    :class:`FileNotFoundError`, so either ``except`` clause catches it.
    """


class NonFiniteWarning(UserWarning):
    """Points with NaN or infinite coordinates were dropped while reading."""


class SkippedFilesWarning(UserWarning):
    """Files of a folder that are not point clouds were left out.

    Raised by :func:`skpcd.io.read_segments` with ``errors="skip"``; the
    message names every file skipped and why.
    """


class SegmentationWarning(UserWarning):
    """An automatic choice of the segmentation was corrected for this scan.

    Raised by :func:`skpcd.segmentation.segment_scene` when the automatic
    eps joined a segment spanning most of the scene: the message gives the
    radius used instead and the parameter to set.
    """


class IncompatibleModelError(PointCloudFileError):
    """A saved model was written by another skpcd or scikit-learn release.

    Saved estimators are only sure to work with the versions that wrote
    them; :func:`skpcd.io.load_model` raises this instead of guessing. The
    message names both versions.
    """


class UntrustedModelError(PointCloudFileError):
    """A saved model would need more trust than :func:`skpcd.io.load_model` gives.

    Raised, before anything from the file is run, for a pickle (joblib)
    model loaded without ``trust_pickle=True``, and for a skops model whose
    payload names types outside ``skpcd.io._model.TRUSTED_TYPES`` and the
    ``trusted`` argument. The message says how to opt in.

    Parameters
    ----------
    path : str or path-like
        The model file.
    problem : str
        What is wrong with it, in words.
    types : list of str, default=()
        The fully qualified names of the types that are not trusted (empty
        for a pickle). Kept as the ``types`` attribute.
    """

    def __init__(self, path, problem, types=()):
        self.types = list(types)
        super().__init__(path, problem)

    def __reduce__(self):
        return (type(self), (self.path, self.problem, self.types))
