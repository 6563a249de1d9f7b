"""Far outliers do not move the automatic parameters (issue 29 item 13).

One point 100 km above a real sweep used to change the automatic eps from
0.5 to 3 m (2.5e25 m for a point at 1e30) and the segments of every other
point. Now a real sweep with one or a few points 100 m, 100 km or 1e30 m
away keeps its automatic eps, its scan kind and its segments; the far
points end as noise. (The ground filter is not in these tests: CSF moves
with a point 1 km above the sweep, 66 of its 115,384 ground flags.)
"""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from skpcd.exceptions import SegmentationWarning
from skpcd.segmentation import (
    GROUND_PRESETS,
    GroundFilter,
    describe_scan,
    estimate_eps,
    segment_scene,
)
from skpcd.segmentation._dbscan import kdist_mean, sample_queries, stable_draw
from skpcd.segmentation._scene import _radius_of_kind

AUTZEN = Path(__file__).parents[1] / "data" / "las" / "autzen_trim.laz"


def read_sweep(path):
    import laspy

    f = laspy.read(path)
    return np.column_stack([f.x, f.y, f.z])


@pytest.fixture(scope="module")
def sweep(real_sweeps):
    """A KITTI sweep (115,384 points: more than the eps estimate samples)."""
    return read_sweep(next(p for p in real_sweeps if p.name.startswith("kitti")))


def far_points(xyz, case):
    """Points far above the sweep (within its horizontal extent)."""
    x, y, z = np.median(xyz, axis=0)
    heights = {
        "100 m": [100.0],
        "1 km": [1e3],
        "100 km": [1e5],
        "1e30": [1e30],
        "a few": [100.0, 1e3, 1e5, 1e30],
    }[case]
    return np.array([[x + i, y - 2 * i, z + h] for i, h in enumerate(heights)])


CASES = ["100 m", "1 km", "100 km", "1e30", "a few"]


def test_the_draw_keeps_its_points_when_points_are_appended():
    for n, size in [(10_000, 3_000), (115_384, 100_000), (50, 50)]:
        before = stable_draw(n, size, np.random.default_rng(0))
        after = stable_draw(n + 3, size, np.random.default_rng(0))
        assert len(np.unique(before)) == size and before.max() < n
        # at most the 3 appended points come in, and as many others go out
        assert len(np.setdiff1d(before, after)) <= 3
        assert np.setdiff1d(after, before).min(initial=n) >= n
        # drawn chunk by chunk (memory O(size + chunk)), the same draw
        chunked = stable_draw(n + 3, size, np.random.default_rng(0), chunk=1000)
        np.testing.assert_array_equal(chunked, after)
        rows = sample_queries(n + 3, size, 0)
        assert np.all(np.diff(rows) > 0)
        assert len(np.setdiff1d(sample_queries(n, size, 0), rows)) <= 3


def test_every_point_of_a_real_sweep_counts_in_the_curve(sweep):
    dist, _ = cKDTree(sweep).query(sweep[::4], k=31, workers=2)
    dist = dist[:, 1:]
    np.testing.assert_array_equal(kdist_mean(dist), dist.mean(axis=0))
    # a far point's row is left out: the curve is that of the sweep alone
    far = np.vstack([dist, np.full((1, 30), 1e30), np.linspace(1e5, 2e5, 30)])
    np.testing.assert_allclose(kdist_mean(far), dist.mean(axis=0), rtol=1e-12)


@pytest.mark.parametrize("case", CASES)
def test_far_points_leave_the_eps_and_the_scan_kind(sweep, case):
    # was: eps 0.50 -> 3.0 m for a point 100 km up, 2.5e25 m at 1e30
    with_far = np.vstack([sweep, far_points(sweep, case)])
    eps = estimate_eps(sweep, random_state=0)
    assert estimate_eps(with_far, random_state=0) == pytest.approx(eps, rel=2e-3)
    alone, far = (describe_scan(p, random_state=0) for p in (sweep, with_far))
    assert far.kind == alone.kind == "spinning"
    # the position the sweep turns around, which sets its relative radius
    assert far.centre == pytest.approx(alone.centre, abs=1e-9)
    assert far.concentration == pytest.approx(alone.concentration, abs=0.005)
    assert far.vertical == pytest.approx(alone.vertical, abs=0.005)


