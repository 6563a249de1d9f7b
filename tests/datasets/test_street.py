"""Simulated street scans: truth, determinism, occlusion, scan geometry."""

import numpy as np
import pytest

from skpcd.datasets import (
    SCAN_PATTERNS,
    STREET_CLASSES,
    STREET_OBJECT_CLASSES,
    make_street_objects,
    make_street_scene,
)
from skpcd.datasets._street._layout import CLASS_ID, Street
from skpcd.datasets._street._primitives import Parts, SceneArrays, rot_x, rot_z
from skpcd.datasets._street._scanners import first_hits

# coarse patterns keep the scans small; the geometry is the default one
UGV = {"azimuth_step": 0.5}
MOBILE = {"angular_step": 0.5, "rotation_rate": 100.0}


@pytest.fixture(scope="module")
def ugv_scene():
    return make_street_scene(
        40.0,
        scanner="ugv",
        scanner_params=UGV,
        range_noise=0.0,
        beam_divergence=0.0,
        random_state=7,
    )


@pytest.fixture(scope="module")
def mobile_scene():
    return make_street_scene(
        30.0,
        scanner="mobile",
        scanner_params={**MOBILE, "mount_offsets": ((0, 0, 0), (0, 0, 0))},
        range_noise=0.0,
        beam_divergence=0.0,
        slope=0.0,
        random_state=7,
    )


# ---------------------------------------------------------------------------
# truth


@pytest.mark.parametrize("name", ["ugv_scene", "mobile_scene"])
def test_truth_arrays(name, request):
    scene = request.getfixturevalue(name)
    n = len(scene.points)
    assert scene.points.shape == (n, 3) and scene.points.dtype == np.float64
    assert scene.labels.shape == scene.instances.shape == scene.ranges.shape == (n,)
    assert set(scene.labels) <= set(STREET_CLASSES)
    assert {"ground", "facade", "tree"} <= set(scene.labels)
    # -1 exactly for the ground
    np.testing.assert_array_equal(scene.instances == -1, scene.labels == "ground")
    # every instance is an entry of the frame, of the same class as its points
    ids = scene.instances[scene.instances >= 0]
    assert ids.max() < len(scene.frame)
    frame_class = np.array([f["class"] for f in scene.frame], dtype=object)
    np.testing.assert_array_equal(frame_class[ids], scene.labels[scene.instances >= 0])
    assert all(f["id"] == i for i, f in enumerate(scene.frame))
    # the ground points lie on the exact ground (kerb faces: within the kerb)
    g = scene.points[scene.labels == "ground"]
    dz = g[:, 2] - scene.ground_height(g[:, 0], g[:, 1])
    assert np.abs(dz).max() < scene.street["kerb_height"] + 1e-6
    assert np.median(np.abs(dz)) < 1e-6


def test_wires_and_classes_of_a_town_street(ugv_scene):
    classes = {f["class"] for f in ugv_scene.frame}
    assert {"wire", "traffic_light", "pedestrian_signal", "lamp_post"} <= classes
    wire = next(f for f in ugv_scene.frame if f["class"] == "wire")
    assert {"start", "end", "sag"} <= set(wire["params"])


# ---------------------------------------------------------------------------
# determinism


def test_same_seed_same_scan_and_the_street_does_not_depend_on_the_scanner():
    kw = {"scanner": "ugv", "scanner_params": {"azimuth_step": 1.0}}
    a = make_street_scene(25.0, random_state=3, **kw)
    b = make_street_scene(25.0, random_state=3, **kw)
    c = make_street_scene(25.0, random_state=4, **kw)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.instances, b.instances)
    assert len(a.points) != len(c.points) or not np.array_equal(a.points, c.points)
    air = make_street_scene(25.0, scanner="aerial", random_state=3)
    assert [f["position"] for f in air.frame] == [f["position"] for f in a.frame]


def test_threads_and_chunks_do_not_change_the_scan():
    kw = {"scanner_params": MOBILE, "random_state": 1}
    one = make_street_scene(25.0, **kw)  # two chunks of pulses
    two = make_street_scene(25.0, n_jobs=2, **kw)
    np.testing.assert_array_equal(one.points, two.points)
    np.testing.assert_array_equal(one.instances, two.instances)


# ---------------------------------------------------------------------------
# occlusion


