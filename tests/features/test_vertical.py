import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.features import VerticalProfile, vertical_features

NAMES = list(VerticalProfile().get_feature_names_out())


def _pole(rng, height=6.0, radius=0.1, n=800, one_sided=False):
    """Points on the surface of a vertical cylinder at the origin."""
    span = np.pi if one_sided else 2 * np.pi
    angle = rng.uniform(0, span, n)
    z = rng.uniform(0, height, n)
    return np.c_[radius * np.cos(angle), radius * np.sin(angle), z]


def _arm(rng, length, z, direction, n=300):
    """A thin horizontal arm leaving the axis at height z."""
    t = rng.uniform(0.0, length, n)
    ux, uy = np.cos(direction), np.sin(direction)
    return np.c_[t * ux, t * uy, z + rng.normal(0, 0.02, n)]


def _street_light(rng, arms=(0.0,), height=8.0, length=2.0):
    parts = [_pole(rng, height)]
    parts += [_arm(rng, length, height - 0.3, a) for a in arms]
    return np.vstack(parts)


def _features(points, **kw):
    return dict(zip(NAMES, vertical_features(points, **kw)))


def test_names_match_columns():
    for n_slices in (1, 4, 10):
        est = VerticalProfile(n_slices=n_slices)
        names = est.get_feature_names_out()
        X = est.fit_transform([np.random.default_rng(0).random((30, 3))])
        assert X.shape == (1, len(names)) == (1, 26 + 4 * n_slices)
        assert len(set(names)) == len(names)


def test_bare_pole():
    f = _features(_pole(np.random.default_rng(0)))
    assert f["height"] == pytest.approx(6.0, abs=0.02)
    # the outer radius of a cylinder seen all round is its radius
    assert f["trunk_radius_outer"] == pytest.approx(0.1, abs=0.02)
    assert f["trunk_lean"] < 0.03
    # nothing wider than the trunk: the pole is the whole height, no head
    assert f["pole_height_ratio"] == 1.0
    assert f["head_share"] == 0.0 and f["head_reach"] == 0.0
    shares = [f[f"slice{i}_share"] for i in range(10)]
    assert sum(shares) == pytest.approx(1.0)
    assert min(shares) > 0.07
    # thin slices of a pole: a small horizontal spread, mostly vertical
    assert max(f[f"slice{i}_spread"] for i in range(10)) < 0.1
    # 0.6 m slices of a 0.1 m cylinder: var z 0.03, var xy 0.01
    assert min(f[f"slice{i}_verticality"] for i in range(10)) > 0.65


def test_leaning_pole():
    pole = _pole(np.random.default_rng(1))
    pole[:, 0] += 0.05 * pole[:, 2]  # 5 cm per metre
    assert _features(pole)["trunk_lean"] == pytest.approx(0.05, abs=0.005)


def test_one_sided_arm_against_two_arms():
    rng = np.random.default_rng(2)
    one = _features(_street_light(rng, arms=(0.3,)))
    two = _features(_street_light(rng, arms=(0.3, 0.3 + np.pi)))
    for f in (one, two):
        # the pole ends where the arms start, the head reaches their tips
        assert f["pole_height"] == pytest.approx(7.7, abs=0.1)
        assert 1.75 < f["head_reach"] < 2.05  # 95th percentile of the arm
        assert f["head_extent_z"] < 0.4
    assert one["head_asymmetry"] > 0.95
    assert two["head_asymmetry"] < 0.15
    assert one["head_offset"] > 0.5 > two["head_offset"]
    # the top slice holds the arm: wide and offset for one arm only
    assert one["slice9_offset"] > 0.3 > two["slice9_offset"]
    assert one["slice9_spread"] > 0.5 and two["slice9_spread"] > 0.5


def test_plate_on_a_short_pole():
    """A traffic sign: a 0.6 m plate on a 2.5 m pole, seen from one side."""
    rng = np.random.default_rng(3)
    pole = _pole(rng, height=2.5, radius=0.04, one_sided=True)
    plate = np.c_[
        rng.uniform(-0.3, 0.3, 400), np.full(400, 0.06), rng.uniform(1.9, 2.5, 400)
    ]
    f = _features(np.vstack([pole, plate]))
    assert f["pole_height"] == pytest.approx(1.9, abs=0.1)
    # twice the standard deviation across the plate (0.35 m), a little
    # less with the pole's top among the head's points
    assert 0.25 < f["head_length"] < 0.4
    assert f["head_width"] < 0.05  # a plate: no depth
    assert f["head_planarity"] > 0.5


