"""Structures that touch objects: facades, overhead wires, poles in clusters.

A street scan is not a set of separate objects on the ground: trees grow
against facades, wires run from pole to pole through the crowns, a lamp
post stands inside a tree. DBSCAN joins whatever touches. Before
clustering, the non-ground points are typed by the shape of their
neighbourhood (the eigenvalues ``l1 >= l2 >= l3`` of the covariance of
their k nearest neighbours):

- facade points: planar (``(l2 - l3) / l1``), with a horizontal normal,
  linked into pieces at least ``facade_min_height`` tall and
  ``facade_min_length`` long, then grown over the neighbours that are
  mostly facade;
- wire points: linear (``(l1 - l2) / l1``), with a horizontal-ish axis,
  thin, at least ``wire_min_height`` above the ground, linked into pieces
  at least ``wire_min_length`` long.

Each gets its own segments (the linked pieces); the other points are
clustered by DBSCAN, and a cluster holding several vertical trunks (poles,
tree trunks: linear, vertical, in the first metres above the ground) is
split between them, every point going to the trunk nearest along the
k-NN graph of the cluster.
"""

import numpy as np
from scipy.sparse import csr_array
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from skpcd.neighbors._grid import argsort_keys
from skpcd.neighbors._neighbors import search_packed, suits_knn
from skpcd.segmentation._clusters import euclidean_clusters, fine_clusters, fine_grid
from skpcd.segmentation._structure_kernels import (
    aligned_components,
    column_counts,
    column_keys,
    component_covariance,
    first_rows,
    local_shape_rows,
    nearest_square,
    neighbour_share,
    same_label_edges,
    segment_extents,
    sort_columns,
)
from skpcd.utils._parallel import effective_threads, parallel_rows

__all__ = ["STRUCTURE_DEFAULTS", "height_above_ground", "segment_structures"]

# the parameters of segment_scene(structures=True); lengths in metres. The
# facades' least height, 2 m, was chosen on the real sweeps of
# ../shared/data/real_labelled leaving one source out (SemanticKITTI,
# nuScenes, PandaSet: 3, 2.5, 2, 1.5 m tried): the walls a 64- or 32-beam
# sweep sees are 2 to 3 m tall, so at 3 m the facades held 2 % of the
# building points of the SemanticKITTI sweeps and none of nuScenes'; at 2 m
# 22 % and 35 % (84 % and 93 % of what is typed facade is building), 50 %
# on PandaSet as at 3 m. 1.5 m typed ten times more vegetation, cars and
# people as facade on SemanticKITTI.
STRUCTURE_DEFAULTS = {
    "n_neighbors": 12,
    "facade_min_height": 2.0,
    "facade_min_length": 4.0,
    "wire_min_height": 3.0,
    "wire_min_length": 4.0,
    "wire_max_width": 0.3,
    "trunk_min_height": 1.2,
}

# kinds of segment, as written in segments.csv
KINDS = ("object", "facade", "wire")

# thresholds on the local shape (dimensionless)
_PLANAR = 0.5  # planarity of a facade point
_VERTICAL_NORMAL = 0.3  # largest |normal z| of a facade point (73 degrees)
_LINEAR = 0.8  # linearity of a wire point
_HORIZONTAL_AXIS = 0.5  # largest |axis z| of a wire point (30 degrees)
_TRUNK_LINEAR = 0.6  # linearity of a trunk point
_VERTICAL_AXIS = 0.85  # smallest |axis z| of a trunk point
_TRUNK_BAND = (0.2, 3.0)  # heights of trunk points above the ground
_TRUNK_MAX_WIDTH = 0.35  # largest horizontal standard deviation of a trunk
_GROW_SHARE = 0.5  # a point with this share of facade neighbours is facade
_NORMAL_COS = float(np.cos(np.deg2rad(20.0)))  # normals of one facade region
_GROW_STEPS = 2
_COLUMN = 0.5  # side of the columns of the wire test (metres)
_WIRE_COLUMN_POINTS = 3  # most points 0.3-2 m above or below a wire point
_FLAT_SHARE = 0.5  # planar share of a cluster touching a facade that joins it