def _segment_meets_box(o, p, lo, hi):
    """Does the segment o -> p (rows) cross the axis-aligned box [lo, hi]?"""
    d = p - o
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (lo - o) / d, (hi - o) / d
    t0 = np.nanmax(np.minimum(ta, tb), axis=1)
    t1 = np.nanmin(np.maximum(ta, tb), axis=1)
    return (t0 <= t1) & (t1 > 0) & (t0 < 1)


def test_nothing_is_seen_in_the_shadow_of_an_opaque_box():
    arrays = SceneArrays()
    arrays.add(Parts().box((20.0, 0.0, 5.0), (0.5, 20.0, 5.0)), 0, CLASS_ID["facade"])
    arrays.add(Parts().box((10.0, 0.0, 2.0), (0.5, 1.0, 1.0)), 1, CLASS_ID["car"])
    scene = arrays.pack()
    rng = np.random.default_rng(0)
    origin = np.array([0.0, 0.0, 2.0])
    target = np.column_stack(
        [np.full(4000, 19.5), rng.uniform(-6, 6, 4000), rng.uniform(0, 6, 4000)]
    )
    prim, t = first_hits(scene, np.tile(origin, (4000, 1)), target - origin)
    d = (target - origin) / np.linalg.norm(target - origin, axis=1, keepdims=True)
    pts = origin + t[:, None] * d
    wall, box = prim == 0, prim == 1
    assert wall.sum() > 3000 and box.sum() > 100
    lo, hi = np.array([9.5, -1.0, 1.0]), np.array([10.5, 1.0, 3.0])
    # no wall point has the box between it and the scanner...
    assert not _segment_meets_box(origin, pts[wall], lo, hi).any()
    # ...and every ray aimed through the box stops on it, at its front face
    aimed = _segment_meets_box(origin, target, lo, hi)
    np.testing.assert_array_equal(aimed, box)
    np.testing.assert_allclose(pts[box, 0], 9.5, atol=1e-9)
    np.testing.assert_allclose(pts[wall, 0], 19.5, atol=1e-9)


def test_far_side_of_poles_and_trunks_is_never_seen(ugv_scene):
    o = ugv_scene.trajectory[0]
    seen = 0
    for f in ugv_scene.frame:
        if f["class"] not in ("pole", "lamp_post", "street_light"):
            continue
        pts = ugv_scene.points[ugv_scene.instances == f["id"]]
        base = np.asarray(f["position"])
        low = pts[(pts[:, 2] > base[2] + 0.3) & (pts[:, 2] < base[2] + 1.5)]
        if not len(low):
            continue
        # points of the shaft face the scanner: on the near half of the pole
        toward = (o - base)[:2] / np.linalg.norm((o - base)[:2])
        assert ((low[:, :2] - base[:2]) @ toward > -0.02).all()
        seen += 1
    assert seen >= 2


def test_hit_probability_lets_part_of_the_beams_through():
    arrays = SceneArrays()
    arrays.add(Parts().box((20.0, 0.0, 5.0), (0.5, 20.0, 5.0)), 0, CLASS_ID["facade"])
    arrays.add(Parts().box((10.0, 0.0, 2.0), (0.5, 2.0, 2.0), hit=0.4), 1, 0)
    scene = arrays.pack()
    n = 5000
    target = np.column_stack([np.full(n, 10.0), np.linspace(-1, 1, n), np.full(n, 2.0)])
    origin = np.tile([0.0, 0.0, 2.0], (n, 1))
    prim, _ = first_hits(scene, origin, target - origin)
    assert abs((prim == 1).mean() - 0.4) < 0.03
    assert ((prim == 0) | (prim == 1)).all()


def test_window_openings_reveals_and_glass():
    # a 0.3 m thick wall, front face at y = 9.85, one 2 x 2 m opening
    win = (-1.0, 10.0, 2.0, 1, -1.0, 10.0, 2.0, 1)
    for glass, through in ((0.0, True), (1.0, False)):
        arrays = SceneArrays()
        arrays.add(Parts().wall((0, 10, 0), (3, 0.15, 3), win, glass=glass), 0, 1)
        scene = arrays.pack()
        prim, t = first_hits(
            scene,
            [[0, 0, 0], [0, 0, 0], [0, 0, 0]],
            [[0, 1, 0], [2.5, 10, 0], [1.0, 10, 0]],
        )
        # straight through the opening: the glass, or nothing
        assert (prim[0] == -1) == through
        if not through:
            assert t[0] == pytest.approx(10.15)
        assert t[1] == pytest.approx(np.hypot(2.5, 10) * 9.85 / 10)  # the wall
        assert t[2] == pytest.approx(np.hypot(1.0, 10))  # a reveal, at x = 1


