import numpy as np
import pytest

from skpcd.datasets import URBAN_CLASSES, make_point_clouds, make_urban_objects


def test_urban_objects_reproducible_and_balanced():
    a, ya = make_urban_objects(n_per_class=5, random_state=3)
    b, yb = make_urban_objects(n_per_class=5, random_state=3)
    assert len(a) == 25 and (ya == yb).all()
    assert all(np.array_equal(u, v) for u, v in zip(a, b))
    assert {k: int((ya == k).sum()) for k in URBAN_CLASSES} == dict.fromkeys(
        URBAN_CLASSES, 5
    )
    c, _ = make_urban_objects(n_per_class=5, random_state=4)
    assert not np.array_equal(a[0], c[0])


def test_urban_objects_have_plausible_sizes():
    clouds, labels = make_urban_objects(n_per_class=10, random_state=0)
    height = {
        k: [np.ptp(c[:, 2]) for c, y in zip(clouds, labels) if y == k]
        for k in URBAN_CLASSES
    }
    assert max(height["car"]) < 2.5
    assert min(height["pole"]) > 3.5
    assert max(height["fence"]) < 2.7
    assert all(len(c) >= 20 for c in clouds)


def test_urban_objects_noise_free():
    clouds, labels = make_urban_objects(n_per_class=1, noise=0, random_state=0)
    assert all(np.isfinite(c).all() for c in clouds)
    # without noise the car roof (cabin) is exactly flat at the box height
    car = clouds[labels.tolist().index("car")]
    top = np.isclose(car[:, 2], car[:, 2].max())
    assert top.sum() > 10


@pytest.mark.parametrize("bad", [{"n_per_class": 0}, {"noise": -1}])
def test_urban_objects_bad_params(bad):
    with pytest.raises(ValueError):
        make_urban_objects(**bad)


def test_make_point_clouds_shapes():
    clouds = make_point_clouds(5, n_points=(10, 12), n_columns=4, random_state=0)
    assert len(clouds) == 5
    assert all(10 <= len(c) <= 12 and c.shape[1] == 4 for c in clouds)
    assert all(len(c) == 7 for c in make_point_clouds(3, n_points=7, random_state=0))
    with pytest.raises(ValueError):
        make_point_clouds(2, n_columns=2)


@pytest.mark.parametrize("n_columns", [6, 8])
def test_make_point_clouds_columns_3_to_5_are_unit_normals(n_columns):
    """With 6 or more columns, columns 3-5 are the surface's unit normals (the
    descriptors read them as given normals); further columns are noise."""
    from skpcd.features import PFHTransformer
    from skpcd.preprocessing import estimate_normals

    clouds = make_point_clouds(4, n_columns=n_columns, noise=0.0, random_state=0)
    for c in clouds:
        assert c.shape[1] == n_columns
        np.testing.assert_allclose(np.linalg.norm(c[:, 3:6], axis=1), 1.0, atol=1e-12)
        # the normals of the (noise-free) surface: the estimate's axis
        estimated, _ = estimate_normals(c, n_neighbors=10)
        cos = np.abs(np.sum(estimated * c[:, 3:6], axis=1))
        assert np.median(cos) > 0.99
        assert ((c[:, 6:] >= 0) & (c[:, 6:] < 1)).all()
    # accepted as given normals by default
    rows = PFHTransformer(pooling="mean").fit_transform(clouds)
    assert rows.shape == (4, 125) and np.isfinite(rows).all()
    # the xyz columns do not depend on n_columns
    plain = make_point_clouds(4, noise=0.0, random_state=0)
    np.testing.assert_array_equal(plain[0], clouds[0][:, :3])


def test_make_primitives_shapes_sizes_and_seed():
    from skpcd.datasets import PRIMITIVES, make_primitives

    clouds, labels = make_primitives(3, n_points=(100, 200), random_state=0)
    assert len(clouds) == 18 and sorted(set(labels)) == sorted(PRIMITIVES)
    assert all(100 <= len(c) <= 200 and c.shape[1] == 3 for c in clouds)
    again, _ = make_primitives(3, n_points=(100, 200), random_state=0)
    assert all(np.array_equal(a, b) for a, b in zip(clouds, again))
    # noiseless spheres lie on a sphere, cylinders have a constant radius
    clouds, labels = make_primitives(
        2, shapes=["sphere", "plane"], noise=0.0, random_state=1
    )
    sphere = clouds[0] - clouds[0].mean(axis=0)
    r = np.linalg.norm(sphere, axis=1)
    assert r.std() < 0.05 * r.mean()
    plane = clouds[1] - clouds[1].mean(axis=0)
    assert np.linalg.svd(plane, compute_uv=False)[2] < 1e-9
    with pytest.raises(ValueError, match="unknown shapes"):
        make_primitives(1, shapes=["torus"])
    with pytest.raises(ValueError, match="n_per_shape"):
        make_primitives(0)


def test_load_dales_objects_reads_the_folder(dales_dir, monkeypatch):
    from skpcd.datasets import load_dales_objects

    monkeypatch.delenv("SKPCD_DALES_DIR", raising=False)
    objects = load_dales_objects(dales_dir)
    assert objects.source == "DALES objects" and objects.folder == dales_dir
    assert len(objects.data) == len(objects.target) == len(objects.filenames) > 300
    assert set(objects.target) == set(URBAN_CLASSES)
    assert all(c.ndim == 2 and c.shape[1] == 3 for c in objects.data)
    # the environment variable names the same folder
    monkeypatch.setenv("SKPCD_DALES_DIR", str(dales_dir))
    clouds, labels = load_dales_objects(return_X_y=True)
    assert (labels == objects.target).all()
    assert all(np.array_equal(a, b) for a, b in zip(clouds, objects.data))


def test_load_dales_objects_missing(tmp_path, monkeypatch):
    from skpcd.datasets import load_dales_objects
    from skpcd.exceptions import MissingFileError

    monkeypatch.delenv("SKPCD_DALES_DIR", raising=False)
    with pytest.raises(MissingFileError, match="SKPCD_DALES_DIR"):
        load_dales_objects()
    with pytest.raises(MissingFileError, match=r"labels\.csv"):
        load_dales_objects(tmp_path)
    objects = load_dales_objects(tmp_path, synthetic_if_missing=True, n_per_class=3)
    assert objects.source == "synthetic urban objects" and objects.folder is None
    expected, labels = make_urban_objects(n_per_class=3, random_state=0)
    assert (objects.target == labels).all()
    assert all(np.array_equal(a, b) for a, b in zip(objects.data, expected))
