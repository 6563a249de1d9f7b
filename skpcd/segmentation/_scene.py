"""A whole scene to segments: ground removal, clustering, segment sizes."""

import os
from numbers import Integral, Real

import numpy as np
from sklearn.base import clone
from sklearn.utils._param_validation import (
    HasMethods,
    Interval,
    StrOptions,
    validate_params,
)

from skpcd.io import iter_points, linear_unit, read_las_extent, read_point_cloud
from skpcd.io._api import read_fields
from skpcd.preprocessing import (
    RadiusOutlierFilter,
    StatisticalOutlierFilter,
)
from skpcd.segmentation._dbscan import EPS_SCALE, estimate_eps
from skpcd.segmentation._result import SceneSegmentation, kind_names
from skpcd.segmentation._scan_kind import SCAN_KINDS, describe_scan, sweep_coordinates
from skpcd.segmentation._scene_clusters import cluster_rest
from skpcd.segmentation._structures import (
    STRUCTURE_DEFAULTS,
)
from skpcd.segmentation._sweeps import segment_sweep
from skpcd.segmentation.ground import GROUND_PRESETS, GroundFilter
from skpcd.segmentation.ground._classified import (
    FROM_FILE,
    ClassifiedGround,
    classified_ground,
    ground_flags,
)
from skpcd.segmentation.tiling._segment import segment_tiled
from skpcd.utils._compile import entry_point
from skpcd.utils._validation import check_scene

__all__ = ["segment_scene"]


