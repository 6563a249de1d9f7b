"""Point Feature Histograms (PFH) and Fast PFH, as PCL 1.13 computes them.

The function forms (:func:`compute_pfh`, :func:`compute_fpfh`) take one
cloud with its normals and neighbourhoods; the transformers take a list of
clouds, search neighbourhoods once, estimate normals and run one parallel
kernel over all points of all clouds.
"""

import itertools
import typing
from numbers import Integral, Real
from queue import SimpleQueue

import numpy as np
from sklearn.utils._param_validation import Interval, StrOptions

from skpcd.features._descriptor import FeatureNamesMixin, numbered
from skpcd.features._pfh_kernels import (
    ROW_MIN,
    fpfh_rows,
    increment_sums,
    pfh_rows,
    pfh_rows_reuse,
    spfh_rows,
    spfh_values,
)
from skpcd.neighbors._grid import ball_block, radius_grid, snake_order
from skpcd.neighbors._neighbors import (
    Neighborhoods,
    compute_neighborhoods,
    scattered,
)
from skpcd.preprocessing._normals import (
    CLOUD_VIEWPOINT,
    ball_block_normals,
    check_viewpoint,
    local_viewpoints,
    normals_f32,
    pack_neighborhoods,
)
from skpcd.utils import check_point_clouds
from skpcd.utils._compile import entry_point
from skpcd.utils._estimator import CloudTransformer
from skpcd.utils._geometry import cloud_bounds, local_frame, max_extent
from skpcd.utils._memory import release_free_memory, unshared_zeros
from skpcd.utils._parallel import effective_threads, map_batches, parallel_rows
from skpcd.utils._validation import (
    NORMALS_OPTIONS,
    check_extents,
    check_given_normals,
    check_unit_normals,
    has_normal_columns,
)

__all__ = ["FPFHTransformer", "PFHTransformer", "compute_fpfh", "compute_pfh"]

FPFH_CONVENTIONS = ("pcl", "open3d", "paper")


def _as_f32(points, normals, neighborhoods):
    """The cloud in its local frame (float32) and the normals, checked."""
    xyz = np.ascontiguousarray(np.asarray(points)[:, :3], dtype=np.float64)
    p, _ = local_frame(xyz, np.array([0, len(xyz)]), input_name="points")
    n = np.ascontiguousarray(normals, dtype=np.float32)
    if n.shape != p.shape:
        raise ValueError(f"normals must have shape {p.shape}, got {n.shape}")
    check_unit_normals(n)
    if not isinstance(neighborhoods, Neighborhoods):
        raise TypeError("neighborhoods must come from compute_neighborhoods")
    if neighborhoods.n_points != len(p):
        raise ValueError(
            f"neighborhoods cover {neighborhoods.n_points} points, "
            f"the cloud has {len(p)}"
        )
    return p, n


def _neighborhoods(points, neighborhoods, n_neighbors, radius, n_threads):
    if neighborhoods is not None:
        return neighborhoods
    return compute_neighborhoods(
        points, n_neighbors=n_neighbors, radius=radius, n_jobs=n_threads
    )


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


# Points per part of a pooled transform (whole clouds; a larger cloud is a
# part of its own): the parts share one output buffer.
_POOLED_PART = 1 << 18

# Pair counts up to this many are turned into PCL's sums by table lookup.
_TABLE_PAIRS = 255


def _spfh_counts(p, n, nb, n_bins, n_threads, pack=False):
    """SPFH as pair counts per bin, and the table of PCL's increment sums.

    One byte per bin (two above 255 neighbours), not a float32's four; with
    ``pack``, and no point with more than 15 pairs, two 4-bit counts per byte
    (see :func:`~skpcd.features._pfh_kernels.spfh_rows`).
    """
    max_pairs = max(int(nb.sizes.max(initial=1)) - 1, 1)
    dtype = (
        np.uint8 if max_pairs <= 255 else np.uint16 if max_pairs < 2**16 else np.uint32
    )
    width = 3 * n_bins
    if pack and max_pairs <= 15:
        width = (width + 1) // 2
    counts = np.zeros((len(p), width), dtype=dtype)
    args = (p, n, nb.indptr, nb.indices, n_bins, counts)
    parallel_rows(spfh_rows, len(p), n_threads, *args)
    return counts, increment_sums(min(max_pairs, _TABLE_PAIRS))