@pytest.fixture(scope="module")
def sweep_ground(sweep):
    """The ground of the sweep as ``segment_scene`` finds it (the street
    preset of its kind)."""
    return GroundFilter(**GROUND_PRESETS["street"]).fit_predict(sweep)


def test_far_points_leave_the_radii_of_the_sweep(sweep, sweep_ground):
    # the radius and the relative radius (in sweep coordinates, where a
    # point above the sensor's position lands as far as its height) that
    # segment_scene takes from the kind of the scan
    clustering = {"eps_scale": 2.5, "random_state": 0, "n_jobs": None}
    far = far_points(sweep, "a few")
    with_far = np.vstack([sweep, far])
    ground = np.r_[sweep_ground, np.zeros(len(far), dtype=bool)]
    alone = _radius_of_kind(
        sweep, sweep_ground, describe_scan(sweep, random_state=0), clustering
    )
    found = _radius_of_kind(
        with_far, ground, describe_scan(with_far, random_state=0), clustering
    )
    assert found == alone


def test_far_points_end_as_noise_and_leave_the_segments(sweep, sweep_ground):
    rest = sweep[~sweep_ground]
    kw = {"ground": None, "structures": False, "random_state": 0}
    alone = segment_scene(rest, **kw)
    seg = segment_scene(np.vstack([rest, far_points(sweep, "a few")]), **kw)
    assert seg.eps == alone.eps
    np.testing.assert_array_equal(seg.labels[: len(rest)], alone.labels)
    assert (seg.labels[len(rest) :] == -1).all()


@pytest.mark.parametrize("height", [1e5, 1e30])
def test_a_point_far_above_an_airborne_tile_leaves_its_segments(height):
    # PDAL's autzen tile: was eps 8.25 -> 13.4 m and 16 -> 7 segments with a
    # point 100 km up, eps 6.4e24 m and 2 segments with one at 1e30
    from skpcd.io import read_point_cloud

    xyz = np.asarray(read_point_cloud(AUTZEN))[:, :3]
    x, y, z = np.median(xyz, axis=0)
    with pytest.warns(SegmentationWarning, match="automatic eps") as alone_warns:
        alone = segment_scene(xyz, random_state=0)
    with pytest.warns(SegmentationWarning, match="automatic eps") as far_warns:
        seg = segment_scene(np.vstack([xyz, [[x, y, z + height]]]), random_state=0)
    assert seg.scan.kind == alone.scan.kind == "airborne"
    assert seg.eps == alone.eps and seg.n_segments == alone.n_segments
    np.testing.assert_array_equal(seg.labels[:-1], alone.labels)
    assert seg.labels[-1] == -1
    assert str(far_warns[0].message) == str(alone_warns[0].message)


def sparse_tile(n=6000, side=300.0, seed=0):
    """Points scattered over a wide tile a metre or two up: the automatic
    radius follows their spacing and joins them all."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0, side, (n, 2)), rng.uniform(1, 3, n)])


def test_a_far_point_leaves_the_check_of_a_joining_eps(recwarn):
    # the check compares the largest segment with the scene's extent: one
    # point 100 km away made the scene so wide that the check never fired
    xyz = sparse_tile()
    kw = {"ground": None, "structures": False, "min_cluster_size": 5}
    with pytest.warns(SegmentationWarning, match="automatic eps") as alone_warns:
        alone = segment_scene(xyz, **kw)
    far = np.vstack([xyz, [[1e5, 150.0, 2.0]]])
    with pytest.warns(SegmentationWarning, match="automatic eps") as far_warns:
        seg = segment_scene(far, **kw)
    assert seg.eps == alone.eps
    np.testing.assert_array_equal(seg.labels[:-1], alone.labels)
    assert seg.labels[-1] == -1
    # the scene's extent in the message is that of the tile, not 100 km
    assert str(far_warns[0].message) == str(alone_warns[0].message)
