"""Simulated LiDAR scans of streets with per-point truth.

:func:`make_street_scene` lays out a street (terrain, facades, trees,
furniture, cars, wires), scans it with a mobile, aerial or UGV pattern by
ray casting and returns every return with its class and instance.
:func:`make_street_objects` cuts labelled objects out of such scans.
"""

from numbers import Integral, Real

import numpy as np
from scipy.spatial import cKDTree
from sklearn.utils import Bunch, check_random_state
from sklearn.utils._param_validation import Interval, StrOptions, validate_params

from skpcd.datasets._street._catalogue import OBJECT_CLASSES
from skpcd.datasets._street._layout import (
    STREET_CLASSES,
    Street,
    build_scene,
    furnish,
)
from skpcd.datasets._street._raycast import ELLIPSOID
from skpcd.datasets._street._scanners import (
    SCAN_PATTERNS,
    apply_footprint,
    build_grid,
    plan_scan,
    randomise_pattern,
    resolve_pattern,
    scan,
)
from skpcd.utils._compile import entry_point

__all__ = [
    "SCAN_PATTERNS",
    "STREET_CLASSES",
    "STREET_OBJECT_CLASSES",
    "make_street_objects",
    "make_street_scene",
]

# the object classes make_street_objects can cut out
STREET_OBJECT_CLASSES = OBJECT_CLASSES

# the classes it returns by default (all but fence and person)
_DEFAULT_CLASSES = tuple(c for c in OBJECT_CLASSES if c not in ("fence", "person"))

_CLASS_NAMES = np.array(STREET_CLASSES, dtype=object)


def _seeds(random_state):
    rng = check_random_state(random_state)
    layout, scan_seed = rng.randint(0, 2**31 - 1, size=2)
    return np.random.RandomState(layout), int(scan_seed)


_FENCE = STREET_CLASSES.index("fence")


def _porous(scene):
    """Primitives a wide beam sees as porous: foliage clusters (every
    ellipsoid a ray may cross, in trees, bushes and planters) and fence
    mesh, not glass."""

    return (scene["hit"] < 1.0) & (
        (scene["kind"] == ELLIPSOID) | (scene["class_id"] == _FENCE)
    )


def _simulate(street, scene, scanner, conf, seed, drop, n_jobs, interest=None):
    plan = plan_scan(scanner, conf, street)
    scene = apply_footprint(scene, float(conf["footprint"]), _porous(scene))
    grid = build_grid(scene)
    out = scan(
        plan, conf, scene, grid, seed, drop=drop, interest=interest, n_jobs=n_jobs
    )
    return (plan, *out)


_SCENE_PARAMS = {
    "length": [Interval(Real, 5, None, closed="left")],
    "scanner": [StrOptions(set(SCAN_PATTERNS))],
    "scanner_params": [dict, None],
    "max_range": [Interval(Real, 0, None, closed="neither"), None],
    "range_noise": [Interval(Real, 0, None, closed="left"), None],
    "beam_divergence": [Interval(Real, 0, None, closed="left"), None],
    "drop": [Interval(Real, 0, 1, closed="left")],
    "slope": [Interval(Real, -0.2, 0.2, closed="both"), None],
    "random_state": ["random_state"],
    "n_jobs": [Integral, None],
}