def _spfh(p, n, nb, n_bins, n_threads=1):
    """SPFH of every point as PCL's float32 values, (n, 3 * n_bins)."""
    counts, table = _spfh_counts(p, n, nb, n_bins, n_threads)
    out = np.empty(counts.shape, dtype=np.float32)
    parallel_rows(spfh_values, len(p), n_threads, counts, nb.indptr, table, out)
    return out


def _fpfh_packed(p, n, nb, n_bins, convention, n_threads):
    """SPFH (as pair counts) then FPFH kernels over float32 packed arrays."""
    counts, table = _spfh_counts(p, n, nb, n_bins, n_threads, pack=True)
    return _fpfh_from_counts(p, counts, table, nb, n_bins, convention, n_threads)


def _fpfh_from_counts(
    p, counts, table, nb, n_bins, convention, n_threads, out=None, rows=None
):
    """FPFH from the SPFH pair counts of :func:`_spfh_counts`, into ``out``
    (zeroed, float32) when given, unless the convention sums in float64;
    point ``i``'s row at ``rows[i]`` when given."""
    mode = FPFH_CONVENTIONS.index(convention)
    if out is None or mode == 2:
        dtype = np.float64 if mode == 2 else np.float32
        out = unshared_zeros((len(p), 3 * n_bins), dtype)
    rows = np.zeros(0, np.int64) if rows is None else rows
    args = (p, counts, nb.indptr, nb.indices, table, n_bins, mode, rows, out)
    parallel_rows(fpfh_rows, len(p), n_threads, *args)
    return out.astype(np.float32, copy=False)


@entry_point
def compute_fpfh(
    points,
    normals,
    *,
    n_neighbors=None,
    radius=None,
    neighborhoods=None,
    n_bins=11,
    convention="pcl",
    n_jobs=None,
):
    """FPFH of every point of one cloud.

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
        Precomputed neighbourhoods, sorted by distance, the point first.
    n_bins : int, default=11
        Bins per feature; the descriptor has ``3 * n_bins`` values laid out
        ``[f1 | f2 | f3]``.
    convention : {"pcl", "open3d", "paper"}, default="pcl"
        ``"pcl"``: PCL's ``FPFHEstimation``, the neighbours' SPFH weighted by
        1/squared distance, the point's own SPFH left out, each block
        rescaled to sum to 100. ``"open3d"``: the same plus the point's own
        SPFH, so blocks sum to 200 (Open3D's ``compute_fpfh_feature``).
        ``"paper"``: Rusu et al. (2009), SPFH(p) + (1/k) sum SPFH(q) / d,
        not rescaled.
    n_jobs : int, default=None
        Threads; None means 1, -1 all cores.

    Returns
    -------
    fpfh : ndarray of shape (n_points, 3 * n_bins), dtype float32
        One row per point. A point without a neighbour at a non-zero
        distance gets zeros (``"pcl"``) or its own SPFH.

    Raises
    ------
    ValueError
        If ``convention`` is unknown, ``normals`` has another shape than the
        points, or a row without NaN that is not a unit vector, or the cloud
        spans more than float32 squared distances can hold (about 1e19).
    """
    if convention not in FPFH_CONVENTIONS:
        raise ValueError(
            f"convention must be one of {FPFH_CONVENTIONS}, got {convention!r}"
        )
    n_threads = effective_threads(n_jobs)
    nb = _neighborhoods(points, neighborhoods, n_neighbors, radius, n_threads)
    p, n = _as_f32(points, normals, nb)
    return _fpfh_packed(p, n, nb, int(n_bins), convention, n_threads)