# ---------------------------------------------------------------------------
# the intersections against a slow reference: march along the ray


def _inside(kind, geo, p):
    if kind == "cylinder":
        p0, p1, r0, r1 = geo
        axis = (p1 - p0) / np.linalg.norm(p1 - p0)
        h = (p - p0) @ axis
        radial = np.linalg.norm(p - p0 - h[:, None] * axis, axis=1)
        length = np.linalg.norm(p1 - p0)
        return (h >= 0) & (h <= length) & (radial <= r0 + (r1 - r0) * h / length)
    center, half, rot = geo
    local = (p - center) @ rot
    if kind == "box":
        return (np.abs(local) <= half).all(axis=1)
    return ((local / half) ** 2).sum(axis=1) <= 1


@pytest.mark.parametrize("kind", ["cylinder", "box", "ellipsoid"])
def test_intersections_equal_a_marching_reference(kind):
    rng = np.random.default_rng({"cylinder": 0, "box": 1, "ellipsoid": 2}[kind])
    for _ in range(3):
        center = rng.uniform(-1, 1, 3) + np.array([6.0, 0.0, 1.0])
        rot = rot_z(rng.uniform(0, 6)) @ rot_x(rng.uniform(-1, 1))
        parts = Parts()
        if kind == "cylinder":
            p0 = center - rot[:, 2] * rng.uniform(0.5, 2)
            p1 = center + rot[:, 2] * rng.uniform(0.5, 2)
            geo = (p0, p1, rng.uniform(0.1, 0.8), rng.uniform(0.05, 0.8))
            parts.cylinder(*geo)
        else:
            geo = (center, rng.uniform(0.2, 1.5, 3), rot)
            getattr(parts, kind)(*geo)
        arrays = SceneArrays()
        arrays.add(parts, 0, 0)
        n = 120
        origins = rng.uniform(-1, 1, (n, 3))
        dirs = center + rng.normal(0, 0.4, (n, 3)) - origins
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        _, t = first_hits(arrays.pack(), origins, dirs)
        step = 1e-3
        ts = np.arange(0, 11, step)
        marched = origins[:, None, :] + ts[None, :, None] * dirs[:, None, :]
        inside = _inside(kind, geo, marched.reshape(-1, 3)).reshape(n, -1)
        hit = inside.any(axis=1)
        first = ts[np.argmax(inside, axis=1)]
        assert hit.sum() > n / 8
        # the kernel's first hit lies within one marching step before the
        # reference's first inside sample
        assert (t[hit] <= first[hit] + 1e-9).all()
        assert (t[hit] >= first[hit] - step - 1e-9).all()
        # no hit where no sample is inside (but grazes thinner than a step)
        assert np.isinf(t[~hit]).mean() > 0.95


def test_terrain_profile_is_the_ground_height():
    street = Street(np.random.RandomState(0), 30.0, slope=0.03)
    arrays = SceneArrays()
    arrays.add(street.ground_parts((15.0, 15.0)), -1, 0)
    rng = np.random.default_rng(0)
    xy = np.column_stack([rng.uniform(0, 30, 500), rng.uniform(-14, 14, 500)])
    origins = np.column_stack([xy, np.full(500, 20.0)])
    prim, t = first_hits(arrays.pack(), origins, np.tile([0, 0, -1.0], (500, 1)))
    assert (prim == 0).all()
    np.testing.assert_allclose(20.0 - t, street.ground_height(xy[:, 0], xy[:, 1]))


# ---------------------------------------------------------------------------
# scan geometry


def test_ugv_rings_azimuths_and_ranges(ugv_scene):
    o = ugv_scene.trajectory[0]
    v = ugv_scene.points - o
    r = np.linalg.norm(v, axis=1)
    np.testing.assert_allclose(r, ugv_scene.ranges, rtol=1e-9)
    conf = ugv_scene.scanner
    assert ((r >= conf["min_range"]) & (r <= conf["max_range"])).all()
    el = np.rad2deg(np.arcsin(v[:, 2] / r))
    ring = np.deg2rad(np.asarray(conf["elevations"]))[ugv_scene.channels]
    np.testing.assert_allclose(np.deg2rad(el), ring, atol=1e-9)
    assert np.unique(ugv_scene.channels).size == 32
    az = np.rad2deg(np.arctan2(v[:, 1], v[:, 0])) % 360
    steps = az / conf["azimuth_step"]
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)