def test_clutter_at_the_foot_leaves_the_trunk_alone():
    rng = np.random.default_rng(4)
    pole = _pole(rng, height=6.0, radius=0.12)
    ground = np.c_[rng.uniform(-1, 1, (300, 2)), rng.uniform(0, 0.1, 300)]
    clean, cluttered = _features(pole), _features(np.vstack([pole, ground]))
    for name in ("trunk_radius_outer", "trunk_radius_inner", "pole_height"):
        assert cluttered[name] == pytest.approx(clean[name], abs=0.03)
    assert cluttered["head_share"] == 0.0


def test_degenerate_segments_give_finite_values():
    clouds = [
        np.zeros((1, 3)),
        np.zeros((5, 3)),
        np.array([[0, 0, 0], [1, 0, 0.0]]),
        np.array([[0, 0, 0], [0, 0, 1.0]]),
        np.c_[np.random.default_rng(0).random((50, 2)), np.zeros(50)],
    ]
    X = VerticalProfile().fit_transform(clouds)
    assert np.isfinite(X).all()
    # one point: no height, no spread, no head
    one = dict(zip(NAMES, X[0]))
    assert one["height"] == one["reach"] == one["head_share"] == 0.0
    assert one["slice0_share"] == 1.0 and one["slice0_spread"] == 0.0


def _random_object(seed):
    """A pole with random arms, a head or a crown, noise and ground clutter."""
    rng = np.random.default_rng(seed)
    height = rng.uniform(1.5, 10)
    parts = [_pole(rng, height, rng.uniform(0.03, 0.3), n=rng.integers(20, 400))]
    for _ in range(rng.integers(0, 3)):
        z = rng.uniform(0.5, 1.0) * height
        parts.append(_arm(rng, rng.uniform(0.3, 3), z, rng.uniform(0, 6.3), n=50))
    if rng.random() < 0.5:
        parts.append(rng.normal([0, 0, height], rng.uniform(0.1, 2), (100, 3)))
    parts.append(np.c_[rng.uniform(-0.5, 0.5, (30, 2)), rng.uniform(0, 0.2, 30)])
    return np.vstack(parts)


@settings(max_examples=20, deadline=None)
@given(
    angle=st.floats(0, 2 * np.pi),
    shift=st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4), st.floats(-100, 100)),
    seed=st.integers(0, 2**16),
)
def test_invariant_to_z_rotation_translation_and_order(angle, shift, seed):
    pts = _random_object(seed)
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    order = np.random.default_rng(seed).permutation(len(pts))
    ref = vertical_features(pts)
    np.testing.assert_allclose(vertical_features(pts @ rot.T), ref, atol=1e-7)
    np.testing.assert_allclose(vertical_features(pts + shift), ref, atol=1e-7)
    np.testing.assert_allclose(vertical_features(pts[order]), ref, atol=1e-9)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**16), angle=st.floats(0, 2 * np.pi))
def test_invariant_at_utm_coordinates(seed, angle):
    pts = _random_object(seed)
    c, s = np.cos(angle), np.sin(angle)
    moved = pts @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    far = moved + np.array([5e5, 4.2e6, 0.0])
    ref = vertical_features(pts)
    np.testing.assert_allclose(vertical_features(far), ref, atol=1e-6)


def test_transformer_matches_function_and_keeps_extra_columns_out():
    rng = np.random.default_rng(5)
    clouds = [_random_object(k) for k in range(3)]
    with_intensity = [np.c_[c, rng.random(len(c))] for c in clouds]
    X = VerticalProfile(n_slices=6).fit_transform(with_intensity)
    for row, c in zip(X, clouds):
        np.testing.assert_array_equal(row, vertical_features(c, n_slices=6))


def test_separates_street_furniture_kinds():
    """Bare poles, street lights and signs fall apart on a few features."""
    rng = np.random.default_rng(6)
    light = _features(_street_light(rng, arms=(1.0,)))
    bare = _features(_pole(rng, height=8.0))
    assert light["head_reach"] > 1.5 > bare["head_reach"]
    assert light["pole_height_ratio"] < 1.0 == bare["pole_height_ratio"]