# The squares of height_above_ground are searched in a table when the
# ground's bounding box holds at most this many squares per ground point (a
# few arrays of its size: memory of the order of the points, whatever a far
# outlier does to the box), and this many rings of squares around a point
# before a k-d tree answers it.
_SQUARES_PER_POINT = 4
_SQUARE_RINGS = 8


def height_above_ground(xyz, ground_xyz, cell=1.0, n_threads=1):
    """Height of points above the ground points: ``z`` minus the mean height
    of the ground points in the nearest ``cell`` x ``cell`` square holding
    ground; ``z`` minus the lowest ``z`` without ground. "Nearest" is by
    the plane distance to a representative ground point of each square
    (its first), ties to the lower square; the squares holding ground are
    searched in rings around each point in a table of the ground's
    bounding box (a k-d tree of the representatives when that box holds
    over ``_SQUARES_PER_POINT`` squares per ground point, or for a point
    with no ground square within ``_SQUARE_RINGS`` rings).

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
    ground_xyz : ndarray of shape (n_ground, 3)
    cell : float, default=1.0
    n_threads : int, default=1
        Threads of the search (each point's answer is its own: the same
        whatever the count).

    Returns
    -------
    height : ndarray of shape (n_points,), float32
    """

    if len(xyz) == 0:
        return np.zeros(0, dtype=np.float32)
    if len(ground_xyz) == 0:
        return (xyz[:, 2] - xyz[:, 2].min()).astype(np.float32)
    origin = ground_xyz[:, :2].min(axis=0)
    ij = np.floor((ground_xyz[:, :2] - origin) / cell).astype(np.int64)
    shape = (int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1)
    key = ij[:, 0] * shape[1] + ij[:, 1]
    j = np.full(len(xyz), -1, dtype=np.int64)
    if shape[0] * shape[1] <= _SQUARES_PER_POINT * max(len(ground_xyz), 1 << 14):
        # the squares in a table (no sort of the keys), searched ring by
        # ring around each point; squares numbered in the order of their key
        n_keys = shape[0] * shape[1]
        count = np.bincount(key, minlength=n_keys)
        uniq = np.flatnonzero(count)
        zmean = np.bincount(key, ground_xyz[:, 2], minlength=n_keys)[uniq] / count[uniq]
        first = np.full(n_keys, -1, dtype=np.int64)
        first_rows(key, first)
        first = first[uniq]
        table = np.full(n_keys, -1, dtype=np.int64)
        table[uniq] = np.arange(len(uniq))
        centre = ground_xyz[first, :2]  # a ground point of each square
        del key, count, first
        parallel_rows(
            nearest_square, len(xyz), n_threads, xyz, table.reshape(shape), centre,
            float(origin[0]), float(origin[1]), float(cell), _SQUARE_RINGS, j,
        )  # fmt: skip
        del table
    else:
        uniq, first, inv = np.unique(key, return_index=True, return_inverse=True)
        zmean = np.bincount(inv, ground_xyz[:, 2]) / np.bincount(inv)
        centre = ground_xyz[first, :2]
        del key, inv
    del ij, uniq
    far = np.flatnonzero(j < 0)
    if len(far):
        j[far] = cKDTree(centre).query(xyz[far, :2], workers=n_threads)[1]
    return (xyz[:, 2] - zmean[j]).astype(np.float32)