class _LocalDescriptor(FeatureNamesMixin, CloudTransformer):
    """Shared machinery of the per-point histogram transformers."""

    _parameter_constraints: typing.ClassVar[dict] = {
        "n_neighbors": [Interval(Integral, 2, None, closed="left"), None],
        "radius": [Interval(Real, 0, None, closed="neither"), None],
        "n_bins": [Interval(Integral, 2, None, closed="left")],
        "normals": [StrOptions(set(NORMALS_OPTIONS))],
        "normal_n_neighbors": [Interval(Integral, 3, None, closed="left"), None],
        "normal_radius": [Interval(Real, 0, None, closed="neither"), None],
        "viewpoint": ["array-like", StrOptions({CLOUD_VIEWPOINT})],
        "undefined": [StrOptions({"nan", "zero", "drop", "keep"})],
        "pooling": [StrOptions({"mean", "sum", "max"}), None],
        "n_jobs": [Integral, None],
    }
    _default_n_neighbors = 10
    # clouds whose neighbours lie far apart in memory (shuffled) computed in
    # the search's grid order (`scattered`): FPFH on the DALES objects as one
    # shuffled cloud 1.38-1.52x faster (benchmarks/bench_point_order.py);
    # clouds in recorded order are left in theirs (renumbering them anyway was
    # slower in three runs of four). PFH's pair stage is bound by its
    # arithmetic, not by its reads (1.2-1.4x slower shuffled): not renumbered.
    # Only a stage that writes its rows through `rows` may set this
    _grid_order = False

    def _check_search(self):
        if self.n_neighbors is not None and self.radius is not None:
            raise ValueError(
                "give n_neighbors or radius, not both "
                f"(n_neighbors={self.n_neighbors}, radius={self.radius})"
            )
        if self.normal_n_neighbors is not None and self.normal_radius is not None:
            raise ValueError("give normal_n_neighbors or normal_radius, not both")
        check_viewpoint(self.viewpoint)

    @property
    def _bounded_batches(self):
        # pooled: one row per cloud, so the per-point rows of one batch at a
        # time, not of all clouds, are held (bounded memory)
        return self.pooling is not None

    def _validate(self, X):
        self._check_search()
        clouds = check_point_clouds(X, ensure_all_finite=False)
        for i, c in enumerate(clouds):
            if not np.isfinite(c[:, :3]).all():
                raise ValueError(f"X[{i}] has NaN or infinite coordinates.")
        check_given_normals(clouds, self.normals, estimation=self._estimation_set())
        return clouds

    def _estimation_set(self):
        """The parameters of the normal estimation set away from their default."""
        names = [
            name
            for name in ("normal_n_neighbors", "normal_radius")
            if getattr(self, name) is not None
        ]
        if not isinstance(check_viewpoint(self.viewpoint), str):
            names.append("viewpoint")
        return names

    def _given_normals(self, clouds):
        """The normals given in the clouds' columns 3-5, packed as float32,
        and the mask of the points that have them (NaN rows elsewhere);
        ``(None, None)`` when every cloud's normals are to be estimated."""
        given = [has_normal_columns(c, self.normals) for c in clouds]
        if not any(given):
            return None, None
        if all(given):
            n = np.vstack([c[:, 3:6] for c in clouds]).astype(np.float32)
            return n, np.ones(len(n), dtype=bool)
        blocks = [
            c[:, 3:6] if g else np.full((len(c), 3), np.nan)
            for c, g in zip(clouds, given)
        ]
        mask = np.repeat(np.asarray(given), [len(c) for c in clouds])
        return np.vstack(blocks).astype(np.float32), mask

    def _compute(self, clouds, n_threads, out=None):
        """Packed descriptors, the undefined-point mask and the cloud offsets
        of validated clouds, the kernels on ``n_threads`` threads; into
        ``out`` (zeroed rows, one per point) when given."""
        k = self.n_neighbors
        if k is None and self.radius is None:
            k = self._default_n_neighbors
        xyz, offsets, nb, order = pack_neighborhoods(
            clouds, n_neighbors=k, radius=self.radius, n_threads=n_threads,
            with_sqdist=False, return_order=True,
        )  # fmt: skip
        if not self._grid_order or not scattered(nb):
            order = None
        if order is not None:
            # the points renumbered in the search's grid order (by cell):
            # neighbours close in memory, whatever the clouds' own order
            nb = nb.renumbered(order, n_threads)
        # float32 as PCL, each cloud in its local frame (far from the origin:
        # relative to its minimum), the viewpoint moved into the same frame
        p, origins = local_frame(xyz, offsets)
        if order is not None:
            p = p[order]
        given, mask = self._given_normals(clouds)
        if order is not None and given is not None:
            given, mask = given[order], mask[order]
        if given is not None and mask.all():
            n = given
        else:
            nnb = nb
            if self.normal_n_neighbors is not None or self.normal_radius is not None:
                _, _, nnb = pack_neighborhoods(
                    clouds,
                    n_neighbors=self.normal_n_neighbors,
                    radius=self.normal_radius,
                    n_threads=n_threads,
                    with_sqdist=False,
                )
                if order is not None:
                    nnb = nnb.renumbered(order, n_threads)
            vp = local_viewpoints(
                check_viewpoint(self.viewpoint), xyz, offsets, origins
            )
            n = normals_f32(p, nnb, vp, n_threads, offsets)[0]
            del nnb
            if given is not None:  # "auto" on clouds with and without normals
                n[mask] = given[mask]
        del xyz, given, mask  # the descriptors work in float32
        undefined = ~np.isfinite(n).all(axis=1) | (nb.sizes < 2)
        if order is not None:
            undefined[order] = undefined.copy()
        # the search's temporaries are freed: return their pages to the system
        # before the kernels allocate their outputs (lower peak memory)
        release_free_memory()
        pairs = self._pair_stage(p, n, nb, offsets, n_threads, out)
        del n  # no later stage reads the normals: freed before its output
        out = self._final_stage(p, pairs, nb, n_threads, out, order)
        return out, undefined, offsets

    def _pair_stage(self, p, n, nb, offsets, n_threads, out=None):
        """The kernels that read the normals (the pair features)."""
        raise NotImplementedError

    def _final_stage(self, p, pairs, nb, n_threads, out=None, rows=None):
        """The kernels after the normals are freed; by default none. Point
        ``i``'s row of the output is ``rows[i]`` when given (the points in
        grid order, :attr:`_grid_order`)."""
        return pairs

    def undefined_mask(self, X):
        """Which points have an undefined descriptor.

        A descriptor is undefined where the point's normal is undefined
        (estimated: fewer than 3 neighbours, or a collinear neighbourhood;
        given: a row with a NaN) or the point has no neighbour but itself.
        What :meth:`transform` does with those points is set by
        ``undefined``.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_points_i, 3+)
            The clouds.

        Returns
        -------
        masks : list of ndarray of bool of shape (n_points_i,)
            True for the points whose descriptor is undefined.
        """
        return map_batches(self._undefined_batch, self._validate(X), self.n_jobs)

    def _undefined_batch(self, clouds, n_threads):
        _, undefined, offsets = self._compute(clouds, n_threads)
        return [undefined[offsets[i] : offsets[i + 1]] for i in range(len(offsets) - 1)]

    def transform(self, X):
        """Compute the descriptor of every point of every cloud.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_points_i, 3+)
            The clouds, xyz first; with ``normals="auto"`` (the default)
            columns 3-5 of a cloud with 6 or more columns are its normals.

        Returns
        -------
        descriptors : list of ndarray of shape (n_rows_i, n_features) or ndarray of shape (n_clouds, n_features)
            One float32 array per cloud, a row per point (fewer with
            ``undefined="drop"``); with ``pooling``, one row per cloud.
        """  # noqa: E501
        return super().transform(X)

    def _transform_batch(self, clouds, n_threads):
        """:meth:`transform` of validated clouds (one batch of them)."""
        if self.pooling is not None:
            return self._pooled_batch(clouds, n_threads)
        return self._rows(*self._compute(clouds, n_threads))

    def _pooled_batch(self, clouds, n_threads):
        """The pooled rows of a batch, computed a part of at most
        :data:`_POOLED_PART` points at a time (whole clouds) in one output
        buffer, zeroed between parts: no array of every point's
        descriptor, and its pages faulted in once, not for each point of
        the batch (the same rows as all at once: clouds never interact)."""
        parts, size = [], 0
        for c in clouds:
            if not parts or size + len(c) > _POOLED_PART:
                parts.append([])
                size = 0
            parts[-1].append(c)
            size += len(c)
        largest = max(sum(len(c) for c in part) for part in parts)
        buffer = unshared_zeros((largest, self._width()), np.float32)
        pooled = []
        for k, part in enumerate(parts):
            m = sum(len(c) for c in part)
            if k:
                buffer[:m] = 0.0
            rows = self._rows(*self._compute(part, n_threads, buffer[:m]))
            pooled.extend(_pool(block, self.pooling) for block in rows)
        return np.vstack(pooled)

    def _rows(self, out, undefined, offsets):
        """The per-point rows of each cloud, undefined points as asked."""
        if self.undefined == "nan":
            out[undefined] = np.nan
        elif self.undefined == "zero":
            out[undefined] = 0.0
        rows = []
        for i in range(len(offsets) - 1):
            block = out[offsets[i] : offsets[i + 1]]
            if self.undefined == "drop":
                block = block[~undefined[offsets[i] : offsets[i + 1]]]
            rows.append(block)
        return rows

    def _feature_names(self):
        # pfh0, pfh1... or fpfh0, fpfh1...
        prefix = type(self).__name__.removesuffix("Transformer").lower()
        return numbered(prefix, self._width())

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = True
        return tags


