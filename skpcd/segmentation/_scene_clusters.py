"""The segments of a scene's non-ground points: the structures step or
plain clustering, the check of an automatic eps (a segment as wide as the
scene halves it), and the size range (see
:func:`~skpcd.segmentation.segment_scene`)."""

import warnings

import numpy as np

from skpcd.exceptions import SegmentationWarning
from skpcd.preprocessing import point_spacing
from skpcd.segmentation._clusters import (
    EUCLIDEAN_EPS,
    EuclideanClusters,
    filter_cluster_sizes,
)
from skpcd.segmentation._dbscan import AutoEpsDBSCAN, estimate_eps
from skpcd.segmentation._result import SceneSegmentation, kind_names, with_kinds
from skpcd.segmentation._scan_kind import sweep_coordinates
from skpcd.segmentation._structures import segment_bounds, segment_structures
from skpcd.utils._progress import stage

__all__ = ["cluster_rest", "largest_box", "robust_extent", "segment_rest"]


# The check of an automatic eps: a segment whose horizontal bounding box
# covers more than this fraction of the scene's (between the 0.1 and 99.9 %
# quantiles of x and y, see robust_extent), and more than
# _MERGED_AREA square units, joined what should be apart (a whole tile as
# one object); the radius is then halved, at most _MERGED_RETRIES times and
# not below twice the point spacing.
_MERGED_FRACTION = 0.5
_MERGED_AREA = 2500.0
_MERGED_RETRIES = 4


def robust_extent(xyz):
    """Horizontal extent (dx, dy) of the scene between the 0.1 and 99.9 %
    quantiles of x and y, so that a few far outliers do not widen it."""
    if not len(xyz):
        return np.zeros(2)
    low, high = np.quantile(xyz[:, :2], [0.001, 0.999], axis=0)
    return high - low


def largest_box(xyz, labels):
    """Horizontal extent (dx, dy) of the segment whose bounding box has the
    largest area, and that area."""
    seg = labels >= 0
    if not seg.any():
        return np.zeros(2), 0.0
    n = int(labels.max()) + 1
    lo, hi, _ = segment_bounds(labels, xyz, n)
    lo, hi = lo[:, :2], hi[:, :2]
    ext = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
    area = ext.prod(axis=1)
    i = int(np.argmax(area))
    return ext[i], float(area[i])


def cluster_rest(
    xyz, is_ground, *, method, eps, eps_scale, min_samples, min_cluster_size,
    max_cluster_size, random_state, n_jobs, structures, sweep=None, unit=1.0,
):  # fmt: skip
    """The segments of the non-ground points, with the check of an
    automatic eps (see segment_scene); its warning gives lengths in the
    units of the coordinates (``xyz`` is in metres, ``unit`` metres a
    unit)."""

    kw = {
        "method": method, "eps_scale": eps_scale, "min_samples": min_samples,
        "min_cluster_size": min_cluster_size, "max_cluster_size": max_cluster_size,
        "random_state": random_state, "n_jobs": n_jobs, "structures": structures,
    }  # fmt: skip
    seg = segment_rest(xyz, is_ground, eps=eps, sweep=sweep, **kw)
    if eps is not None or method != "dbscan" or seg.n_segments == 0:
        return seg
    extent = None  # the scene's, measured only for a segment over _MERGED_AREA
    first, floor, merged = seg.eps, None, None
    for _ in range(_MERGED_RETRIES):
        ext, area = largest_box(xyz, seg.labels)
        if area <= _MERGED_AREA:
            break
        if extent is None:
            extent = robust_extent(xyz)
        if area <= _MERGED_FRACTION * extent.prod():
            break
        merged = ext if merged is None else merged
        if floor is None:
            rest = xyz[~is_ground]
            floor = 2.0 * point_spacing(rest, random_state=0) if len(rest) > 1 else 0.0
        smaller = seg.eps / 2
        if not smaller >= floor:
            break
        seg = segment_rest(xyz, is_ground, eps=smaller, **kw)
    if seg.eps != first:
        first, merged, extent = first / unit, merged / unit, extent / unit
        warnings.warn(
            f"the automatic eps {first:.3g} joined a segment of {merged[0]:.4g} x "
            f"{merged[1]:.4g} in a scene of {extent[0]:.4g} x "
            f"{extent[1]:.4g}: eps {seg.eps / unit:.3g} used instead; set eps "
            "(--eps) to choose the radius",
            SegmentationWarning,
            stacklevel=3,
        )
    return seg


