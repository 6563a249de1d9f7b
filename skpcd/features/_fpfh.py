"""Fast Point Feature Histograms (FPFH), as PCL 1.13 computes them.

The function form (:func:`compute_fpfh`) takes one cloud with its normals and
neighbourhoods; :class:`FPFHTransformer` takes a list of clouds, searches
neighbourhoods once, estimates normals and runs one parallel kernel over all
points of all clouds (:mod:`skpcd.features._local_descriptor`). Both compute
the SPFH of every point as pair counts, then the FPFH from them.
"""

import typing

import numpy as np
from sklearn.utils._param_validation import StrOptions

from skpcd.features._fpfh_kernels import (
    fpfh_rows,
    increment_sums,
    spfh_rows,
    spfh_values,
)
from skpcd.features._local_descriptor import _as_f32, _LocalDescriptor, _neighborhoods
from skpcd.preprocessing._normals import CLOUD_VIEWPOINT
from skpcd.utils._compile import entry_point
from skpcd.utils._memory import release_free_memory, unshared_zeros
from skpcd.utils._parallel import effective_threads, parallel_rows

__all__ = ["FPFHTransformer", "compute_fpfh"]

FPFH_CONVENTIONS = ("pcl", "open3d", "paper")


# Pair counts up to this many are turned into PCL's sums by table lookup.
_TABLE_PAIRS = 255


def _spfh_counts(p, n, nb, n_bins, n_threads, pack=False):
    """SPFH as pair counts per bin, and the table of PCL's increment sums.

    One byte per bin (two above 255 neighbours), not a float32's four; with
    ``pack``, and no point with more than 15 pairs, two 4-bit counts per byte
    (see :func:`~skpcd.features._fpfh_kernels.spfh_rows`).
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
