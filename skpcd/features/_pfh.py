"""Point Feature Histograms (PFH), as PCL 1.13 computes them.

The function form (:func:`compute_pfh`) takes one cloud with its normals and
neighbourhoods; :class:`PFHTransformer` takes a list of clouds, searches
neighbourhoods once, estimates normals and runs one parallel kernel over all
points of all clouds (:mod:`skpcd.features._local_descriptor`); with a
radius search, block by block.
"""

import itertools
from queue import SimpleQueue

import numpy as np

from skpcd.features._local_descriptor import _as_f32, _LocalDescriptor, _neighborhoods
from skpcd.features._pair_kernels import ROW_MIN
from skpcd.features._pfh_kernels import pfh_rows, pfh_rows_reuse
from skpcd.neighbors._grid import ball_block, radius_grid, snake_order
from skpcd.preprocessing._normals import (
    CLOUD_VIEWPOINT,
    ball_block_normals,
    check_viewpoint,
    local_viewpoints,
)
from skpcd.utils._compile import entry_point
from skpcd.utils._geometry import cloud_bounds, local_frame, max_extent
from skpcd.utils._memory import release_free_memory, unshared_zeros
from skpcd.utils._parallel import effective_threads, parallel_rows
from skpcd.utils._validation import check_extents

__all__ = ["PFHTransformer", "compute_pfh"]


@entry_point
def compute_pfh(
    points,
    normals,
    *,
    n_neighbors=None,
    radius=None,
    neighborhoods=None,
    n_bins=5,
    n_jobs=None,
):
    """PFH of every point of one cloud, bin for bin as PCL's ``PFHEstimation``.

    Parameters
    ----------
    points : array-like of shape (n_points, 3+)
        The cloud (float32 precision is used, as in PCL; an axis reaching
        beyond 1024 from the origin is first taken relative to the cloud's
        minimum, see the user guide).
    normals : array-like of shape (n_points, 3)
        Unit normals, used as given (PCL ``setInputNormals``): a norm more
        than 1e-3 away from 1 is an error. A row with a NaN is an undefined
        normal, binned as PCL bins it: its pairs' NaN angles go to bin 0.
    n_neighbors, radius : int or float, default=None
        The neighbourhood search, unless ``neighborhoods`` is given.
    neighborhoods : Neighborhoods, default=None
        Precomputed neighbourhoods, the point first in each.
    n_bins : int, default=5
        Subdivisions per feature (PCL ``nr_subdiv``); the histogram has
        ``n_bins ** 3`` bins.
    n_jobs : int, default=None
        Threads; None means 1, -1 all cores.

    Returns
    -------
    pfh : ndarray of shape (n_points, n_bins ** 3), dtype float32
        Rows sum to 100; a point alone in its neighbourhood gets zeros.

    Raises
    ------
    ValueError
        If ``normals`` has another shape than the points, or a row without
        NaN that is not a unit vector, or the cloud spans more than float32
        squared distances can hold (about 1e19).
    """
    n_threads = effective_threads(n_jobs)
    nb = _neighborhoods(points, neighborhoods, n_neighbors, radius, n_threads)
    p, n = _as_f32(points, normals, nb)
    return _pfh_packed(p, n, nb, int(n_bins), n_threads)


def _pfh_packed(p, n, nb, n_bins, n_threads, offsets=None, out=None):
    """PFH kernel over float32 packed arrays (clouds at ``offsets``, in
    their local frames), into ``out`` (zeroed, float32) when given."""
    if out is None:
        out = unshared_zeros((len(p), n_bins**3), np.float32)
    args = (p, n, nb.indptr, nb.indices, n_bins, out)
    if len(p) and len(nb.indices) >= ROW_MIN * len(p) and n_bins**3 < 2**15:
        # large neighbourhoods: visited in space order, consecutive ones
        # share most of their pairs (pfh_rows_reuse)
        cloud = None
        if offsets is not None and len(offsets) > 2:
            cloud = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
        rows = _space_order(p, _radius_of(p, nb), cloud, n_threads)
        sorted_nb = (np.empty((0, 3)), np.empty(0, np.int32))
        rows = (rows, np.empty(0, np.int64), *sorted_nb)
        _pfh_reuse(*rows, *args, n_threads, _pos_pool(p, n_threads))
    else:
        parallel_rows(pfh_rows, len(p), n_threads, *args)
    return out