def _column_counts(xyz, mask, n_threads=1):
    """For the masked points: points within 0.3 to 2 m above or below them
    in their ``_COLUMN`` x ``_COLUMN`` column (others 0)."""

    out = np.zeros(len(xyz), dtype=np.int64)
    if not mask.any():
        return out
    lo, hi = xyz[:, :2].min(axis=0), xyz[:, :2].max(axis=0)
    if ((hi - lo) / _COLUMN < 2.0**30).all():
        ny = int(np.floor((hi[1] - lo[1]) / _COLUMN)) + 1
        key = np.empty(len(xyz), dtype=np.int64)
        parallel_rows(
            column_keys, len(xyz), n_threads, xyz, float(lo[0]), float(lo[1]),
            _COLUMN, ny, key,
        )  # fmt: skip
    else:  # columns beyond an int64 key (a point 1e9 m away): numbered
        ij = np.floor((xyz[:, :2] - lo) / _COLUMN)
        key = np.unique(ij, axis=0, return_inverse=True)[1].ravel()
        del ij
    # only the columns holding a masked point: a table over the keys when
    # they are few (a street: tens of thousands of columns), np.isin when
    # the scene's extent makes them many (a far outlier)
    n_keys = int(key.max()) + 1
    if n_keys <= 4 * len(key):
        table = np.zeros(n_keys, dtype=bool)
        table[key[mask]] = True
        wanted = table[key]
        del table
    else:
        wanted = np.isin(key, np.unique(key[mask]))
    idx = np.flatnonzero(wanted)
    by_key, sk = argsort_keys(key[idx], n_threads)
    order = idx[by_key]
    starts = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1], True])
    zs = np.ascontiguousarray(xyz[order, 2])
    sort_columns(order, starts, zs)
    column_counts(order, starts, zs, mask, 0.3, 2.0, out)
    return out


def _components(xyz, mask, eps, n_jobs, fine=None):
    """Connected components (``eps`` apart) of the masked points: labels
    over all points (-1 outside the mask) and their count. ``fine``: the
    :class:`~skpcd.segmentation._clusters.FineGrid` of all the points for
    ``eps``, searched with the mask instead of a grid of the masked points
    when they are at least a quarter of all (the same components; for
    fewer, its passes over all points cost more than a grid of theirs)."""
    n_masked = int(mask.sum())
    if not n_masked:
        return np.full(len(xyz), -1, dtype=np.int64), 0
    if fine is not None and fine.eps == eps and 4 * n_masked >= len(xyz):
        labels, _ = fine_clusters(fine, 1, effective_threads(n_jobs), member=mask)
        return labels, int(labels.max()) + 1
    labels = np.full(len(xyz), -1, dtype=np.int64)
    idx = np.flatnonzero(mask)
    sub = euclidean_clusters(xyz[idx], eps=eps, min_cluster_size=1, n_jobs=n_jobs)
    labels[idx] = sub
    return labels, int(sub.max()) + 1


def segment_bounds(labels, xyz, n):
    """Bounding box of each of the ``n`` segments of ``labels`` (-1: in
    none) and its point count: ``lo, hi`` of shape (n, 3) (+inf / -inf for
    a segment without points) and ``count`` of shape (n,)."""

    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    count = np.zeros(n, dtype=np.int64)
    segment_extents(labels, xyz, n, lo, hi, count)
    return lo, hi, count


def _xy_axes(labels, xyz, n):
    """Per component: the standard deviations of xy along its major and
    minor horizontal axes."""

    mean = np.zeros((n, 2))
    cov = np.zeros((n, 3))
    count = np.zeros(n, dtype=np.int64)
    component_covariance(labels, np.ascontiguousarray(xyz[:, :2]), n, mean, cov, count)
    half_trace = (cov[:, 0] + cov[:, 2]) / 2
    root = np.sqrt(((cov[:, 0] - cov[:, 2]) / 2) ** 2 + cov[:, 1] ** 2)
    major = np.sqrt(np.maximum(half_trace + root, 0))
    minor = np.sqrt(np.maximum(half_trace - root, 0))
    return major, minor


def _keep(labels, good):
    """Points whose component is ``good``."""
    out = np.zeros(len(labels), dtype=bool)
    inside = labels >= 0
    out[inside] = good[labels[inside]]
    return out


def local_shapes(xyz, nb, n_threads=1):
    """Linearity, planarity, normal (n, 3), |axis z| and spread of every
    point (rows in chunks on ``n_threads`` threads; every row its own)."""

    out = [np.empty(len(xyz), dtype=np.float32) for _ in range(4)]
    normal = np.empty((len(xyz), 3), dtype=np.float32)
    out.insert(2, normal)
    parallel_rows(
        local_shape_rows, len(xyz), n_threads, xyz, nb.indptr, nb.indices, *out
    )
    return out


def _csr(nb, keep, counts, data):
    """The k-NN graph's pairs with ``keep`` (``counts`` of them in each row),
    as a sparse matrix built directly in CSR form (no COO copy: about 5
    bytes per edge kept)."""

    n = len(nb.indptr) - 1
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    return csr_array((data, nb.indices[keep], indptr), shape=(n, n))