@validate_params(
    {
        "points": ["array-like", str, os.PathLike],
        "ground": [
            StrOptions({"auto", FROM_FILE, *GROUND_PRESETS}),
            GroundFilter,
            ClassifiedGround,
            "array-like",
            None,
        ],
        "sensor": ["array-like", None],
        "rings": ["array-like", None],
        "method": [StrOptions({"dbscan", "euclidean", "range-image"})],
        "eps": [Interval(Real, 0, None, closed="neither"), None],
        "eps_scale": [Interval(Real, 0, None, closed="neither")],
        "min_samples": [Interval(Integral, 1, None, closed="left")],
        "min_cluster_size": [Interval(Integral, 1, None, closed="left")],
        "max_cluster_size": [Interval(Integral, 1, None, closed="left"), None],
        "random_state": ["random_state"],
        "n_jobs": [Integral, None],
        "tile_size": [Interval(Real, 0, None, closed="neither"), None],
        "tile_buffer": [Interval(Real, 0, None, closed="left"), None],
        "temp_folder": [str, os.PathLike, None],
        "denoise": [
            StrOptions({"statistical", "radius"}),
            HasMethods("fit_predict"),
            None,
        ],
        "structures": ["boolean", dict],
        "unit": [StrOptions({"auto"}), Interval(Real, 0, None, closed="neither")],
    },
    prefer_skip_nested_validation=True,
)
@entry_point
def segment_scene(
    points,
    *,
    ground="auto",
    sensor=None,
    rings=None,
    method="dbscan",
    eps=None,
    eps_scale=EPS_SCALE,
    min_samples=5,
    min_cluster_size=50,
    max_cluster_size=None,
    random_state=0,
    n_jobs=None,
    tile_size=None,
    tile_buffer=None,
    temp_folder=None,
    denoise=None,
    structures=True,
    unit="auto",
):
    """Cut a LiDAR scene into object segments.

    The ground is removed (:class:`GroundFilter`, by default the cloth
    simulation filter), facades and overhead wires are taken out of the
    other points as segments of their own, the rest is clustered
    (:class:`AutoEpsDBSCAN` or :class:`EuclideanClusters`) and clusters
    holding several vertical trunks (poles, a pole in a tree) are split
    between them; segments with too few or too many points are dropped.

    Read more in the :ref:`User Guide <segmentation>`.

    Parameters
    ----------
    points : array-like of shape (n_points, 3+), str or path-like
        The scene (columns beyond the third are ignored), or a point-cloud
        file. With ``tile_size``, a LAS/LAZ file is streamed in chunks
        (other formats are read whole first).
    ground : {"auto", "street", "csf", "aerial", "mobile", "from-file"}, \
            GroundFilter, ClassifiedGround, array-like of bool or None, \
            default="auto"
        Ground removal: a :class:`GroundFilter` with the parameters of
        ``GROUND_PRESETS[ground]`` ("csf": the cloth simulation filter,
        through the package ``cloth-simulation-filter``; "street": the
        same followed by the pass that gives the bases of objects back,
        ``keep_bases``; "aerial" and "mobile": SMRF), a filter of your own
        (cloned), or None to keep every point. "auto" asks
        :func:`describe_scan` what the scan is and takes
        ``SCAN_KINDS[kind]["ground"]``: "aerial" for an airborne scan,
        "street" for the others; with ``tile_size`` the kind is told from
        a sample of the scan. The filter runs on the threads of ``n_jobs`` (one of
        your own keeps its ``n_jobs`` unless None). "from-file" takes the
        ground a scan already carries, the points of ASPRS class 2 in its
        ``classification`` field (``points`` must then be a file; a file
        without that field is a :class:`~skpcd.exceptions.PointCloudFileError`
        naming it), and
        :class:`~skpcd.segmentation.ground.ClassifiedGround` other codes
        (``ClassifiedGround(codes=(2, 8))``); a boolean array, one flag per
        point, gives the ground points outright.
    sensor : array-like of shape (3,) or None, default=None
        With ``ground="auto"``, the position of the sensor of a single
        sweep if known (see :func:`describe_scan`); with
        ``method="range-image"``, where the rays start (None: the origin).
    rings : array-like of shape (n_points,) or None, default=None
        With ``method="range-image"``, the ring of each point (see
        :func:`range_image`); None takes them from a file's ring field
        (``RING_FIELDS``, when it holds at least 4 values), else finds them
        from the elevation angles.
    method : {"dbscan", "euclidean", "range-image"}, default="dbscan"
        :class:`AutoEpsDBSCAN` (eps estimated from the non-ground points
        unless given), :class:`EuclideanClusters` (every point core; eps
        0.2 unless given), or, for one sweep of a spinning sensor in its
        sensor's frame (or ``sensor`` given), the segmentation in its range
        image, :func:`segment_sweep` (ground="auto" walks the ground along
        the image's columns; the rings are those of a file's ``ring`` or
        ``scanner_channel`` field when it has one; ``structures`` runs the
        structures step on the image's clusters; ``eps``, ``eps_scale``
        and ``min_samples`` do not apply; not with ``tile_size``).
    eps : float or None, default=None
        Clustering radius; see ``method``. An automatic radius that joins
        a segment covering more than half of the scene's horizontal
        extent (and more than 50 x 50 m) is halved until none does, at
        least twice the point spacing, with a :class:`SegmentationWarning`
        naming the radius used: give ``eps`` to choose it. With
        ``ground="auto"`` on a single sweep (spinning, robot), the automatic
        radius is at most ``SCAN_KINDS[kind]["max_eps"]`` (0.75 m; the
        radius of the structures, returned as ``eps``) and DBSCAN clusters
        in coordinates ``(log range, azimuth, height / range)`` around
        ``scan.centre`` (:func:`sweep_coordinates`), where one radius is a
        distance proportional to the range: a sweep is dense near the
        sensor and sparse far away. That radius is estimated in those
        coordinates, ``SCAN_KINDS[kind]["relative_eps_scale"]`` (1.4) times
        the knee distance, so that it bridges the rings of the sensor
        (2 to 3 % of the range on real 64-beam sweeps, about twice that on
        simulated 16-beam ones).
    eps_scale : float, default=2.5
        With ``method="dbscan"`` and ``eps=None``, the estimated radius is
        this multiple of the knee distance of :class:`AutoEpsDBSCAN`
        (chosen by cross-validation on scenes of real objects; lower it for
        objects closer together than about ``eps_scale`` times the point
        spacing). Ignored when ``eps`` is given.
    min_samples : int, default=5
        DBSCAN's core-point count (ignored by "euclidean").
    min_cluster_size : int, default=50
        Smaller segments are dropped.
    max_cluster_size : int or None, default=None
        Larger segments are dropped.
    random_state : int, RandomState instance or None, default=0
        Draws the points of the eps estimate.
    n_jobs : int, default=None
        Threads; None means 1, -1 all cores. With ``tile_size``, the tiles
        run one after the other, each on ``n_jobs`` threads, unless a joblib
        backend is chosen (``joblib.parallel_config(backend=...)``, for
        example ``backend="dask"`` with a ``dask.distributed.Client``):
        then the tiles are dispatched through joblib, ``n_jobs`` at once
        (None: the context's; all worker threads on Dask), each on the
        cores left to its task (as the batches of the descriptors).
    tile_size : float or None, default=None
        None segments the scene in memory. A number cuts it into square
        tiles of that side (in metres), spilled to temporary files and
        processed one at a time, so that memory is bounded by the tile size,
        not the scan size (see Notes). The result is the untiled one.
    tile_buffer : float or None, default=None
        Overlap loaded around each tile. None picks the smallest that keeps
        the result equal to the untiled one (a smaller buffer, at least
        ``2 * eps``, keeps the clustering exact but lets the ground filter
        differ near tile borders): the reach of the SMRF filter,
        ``(3 * ceil(window / cell) + 11) * cell`` plus two cells, 1 % more
        (67.7 m for ``"aerial"``, 36.9 m for ``"mobile"``; for ``"street"``
        that of its bases pass, 12.6 m; CSF needs none), at least ``2 *
        eps``, and with ``structures`` at least ``max(10, 8 * eps)`` metres
        (the points the structures step sees around a tile; with
        ``eps=None``, 10 m, and the scan is cut again with a larger buffer
        if the estimated eps needs more); with ``eps=None``, no SMRF and no
        structures, a quarter of the tile. A buffer given that the
        estimated eps needs more than is a ValueError. Tiles should be
        several times larger than their buffer, or the overlap dominates
        the work.
    temp_folder : str or path-like, default=None
        Where the tile files and the result arrays are spilled with
        ``tile_size`` (the system's temporary folder when None); it needs
        about 32 bytes per point and buffered tile, plus 9 bytes per point
        (18 with the bases pass of ``"street"``).
    denoise : {"statistical", "radius"}, outlier filter or None, default=None
        Outlier removal before everything else:
        :class:`~skpcd.preprocessing.StatisticalOutlierFilter` or
        :class:`~skpcd.preprocessing.RadiusOutlierFilter` with their
        defaults, or a filter of your own (cloned; its ``fit_predict``
        gives -1 for an outlier). The outliers are labelled -1 and are not
        ground; the other steps see the inliers only. Not with
        ``tile_size`` (a ValueError): filter the scan beforehand.
    structures : bool or dict, default=True
        Take facades and overhead wires out before clustering, as segments
        of their own, and split clusters at vertical trunks (see Notes). A
        dict overrides the parameters of ``STRUCTURE_DEFAULTS`` (lengths in
        metres): ``facade_min_height`` (2.0) and ``facade_min_length``
        (4.0), the smallest vertical and horizontal extent of a facade;
        ``wire_min_height`` (3.0), the lowest a wire runs above the ground,
        ``wire_min_length`` (4.0) its shortest horizontal length and
        ``wire_max_width`` (0.3) the largest thickness of its points'
        neighbourhoods and horizontal spread across it;
        ``trunk_min_height`` (1.2), the shortest vertical trunk that seeds a
        split; ``n_neighbors`` (12), the neighbours of the local shape.
        False clusters every non-ground point alike (the earlier pipeline).
        Not with ``tile_size`` (a ValueError).
    unit : "auto" or float, default="auto"
        The length of one coordinate unit in metres: every default length
        (the ground presets, the structures, the largest automatic radius
        of a sweep) is in metres, and a scan in other units is segmented
        in metres (its coordinates scaled by ``unit``; the result's labels
        are those of the points as given). ``eps``, ``tile_size``,
        ``tile_buffer``, ``sensor`` and the result's ``eps`` are in the
        units of the coordinates. "auto": the unit of a LAS/LAZ file's CRS
        (:func:`skpcd.io.linear_unit`: 0.3048 for international feet, as
        PDAL's and laspy's ``autzen`` files), else 1 (metres), as for an
        array.

    Returns
    -------
    result : SceneSegmentation
        Named tuple ``(labels, ground, eps, kinds)``; ``labels`` is -1
        outside segments, ``ground`` marks the ground points, ``kinds``
        says what each segment is ("object", "facade" or "wire"). With ``tile_size``
        both arrays are :class:`numpy.memmap` of files in ``temp_folder``
        (unlinked already on POSIX systems, so nothing is left behind).

    See Also
    --------
    skpcd.datasets.make_scene : Real objects on a synthetic terrain, to score this.
    skpcd.io.iter_points : Read a LAS/LAZ file chunk by chunk.

    Notes
    -----
    The structures (``structures=True``): every non-ground point gets the
    shape of its ``n_neighbors`` nearest neighbours (the eigenvalues ``l1
    >= l2 >= l3`` of their covariance) and its height above the ground
    points. Facade points are planar (``(l2 - l3) / l1 >= 0.5``) with a
    horizontal normal (``|n_z| <= 0.3``), joined over the k-NN graph where
    their normals agree within 20 degrees into regions at least
    ``facade_min_height`` tall and ``facade_min_length`` long; the planar
    vertical points linked (``eps`` apart) to such a region, the points
    whose neighbours are mostly facade (twice) and the clusters of mostly
    planar points touching a facade join it. Wire points are linear
    (``(l1 - l2) / l1 >= 0.8``) with an axis within 30 degrees of the
    horizontal, thin, ``wire_min_height`` above the ground and hanging free
    (at most 3 points 0.3 to 2 m above or below in their 0.5 m column),
    linked into pieces ``wire_min_length`` long and at most
    ``wire_max_width`` wide. The facade and wire pieces are segments of
    kind "facade" and "wire"; the other points are clustered. Trunk points
    are linear and vertical (axis within 32 degrees of the vertical)
    between 0.2 and 3 m above the ground; their pieces at least
    ``trunk_min_height`` tall and at most 0.35 m wide (standard deviation)
    are trunks, and a cluster holding two or more is split: each point goes
    to the trunk nearest along the k-NN graph of the cluster. Segments are
    numbered objects first, then facades, then wires.

    The ground presets and these defaults were chosen by measurement on
    simulated street scans (:func:`~skpcd.datasets.make_street_scene`,
    mobile and UGV) and on scenes of real DALES objects
    (:func:`~skpcd.datasets.make_scene`): ``benchmarks/bench_ground.py`` and
    ``benchmarks/bench_street_segmentation.py``, numbers in the user guide.

    With ``tile_size``, ``structures`` must be False (a ValueError
    otherwise): the structures are found from pieces of any size, which
    have no bounded reach that would make the tiled result the in-memory
    one. With ``tile_size``, ``ground="auto"`` does not use the relative
    radius of a single sweep (see :func:`describe_scan`): a sweep small
    enough for it is segmented in memory.

    With ``tile_size``, the scan is read chunk by chunk and each point is
    written to the temporary file of every buffered tile holding it (its
    own tile, and the neighbours whose buffer reaches it). Then, tile by
    tile, with the tile's buffer:

    1. SMRF runs on the cells of the scene's raster that cover the tile
       grown by the filter's reach (same cells as untiled), and classifies
       the tile's own points: every step of the filter computes a cell
       from the cells within a fixed distance (its reach), so these are
       the untiled flags. CSF lets one cloth fall over the whole scan: the
       reference simulation sees the points only through the nearest
       point of each cloth particle, so two passes over the tiles gather
       those (memory follows the cloth's particles, not the points), the
       simulation runs once, and each tile's points are
       tested against the cloth as CSF tests them: the untiled flags, bit
       for bit. The ``keep_bases`` pass of ``"street"`` runs its SMRF on
       the ground points tile by tile, with the spread of their heights
       taken over the whole scan;
    2. with ``eps=None``, eps is estimated once for the whole scan, not per
       tile: the same random sample of non-ground points as the untiled
       estimate, their neighbours searched in their tile with its buffer,
       and, for the few whose neighbours the tile may not hold (isolated
       points), in every tile within reach: the untiled distances;
    3. DBSCAN runs on the non-ground points within ``2 * eps`` of the tile.
       Every point within ``eps`` of the tile then has its exact core
       status, so each tile has the exact clusters of its own points, and
       clusters of neighbouring tiles sharing a core point are the same
       segment (joined by union-find): no object is cut at a tile border or
       counted twice. Segments are then numbered as untiled (in the order
       of their first point) after the size range is applied over the whole
       scan.

    Memory holds one buffered tile and its segmentation, plus the result
    arrays, 9 bytes per point (18 with the bases pass of ``"street"``),
    which are memory-mapped files (unlinked once mapped on POSIX systems).
    Without the structures step the result is the untiled one whatever the
    tile size, for both methods, a given or an estimated eps and any
    ground filter (the tests compare them on a street scan whose bounding
    box is mostly empty, with objects across tile borders, and on real
    sweeps); with it, the segments agree up to a bound (see the user
    guide's "Scanning a city").

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.segmentation import segment_scene
    >>> rng = np.random.default_rng(0)
    >>> floor = np.column_stack([rng.uniform(0, 30, (9000, 2)), np.zeros(9000)])
    >>> boxes = [rng.uniform([x, 5, 0.6], [x + 3, 8, 3], (800, 3)) for x in (5, 15)]
    >>> seg = segment_scene(np.vstack([floor, *boxes]))
    >>> seg.n_segments, int(seg.ground.sum()), np.bincount(seg.labels[9000:]).tolist()
    (2, 9000, [800, 800])
    >>> seg.kinds.tolist()
    ['object', 'object']
    """
    _check_options(denoise, tile_size, structures)
    if rings is not None and method != "range-image":
        raise ValueError("rings are used by method='range-image' only")
    if method == "range-image" and tile_size is not None:
        raise ValueError(
            "method='range-image' segments one sweep in memory; it is not "
            "available with tile_size"
        )
    unit = resolve_unit(unit, points)
    if unit != 1.0:  # every length given in metres, as the defaults
        eps = None if eps is None else eps * unit
        sensor = None if sensor is None else np.asarray(sensor, dtype=float) * unit
        tile_size = None if tile_size is None else tile_size * unit
        tile_buffer = None if tile_buffer is None else tile_buffer * unit
    clustering = {
        "method": method, "eps": eps, "eps_scale": eps_scale,
        "min_samples": min_samples, "min_cluster_size": min_cluster_size,
        "max_cluster_size": max_cluster_size, "random_state": random_state,
        "n_jobs": n_jobs,
    }  # fmt: skip
    if tile_size is not None:
        seg = _segment_in_tiles(
            points, ground, sensor, structures,
            (tile_size, tile_buffer, temp_folder, unit), clustering,
        )  # fmt: skip
        return seg._replace(eps=seg.eps / unit, unit=unit)
    from_file = classified_ground(ground, points)
    given = None
    if from_file is not None:
        points, given = from_file.read(points)
    elif isinstance(points, (str, os.PathLike)) and method == "range-image":
        points, found = read_rings(points)
        rings = found if rings is None else rings
    elif isinstance(points, (str, os.PathLike)):
        points = read_point_cloud(points)
    xyz = check_scene(points)
    full = len(xyz)
    if unit != 1.0:
        xyz = xyz * unit
    if from_file is None:
        given = ground_flags(ground, len(xyz))
    keep = None
    if denoise is not None:
        keep = _inliers(xyz, denoise, n_jobs)
        xyz = np.ascontiguousarray(xyz[keep])
        given = None if given is None else given[keep]
        rings = None if rings is None else rings[keep]
    if method == "range-image":
        seg = _segment_in_image(
            xyz, ground, (given, from_file), sensor, rings,
            {**clustering, "structures": structures},
        )  # fmt: skip
        return _restored(seg._replace(unit=unit), keep, full)
    scan = None
    if isinstance(ground, str) and ground == "auto":
        defaults = SCAN_KINDS["spinning"]  # too few points to tell
        if len(xyz) >= 13:
            scan = describe_scan(xyz, sensor=sensor, random_state=random_state)
            defaults = SCAN_KINDS[scan.kind]
        ground = defaults["ground"]
    filt = None if given is not None else _ground_filter(ground, n_jobs)
    if given is not None:
        is_ground = given
    else:
        is_ground = (
            np.zeros(len(xyz), dtype=bool) if filt is None else filt.fit_predict(xyz)
        )
    sweep = None
    if scan is not None and eps is None and method == "dbscan":
        eps, sweep = _radius_of_kind(xyz, is_ground, scan, clustering)
    seg = cluster_rest(
        xyz, is_ground, **{**clustering, "eps": eps}, structures=structures,
        sweep=sweep, unit=unit,
    )  # fmt: skip
    seg = seg._replace(
        eps=seg.eps / unit,
        scan=scan,
        ground_filter=_ground_name(ground, from_file),
        unit=unit,
    )
    return _restored(seg, keep, full)