def test_mobile_scan_planes_angular_step_and_blind_cone(mobile_scene):
    conf = mobile_scene.scanner
    x = conf["speed"] * mobile_scene.times
    lane = mobile_scene.street["right_lane"]
    z = mobile_scene.ground_height(0.0, lane) + conf["height"]
    o = np.column_stack([x, np.full_like(x, lane), np.full_like(x, z)])
    v = mobile_scene.points - o
    r = np.linalg.norm(v, axis=1)
    np.testing.assert_allclose(r, mobile_scene.ranges, rtol=1e-7)
    assert ((r >= conf["min_range"]) & (r <= conf["max_range"])).all()
    # each scanner's returns lie in its vertical plane at +-45 degrees
    for s, psi in enumerate(conf["plane_azimuths"]):
        w = v[mobile_scene.channels == s]
        normal = np.array([-np.sin(np.deg2rad(psi)), np.cos(np.deg2rad(psi)), 0.0])
        assert np.abs(w @ normal).max() < 1e-6
        h = w @ np.array([np.cos(np.deg2rad(psi)), np.sin(np.deg2rad(psi)), 0.0])
        alpha = np.rad2deg(np.arctan2(w[:, 2], h)) % 360
        steps = alpha / conf["angular_step"]
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
    # nothing inside the cone below the scanners hidden by the vehicle
    assert (np.rad2deg(np.arccos(-v[:, 2] / r)) >= conf["blind_angle"] - 1e-6).all()
    # both sides of the street, density falling with range
    near = (r > 3) & (r < 6)
    far = (r > 12) & (r < 15)
    assert near.sum() / 3 > far.sum() / 3


def test_max_range_noise_and_drop():
    kw = {"scanner": "ugv", "scanner_params": UGV, "random_state": 2}
    short = make_street_scene(30.0, max_range=12.0, **kw)
    # the true distance is within range; the noise comes on top
    assert short.ranges.max() <= 12.0 + 6 * short.scanner["range_noise"]
    full = make_street_scene(30.0, **kw)
    dropped = make_street_scene(30.0, drop=0.3, **kw)
    assert abs(len(dropped.points) / len(full.points) - 0.7) < 0.02
    # dropping removes returns; it does not move the others
    kept = {tuple(p) for p in dropped.points[:2000]}
    assert kept <= {tuple(p) for p in full.points}
    noisy = make_street_scene(30.0, range_noise=0.05, beam_divergence=0.0, **kw)
    exact = make_street_scene(30.0, range_noise=0.0, beam_divergence=0.0, **kw)
    # the same pulses return (pulse: firing time and beam)
    key = [
        np.round(s.times * 1e7).astype(np.int64) * 64 + s.channels
        for s in (noisy, exact)
    ]
    both = np.intersect1d(key[0], key[1])
    assert len(both) > 0.99 * len(key[1])
    err = noisy.ranges[np.isin(key[0], both)] - exact.ranges[np.isin(key[1], both)]
    assert 0.045 < err.std() < 0.055


def test_aerial_density_is_dales_like():
    air = make_street_scene(60.0, scanner="aerial", random_state=0)
    g = air.points[air.labels == "ground"]
    road = (g[:, 0] > 10) & (g[:, 0] < 50) & (np.abs(g[:, 1]) < 2.5)
    density = road.sum() / (40 * 5)
    assert 20 < density < 50
    assert air.trajectory[:, 2].min() > 1000