def segment_rest(
    xyz, is_ground, *, method, eps, eps_scale, min_samples, min_cluster_size,
    max_cluster_size, random_state, n_jobs, structures=False, sweep=None,
):  # fmt: skip
    """The segments of the non-ground points of checked xyz (see
    segment_scene). ``sweep``, ``(centre, z0, radius)``: DBSCAN runs in the
    coordinates of :func:`sweep_coordinates` with that radius (a distance
    proportional to the range)."""

    rest = np.flatnonzero(~is_ground)
    labels = np.full(len(xyz), -1, dtype=np.int64)
    if len(rest) < 2:
        return with_kinds(labels, is_ground, float(eps or 0.0))
    if structures is not False:
        pts = np.ascontiguousarray(xyz[rest])
        if method == "dbscan":
            used = (
                float(eps)
                if eps is not None
                else estimate_eps(
                    pts, eps_scale=eps_scale, random_state=random_state, n_jobs=n_jobs
                )
            )

            space, radius = pts, used
            if sweep is not None:
                space, radius = sweep_coordinates(pts, sweep[0], sweep[1]), sweep[2]

            def cluster(mask):
                if mask.sum() < 2:
                    return np.full(int(mask.sum()), -1, dtype=np.int64)
                return (
                    AutoEpsDBSCAN(eps=radius, min_samples=min_samples, n_jobs=n_jobs)
                    .fit(space[mask])
                    .labels_
                )
        else:
            used = EUCLIDEAN_EPS if eps is None else float(eps)

            def cluster(mask):
                if mask.sum() < 2:
                    return np.full(int(mask.sum()), -1, dtype=np.int64)
                return (
                    EuclideanClusters(eps=used, min_cluster_size=1, n_jobs=n_jobs)
                    .fit(pts[mask])
                    .labels_
                )

        ground_xyz = xyz[is_ground]
        with stage("structures (facades, wires, trunks)"):  # on the terminal
            sub, kinds, _ = segment_structures(
                pts,
                ground_xyz,
                used,
                structures if isinstance(structures, dict) else None,
                cluster,
                n_jobs=n_jobs,
            )
        del ground_xyz, pts
        kept = size_filter(sub, len(kinds), min_cluster_size, max_cluster_size)
        labels[rest] = kept[sub]
        kinds = kinds[kept[:-1] >= 0]
        return SceneSegmentation(labels, is_ground, float(used), kind_names(kinds))
    if method == "dbscan" and sweep is not None:
        used = float(eps)
        sub = (
            AutoEpsDBSCAN(eps=sweep[2], min_samples=min_samples, n_jobs=n_jobs)
            .fit(sweep_coordinates(xyz[rest], sweep[0], sweep[1]))
            .labels_
        )
    elif method == "dbscan":
        est = AutoEpsDBSCAN(
            eps=eps,
            eps_scale=eps_scale,
            min_samples=min_samples,
            random_state=random_state,
            n_jobs=n_jobs,
        ).fit(xyz[rest])
        used = est.eps_
        sub = est.labels_
    else:
        used = EUCLIDEAN_EPS if eps is None else float(eps)
        sub = (
            EuclideanClusters(eps=used, min_cluster_size=1, n_jobs=n_jobs)
            .fit(xyz[rest])
            .labels_
        )
    labels[rest] = filter_cluster_sizes(sub, min_cluster_size, max_cluster_size)
    return with_kinds(labels, is_ground, float(used))


def size_filter(sub, n, min_size, max_size):
    """New number of each of ``n`` segments (-1: dropped for its size), and
    -1 at index ``n`` (for the points in no segment, label -1)."""
    sizes = np.bincount(sub[sub >= 0], minlength=n)
    keep = sizes >= min_size
    if max_size is not None:
        keep &= sizes <= max_size
    new = np.full(n + 1, -1, dtype=np.int64)
    new[:n][keep] = np.arange(int(keep.sum()))
    return new