def _restored(seg, keep, full):
    """The result over all the points, the outliers of ``denoise`` (the
    points not in ``keep``) in no segment and not ground."""
    if keep is None:
        return seg
    labels = np.full(full, -1, dtype=np.int64)
    labels[keep] = seg.labels
    is_ground = np.zeros(full, dtype=bool)
    is_ground[keep] = seg.ground
    return seg._replace(labels=labels, ground=is_ground)


# Fields that hold the ring of each point in the files of spinning sensors.
RING_FIELDS = ("ring", "scanner_channel", "laser_number", "laser_id", "channel")


def read_rings(path):
    """The points of a file and the ring of each (see :func:`rings_of`)."""
    xyz, extras = read_fields(path, optional=[RING_FIELDS])
    return xyz, rings_of(extras)


def rings_of(fields):
    """The ring of each point: the first of ``RING_FIELDS`` among the
    ``fields`` read from a file that holds at least 4 values (a LAS 1.4
    file's scanner_channel, all 0, or a scanner's few channels are not
    rings); None if none does."""
    rings = next((fields[n] for n in RING_FIELDS if n in fields), None)
    if rings is None or len(np.unique(rings)) < 4:
        return None
    return np.asarray(rings)


def _segment_in_image(xyz, ground, given, sensor, rings, clustering):
    """segment_scene with method="range-image" (see segment_sweep);
    ``given = (flags, from_file)``, the ground flags given or read."""
    given, from_file = given
    if given is not None:
        flags = given
    elif isinstance(ground, str) and ground == "auto":
        flags = True
    elif ground is None:
        flags = False
    else:
        flags = _ground_filter(ground, clustering["n_jobs"]).fit_predict(xyz)
    seg = segment_sweep(
        xyz, sensor=sensor, rings=rings, ground=flags,
        min_cluster_size=clustering["min_cluster_size"],
        max_cluster_size=clustering["max_cluster_size"],
        structures=clustering["structures"], n_jobs=clustering["n_jobs"],
    )  # fmt: skip
    if flags is True:
        return seg
    return seg._replace(ground_filter=_ground_name(ground, from_file))