def _regions(nb, mask, normal):
    """Connected regions of the masked points over the k-NN graph, joined
    only where the normals agree within ``_NORMAL_ANGLE``: one per smooth
    surface (a wall), none across a pole or a crown whose normals turn."""

    labels = np.empty(len(mask), dtype=np.int64)
    n = aligned_components(nb.indptr, nb.indices, mask, normal, _NORMAL_COS, labels)
    return labels, int(n)


def find_structures(xyz, height, nb, eps, params, n_jobs=None, fine=None):
    """Kind of every point: 0 object, 1 facade, 2 wire (int8). ``fine``:
    the fine grid of the points for ``eps`` (see :func:`_components`)."""

    lin, plan, normal, axis_z, spread = local_shapes(xyz, nb, effective_threads(n_jobs))
    normal_z = np.abs(normal[:, 2])
    kind = np.zeros(len(xyz), dtype=np.int8)
    # wires: linear, horizontal-ish, thin, high; long pieces
    cand = (
        (lin >= _LINEAR)
        & (axis_z <= _HORIZONTAL_AXIS)
        & (spread <= params["wire_max_width"] / 2)
        & (height >= params["wire_min_height"])
    )
    # a wire hangs free: the points of a facade scanned in horizontal rings
    # (a spinning sensor) are linear too, but rings lie above and below
    cand &= _column_counts(xyz, cand, effective_threads(n_jobs)) <= _WIRE_COLUMN_POINTS
    labels, n = _components(xyz, cand, eps, n_jobs, fine)
    if n:
        _, minor = _xy_axes(labels, xyz, n)
        lo, hi, _ = segment_bounds(labels, xyz, n)
        length = np.hypot(hi[:, 0] - lo[:, 0], hi[:, 1] - lo[:, 1])
        good = (length >= params["wire_min_length"]) & (
            minor <= params["wire_max_width"]
        )
        kind[_keep(labels, good)] = 2
    # facades: planar, vertical; tall and long pieces, grown over the
    # neighbours that are mostly facade
    cand = (plan >= _PLANAR) & (normal_z <= _VERTICAL_NORMAL) & (kind == 0)
    labels, n = _regions(nb, cand, normal)
    del normal
    if n:
        lo, hi, _ = segment_bounds(labels, xyz, n)
        length = np.hypot(hi[:, 0] - lo[:, 0], hi[:, 1] - lo[:, 1])
        good = (hi[:, 2] - lo[:, 2] >= params["facade_min_height"]) & (
            length >= params["facade_min_length"]
        )
        facade = _keep(labels, good)
        # the planar vertical patches linked to a facade (window recesses,
        # doors, shop fronts set back from the wall) are facade too
        comp, m = _components(xyz, cand | facade, eps, n_jobs, fine)
        linked = np.zeros(m + 1, dtype=bool)
        linked[comp[facade]] = True
        facade = (comp >= 0) & linked[comp]
        del comp
        share = np.empty(len(xyz), dtype=np.float32)
        for _ in range(_GROW_STEPS):
            neighbour_share(nb.indptr, nb.indices, facade, share)
            facade |= (share >= _GROW_SHARE) & (kind == 0)
        kind[facade] = 1
    trunk = (
        (kind == 0)
        & (lin >= _TRUNK_LINEAR)
        & (axis_z >= _VERTICAL_AXIS)
        & (height >= _TRUNK_BAND[0])
        & (height <= _TRUNK_BAND[1])
    )
    return kind, trunk, plan >= _PLANAR


def filter_labels(labels):
    """Labels renumbered 0, 1, ... in order (-1 kept)."""
    out = np.asarray(labels, dtype=np.int64).copy()
    inside = out >= 0
    if inside.any():
        _, out[inside] = np.unique(out[inside], return_inverse=True)
    return out