@validate_params(_SCENE_PARAMS, prefer_skip_nested_validation=True)
@entry_point
def make_street_scene(
    length=100.0,
    *,
    scanner="mobile",
    scanner_params=None,
    max_range=None,
    range_noise=None,
    beam_divergence=None,
    drop=0.0,
    slope=None,
    random_state=None,
    n_jobs=None,
):
    """Simulate a LiDAR scan of a street, with the class and object of every point.

    A street ``length`` metres long is laid out at random: a cambered road
    with parking lanes, kerbs, pavements and front gardens on a longitudinal
    slope; rows of buildings whose facades have recesses, window openings
    with reveals and glass, shop fronts, balconies and flat or gabled roofs;
    trees (trunk, branches, a crown of foliage clusters that let part of
    the beam through), bushes and hedges, parked cars, street lights, lamp
    posts, traffic lights, pedestrian signals, traffic signs, bare and
    utility poles with overhead wires, fences and clutter (bins, benches,
    bollards, cabinets...). The street is then scanned by ray casting
    against these analytic shapes: each pulse returns the first surface it
    meets (what stands behind a pole or a car is not seen), within the
    scanner's range, with Gaussian range noise and a jitter of the beam
    direction. Read more in the :ref:`User Guide <simulation>`.

    Parameters
    ----------
    length : float, default=100.0
        Length of the street in metres (along ``x``, from 0).
    scanner : {"mobile", "aerial", "ugv", "spinning"}, default="mobile"
        The scan pattern; its default numbers are in
        ``skpcd.datasets.SCAN_PATTERNS[scanner]``:

        - ``"mobile"``: two profilers on a vehicle driving the right lane
          at 10 m/s, centres 2.2 m above the road, vertical rotation planes
          at +-45 degrees to the driving direction (Optech Lynx, as in He et
          al., 2017), 200 rotations per second, 0.1 degree between pulses
          (720 000 pulses per second and scanner), a 40 degree cone below
          the scanners hidden by the vehicle, 1-100 m range, 8 mm noise.
        - ``"aerial"``: parallel scan lines across track from 1300 m at
          72 m/s, by two channels looking 14 degrees forward and backward
          (crossed scan lines), five flight lines along the street (y = 0,
          +-250 and +-550 m) flown in alternate directions, 8 pulses per m2
          each at nadir (DALES-like: about 40 per m2 in total), up to 4
          echoes per pulse, 2 cm noise, a beam footprint of 0.15 m radius
          (cylinders and thin panels look that much wider; foliage and mesh
          return from most pulses that cross them).
        - ``"ugv"``: one sweep of a spinning 32-beam sensor 1.8 m above
          the road in the middle of the street (HDL-32E vertical angles
          -30.67 to +10.67 degrees, 0.16 degree azimuth step), 1-100 m
          range, 2 cm noise.
        - ``"spinning"``: one sweep of a spinning multi-beam sensor on a
          car's roof, 1.73 m above the right lane in the middle of the
          street: ``scanner_params={"sensor": ...}`` picks the beams of
          ``"vlp16"``, ``"hdl32"``, ``"hdl64"`` (the default, KITTI's),
          ``"pandar64"`` (PandaSet's) or ``"os128"``; 2-120 m range.
    scanner_params : dict or None, default=None
        Overrides of the pattern's numbers, e.g. ``{"speed": 5.0}`` or
        ``{"angular_step": 0.2, "plane_azimuths": (45.0,)}`` (one scanner).
    max_range : float or None, default=None
        Longest range returned, metres; None keeps the pattern's.
    range_noise : float or None, default=None
        Standard deviation of the Gaussian noise along each ray, metres;
        None keeps the pattern's.
    beam_divergence : float or None, default=None
        Standard deviation of the random jitter of each ray's direction,
        radians (a stand-in for the width of the beam); None keeps the
        pattern's.
    drop : float, default=0.0
        Probability that a return is lost (dark or specular surfaces,
        weather).
    slope : float or None, default=None
        Longitudinal slope of the street (rise over run); None draws it
        between -4 and 4 %.
    random_state : int, RandomState instance or None, default=None
        Seeds the street and the scan. The street depends only on the seed,
        not on the scanner: the same seed scanned with two patterns shows
        the same street.
    n_jobs : int, default=None
        Threads casting chunks of rays; None means 1, -1 all cores. The
        result does not depend on it.

    Returns
    -------
    scene : :class:`~sklearn.utils.Bunch`
        With the fields:

        - ``points``: ndarray of shape (n_points, 3), float64.
        - ``labels``: ndarray of shape (n_points,), dtype object, the class
          name of each point (one of ``STREET_CLASSES``: "ground",
          "facade", "wire", "pole", "lamp_post", ...). An object array of
          shared str, 8 bytes per point.
        - ``instances``: ndarray of shape (n_points,), int64, the object of
          each point (an id of ``frame``), -1 for the ground.
        - ``trajectory``: ndarray of shape (n_positions, 3), the scanner
          positions (the vehicle reference point at each rotation, the
          aircraft at each scan line, the UGV sensor).
        - ``frame``: list of dict, one per instance (index = id), with
          ``id``, ``class``, ``position`` (base, or facade centre, or wire
          mid-point), ``yaw``, ``height`` and ``params`` (the shape
          parameters drawn).
        - ``ranges`` (float64), ``times`` (float64, seconds from the start
          of the survey), ``channels`` (int64: scanner, flight line or
          beam) and ``return_numbers`` (int64, the echo's number along its
          beam, from 1) of each return.
        - ``ground_height``: callable ``(x, y) -> z`` of the exact ground.
        - ``scanner``: the pattern's name and numbers used; ``street``: the
          cross-section drawn; ``primitives``: the analytic scene (dict of
          arrays ``kind, params, hit, instance, class_id, aabb``).

    See Also
    --------
    make_street_objects : Labelled objects cut from simulated scans.
    skpcd.segmentation.segment_scene : Cut a scene into segments.

    Notes
    -----
    Each ray is cast against the primitives (capped cone frustums, oriented
    boxes, ellipsoids and facade walls with window openings) listed in the
    cells of a 1 m grid that it crosses, in order, stopping at the first
    hit: occlusion is exact. Foliage clusters, car windows, fence mesh and
    window glass are hit with a probability per primitive and otherwise let
    the ray through (and with ``max_returns > 1`` the beam goes on behind
    them for further echoes). Wires are given an effective radius of 2 cm,
    because a real beam several centimetres wide returns from wires
    thinner than that; the aerial pattern adds its footprint (0.15 m) to
    every cylinder and to thin panels for the same reason, and its
    footprint, which covers several leaf clumps or mesh cells, returns an
    echo from foliage or mesh with a higher probability than a thin ray.
    What the simulation does not model (intensity, full waveform, mixed
    pixels at edges, noise points, moving objects, trajectory errors) is
    listed in the user guide, with a comparison against the DALES objects.

    Examples
    --------
    >>> from skpcd.datasets import make_street_scene
    >>> scene = make_street_scene(
    ...     20.0, scanner="ugv", scanner_params={"azimuth_step": 1.0}, random_state=0
    ... )
    >>> scene.points.shape[1], scene.points.dtype
    (3, dtype('float64'))
    >>> bool((scene.instances[scene.labels == "ground"] == -1).all())
    True
    """
    conf = resolve_pattern(
        scanner,
        scanner_params,
        max_range=max_range,
        range_noise=range_noise,
        beam_divergence=beam_divergence,
    )
    layout_rng, seed = _seeds(random_state)
    street = Street(layout_rng, length, slope)
    plan = furnish(street, layout_rng)
    scene, frame = build_scene(street, plan, layout_rng)
    traj_plan, xyz, prim, ranges, times, channels, returns = _simulate(
        street, scene, scanner, conf, seed, drop, n_jobs
    )
    return Bunch(
        points=xyz,
        labels=_CLASS_NAMES[scene["class_id"][prim]],
        instances=scene["instance"][prim],
        trajectory=traj_plan["trajectory"],
        frame=frame,
        ranges=ranges,
        times=times,
        channels=channels,
        return_numbers=returns,
        ground_height=street.ground_height,
        scanner={"pattern": scanner, **conf},
        street=_describe(street),
        primitives=scene,
    )