def _check_options(denoise, tile_size, structures):
    """The errors of option combinations that segment_scene refuses."""
    if denoise is not None and tile_size is not None:
        raise ValueError(
            "denoise is not available with tile_size; remove the outliers "
            "from the scan beforehand"
        )
    if isinstance(structures, dict):
        unknown = sorted(set(structures) - set(STRUCTURE_DEFAULTS))
        if unknown:
            raise ValueError(
                f"unknown structures parameter(s) {unknown}; known: "
                f"{sorted(STRUCTURE_DEFAULTS)}"
            )


def _segment_in_tiles(points, ground, sensor, structures, tiling, clustering):
    """segment_scene with ``tiling = (tile_size, tile_buffer, temp_folder,
    unit)`` (see its Notes; lengths in metres)."""
    tile_size, tile_buffer, temp, unit = tiling
    scan = None
    from_file = classified_ground(ground, points)
    given = None
    if from_file is not None:
        given = from_file.iter_flags(points, _GIVEN_CHUNK)
    elif ground_flags(ground, None) is not None:
        flags = ground_flags(ground, None)
        given = (
            flags[start : start + _GIVEN_CHUNK]
            for start in range(0, len(flags), _GIVEN_CHUNK)
        )
    if isinstance(ground, str) and ground == "auto":
        sample = _scan_sample(points, clustering["random_state"]) * unit
        scan = describe_scan(
            sample, sensor=sensor, random_state=clustering["random_state"]
        )
        ground = SCAN_KINDS[scan.kind]["ground"]
    filt = None if given is not None else _ground_filter(ground, clustering["n_jobs"])
    if filt is not None:
        filt._validate_params()
    params = None
    if structures is not False:
        params = {
            **STRUCTURE_DEFAULTS,
            **(structures if isinstance(structures, dict) else {}),
        }
    eps = clustering["eps"]
    labels, is_ground, used, kinds = segment_tiled(
        points,
        tile_size=float(tile_size),
        tile_buffer=tile_buffer,
        ground=filt,
        given_ground=given,
        structures=params,
        **{**clustering, "eps": None if eps is None else float(eps)},
        temp_folder=temp,
        unit=unit,
    )
    return SceneSegmentation(
        labels, is_ground, used, kind_names(kinds), scan,
        _ground_name(ground, from_file),
    )  # fmt: skip