def find_trunks(xyz, trunk, eps, min_height, n_jobs=None, fine=None):
    """Vertical trunks: pieces of trunk points at least ``min_height`` tall
    and thin; the trunk of every point (-1: none) and their count."""
    labels, n = _components(xyz, trunk, min(eps, 0.5), n_jobs, fine)
    if not n:
        return labels, 0
    lo, hi, _ = segment_bounds(labels, xyz, n)
    major, _ = _xy_axes(labels, xyz, n)
    good = (hi[:, 2] - lo[:, 2] >= min_height) & (major <= _TRUNK_MAX_WIDTH)
    new = np.full(n + 1, -1, dtype=np.int64)
    new[:-1][good] = np.arange(int(good.sum()))
    return new[labels], int(good.sum())


def split_at_trunks(xyz, labels, trunks, nb):
    """Clusters holding several trunks, split: each point goes to the trunk
    nearest along the k-NN graph within its cluster (by straight distance
    to the trunk's points when the graph does not reach it). Returns new
    labels (clusters renumbered) and how many clusters were split."""

    has = (trunks >= 0) & (labels >= 0)
    if not has.any():
        return labels, 0
    # trunks per cluster (a trunk belongs to the cluster of most of its points)
    n_trunks = int(trunks.max()) + 1
    pair, n_pair = np.unique(
        np.column_stack([trunks[has], labels[has]]), axis=0, return_counts=True
    )
    # per trunk, the pair with the most points (sorted by trunk, then count)
    order = np.lexsort((n_pair, pair[:, 0]))
    last = np.r_[pair[order, 0][1:] != pair[order, 0][:-1], True]
    t_cluster = np.full(n_trunks, -1, dtype=np.int64)
    t_cluster[pair[order, 0][last]] = pair[order, 1][last]
    per_cluster = np.bincount(t_cluster[t_cluster >= 0], minlength=labels.max() + 1)
    split = np.flatnonzero(per_cluster >= 2)
    if len(split) == 0:
        return labels, 0
    inside = np.isin(labels, split)
    idx = np.flatnonzero(inside)
    # edges of the k-NN graph within a cluster being split (the graph over
    # all points, the others without edges)

    keep = np.empty(len(nb.indices), dtype=bool)
    counts = np.empty(len(nb.indptr) - 1, dtype=np.int64)
    same_label_edges(nb.indptr, nb.indices, labels, inside, keep, counts)
    w = np.sqrt(nb.sqdist[keep].astype(np.float64)) + 1e-6
    graph = _csr(nb, keep, counts, w)
    del keep, counts, w
    seeds = np.flatnonzero(inside & (trunks >= 0) & (t_cluster[trunks] == labels))
    _, _, source = dijkstra(
        graph, directed=False, indices=seeds, min_only=True,
        return_predecessors=True,
    )  # fmt: skip
    del graph
    source = source[idx]
    seed_trunk = np.full(len(xyz), -1, dtype=np.int64)
    seed_trunk[seeds] = trunks[seeds]
    owner = np.where(source >= 0, seed_trunk[np.maximum(source, 0)], -1)
    lost = np.flatnonzero(owner < 0)
    if len(lost):
        # the trunk point nearest in space, within the same cluster
        key = 1e6 * (labels[seeds] - labels[seeds].min())
        tree = cKDTree(np.column_stack([xyz[seeds], key]))
        q = np.column_stack(
            [xyz[idx[lost]], 1e6 * (labels[idx[lost]] - labels[seeds].min())]
        )
        owner[lost] = trunks[seeds[tree.query(q)[1]]]
    out = labels.copy()
    base = labels.max() + 1
    out[idx] = base + owner
    # renumber 0, 1, ... in the order of the old cluster, then the trunk
    valid = out >= 0
    _, out[valid] = np.unique(out[valid], return_inverse=True)
    return out, len(split)