def test_aerial_footprint_widens_thin_parts_and_porous_ones_echo_more():
    from skpcd.datasets._street._scanners import GRAIN, apply_footprint
    from skpcd.datasets._street._scene import _porous

    arrays = SceneArrays()
    arrays.add(Parts().cylinder((0, 0, 0), (0, 0, 5), 0.1), 0, CLASS_ID["pole"])
    mesh = Parts().box((5, 0, 1), (0.02, 3, 1), hit=0.3)
    arrays.add(mesh, 1, CLASS_ID["fence"])
    glass = Parts().box((10, 0, 1), (1, 2, 0.5), hit=0.5)
    arrays.add(glass, 2, CLASS_ID["car"])
    crown = Parts().ellipsoid((15, 0, 3), (1, 1, 1), hit=0.35)
    arrays.add(crown, 3, CLASS_ID["tree"])
    scene = arrays.pack()
    porous = _porous(scene)
    np.testing.assert_array_equal(porous, [False, True, False, True])
    assert apply_footprint(scene, 0.0, porous) is scene  # the mobile pattern
    wide = apply_footprint(scene, 0.15, porous)
    np.testing.assert_allclose(wide["params"][0, 6:8], 0.25)  # the pole's radii
    # the mesh panel widened across its thickness only, its box with it
    np.testing.assert_allclose(wide["params"][1, 3:6], [0.17, 3, 1])
    np.testing.assert_allclose(wide["aabb"][1], [4.83, -3, 0, 5.17, 3, 2])
    np.testing.assert_array_equal(wide["params"][2], scene["params"][2])
    # porous: an echo when any of the footprint's patches meets material
    n = np.pi * 0.15**2 / GRAIN**2
    np.testing.assert_allclose(
        wide["hit"][[1, 3]], 1 - (1 - np.array([0.3, 0.35])) ** n
    )
    assert wide["hit"][2] == 0.5 and (wide["hit"] < 1).sum() == 3  # glass as it was
    assert scene["params"][0, 6] == 0.1 and scene["hit"][1] == 0.3  # not modified


def test_aerial_channels_look_forward_and_back():
    # from a flight line right above the street, the shaft of a vertical pole
    # is seen by scan planes tilted along the track, from its front and back
    kw = {"scanner": "aerial", "beam_divergence": 0.0, "random_state": 2}
    one = {"line_offsets": (0.0,), "density": 100.0}
    sides = []
    for tilts in [(0.0,), (8.0, -8.0)]:
        air = make_street_scene(
            40.0, scanner_params={**one, "channel_tilts": tilts}, **kw
        )
        assert np.unique(air.channels).size == len(tilts)
        front = back = 0
        for f in air.frame:
            if f["class"] not in ("pole", "lamp_post", "street_light", "traffic_light"):
                continue
            x, _, z = f["position"]
            pts = air.points[air.instances == f["id"]]
            near = np.hypot(*(pts[:, :2] - f["position"][:2]).T) < 0.3  # no arms
            low = (pts[:, 2] > z + 0.5) & (pts[:, 2] < z + 0.5 * f["height"])
            shaft = pts[near & low]
            front += (shaft[:, 0] > x + 0.05).sum()
            back += (shaft[:, 0] < x - 0.05).sum()
        sides.append((front, back))
    # untilted: only the slanted sides of tapered poles
    assert min(sides[1]) > 20 and sum(sides[1]) > 3 * sum(sides[0]) + 10, sides


def test_bad_parameters():
    with pytest.raises(ValueError, match="unknown parameter"):
        make_street_scene(10.0, scanner_params={"speeed": 3.0})
    with pytest.raises(ValueError):
        make_street_scene(10.0, scanner="lidar")
    with pytest.raises(ValueError):
        make_street_objects(1, classes=["pole", "unicorn"])
    assert set(SCAN_PATTERNS) == {"mobile", "aerial", "ugv", "spinning"}


# ---------------------------------------------------------------------------
# objects

# plausible heights (top to bottom of the cloud, metres) of every class
_HEIGHTS = {
    "pole": (2.0, 11.0),
    "lamp_post": (2.5, 6.2),
    "street_light": (4.5, 13.0),
    "traffic_light": (2.4, 8.5),
    "pedestrian_signal": (2.0, 4.0),
    "traffic_sign": (1.5, 4.0),
    "tree": (2.5, 17.0),
    "car": (0.8, 2.6),
    "bush": (0.3, 2.4),
    "other": (0.3, 4.3),
    "fence": (0.6, 2.6),
    "person": (0.9, 2.0),
}


@pytest.fixture(scope="module")
def street_objects():
    return make_street_objects(
        2,
        classes=STREET_OBJECT_CLASSES,
        scanner_params=MOBILE,
        segment_length=40.0,
        random_state=0,
    )


def test_objects_of_each_class_with_plausible_heights(street_objects):
    clouds, labels = street_objects
    assert labels.tolist() == list(STREET_OBJECT_CLASSES) * 2
    for cloud, label in zip(clouds, labels):
        assert cloud.dtype == np.float64 and cloud.shape[1] == 3
        assert len(cloud) >= 50
        lo, hi = _HEIGHTS[label]
        assert lo <= np.ptp(cloud[:, 2]) <= hi, (label, np.ptp(cloud[:, 2]))


