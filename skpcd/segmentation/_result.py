"""What :func:`~skpcd.segmentation.segment_scene` returns."""

import typing

import numpy as np

from skpcd.segmentation._structures import KINDS

__all__ = ["SceneSegmentation", "kind_names", "with_kinds"]


class SceneSegmentation(typing.NamedTuple):
    """What :func:`~skpcd.segmentation.segment_scene` returns (a named tuple).

    Attributes
    ----------
    labels : ndarray of shape (n_points,), dtype int64
        Segment of each point, 0 .. n_segments - 1; -1 for ground, noise
        and points of segments outside the size range.
    ground : ndarray of shape (n_points,), dtype bool
        Ground points (all False without ground removal).
    eps : float
        The clustering radius used.
    kinds : ndarray of shape (n_segments,), dtype object
        What each segment is: "object", "facade" or "wire" (all "object"
        without ``structures``).
    scan : ScanKind or None
        With ``ground="auto"``, what
        :func:`~skpcd.segmentation.describe_scan` found the scan
        to be (which chose the ground filter); None otherwise.
    ground_filter : str or None
        The ground preset used (a key of ``GROUND_PRESETS``, or "from-file"
        for a classification read from the file), None for a filter or
        flags of your own or none.
    unit : float
        The length of one coordinate unit in metres (``unit`` of
        :func:`~skpcd.segmentation.segment_scene`, resolved): 0.3048 for a scan in feet.
    sensor : tuple of float or None
        Segmented in a range image (:func:`~skpcd.segmentation.segment_sweep`,
        ``method="range-image"``): the position the rays started from; None
        otherwise.
    sensor_from : str or None
        How that position was chosen: "given", "origin" or "above the
        origin" (``RangeImage.sensor_from``); None without a range image.
    """

    labels: np.ndarray
    ground: np.ndarray
    eps: float
    kinds: np.ndarray | None = None
    scan: typing.Any = None
    ground_filter: str | None = None
    unit: float = 1.0
    sensor: tuple | None = None
    sensor_from: str | None = None

    @property
    def n_segments(self):
        """Number of segments."""
        return int(self.labels.max() + 1) if len(self.labels) else 0


def with_kinds(labels, ground, eps):
    """A result whose segments are all objects."""
    n = int(labels.max()) + 1 if len(labels) else 0
    return SceneSegmentation(labels, ground, eps, kind_names(np.zeros(n, np.int8)))


def kind_names(kinds):
    """The names of segment kinds given as indices of ``KINDS``."""
    return np.array(KINDS, dtype=object)[kinds]