def segment_structures(xyz, ground_xyz, eps, params, cluster, n_jobs=None):
    """Facades, wires and objects of the non-ground points.

    Parameters
    ----------
    xyz : ndarray of shape (n_points, 3)
        The non-ground points.
    ground_xyz : ndarray of shape (n_ground, 3)
        The ground points (heights above the ground are measured from them).
    eps : float
        Linking distance of the facade and wire pieces (the clustering
        radius).
    params : dict
        ``STRUCTURE_DEFAULTS`` or overrides of them.
    cluster : callable
        ``cluster(mask) -> labels`` of the masked points (DBSCAN), -1 noise.
    n_jobs : int or None

    Returns
    -------
    labels : ndarray of shape (n_points,), int64
        Segment of each point (-1 none), objects first, then facades, then
        wires (not yet filtered by size).
    kinds : ndarray of shape (n_segments,), dtype int8
        Index in ``KINDS`` of each segment.
    info : dict
        Counts: points typed facade and wire, clusters split.
    """

    params = {**STRUCTURE_DEFAULTS, **(params or {})}
    labels = np.full(len(xyz), -1, dtype=np.int64)
    if len(xyz) < 3:
        return labels, np.zeros(0, dtype=np.int8), {}
    # one grid for the components of every kind of point and, when its
    # cells suit it, for the k-nearest search (exact on any grid)
    threads = effective_threads(n_jobs)
    fine = fine_grid(xyz, eps, threads)
    fine = fine if fine is not None and fine.dense else None
    k = params["n_neighbors"]
    knn_grid = fine.grid if fine is not None and suits_knn(fine.grid, k) else None
    nb = search_packed(
        xyz, np.array([0, len(xyz)]), n_neighbors=k, n_threads=threads, grid=knn_grid
    )
    del knn_grid
    height = height_above_ground(xyz, ground_xyz, n_threads=effective_threads(n_jobs))
    kind, trunk_points, planar = find_structures(
        xyz, height, nb, eps, params, n_jobs, fine
    )
    del height
    objects = kind == 0
    sub = cluster(objects)
    facade_parts = None  # the components of the facade points, once known
    if (kind == 1).any() and len(sub):
        # clusters of mostly planar points touching a facade (balconies,
        # window reveals, shop signs, roof edges) are part of it
        n_sub = int(sub.max()) + 1
        inside = sub >= 0
        share = np.bincount(
            sub[inside], weights=planar[objects][inside], minlength=n_sub
        ) / np.maximum(np.bincount(sub[inside], minlength=n_sub), 1)
        flat = np.zeros(len(xyz), dtype=bool)
        flat[np.flatnonzero(objects)[inside]] = share[sub[inside]] >= _FLAT_SHARE
        comp, m = _components(xyz, flat | (kind == 1), eps, n_jobs, fine)
        touching = np.zeros(m + 1, dtype=bool)
        touching[comp[kind == 1]] = True
        absorbed = flat & touching[comp]
        if absorbed.any():
            kind[absorbed] = 1
            keep = ~absorbed[objects]
            objects = kind == 0
            sub = filter_labels(sub[keep])
        # the facade points are now the components of flat | facade that
        # touch a facade, so those are their components too, in the same
        # order (lowest point first): no second search over them
        rank = np.full(m + 1, -1, dtype=np.int32)
        rank[:m][touching[:m]] = np.arange(int(touching[:m].sum()))
        facade_parts = rank[comp], int(touching[:m].sum())
        del comp, flat, rank
    del planar
    trunks, n_trunks = find_trunks(
        xyz, trunk_points & objects, eps, params["trunk_min_height"], n_jobs, fine
    )
    obj_labels = np.full(len(xyz), -1, dtype=np.int64)
    obj_labels[objects] = sub
    n_split = 0
    if n_trunks >= 2:
        obj_labels, n_split = split_at_trunks(xyz, obj_labels, trunks, nb)
    del nb
    n_obj = int(obj_labels.max()) + 1
    labels = obj_labels
    kinds = [np.zeros(n_obj, dtype=np.int8)]
    offset = n_obj
    for k in (1, 2):
        if k == 1 and facade_parts is not None:
            part, n = facade_parts
        else:
            part, n = _components(xyz, kind == k, eps, n_jobs, fine)
        inside = part >= 0
        labels[inside] = part[inside].astype(np.int64) + offset
        kinds.append(np.full(n, k, dtype=np.int8))
        offset += n
    info = {
        "facade_points": int((kind == 1).sum()),
        "wire_points": int((kind == 2).sum()),
        "trunks": n_trunks,
        "clusters_split": n_split,
    }
    return labels, np.concatenate(kinds), info
