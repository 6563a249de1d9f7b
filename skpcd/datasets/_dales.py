"""The DALES Objects segments, read from a local folder."""

import os
from pathlib import Path

from sklearn.utils import Bunch

from skpcd.datasets._urban import make_urban_objects
from skpcd.exceptions import MissingFileError
from skpcd.io import read_segments

__all__ = ["DALES_ENV", "load_dales_objects"]

DALES_ENV = "SKPCD_DALES_DIR"


def load_dales_objects(
    folder=None,
    *,
    return_X_y=False,
    synthetic_if_missing=False,
    n_per_class=40,
    random_state=0,
):
    """Load the DALES Objects segments (real aerial LiDAR), one cloud per object.

    The data are not downloaded: they are read from ``folder``, or from the
    folder named by the environment variable ``SKPCD_DALES_DIR``. That folder
    holds one point-cloud file per object and a ``labels.csv`` of
    ``file,label`` rows (building, car, fence, pole, tree).

    Read more in the :ref:`User Guide <io>`.

    Parameters
    ----------
    folder : str, path-like or None, default=None
        The folder; None reads ``SKPCD_DALES_DIR``.
    return_X_y : bool, default=False
        Return ``(clouds, labels)`` instead of a :class:`~sklearn.utils.Bunch`.
    synthetic_if_missing : bool, default=False
        When the folder is not given, not set or has no ``labels.csv``,
        return the embedded synthetic objects of
        :func:`make_urban_objects` (same five classes) instead of raising;
        ``source`` says which data came back.
    n_per_class : int, default=40
        Objects per class of the synthetic stand-in.
    random_state : int, RandomState instance or None, default=0
        Seed of the synthetic stand-in.

    Returns
    -------
    data : :class:`~sklearn.utils.Bunch`
        ``data`` (list of ndarray of shape (n_points_i, 3)), ``target``
        (ndarray of str of shape (n_clouds,)), ``filenames`` (list of str,
        empty for synthetic objects), ``source`` (``"DALES objects"`` or
        ``"synthetic urban objects"``) and ``folder`` (the folder read, or
        None).
    (clouds, labels) : tuple
        With ``return_X_y=True``.

    Raises
    ------
    MissingFileError
        If no folder with a ``labels.csv`` is found and
        ``synthetic_if_missing`` is False, or if a labelled file is missing.

    See Also
    --------
    skpcd.io.read_segments : Read any folder of labelled segments.
    make_urban_objects : The synthetic stand-in.

    Examples
    --------
    >>> from skpcd.datasets import load_dales_objects
    >>> objects = load_dales_objects(
    ...     "no/such/folder", synthetic_if_missing=True, n_per_class=2
    ... )
    >>> objects.source, len(objects.data), sorted(set(objects.target.tolist()))[:2]
    ('synthetic urban objects', 10, ['building', 'car'])
    """

    if folder is None:
        folder = os.environ.get(DALES_ENV)
    labels_file = Path(folder) / "labels.csv" if folder else None
    if labels_file is not None and labels_file.is_file():
        clouds, labels, names = read_segments(folder, labels_file)
        data = Bunch(
            data=clouds,
            target=labels,
            filenames=names,
            source="DALES objects",
            folder=Path(folder),
        )
    elif synthetic_if_missing:
        clouds, labels = make_urban_objects(
            n_per_class=n_per_class, random_state=random_state
        )
        data = Bunch(
            data=clouds,
            target=labels,
            filenames=[],
            source="synthetic urban objects",
            folder=None,
        )
    else:
        where = labels_file if labels_file else f"${DALES_ENV} (not set)"
        raise MissingFileError(
            where,
            "no DALES objects here: give the folder holding the objects and "
            f"labels.csv, or set {DALES_ENV}",
        )
    if return_X_y:
        return data.data, data.target
    return data
