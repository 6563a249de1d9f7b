"""Ground by the cloth simulation filter, and the structures of a street:
facades and wires as segments of their own, clusters split at trunks."""

import sys

import numpy as np
import pytest

from skpcd.segmentation import GroundFilter, segment_scene
from skpcd.segmentation._structure_kernels import local_shape


def _street(seed=0):
    """A small street: ground, a facade (30 x 8 m), a tree against it with
    a lamp post standing in its crown, a utility pole 12 m away with a wire
    from the lamp post to it, and a car. Returns points and the part of
    every point (names)."""
    rng = np.random.default_rng(seed)
    parts = {}
    g = rng.uniform([-5, -5], [35, 12], (30000, 2))
    parts["ground"] = np.column_stack([g, rng.normal(0, 0.01, len(g))])
    # facade: the plane y = 10 sampled as a scan (a 6 cm grid, jittered),
    # with 0.3 m deep recesses (windows)
    u, v = np.meshgrid(np.arange(0, 30, 0.06), np.arange(0, 8, 0.06))
    f = np.column_stack([u.ravel(), v.ravel()]) + rng.normal(0, 0.01, (u.size, 2))
    depth = np.where((f[:, 0] % 3 < 1) & (f[:, 1] % 3 > 1), 0.3, 0.0)
    parts["facade"] = np.column_stack([f[:, 0], 10 + depth, f[:, 1]])

    def cylinder(x, y, r, z0, z1, n):
        a = rng.uniform(0, 2 * np.pi, n)
        return np.column_stack(
            [x + r * np.cos(a), y + r * np.sin(a), rng.uniform(z0, z1, n)]
        )

    def ball(c, r, n):
        v = rng.normal(size=(n, 3))
        v *= (r * rng.uniform(0.6, 1.0, n) ** (1 / 3) / np.linalg.norm(v, axis=1))[
            :, None
        ]
        return v + c

    # tree 2 m from the facade, crown touching it; a lamp post in the crown
    parts["tree"] = np.vstack(
        [cylinder(10, 7.5, 0.2, 0, 3.5, 1500), ball([10, 7.8, 5.5], 2.4, 5000)]
    )
    parts["lamp"] = cylinder(11.2, 7.0, 0.08, 0, 7.5, 1500)
    parts["pole"] = cylinder(23.2, 7.0, 0.1, 0, 7.5, 1500)
    # wire from the lamp post top to the pole, sagging 0.2 m, points every 4 cm
    t = np.linspace(0, 1, 300)
    parts["wire"] = np.column_stack(
        [11.2 + 12 * t, np.full_like(t, 7.0), 7.4 - 0.8 * t * (1 - t)]
    ) + rng.normal(0, 0.005, (len(t), 3))
    parts["car"] = rng.uniform([16, 2, 0.3], [20.5, 3.8, 1.5], (3000, 3))
    names = np.concatenate([np.full(len(v), k) for k, v in parts.items()])
    return np.vstack(list(parts.values())), names


@pytest.fixture(scope="module")
def street():
    points, names = _street()
    # the structures under CSF's ground (what they were measured with)
    return points, names, segment_scene(points, ground="csf")


def test_csf_ground_filter_separates_ground_and_repeats():
    rng = np.random.default_rng(0)
    ground = np.column_stack([rng.uniform(0, 40, (4000, 2)), rng.normal(0, 0.03, 4000)])
    box = rng.uniform([10, 10, 1], [16, 16, 4], (600, 3))
    X = np.vstack([ground, box])
    filt = GroundFilter(method="csf").fit(X)
    assert filt.ground_[:4000].all() and not filt.ground_[4000:].any()
    # CSF runs on one OpenMP thread: the same flags every run
    assert np.array_equal(GroundFilter(method="csf").fit_predict(X), filt.ground_)
    # the DEM of the ground points: heights of the ground near 0
    assert np.abs(filt.height(ground)).max() < 0.2
    assert np.array_equal(filt.predict(X), filt.ground_)


def test_csf_missing_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "CSF", None)
    with pytest.raises(ImportError, match="pip install cloth-simulation-filter"):
        GroundFilter(method="csf").fit(np.random.default_rng(0).random((50, 3)))


def test_csf_fills_the_empty_parts_of_the_bounding_box():
    from skpcd.segmentation.ground._csf import _far_fill

    rng = np.random.default_rng(0)
    # a street in steps along a diagonal: most of the box is empty
    steps = []
    for i in range(6):
        xy = rng.uniform(0, 10, (3000, 2)) + 40 * i
        steps.append(np.column_stack([xy, rng.normal(0, 0.02, len(xy))]))
    box = rng.uniform([42, 42, 0.5], [46, 46, 3.0], (800, 3))
    X = np.vstack([*steps, box])
    shifted = X - X.min(axis=0)
    fill = _far_fill(shifted, 1.0)
    assert len(fill) > 10_000  # the empty cells far from the points
    assert np.abs(fill[:, 2] - shifted[:18000, 2].min()).max() < 0.2
    g = GroundFilter(method="csf").fit_predict(X)
    assert g[:18000].mean() > 0.99 and not g[18000:].any()
    # a compact scene gets no fill: CSF's own answer
    assert len(_far_fill(shifted[:3000], 1.0)) == 0


