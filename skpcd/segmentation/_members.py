"""The points of each segment of a segmented scene, in memory or streamed."""

import shutil
import tempfile
from pathlib import Path

import numpy as np

from skpcd.segmentation.tiling._spill import iter_chunks

__all__ = ["iter_segment_points", "segment_members", "spread_to_points"]


def segment_members(labels, n_segments):
    """Point indices of each segment ``0..n_segments-1``, in one sort.

    Parameters
    ----------
    labels : ndarray of shape (n_points,)
        Segment of each point; -1 (or any negative value) for none.
    n_segments : int
        Number of segments.

    Returns
    -------
    members : list of ndarray
        ``members[i]`` holds the indices of the points of segment ``i``,
        in increasing order.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation._members import segment_members
    >>> [m.tolist() for m in segment_members(np.array([1, -1, 0, 1]), 2)]
    [[2], [0, 3]]
    """
    labels = np.asarray(labels)
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n_segments + 1))
    return [order[bounds[i] : bounds[i + 1]] for i in range(n_segments)]


def iter_segment_points(
    scene, labels, n_segments, *, fields=False, folder=None, chunk_size=1_000_000
):
    """``(points, extras)`` of each segment of a scene file, in segment order,
    without holding the scene in memory.

    One pass over the scene's chunks appends the points of each segment to
    a temporary file of its own; the segments are then read back one by
    one. Memory is one chunk plus the largest segment.

    Parameters
    ----------
    scene : str or path-like
        The scene file (streamed when LAS/LAZ, else read whole).
    labels : array-like of shape (n_points,)
        Segment of each point of the file, in file order (a
        :class:`numpy.memmap` stays on disk); negative for none.
    n_segments : int
        Number of segments.
    fields : bool, default=False
        Also gather every extra field of the file.
    folder : path-like, default=None
        Where the temporary files go (a hidden folder made and removed
        inside it); None: the system's temporary folder.
    chunk_size : int, default=1_000_000
        Points read at a time.

    Yields
    ------
    points : ndarray of shape (n_i, 3)
        The points of segment ``i``, in file order.
    extras : dict of str to ndarray
        Their fields (empty without ``fields``).
    """

    spill = Path(tempfile.mkdtemp(prefix=".skpcd_segments_", dir=folder))
    try:
        dtype, start = None, 0
        chunks = iter_chunks(scene, chunk_size, fields=fields)
        if not fields:
            chunks = ((xyz, {}) for xyz in chunks)
        for xyz, extras in chunks:
            if dtype is None:
                dtype = np.dtype(
                    [("xyz", np.float64, (3,))]
                    + [(k, v.dtype, v.shape[1:]) for k, v in extras.items()]
                )
            part = np.asarray(labels[start : start + len(xyz)])
            start += len(xyz)
            order = np.argsort(part, kind="stable")
            bounds = np.searchsorted(part[order], np.arange(n_segments + 1))
            records = np.empty(len(xyz), dtype=dtype)
            records["xyz"] = xyz
            for k, v in extras.items():
                records[k] = v
            for i in np.flatnonzero(np.diff(bounds)):
                with open(spill / f"{i}.bin", "ab") as f:
                    records[order[bounds[i] : bounds[i + 1]]].tofile(f)
        if start != len(labels):
            raise ValueError(
                f"{scene}: read {start} points but the labels are for {len(labels)}"
            )
        for i in range(n_segments):
            records = np.fromfile(spill / f"{i}.bin", dtype=dtype)
            yield (
                np.ascontiguousarray(records["xyz"]),
                {k: records[k] for k in dtype.names[1:]},
            )
    finally:
        shutil.rmtree(spill, ignore_errors=True)


def spread_to_points(labels, values, fill, out, chunk=1_000_000):
    """The value of each point's segment: ``values[labels]``, ``fill`` where
    a label is negative, into ``out``, a chunk of points at a time
    (``labels`` and ``out`` may be memmaps that stay on disk).

    Parameters
    ----------
    labels : array-like of shape (n_points,)
        Segment of each point; negative for none.
    values : ndarray of shape (n_segments,)
        A value per segment.
    fill : scalar
        The value of the points in no segment.
    out : array-like of shape (n_points,)
        Where the values go (its dtype is theirs).
    chunk : int, default=1_000_000
        Points at a time.

    Returns
    -------
    out : array-like of shape (n_points,)

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation._members import spread_to_points
    >>> spread_to_points(np.array([1, -1, 0]), np.array([5, 7]), 0, np.empty(3, int))
    array([7, 0, 5])
    """
    for start in range(0, len(labels), chunk):
        lab = np.asarray(labels[start : start + chunk])
        part = np.full(len(lab), fill, dtype=out.dtype)
        inside = lab >= 0
        part[inside] = values[lab[inside]]
        out[start : start + len(lab)] = part
    return out
