"""Files the CLI tests run the commands on, made by the tests themselves."""

import numpy as np
import pytest

from skpcd.io import write_point_cloud


def _labelled_folder(folder, n_per_class=6, random_state=1):
    """Synthetic urban objects written to ``folder``, one ``.xyz`` file
    each, with ``labels.csv``; returns the labels."""
    from skpcd.datasets import make_urban_objects

    clouds, labels = make_urban_objects(
        n_per_class=n_per_class, random_state=random_state
    )
    return write_labelled(folder, clouds, labels)


def _street_folder(folder, n_per_class=3, random_state=6):
    """Simulated objects of a car-mounted spinning sensor (cars, people)
    written as ``_labelled_folder`` does; returns the labels."""
    from skpcd.datasets import make_street_objects

    clouds, labels = make_street_objects(
        n_per_class,
        classes=["car", "person"],
        scanner="spinning",
        min_points=20,
        random_state=random_state,
    )
    return write_labelled(folder, clouds, labels)


def write_labelled(folder, clouds, labels):
    """``clouds`` written to ``folder`` one ``.xyz`` file each, with
    ``labels.csv``; returns the labels."""
    folder.mkdir(exist_ok=True)
    rows = ["file,label"]
    for i, (c, y) in enumerate(zip(clouds, labels)):
        write_point_cloud(folder / f"{i:03d}.xyz", c)
        rows.append(f"{i:03d}.xyz,{y}")
    (folder / "labels.csv").write_text("\n".join(rows))
    return labels


def _scene_file(path, n_per_class=2, random_state=0):
    """Synthetic urban objects on a terrain, written to ``path`` with an
    intensity field (the point's index); returns the points, the true
    object of each (-1: terrain) and the objects' labels."""
    from skpcd.datasets import make_urban_objects
    from skpcd.segmentation import make_scene

    clouds, labels = make_urban_objects(
        n_per_class=n_per_class, random_state=random_state
    )
    points, truth = make_scene(clouds, gap=3.0, random_state=random_state)
    write_point_cloud(path, points, fields={"intensity": np.arange(len(points))})
    return points, truth, labels


@pytest.fixture
def labelled_folder():
    """``labelled_folder(folder, n_per_class=6, random_state=1)``."""
    return _labelled_folder


@pytest.fixture
def street_folder():
    """``street_folder(folder, n_per_class=3, random_state=6)``."""
    return _street_folder


@pytest.fixture
def scene_file():
    """``scene_file(path, n_per_class=2, random_state=0)``."""
    return _scene_file