def test_tiles_take_csf_and_structures():
    # the tiled path runs the in-memory defaults (CSF through one cloth for
    # the whole scan, the structures step): test_tiling_street.py compares
    # the answers; here, the options are accepted and chosen alike
    X = np.random.default_rng(0).random((100, 3)) * [30.0, 30.0, 0.1]
    tiled = segment_scene(X, ground="csf", tile_size=10.0, structures=False)
    whole = segment_scene(X, ground="csf", structures=False)
    assert np.array_equal(tiled.ground, whole.ground)
    auto = segment_scene(X, tile_size=10.0, structures=False).ground_filter
    assert auto == segment_scene(X, structures=False).ground_filter
    seg = segment_scene(X, ground="aerial", tile_size=10.0)
    assert len(seg.kinds) == seg.n_segments
    with pytest.raises(ValueError, match="unknown structures"):
        segment_scene(X, structures={"wire_height": 5.0})
    with pytest.raises(ValueError, match="denoise"):
        segment_scene(X, tile_size=10.0, denoise="radius")


def test_local_shape_equals_numpy():
    rng = np.random.default_rng(0)
    xyz = rng.normal(size=(200, 3)) * [3.0, 1.0, 0.2]
    xyz[:50] = np.column_stack([np.linspace(0, 5, 50), np.zeros(50), np.zeros(50)])
    xyz[:50, 0] += 100.0  # a line, away from the cloud
    xyz[:50] += rng.normal(0, 1e-3, (50, 3))
    from skpcd.preprocessing import compute_neighborhoods

    nb = compute_neighborhoods(xyz, n_neighbors=10)
    out = [np.empty(len(xyz), dtype=np.float32) for _ in range(4)]
    out.insert(2, np.empty((len(xyz), 3), dtype=np.float32))
    local_shape(xyz, nb.indptr, nb.indices, *out)
    for i in range(len(xyz)):
        pts = xyz[nb.indices[nb.indptr[i] : nb.indptr[i + 1]]]
        w, v = np.linalg.eigh(np.cov(pts.T, bias=True))
        l3, l2, l1 = w
        np.testing.assert_allclose(out[0][i], (l1 - l2) / l1, atol=1e-4)
        np.testing.assert_allclose(out[1][i], (l2 - l3) / l1, atol=1e-4)
        np.testing.assert_allclose(abs(out[2][i] @ v[:, 0]), 1.0, atol=2e-3)
        np.testing.assert_allclose(out[3][i], abs(v[2, 2]), atol=2e-3)
        np.testing.assert_allclose(out[4][i], np.sqrt(max(l2, 0)), atol=1e-5)
    assert out[0][:50].min() > 0.95  # the line is linear


def _main_segment(seg, names, part):
    lab = seg.labels[names == part]
    values, counts = np.unique(lab[lab >= 0], return_counts=True)
    return values[counts.argmax()], counts.max() / len(lab)


def test_facade_and_wire_are_their_own_segments(street):
    _, names, seg = street
    assert seg.ground[names == "ground"].mean() > 0.99
    facade, share = _main_segment(seg, names, "facade")
    assert seg.kinds[facade] == "facade" and share > 0.95
    wire, share = _main_segment(seg, names, "wire")
    assert seg.kinds[wire] == "wire" and share > 0.8
    # little else in them
    assert (names[seg.labels == facade] == "facade").mean() > 0.97
    assert (names[seg.labels == wire] == "wire").mean() > 0.9
    # the tree touching the facade is an object (without the facade); the
    # crown points nearer the lamp post than the trunk go with the post
    tree, share = _main_segment(seg, names, "tree")
    assert seg.kinds[tree] == "object" and share > 0.6
    assert (names[seg.labels == tree] == "tree").mean() > 0.95


def test_pole_in_the_crown_and_the_far_pole_are_split(street):
    _, names, seg = street
    tree, _ = _main_segment(seg, names, "tree")
    lamp, lamp_share = _main_segment(seg, names, "lamp")
    pole, pole_share = _main_segment(seg, names, "pole")
    assert len({tree, lamp, pole}) == 3
    assert lamp_share > 0.9 and pole_share > 0.9
    # the pole and the lamp post are whole (the wire is its own segment)
    assert (names[seg.labels == pole] == "pole").mean() > 0.99
    car, share = _main_segment(seg, names, "car")
    assert share > 0.9 and car not in (tree, lamp, pole)


def test_without_structures_the_touching_objects_merge(street):
    points, names, _ = street
    seg = segment_scene(points, structures=False)
    assert set(seg.kinds) == {"object"}
    tree, _ = _main_segment(seg, names, "tree")
    facade, _ = _main_segment(seg, names, "facade")
    lamp, _ = _main_segment(seg, names, "lamp")
    pole, _ = _main_segment(seg, names, "pole")
    assert tree == facade == lamp == pole  # one segment through the wire


def test_structure_parameters_are_metres(street):
    points, names, _ = street
    # a facade taller than the 8 m wall: none found, the wall is an object
    seg = segment_scene(points, structures={"facade_min_height": 9.0})
    assert "facade" not in set(seg.kinds)
    facade, _ = _main_segment(seg, names, "facade")
    assert seg.kinds[facade] == "object"