def _pool(block, how):
    valid = block[np.isfinite(block).all(axis=1)]
    if len(valid) == 0:
        return np.full(block.shape[1], np.nan, dtype=np.float32)
    if how == "mean":
        return valid.mean(axis=0, dtype=np.float64).astype(np.float32)
    if how == "sum":
        return valid.sum(axis=0, dtype=np.float64).astype(np.float32)
    return valid.max(axis=0)


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


class FPFHTransformer(_LocalDescriptor):
    """Fast Point Feature Histogram of every point.

    The SPFH of a point bins the three angles of the pairs (point,
    neighbour) into three ``n_bins`` histograms; the FPFH combines the
    neighbours' SPFH, by default exactly as PCL 1.13's ``FPFHEstimation``
    (weights 1/squared distance, own SPFH left out, each block rescaled to
    100). ``convention`` selects Open3D's or the original paper's variant.

    Read more in the :ref:`User Guide <local_descriptors>`.

    Parameters
    ----------
    n_neighbors : int, default=None
        k for the k-nearest-neighbour search, the point itself included (PCL
        ``setKSearch``, Open3D ``max_nn``). When neither ``n_neighbors`` nor
        ``radius`` is given, k = 10.
    radius : float, default=None
        Radius search instead (PCL ``setRadiusSearch``); give one of the two.
    n_bins : int, default=11
        Bins per feature (3 * n_bins values).
    normals : {"auto", "columns", "estimate"}, default="auto"
        Where the normals come from: given in columns 3-5, estimated, or
        given where a cloud has them (the default), as in
        :class:`PFHTransformer`.
    normal_n_neighbors : int, default=None
        k for the estimated normals; by default the descriptor's own
        neighbourhoods (see :class:`PFHTransformer`).
    normal_radius : float, default=None
        Radius for the estimated normals instead.
    viewpoint : "corner" or tuple of 3 float, default="corner"
        The point estimated normals face: a corner fixed to each cloud, or
        three coordinates (``(0, 0, 0)`` gives PCL's histograms bin for
        bin), as in :class:`PFHTransformer`.
    undefined : {"nan", "zero", "drop", "keep"}, default="nan"
        What becomes of the points whose descriptor is undefined, as in
        :class:`PFHTransformer`; :meth:`undefined_mask` says which they are.
    pooling : {"mean", "sum", "max"}, default=None
        Return one row per cloud, pooled over its defined rows, instead of a
        list of per-point arrays.
    convention : {"pcl", "open3d", "paper"}, default="pcl"
        PCL's FPFH, Open3D's (adds the point's own SPFH) or the paper's
        (1/distance weights); see :func:`compute_fpfh`.
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
    PFHTransformer : The full pairwise histogram.
    compute_fpfh : The function form for one cloud.

    Notes
    -----
    ``n_bins=11`` gives PCL's ``FPFHSignature33``.

    References
    ----------
    .. [1] R. B. Rusu, N. Blodow, M. Beetz, "Fast Point Feature Histograms
       (FPFH) for 3D registration", ICRA 2009.

    Examples
    --------
    >>> from skpcd.datasets import make_point_clouds
    >>> from skpcd.features import FPFHTransformer
    >>> clouds = make_point_clouds(2, n_points=40, random_state=0)
    >>> FPFHTransformer(n_neighbors=8, pooling="mean").fit_transform(clouds).shape
    (2, 33)
    """

    _parameter_constraints: typing.ClassVar[dict] = {
        **_LocalDescriptor._parameter_constraints,
        "convention": [StrOptions(set(FPFH_CONVENTIONS))],
    }

    _grid_order = True

    def __init__(
        self,
        n_neighbors=None,
        *,
        radius=None,
        n_bins=11,
        normals="auto",
        normal_n_neighbors=None,
        normal_radius=None,
        viewpoint=CLOUD_VIEWPOINT,
        undefined="nan",
        pooling=None,
        convention="pcl",
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
        self.convention = convention
        self.n_jobs = n_jobs

    def _width(self):
        return 3 * int(self.n_bins)

    def _pair_stage(self, p, n, nb, offsets, n_threads, out=None):
        """SPFH as pair counts: the only FPFH stage that reads the normals."""
        return _spfh_counts(p, n, nb, int(self.n_bins), n_threads, pack=True)

    def _final_stage(self, p, pairs, nb, n_threads, out=None, rows=None):
        counts, table = pairs
        # the normals are gone: hand their pages back before the output
        release_free_memory()
        args = (p, counts, table, nb, int(self.n_bins), self.convention, n_threads)
        return _fpfh_from_counts(*args, out, rows)
