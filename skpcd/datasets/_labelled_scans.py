"""Objects to train on, cut from scans labelled point by point."""

import numpy as np
from sklearn.utils import Bunch

from skpcd.io._class_codes import class_key
from skpcd.io._point_labels import read_point_labels
from skpcd.segmentation import segment_scene

__all__ = ["GROUND_CLASSES", "objects_from_labelled_scans"]

#: class names (lower case, words joined by ``_``) of ground points: left
#: out of the objects (the segmentation finds the ground itself)
GROUND_CLASSES = (
    "ground",
    "road",
    "road_surface",
    "sidewalk",
    "parking",
    "terrain",
    "other_ground",
    "lane_marking",
)


def _majority(labels, groups, n_groups):
    """Majority class, its share and the count of each group's points
    (``groups`` -1: in no group)."""
    inside = groups >= 0
    names, codes = np.unique(labels[inside], return_inverse=True)
    counts = np.zeros((n_groups, len(names)), dtype=np.int64)
    np.add.at(counts, (groups[inside], codes.reshape(-1)), 1)
    total = counts.sum(axis=1)
    best = counts.argmax(axis=1) if len(names) else np.zeros(n_groups, dtype=int)
    share = np.divide(
        counts[np.arange(n_groups), best] if len(names) else np.zeros(n_groups),
        total,
        out=np.zeros(n_groups),
        where=total > 0,
    )
    return (names[best] if len(names) else np.full(n_groups, "", object)), share, total


def objects_from_labelled_scans(
    scans,
    field=None,
    *,
    instances="auto",
    class_map=None,
    ground=GROUND_CLASSES,
    min_purity=0.5,
    min_points=50,
    segmentation=None,
    return_X_y=False,
    n_jobs=None,
):
    """Cut labelled objects out of scans labelled point by point.

    Read more in the :ref:`User Guide <labelled-scan-training>`.

    Each scan is read with :func:`~skpcd.io.read_point_labels`. Points with
    an object id (a SemanticKITTI instance, an ``instance`` field) make one
    object per id. The other points are cut by skpcd's own segmentation
    (:func:`~skpcd.segmentation.segment_scene`, as ``skpcd identify`` cuts a
    scan), and each segment takes the majority class of its labelled points
    (those the class map does not ignore); its *purity* is that class's
    share of them. Objects whose majority is a ground class or whose
    purity is below ``min_purity``, and objects of fewer than ``min_points``
    points, are left out.

    Parameters
    ----------
    scans : sequence of str or path-like
        The labelled scans (files; see :func:`~skpcd.io.labelled_scan_paths`
        for folders).
    field : str, default=None
        The field of the class codes (``classification`` when None; a
        ``.bin`` scan's ``.label``).
    instances : "auto", str or None, default="auto"
        The field of object ids, as :func:`~skpcd.io.read_point_labels`
        takes it; None cuts every object by segmentation.
    class_map : str, path-like or ClassMap, default=None
        How codes become class names (:func:`~skpcd.io.read_class_map`);
        codes mapped to ``ignore`` count in no majority.
    ground : sequence of str, default=GROUND_CLASSES
        The classes of ground points (matched in lower case, spaces and
        hyphens read as ``_``): road, sidewalk, terrain...
    min_purity : float, default=0.5
        The least share of its majority class an object keeps (0 to 1).
    min_points : int, default=50
        The fewest points of an object kept (skpcd identify's segments hold
        at least 50 by default).
    segmentation : dict, default=None
        Keyword arguments of :func:`~skpcd.segmentation.segment_scene`
        (``ground``, ``eps``, ``structures``...).
    return_X_y : bool, default=False
        Return ``(clouds, labels)`` only.
    n_jobs : int, default=None
        Threads of the segmentation (-1: all cores).

    Returns
    -------
    objects : :class:`~sklearn.utils.Bunch`
        With ``clouds`` (list of ndarray of shape (n_i, 3)), ``labels``
        (ndarray of str), ``scan`` (index of each object's scan in
        ``scans``: groups for :class:`~sklearn.model_selection.GroupKFold`),
        ``purity``, ``n_points``, ``cut`` ("instance" or "segment") and
        ``left_out`` (dict: objects left out for each reason).
    (clouds, labels) : tuple
        With ``return_X_y``.

    Raises
    ------
    ValueError
        If ``min_purity`` is not within 0 to 1, or no object is left.
    PointCloudFileError
        For a scan or a class map that cannot be read as asked.

    See Also
    --------
    skpcd.io.read_point_labels : Read one labelled scan.
    skpcd.metrics.scan_scores : Score a labelled scan point by point.
    """
    if not 0 <= min_purity <= 1:
        raise ValueError(f"min_purity must be within 0 and 1, got {min_purity}")
    if min_points < 1:
        raise ValueError(f"min_points must be at least 1, got {min_points}")
    ground = {class_key(g) for g in ground}
    clouds, labels, scan_of, purity, sizes, cut = [], [], [], [], [], []
    left_out = {"ground": 0, "ignored": 0, "impure": 0, "small": 0}
    for s, path in enumerate(scans):
        scan = read_point_labels(path, field, instances=instances, class_map=class_map)
        points, names, objects = scan.points, scan.labels, scan.instances
        named = ~scan.ignored
        has_object = np.zeros(len(points), dtype=bool)
        groups_list = []
        if objects is not None and (objects > 0).any():
            has_object = objects > 0
            ids, inv = np.unique(objects[has_object], return_inverse=True)
            groups = np.full(len(points), -1, dtype=np.int64)
            groups[has_object] = inv.reshape(-1)
            groups_list.append(("instance", groups, len(ids)))
        result = segment_scene(points, n_jobs=n_jobs, **(segmentation or {}))
        seg = np.where(has_object, -1, result.labels)
        groups_list.append(("segment", seg, result.n_segments))
        for how, groups, n_groups in groups_list:
            counted = np.where(named, groups, -1)
            major, share, n_named = _majority(names, counted, n_groups)
            order = np.argsort(groups, kind="stable")
            bounds = np.searchsorted(groups[order], np.arange(n_groups + 1))
            for g in range(n_groups):
                members = order[bounds[g] : bounds[g + 1]]
                if not len(members):  # a segment whose points all have an id
                    continue
                if n_named[g] == 0:
                    left_out["ignored"] += 1
                elif class_key(major[g]) in ground:
                    left_out["ground"] += 1
                elif share[g] < min_purity:
                    left_out["impure"] += 1
                elif len(members) < min_points:
                    left_out["small"] += 1
                else:
                    clouds.append(points[members])
                    labels.append(str(major[g]))
                    scan_of.append(s)
                    purity.append(float(share[g]))
                    sizes.append(len(members))
                    cut.append(how)
    if not clouds:
        raise ValueError(
            f"no object left in {len(scans)} scan(s): "
            + ", ".join(f"{n} {why}" for why, n in left_out.items())
        )
    labels = np.array(labels, dtype=object)
    if return_X_y:
        return clouds, labels
    return Bunch(
        clouds=clouds,
        labels=labels,
        scan=np.array(scan_of),
        purity=np.array(purity),
        n_points=np.array(sizes),
        cut=np.array(cut, dtype=object),
        left_out=left_out,
    )