# Ground flags given (a classification, an array) go to the tiles in
# chunks of this many points.
_GIVEN_CHUNK = 1_000_000


def resolve_unit(unit, points):
    """The length of a coordinate unit in metres: ``unit`` itself, or
    with "auto" the unit of a LAS/LAZ file's CRS (1 for anything else)."""
    if unit != "auto":
        return float(unit)
    if isinstance(points, (str, os.PathLike)) and str(points).lower().endswith(
        (".las", ".laz")
    ):
        found = linear_unit(points)
        if found is not None:
            return float(found.metres)
    return 1.0


def _ground_name(ground, from_file):
    """``ground_filter`` of the result: the preset's name, "from-file", or
    None."""
    if from_file is not None:
        return FROM_FILE
    return ground if isinstance(ground, str) else None


def _inliers(xyz, denoise, n_jobs):
    """Indices of the points that the ``denoise`` filter keeps."""
    if isinstance(denoise, str):
        named = {"statistical": StatisticalOutlierFilter, "radius": RadiusOutlierFilter}
        denoiser = named[denoise](n_jobs=n_jobs)
    else:
        denoiser = clone(denoise)
    return np.flatnonzero(np.asarray(denoiser.fit_predict(xyz)) == 1)


def _radius_of_kind(xyz, is_ground, scan, clustering):
    """The automatic radius of a street scan's kind: the estimate capped at
    the kind's ``max_eps``, and for a single sweep the relative radius in
    sweep coordinates, ``(centre, z0, relative)``; ``(None, None)`` for a
    kind without a cap."""
    kind = SCAN_KINDS[scan.kind]
    rest = xyz[~is_ground]
    if kind.get("max_eps") is None or len(rest) < 2:
        return None, None
    seed, n_jobs = clustering["random_state"], clustering["n_jobs"]
    eps = estimate_eps(
        rest, eps_scale=clustering["eps_scale"], random_state=seed, n_jobs=n_jobs
    )
    eps = min(eps, kind["max_eps"])
    scale = kind.get("relative_eps_scale")
    if scale is None:
        return eps, None
    z0 = float(np.median(xyz[is_ground, 2]) if is_ground.any() else rest[:, 2].min())
    relative = estimate_eps(
        sweep_coordinates(rest, scan.centre, z0),
        eps_scale=scale,
        random_state=seed,
        n_jobs=n_jobs,
    )
    return eps, (scan.centre, z0, relative)


