import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.datasets import make_urban_objects
from skpcd.features import ShapeFeatures, shape_features

NAMES = list(ShapeFeatures().get_feature_names_out())


def _f(points, name):
    return shape_features(points)[NAMES.index(name)]


def test_box_dimensions_and_oriented_footprint():
    rng = np.random.default_rng(0)
    pts = rng.uniform([0, 0, 0], [10, 2, 3], size=(5000, 3))
    angle = 0.7
    rot = np.array(
        [
            [np.cos(angle), -np.sin(angle), 0],
            [np.sin(angle), np.cos(angle), 0],
            [0, 0, 1],
        ]
    )
    f = shape_features(pts @ rot.T + [100, 200, 5])
    got = dict(zip(NAMES, f))
    # PCA axes of a uniform box are estimated, hence a few centimetres
    assert abs(got["length"] - 10) < 0.1 and abs(got["width"] - 2) < 0.1
    assert abs(got["height"] - 3) < 0.01
    assert abs(got["box_volume"] - 60) < 3
    assert abs(got["log10_n_points"] - np.log10(5000)) < 1e-12


def test_line_plane_volume_eigen_features():
    rng = np.random.default_rng(1)
    line = np.column_stack([np.zeros(500), np.zeros(500), rng.uniform(0, 10, 500)])
    plane = np.column_stack(
        [rng.uniform(0, 10, 500), rng.uniform(0, 10, 500), np.zeros(500)]
    )
    ball = rng.normal(size=(500, 3))
    assert _f(line, "linearity") > 0.99 and _f(line, "main_axis_verticality") > 0.99
    assert _f(plane, "planarity") > 0.8 and _f(plane, "scattering") < 1e-12
    assert _f(plane, "normal_verticality") > 0.99
    assert _f(ball, "scattering") > 0.7


def test_degenerate_segments_give_finite_values():
    for pts in (np.zeros((1, 3)), np.zeros((5, 3)), np.array([[0, 0, 0], [1, 0, 0.0]])):
        f = shape_features(pts)
        assert np.isfinite(f).all()


@settings(max_examples=25, deadline=None)
@given(
    angle=st.floats(0, 2 * np.pi),
    shift=st.tuples(*[st.floats(-1e4, 1e4)] * 3),
    seed=st.integers(0, 2**16),
)
def test_invariant_to_z_rotation_translation_and_order(angle, shift, seed):
    clouds, _ = make_urban_objects(n_per_class=1, random_state=seed % 50)
    pts = clouds[seed % 5]
    rot = np.array(
        [
            [np.cos(angle), -np.sin(angle), 0],
            [np.sin(angle), np.cos(angle), 0],
            [0, 0, 1],
        ]
    )
    moved = (pts @ rot.T + shift)[np.random.default_rng(seed).permutation(len(pts))]
    np.testing.assert_allclose(
        shape_features(moved), shape_features(pts), rtol=1e-6, atol=1e-6
    )


def test_transformer_matches_function_and_separates_classes():
    clouds, labels = make_urban_objects(n_per_class=5, random_state=0)
    F = ShapeFeatures().fit_transform(clouds)
    assert F.shape == (25, len(NAMES))
    np.testing.assert_array_equal(F[3], shape_features(clouds[3]))
    height = F[:, NAMES.index("height")]
    assert height[labels == "car"].max() < height[labels == "pole"].min()


@pytest.mark.slow
def test_real_dales_objects_classified_well(dales):
    from sklearn.model_selection import StratifiedKFold, cross_val_score

    from skpcd.classification import make_default_pipeline

    clouds, labels, _ = dales
    scores = cross_val_score(
        make_default_pipeline(n_jobs=2),
        clouds,
        labels,
        cv=StratifiedKFold(5, shuffle=True, random_state=0),
    )
    # global shape features reach about 0.97 on these objects
    assert scores.mean() > 0.93
