"""The ground a scan already carries: the points whose classification is a
ground code (ASPRS class 2 unless other codes are given), instead of a
filter run again."""

import os
import warnings
from numbers import Integral

import numpy as np

from skpcd.exceptions import PointCloudFileError, SegmentationWarning
from skpcd.io import read_point_cloud
from skpcd.io._chunks import is_streamed
from skpcd.io._las_reader import iter_points, read_las_extent
from skpcd.segmentation.ground._filter import GroundFilter
from skpcd.segmentation.ground._presets import FROM_FILE

__all__ = [
    "ASPRS_GROUND",
    "FROM_FILE",
    "ClassifiedGround",
    "classified_ground",
    "ground_flags",
]

ASPRS_GROUND = 2
"""The ground code of the ASPRS classes (LAS ``classification``)."""


class ClassifiedGround:
    """The ground points of a scan file: those whose classification is one
    of ``codes``.

    ``ground="from-file"`` in :func:`~skpcd.segmentation.segment_scene` is
    ``ClassifiedGround()`` (ASPRS class 2, ground); give other codes with
    ``ground=ClassifiedGround(codes=(2, 8))`` (8: model key points in LAS
    1.2 files). The field is ``classification`` (a LAS dimension, or a
    field of that name in any case, as PDAL writes ``Classification`` in
    PCD and PLY files).

    Parameters
    ----------
    codes : int or sequence of int, default=(2,)
        The classification codes of ground points, 0 to 255.

    Attributes
    ----------
    codes : tuple of int
        The codes, sorted, without repeats.

    Examples
    --------
    >>> from skpcd.segmentation.ground import ClassifiedGround
    >>> ClassifiedGround(codes=[8, 2, 2])
    ClassifiedGround(codes=(2, 8))
    >>> ClassifiedGround().flags([1, 2, 2, 6]).tolist()
    [False, True, True, False]
    """

    def __init__(self, codes=(ASPRS_GROUND,)):
        if isinstance(codes, Integral):
            codes = (codes,)
        try:
            values = [int(c) for c in codes]
        except (TypeError, ValueError):
            raise ValueError(
                f"ground codes must be integers 0 to 255, got {codes!r}"
            ) from None
        if not values or not all(
            isinstance(c, Integral) and 0 <= c <= 255 for c in codes
        ):
            raise ValueError(f"ground codes must be integers 0 to 255, got {codes!r}")
        self.codes = tuple(sorted(set(values)))

    def __repr__(self):
        return f"ClassifiedGround(codes={self.codes})"

    def __eq__(self, other):
        return isinstance(other, ClassifiedGround) and other.codes == self.codes

    def __hash__(self):
        return hash(self.codes)

    def flags(self, classification):
        """Which points are ground.

        Parameters
        ----------
        classification : array-like of shape (n_points,)
            The classification of each point (any numeric type: PDAL's
            PCD files store it as floats).

        Returns
        -------
        ground : ndarray of shape (n_points,), dtype bool
            True where the classification is one of ``codes``.
        """
        return np.isin(np.asarray(classification), self.codes)

    def read(self, path):
        """The points of a file and their ground flags, in file order (the
        points that :func:`~skpcd.io.read_point_cloud` drops, with NaN or
        infinite coordinates, dropped from both).

        Parameters
        ----------
        path : str or path-like
            A point-cloud file with a classification field.

        Returns
        -------
        points : ndarray of shape (n_points, 3)
            The coordinates.
        ground : ndarray of shape (n_points,), dtype bool
            The ground flags.

        Raises
        ------
        PointCloudFileError
            If the file has no classification field.
        """
        points, extras = read_point_cloud(path, fields="all")
        return points, self.flags_of(path, extras)

    def flags_of(self, path, fields):
        """The ground flags of a file's points from its fields.

        Parameters
        ----------
        path : str or path-like
            The file, for the messages.
        fields : dict of str to ndarray
            Its fields, as :func:`~skpcd.io.read_point_cloud` returns them
            with ``fields="all"``.

        Returns
        -------
        ground : ndarray of shape (n_points,), dtype bool
            The ground flags; a :class:`~skpcd.exceptions.SegmentationWarning`
            when there is none.

        Raises
        ------
        PointCloudFileError
            If there is no classification field.
        """
        ground = self.flags(fields[_classification_name(path, fields)])
        self._check_found(path, ground.any())
        return ground

    def iter_flags(self, path, chunk_size):
        """The ground flags of a file, chunk by chunk, in file order: a
        LAS/LAZ file is streamed (only its classification is kept), another
        format read whole (as the tiled segmentation reads it). The field
        is looked for now, the chunks read when iterated.

        Parameters
        ----------
        path : str or path-like
            A point-cloud file with a classification field.
        chunk_size : int
            Points per chunk.

        Returns
        -------
        chunks : iterator of ndarray of shape (n_chunk,), dtype bool
            The flags of the points, ``chunk_size`` at a time.

        Raises
        ------
        PointCloudFileError
            If the file has no classification field.
        """
        if not is_streamed(path):
            ground = self.read(path)[1]
            return (
                ground[start : start + chunk_size]
                for start in range(0, len(ground), chunk_size)
            )
        name = _classification_name(path, read_las_extent(path).dimensions)

        def chunks():
            found = False
            for _, extras in iter_points(path, chunk_size=chunk_size, fields=[name]):
                ground = self.flags(extras[name])
                found = found or bool(ground.any())
                yield ground
            self._check_found(path, found)

        return chunks()

    def _check_found(self, path, found):
        if not found:
            warnings.warn(
                f"{path}: no point has classification "
                f"{' or '.join(map(str, self.codes))}: no ground (give the codes "
                "of its ground, or another ground filter)",
                SegmentationWarning,
                stacklevel=4,
            )


def _classification_name(path, names):
    """The name of the classification field among ``names``: exactly
    ``classification``, else in any case."""
    names = list(names)
    if "classification" in names:
        return "classification"
    for name in names:
        if name.lower() == "classification":
            return name
    others = [n for n in names if n not in ("x", "y", "z", "X", "Y", "Z")]
    raise PointCloudFileError(
        path,
        "no classification field to take the ground from (ground 'from-file'); "
        f"the file has: {', '.join(others) or 'x, y, z only'}",
    )


def classified_ground(ground, points):
    """The :class:`ClassifiedGround` a ``ground`` argument asks for (the
    string ``"from-file"`` or an instance), or None for any other; a
    ValueError when the points are not a file to read it from."""
    if isinstance(ground, str) and ground == FROM_FILE:
        ground = ClassifiedGround()
    if not isinstance(ground, ClassifiedGround):
        return None
    if not isinstance(points, (str, os.PathLike)):
        raise ValueError(
            "ground='from-file' takes the ground from the classification of a "
            "file, but the points are an array: pass the file, or the ground "
            "flags as ground (a boolean array, one per point)"
        )
    return ground


def ground_flags(ground, n_points):
    """The ground flags a ``ground`` argument gives outright (a boolean
    array-like, one per point), checked against ``n_points`` unless None;
    None for a preset, a filter, a :class:`ClassifiedGround` or None."""
    if ground is None or isinstance(ground, (str, GroundFilter, ClassifiedGround)):
        return None
    flags = np.asarray(ground)
    if flags.dtype != np.bool_ or flags.ndim != 1:
        raise ValueError(
            "ground flags must be a boolean array of shape (n_points,), got "
            f"dtype {flags.dtype} and shape {flags.shape}"
        )
    if n_points is not None and len(flags) != n_points:
        raise ValueError(f"ground flags hold {len(flags)} values for {n_points} points")
    return flags