def test_objects_ground_margin_adds_only_ground_at_the_foot():
    kw = {
        "classes": ["pole", "car"],
        "scanner_params": MOBILE,
        "segment_length": 30.0,
        "random_state": 1,
    }
    bare, labels = make_street_objects(2, ground_margin=0.0, **kw)
    footed, _ = make_street_objects(2, ground_margin=0.3, **kw)
    assert labels.tolist() == ["pole", "car", "pole", "car"]
    for a, b in zip(bare, footed):
        assert len(b) >= len(a)
        np.testing.assert_array_equal(b[: len(a)], a)
        extra = b[len(a) :]
        if len(extra):
            assert extra[:, 2].max() < a[:, 2].min() + 0.5


def test_a_class_the_scanner_cannot_see_is_a_clear_error():
    # signs are too small to get 50 returns from 1300 m
    with pytest.raises(RuntimeError, match="traffic_sign"):
        make_street_objects(
            1,
            classes=["traffic_sign"],
            scanner="aerial",
            segment_length=20.0,
            random_state=0,
        )


@pytest.mark.parametrize("sensor", ["vlp16", "hdl64", "os128"])
def test_spinning_sensor_rings(sensor):
    """A spinning sensor's returns lie on its beams' cones: their elevation
    angles seen from the sensor are the sensor's, to the ray jitter."""
    from skpcd.datasets import SPINNING_SENSORS

    scene = make_street_scene(
        30.0,
        scanner="spinning",
        scanner_params={"sensor": sensor, "azimuth_step": 2.0, "beam_divergence": 0.0},
        random_state=2,
    )
    origin = scene.trajectory[0]
    d = scene.points - origin
    elevation = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
    beams = np.asarray(SPINNING_SENSORS[sensor]["elevations"])
    gap = np.abs(elevation[:, None] - beams[None, :]).min(axis=1)
    assert np.median(gap) < 0.05
    assert len(np.unique(np.abs(elevation[:, None] - beams).argmin(axis=1))) > 5


def test_randomised_objects_vary_the_scanner():
    """randomise=True draws the sensor per street: the spacing of the
    objects of one class spreads more than with one fixed sensor, and the
    lowest points are cut."""
    from skpcd.preprocessing import point_spacing

    kw = {"classes": ["car"], "scanner": "spinning", "min_points": 20, "n_jobs": 2}
    fixed, _ = make_street_objects(12, random_state=0, **kw)
    mixed, _ = make_street_objects(12, randomise=True, random_state=0, **kw)
    spread = [np.ptp(np.log([point_spacing(c) for c in s])) for s in (fixed, mixed)]
    assert spread[1] > spread[0]


def test_person_stands_on_the_pavement():
    clouds, _ = make_street_objects(
        3, classes=["person"], scanner="spinning", min_points=20, random_state=4
    )
    for cloud in clouds:
        assert 0.9 <= np.ptp(cloud[:, 2]) <= 2.0
        assert np.ptp(cloud[:, 0]) < 1.6 and np.ptp(cloud[:, 1]) < 1.6


def test_traffic_puts_cars_in_the_lanes_but_not_on_the_sensor():
    """traffic=True: some cars drive in the lanes (|y| under half the widest
    carriageway, 3.6 m), none without it; no car stands within 7 m of a
    spinning sensor in its own lane."""
    kw = {"classes": ["car"], "scanner": "spinning", "min_points": 20}
    parked, _ = make_street_objects(6, random_state=1, **kw)
    mixed, _ = make_street_objects(6, traffic=True, random_state=1, **kw)

    def in_lane(clouds):
        return sum(abs(np.median(c[:, 1])) < 3.6 - 0.9 for c in clouds)

    assert in_lane(parked) == 0 and in_lane(mixed) >= 1
    from skpcd.datasets._street._layout import Street, furnish

    street = Street(np.random.RandomState(0), 60.0)
    plan = furnish(
        street,
        np.random.RandomState(1),
        wanted={"car": 40},
        traffic=True,
        clear={0: (23.0, 37.0)},
    )
    lane_y = abs(street.right_lane)
    for cls, _, params, (x, y, _z), _rot, _yaw in plan.items:
        if cls == "car" and y < 0 and abs(abs(y) - lane_y) < 0.5:
            assert not (23.0 - params["length"] / 2 < x < 37.0 + params["length"] / 2)