def _describe(street):
    return {
        "length": street.length,
        "slope": street.slope,
        "carriageway": street.carriageway,
        "parking": tuple(street.parking),
        "kerb_height": street.kerb_height,
        "kerb_width": street.kerb_width,
        "pavement": tuple(street.pavement),
        "garden": tuple(street.garden),
        "building_lines": (
            -street.line(0, "building"),
            street.line(1, "building"),
        ),
        "right_lane": street.right_lane,
    }


def _instance_boxes(scene, n_instances):
    """Bounding box of each instance's primitives, ``(n_instances, 6)``."""
    boxes = np.empty((n_instances, 6))
    boxes[:, :3], boxes[:, 3:] = np.inf, -np.inf
    inst, aabb = scene["instance"], scene["aabb"]
    keep = inst >= 0
    np.minimum.at(boxes[:, :3], inst[keep], aabb[keep, :3])
    np.maximum.at(boxes[:, 3:], inst[keep], aabb[keep, 3:])
    return boxes


def _attach_ground(obj, base_z, ground_sorted, ground_x, margin):
    """The object's points plus ground points within ``margin`` of its base."""
    if margin <= 0 or not len(ground_x):
        return obj
    base = obj[obj[:, 2] < base_z + 0.5]
    if not len(base):
        return obj
    lo, hi = base[:, :2].min(axis=0) - margin, base[:, :2].max(axis=0) + margin
    a, b = np.searchsorted(ground_x, [lo[0], hi[0]])
    cand = ground_sorted[a:b]
    cand = cand[(cand[:, 1] >= lo[1]) & (cand[:, 1] <= hi[1])]
    if not len(cand):
        return obj

    d, _ = cKDTree(base[:, :2]).query(cand[:, :2], distance_upper_bound=margin)
    return np.vstack([obj, cand[np.isfinite(d)]])