def _pos_pool(p, n_threads):
    """The scratch of :func:`~skpcd.features._pfh_kernels.pfh_rows_reuse`,
    one per thread."""
    pool = SimpleQueue()
    for _ in range(n_threads):
        pool.put(np.full(len(p), -1, dtype=np.int32))
    return pool


def _pfh_reuse(
    rows, point_of, xs, inv, p, n, indptr, indices, n_bins, out, n_threads, pool
):
    """PFH of the CSR rows ``rows`` (in that order) with pair codes reused
    (see :func:`~skpcd.features._pfh_kernels.pfh_rows_reuse`)."""

    def run(lo, hi, *args):
        pos = pool.get()
        try:
            pfh_rows_reuse(lo, hi, rows, point_of, pos, xs, inv, *args)
        finally:
            pool.put(pos)

    args = (p, n, indptr, indices, n_bins, out)
    parallel_rows(run, len(rows), n_threads, *args, min_chunk=256)


def _radius_of(p, nb):
    """The neighbourhood radius, from the farthest neighbour of a few points."""
    probe = np.flatnonzero(nb.sizes > 1)[:: max(1, len(p) // 1000)]
    last = p[nb.indices[nb.indptr[probe + 1] - 1]] - p[probe]
    return float(np.median(np.sqrt((last.astype(np.float64) ** 2).sum(1))))


def _space_order(p, radius, cloud=None, n_threads=1):
    """The points in a snake order over cells a quarter of ``radius`` wide
    (:func:`~skpcd.neighbors._grid.snake_order`), cloud by cloud with
    ``cloud`` (each point's cloud: clouds in their local frames overlap)."""
    return snake_order(p, 0.25 * radius, cloud, n_threads)


# Points per block of the blocked radius PFH (at least; 1/64 of the input
# on large inputs): the neighbourhoods of one block at a time are held in
# memory, not those of the whole input.
_BLOCK = 2048


def _pfh_radius_blocked(clouds, radius, n_bins, given, viewpoint, n_threads, out=None):
    """PFH with a radius search, neighbourhoods block by block.

    Memory stays that of the output, the points and their normals: the
    neighbourhoods of a block of grid cells are searched, used and freed.
    A first pass counts the neighbours of every point (and estimates its
    normal from the sorted ball, storing nothing else); a second stores a
    block's neighbourhoods and bins their pairs. The same two passes over
    the grid as one search of all neighbourhoods. ``given`` is ``(normals,
    mask)`` as :meth:`_LocalDescriptor._given_normals`: the normals of the
    points in ``mask`` are given, the others estimated. Returns ``out,
    undefined, offsets`` as :meth:`_LocalDescriptor._compute`.
    """
    release_free_memory()  # e.g. the pages of a previous call's output
    offsets = np.zeros(len(clouds) + 1, dtype=np.int64)
    np.cumsum([len(c) for c in clouds], out=offsets[1:])
    xyz = np.ascontiguousarray(np.vstack([c[:, :3] for c in clouds]), dtype=np.float64)
    n_pts = len(xyz)
    lo_hi = cloud_bounds(xyz, offsets)
    check_extents(
        *lo_hi,
        max_extent(np.float64),
        what="squared distances in float64 (the neighbour search)",
    )
    grid = radius_grid(xyz, offsets, radius, lo_hi, n_threads)
    order, cell_start = grid.order, grid.cell_start
    p, origins = local_frame(xyz, offsets)  # float32, each cloud in its frame
    viewpoints = local_viewpoints(viewpoint, xyz, offsets, origins).astype(np.float32)
    del xyz
    step = max(_BLOCK, n_pts // 64)
    bounds = np.unique(np.searchsorted(cell_start, np.arange(0, n_pts, step)))
    bounds = np.append(bounds[bounds < len(cell_start) - 1], len(cell_start) - 1)
    # neighbourhood sizes in sorted order (the counts of the search)
    counts = np.empty(n_pts, dtype=np.int64)

    blocks = [
        (cells, int(cell_start[cells[0]]), int(cell_start[cells[1]]))
        for cells in itertools.pairwise(bounds)
    ]
    given, mask = given
    if given is None or not mask.all():
        # normals straight from each ball, sorted, nothing stored
        n = np.empty((n_pts, 3), dtype=np.float32)
        curvature = np.empty(n_pts, dtype=np.float32)
        est = (p, viewpoints, n, curvature)
        for cells, t0, t1 in blocks:
            ball_block_normals(grid, radius, cells, counts[t0:t1], *est, n_threads)
        del curvature, est
        if given is not None:  # "auto" on clouds with and without normals
            n[mask] = given[mask]
        del given, mask
    else:
        n = given
        del given, mask
        for cells, t0, t1 in blocks:
            ball_block(grid, radius, cells, counts[t0:t1], n_threads)
    release_free_memory()  # the pages of the freed temporaries, before the output
    if out is None:
        out = unshared_zeros((n_pts, n_bins**3), np.float32)
    pool = _pos_pool(p, n_threads)
    # each point's row in the grid order: pfh_rows_reuse orders the pairs
    # of an unsorted ball by the search's own distances (grid.xs)
    inv = np.empty(n_pts, dtype=np.int32)
    inv[order] = np.arange(n_pts, dtype=np.int32)
    for cells, t0, t1 in blocks:
        indptr = np.zeros(t1 - t0 + 1, dtype=np.int64)
        np.cumsum(counts[t0:t1], out=indptr[1:])
        reuse = indptr[-1] >= ROW_MIN * (t1 - t0) and n_bins**3 < 2**15
        block = (grid, radius, cells, counts[t0:t1], n_threads, indptr)
        indices = ball_block(*block, sort=not reuse)
        point_of = order[t0:t1]
        args = (p, n, indptr, indices, n_bins, out)
        if reuse:
            cloud = np.searchsorted(offsets, point_of, side="right")
            rows = _space_order(p[point_of], radius, cloud, n_threads)
            _pfh_reuse(rows, point_of, grid.xs, inv, *args, n_threads, pool)
        else:
            _pfh_rows_local(point_of, *args, n_threads)
        del indptr, indices
    sizes = np.empty(n_pts, dtype=np.int64)
    sizes[order] = counts
    del pool, inv, grid, counts
    release_free_memory()  # the blocks' scratch, not kept for the next call
    undefined = ~np.isfinite(n).all(axis=1) | (sizes < 2)
    return out, undefined, offsets


def _pfh_rows_local(point_of, p, n, indptr, indices, n_bins, out, n_threads):
    """:func:`pfh_rows` on a CSR whose row ``r`` is point ``point_of[r]``:
    the PFH rows computed in a block and scattered into ``out``."""
    block = np.zeros((len(point_of), n_bins**3), dtype=np.float32)
    # pfh_rows reads the query point only through its neighbourhood
    args = (p, n, indptr, indices, n_bins, block)
    parallel_rows(pfh_rows, len(point_of), n_threads, *args, min_chunk=256)
    out[point_of] = block


class PFHTransformer(_LocalDescriptor):
    """Point Feature Histogram of every point, bin for bin as PCL.

    For every pair of points in a point's neighbourhood (the point
    included), three angles between their normals and the line joining them
    are binned into ``n_bins ** 3`` bins, f1 varying fastest; each pair adds
    ``100 / n_pairs``, so a row sums to 100. This is PCL 1.13's
    ``PFHEstimation`` (``PFHSignature125`` for ``n_bins=5``).

    Read more in the :ref:`User Guide <local_descriptors>`.

    Parameters
    ----------
    n_neighbors : int, default=None
        k for the k-nearest-neighbour search, the point itself included (PCL
        ``setKSearch``, Open3D ``max_nn``). When neither ``n_neighbors`` nor
        ``radius`` is given, k = 10.
    radius : float, default=None
        Radius search instead (PCL ``setRadiusSearch``); give one of the two.
    n_bins : int, default=5
        Bins per feature (PCL ``nr_subdiv``; n_bins ** 3 bins).
    normals : {"auto", "columns", "estimate"}, default="auto"
        Where the normals come from. ``"auto"``: a cloud with 6 or more
        columns carries its normals in columns 3-5 (the layout of
        :class:`~skpcd.preprocessing.NormalEstimator`, and of PCL's
        ``PointNormal``), used as given, as PCL's ``setInputNormals`` uses
        them; a cloud with 3 to 5 columns gets estimated normals (PCA,
        PCL's rules, see :func:`~skpcd.preprocessing.estimate_normals`).
        ``"columns"``: every cloud carries them (fewer than 6 columns is an
        error). ``"estimate"``: always estimated, columns 3-5 ignored.
        Given normals are not renormalised: a norm more than 1e-3 away from
        1 is a ValueError naming the cloud. A row with a NaN is an undefined
        normal, as PCL's ``NormalEstimation`` writes it (see
        ``undefined``).
    normal_n_neighbors : int, default=None
        k for the estimated normals; by default the descriptor's own
        neighbourhoods are reused (one search for both). Setting it for a
        cloud whose normals are given is an error (it would be ignored).
    normal_radius : float, default=None
        Radius for the estimated normals instead; likewise refused with
        given normals.
    viewpoint : "corner" or tuple of 3 float, default="corner"
        Estimated normals face this point (PCL ``setViewPoint``).
        ``"corner"``: a point fixed to each cloud, below and beside it
        (``min - (max - min) - 1`` per axis), so the descriptors do not
        depend on where the cloud lies. Three numbers: a point in the
        clouds' coordinates, the same for all (the sensor's position);
        ``(0, 0, 0)``, PCL's default, gives PCL's histograms bin for bin
        (see "Coordinates far from the origin" in the user guide). Given
        normals keep their sign: a viewpoint with given normals is an
        error.
    undefined : {"nan", "zero", "drop", "keep"}, default="nan"
        Points whose descriptor is undefined (their normal is undefined,
        estimated or given as NaN, or they have no neighbour): a NaN row, a
        zero row, no row, or the value PCL computes for them anyway
        ("keep", which bins NaN features in bin 0). As a neighbour, a point
        with a NaN normal is binned as PCL bins it (bin 0) whatever the
        policy. :meth:`undefined_mask` says which points they are.
    pooling : {"mean", "sum", "max"}, default=None
        Return one row per cloud, pooled over its defined rows, instead of a
        list of per-point arrays.
    n_jobs : int, default=None
        Threads for the searches and the kernels; None means 1, -1 all
        cores. Under a backend chosen with :func:`joblib.parallel_config`
        (e.g. ``"dask"``): the batches of clouds run at once (None: the
        backend's), each on the cores left to its task.

    Attributes
    ----------
    n_features_in_ : int
        Columns of the first cloud seen in :meth:`fit`.

    See Also
    --------
    FPFHTransformer : The fast variant, O(k) per point.
    compute_pfh : The function form for one cloud.

    Notes
    -----
    Pairs at a zero distance, or whose offset is parallel to the source
    normal, are binned as (0, 0, 0) features, as PCL does.

    References
    ----------
    .. [1] R. B. Rusu, N. Blodow, Z. C. Marton, M. Beetz, "Aligning point
       cloud views using persistent feature histograms", IROS 2008.

    Examples
    --------
    >>> from skpcd.datasets import make_point_clouds
    >>> from skpcd.features import PFHTransformer
    >>> clouds = make_point_clouds(2, n_points=40, random_state=0)
    >>> [h.shape for h in PFHTransformer(n_neighbors=8).fit_transform(clouds)]
    [(40, 125), (40, 125)]
    """

    def __init__(
        self,
        n_neighbors=None,
        *,
        radius=None,
        n_bins=5,
        normals="auto",
        normal_n_neighbors=None,
        normal_radius=None,
        viewpoint=CLOUD_VIEWPOINT,
        undefined="nan",
        pooling=None,
        n_jobs=None,
    ):
        self.n_neighbors = n_neighbors
        self.radius = radius
        self.n_bins = n_bins
        self.normals = normals
        self.normal_n_neighbors = normal_n_neighbors
        self.normal_radius = normal_radius
        self.viewpoint = viewpoint
        self.undefined = undefined
        self.pooling = pooling
        self.n_jobs = n_jobs

    def _width(self):
        return int(self.n_bins) ** 3

    def _compute(self, clouds, n_threads, out=None):
        if self.radius is None or not (
            self.normal_n_neighbors is None and self.normal_radius is None
        ):
            return super()._compute(clouds, n_threads, out)
        # radius search: neighbourhoods block by block (memory)
        given = self._given_normals(clouds)
        vp = check_viewpoint(self.viewpoint)
        args = (float(self.radius), int(self.n_bins), given, vp, n_threads)
        return _pfh_radius_blocked(clouds, *args, out)

    def _pair_stage(self, p, n, nb, offsets, n_threads, out=None):
        return _pfh_packed(p, n, nb, int(self.n_bins), n_threads, offsets, out)