def _ground_filter(ground, n_jobs):
    """The filter of a ``ground`` argument (a preset, a filter, None)."""
    if ground is None:
        return None
    filt = (
        GroundFilter(**GROUND_PRESETS[ground])
        if isinstance(ground, str)
        else clone(ground)
    )
    if filt.n_jobs is None:
        filt.set_params(n_jobs=n_jobs)
    return filt


# Points of a file read to tell the kind of a tiled scan: every k-th point.
_TILED_SAMPLE = 200_000


def _scan_sample(points, random_state):
    """Up to ``_TILED_SAMPLE`` points of a scan spread over the whole file
    (one pass, chunk by chunk), or of an array."""

    if not isinstance(points, (str, os.PathLike)):
        xyz = check_scene(points)
        step = max(1, len(xyz) // _TILED_SAMPLE)
        return xyz[::step]

    try:
        n = read_las_extent(points).n_points
    except ValueError:  # not a LAS/LAZ file: read whole, as segment_tiled does
        xyz = read_point_cloud(points)
        return xyz[:: max(1, len(xyz) // _TILED_SAMPLE)]
    step = max(1, n // _TILED_SAMPLE)
    parts, seen = [], 0
    for chunk in iter_points(points):
        first = (-seen) % step
        # a copy: a view would keep the whole chunk alive until the stack
        parts.append(np.asarray(chunk)[first::step, :3].copy())
        seen += len(chunk)
    return np.vstack(parts)