def _scanner_lane(scanner, conf, street):
    """``{side: (x0, x1)}``: the stretch of lane a scanner occupies (a
    spinning sensor's car, a mobile system's whole drive)."""
    if scanner in ("spinning", "ugv"):
        x, y = conf["position"] or (street.length / 2, street.right_lane)
        return {int(y > 0): (x - 7.0, x + 7.0)}
    if scanner == "mobile":
        lane = street.right_lane if conf["lane"] is None else conf["lane"]
        return {int(lane > 0): (-np.inf, np.inf)}
    return {}


@validate_params(
    {
        "n_per_class": [Interval(Integral, 1, None, closed="left")],
        "classes": ["array-like", None],
        "scanner": [StrOptions(set(SCAN_PATTERNS))],
        "scanner_params": [dict, None],
        "ground_margin": [Interval(Real, 0, None, closed="left")],
        "min_points": [Interval(Integral, 1, None, closed="left")],
        "segment_length": [Interval(Real, 10, None, closed="left")],
        "randomise": ["boolean"],
        "traffic": ["boolean"],
        "random_state": ["random_state"],
        "n_jobs": [Integral, None],
    },
    prefer_skip_nested_validation=True,
)
@entry_point
def make_street_objects(
    n_per_class=40,
    *,
    classes=None,
    scanner="mobile",
    scanner_params=None,
    ground_margin=0.25,
    min_points=50,
    segment_length=60.0,
    randomise=False,
    traffic=False,
    random_state=None,
    n_jobs=None,
):
    """Labelled street objects cut from simulated scans by their true instance.

    Streets ``segment_length`` metres long are laid out with objects of the
    requested classes (as many as fit, on both sides, among parked cars,
    buildings and wires) and scanned as :func:`make_street_scene` does;
    each object is then the set of returns of its instance. So the objects
    carry what a real scan gives: only the sides that face the scanner,
    shadows of what stands in front (a parked car hides the foot of a
    pole), density falling with the distance from the trajectory, foliage
    seen through. Objects with fewer than ``min_points`` returns (hidden)
    are skipped and replaced by new ones, so that each class gets
    ``n_per_class``.

    Read more in the :ref:`User Guide <simulation>`.

    Parameters
    ----------
    n_per_class : int, default=40
        Objects per class.
    classes : sequence of str or None, default=None
        The classes, among ``STREET_OBJECT_CLASSES`` (``"pole"``,
        ``"lamp_post"``, ``"street_light"``, ``"traffic_light"``,
        ``"pedestrian_signal"``, ``"traffic_sign"``, ``"tree"``, ``"car"``,
        ``"bush"``, ``"other"``, ``"fence"``, ``"person"``); None takes all
        but ``"fence"`` and ``"person"``.
    scanner : {"mobile", "aerial", "ugv", "spinning"}, default="mobile"
        The scan pattern (see :func:`make_street_scene`). With ``"ugv"``
        each street is swept once from its middle, so distant objects are
        sparse.
    scanner_params : dict or None, default=None
        Overrides of the pattern's numbers.
    ground_margin : float, default=0.25
        Ground points (road, kerb, pavement) within this horizontal
        distance of the object's own points lower than 0.5 m above its base
        are added to the object, as a segmentation leaves them at the foot
        of real objects; 0 returns the object's points only.
    min_points : int, default=50
        Objects with fewer returns are skipped.
    segment_length : float, default=60.0
        Length of each simulated street. A mobile survey drives 12 m beyond
        both ends, so that objects near the ends are seen by both scanners.
    randomise : bool, default=False
        Domain randomisation, for training on simulated objects what is
        applied to real ones: each street draws its own scanner numbers
        around the pattern's (the sensor,
        its height, where it stands or drives, its speed and angular step,
        the noise; ``scanner_params`` still fix what they name), and each
        object loses the points of its lowest 0 to 0.35 m (drawn per
        object) with the ground at its foot in half of the objects, as a
        ground filter or a labelling box cuts real objects.
    traffic : bool, default=False
        Half the cars drive in the lanes (seen from behind and ahead, as
        the traffic around a car-mounted sensor) instead of all being
        parked; the lane of the scanner is kept clear around it.
    random_state : int, RandomState instance or None, default=None
        Seeds the streets and the scans.
    n_jobs : int, default=None
        Threads casting rays; None means 1, -1 all cores.

    Returns
    -------
    clouds : list of ndarray of shape (n_points_i, 3)
        The objects, float64, in the coordinates of their street (each
        street is shifted along ``x`` after the previous one), classes
        interleaved in the order of ``classes``.
    labels : ndarray of str of shape (n_per_class * n_classes,)
        The class of each object.

    Raises
    ------
    RuntimeError
        If a class gets no visible object in five streets (small objects
        seen from the air), or fewer than ``n_per_class`` in many.

    See Also
    --------
    make_street_scene : The whole scan, with per-point truth.
    make_urban_objects : Sampled (not ray-cast) aerial-like objects.

    Examples
    --------
    >>> from skpcd.datasets import make_street_objects
    >>> clouds, labels = make_street_objects(
    ...     2, classes=["pole", "car"], scanner_params={"angular_step": 0.4},
    ...     segment_length=20.0, random_state=0,
    ... )
    >>> labels.tolist()
    ['pole', 'car', 'pole', 'car']
    """
    classes = _DEFAULT_CLASSES if classes is None else tuple(classes)
    unknown = sorted(set(classes) - set(OBJECT_CLASSES))
    if unknown or not classes:
        raise ValueError(
            f"classes must be among {list(OBJECT_CLASSES)}, got unknown {unknown}"
        )
    conf = resolve_pattern(scanner, scanner_params)
    rng = check_random_state(random_state)
    found = {c: [] for c in classes}
    n = int(n_per_class)
    max_streets = 20 + 4 * n * len(classes)
    for k in range(max_streets):
        need = {c: n - len(v) for c, v in found.items() if len(v) < n}
        if not need:
            break
        unseen = sorted(c for c in need if not found[c])
        if k >= 5 and unseen:
            raise RuntimeError(
                f"no object of {unseen} got {min_points} returns in {k} "
                f"simulated streets with the {scanner!r} pattern: lower "
                "min_points, or use another scanner"
            )
        layout_rng = np.random.RandomState(rng.randint(0, 2**31 - 1))
        seed = int(rng.randint(0, 2**31 - 1))
        street = Street(layout_rng, segment_length)
        street.drive = (-12.0, segment_length + 12.0)
        if randomise:
            conf = randomise_pattern(scanner, street, rng, scanner_params)
        # ask for a little more than needed: some will be hidden
        ask = {c: int(np.ceil(v * 1.2)) + 1 for c, v in need.items()}
        clear = _scanner_lane(scanner, conf, street) if traffic else None
        plan = furnish(street, layout_rng, wanted=ask, traffic=traffic, clear=clear)
        scene, frame = build_scene(street, plan, layout_rng)
        # only rays that can reach a wanted object (or the ground at its
        # foot) are cast: exact for those objects, and much cheaper
        wanted = np.array([e["class"] in need for e in frame])
        boxes = _instance_boxes(scene, len(frame))[wanted]
        boxes[:, :2] -= ground_margin + 0.05
        boxes[:, 3:5] += ground_margin + 0.05
        boxes[:, 2] -= 0.5
        _, xyz, prim, *_ = _simulate(
            street, scene, scanner, conf, seed, 0.0, n_jobs, interest=boxes
        )
        inst = scene["instance"][prim]
        order = np.argsort(inst, kind="stable")
        bounds = np.searchsorted(inst[order], np.arange(len(frame) + 1) - 0.5)
        ground = xyz[order[: bounds[0]]]
        ground = ground[np.argsort(ground[:, 0])]
        shift = np.array([k * (segment_length + 50.0), 0.0, 0.0])
        for entry in frame:
            cls = entry["class"]
            if cls not in need or len(found[cls]) >= n:
                continue
            i = entry["id"]
            obj = xyz[order[bounds[i] : bounds[i + 1]]]
            margin = ground_margin
            if randomise:
                obj = obj[obj[:, 2] >= entry["position"][2] + rng.uniform(0, 0.35)]
                margin = ground_margin if rng.random_sample() < 0.5 else 0.0
            if len(obj) < min_points:
                continue
            obj = _attach_ground(
                obj, entry["position"][2], ground, ground[:, 0], margin
            )
            found[cls].append(obj + shift)
    short = {c: len(v) for c, v in found.items() if len(v) < n}
    if short:
        raise RuntimeError(
            f"could not generate {n} visible objects of every class: got {short}"
        )
    clouds, labels = [], []
    for i in range(n):
        for c in classes:
            clouds.append(found[c][i])
            labels.append(c)
    return clouds, np.array(labels)
