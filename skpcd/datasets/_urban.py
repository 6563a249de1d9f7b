"""Synthetic aerial-LiDAR objects of the five DALES object classes.

This is the embedded default dataset of skpcd: it is generated, not
downloaded, so examples and the ``skpcd evaluate`` command run anywhere.
"""

import numpy as np
from sklearn.utils import check_random_state

__all__ = ["URBAN_CLASSES", "make_urban_objects"]

URBAN_CLASSES = ("building", "car", "fence", "pole", "tree")


def _rotate_z(points, angle):
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return points @ rot.T


def _box_surface(rng, n, length, width, height, top_share):
    """Points on the top and the four walls of a box standing on z=0."""
    n_top = rng.binomial(n, top_share)
    top = np.column_stack(
        [
            rng.uniform(-length / 2, length / 2, n_top),
            rng.uniform(-width / 2, width / 2, n_top),
            np.full(n_top, height),
        ]
    )
    n_wall = n - n_top
    # walls in proportion to their area
    side = rng.uniform(0, 2 * (length + width), n_wall)
    x = np.where(side < length, side - length / 2, 0.0)
    y = np.zeros(n_wall)
    a = side < length
    b = (side >= length) & (side < length + width)
    c = (side >= length + width) & (side < 2 * length + width)
    d = side >= 2 * length + width
    x[a], y[a] = side[a] - length / 2, -width / 2
    x[b], y[b] = length / 2, side[b] - length - width / 2
    x[c], y[c] = side[c] - length - width - length / 2, width / 2
    x[d], y[d] = -length / 2, side[d] - 2 * length - width - width / 2
    walls = np.column_stack([x, y, rng.uniform(0, height, n_wall)])
    return np.vstack([top, walls])


def _building(rng):
    length, width = rng.uniform(8, 30), rng.uniform(6, 18)
    height = rng.uniform(3.5, 15)
    n = int(rng.uniform(4, 12) * length * width)
    pts = _box_surface(rng, n, length, width, height, top_share=0.85)
    roof = pts[:, 2] == height
    if rng.random() < 0.5:  # gabled roof: ridge along the length
        pitch = rng.uniform(0.2, 0.7)
        pts[roof, 2] += pitch * (width / 2 - np.abs(pts[roof, 1]))
    return pts


def _car(rng):
    length, width, height = (
        rng.uniform(3.6, 5.2),
        rng.uniform(1.6, 2.0),
        rng.uniform(1.3, 1.8),
    )
    n = int(rng.uniform(15, 40) * length * width)
    pts = _box_surface(rng, n, length, width, height, top_share=0.75)
    top = pts[:, 2] == height
    # bonnet and boot lower than the cabin
    ends = top & (np.abs(pts[:, 0]) > 0.28 * length)
    pts[ends, 2] -= rng.uniform(0.35, 0.6)
    return pts


def _fence(rng):
    length, height = rng.uniform(4, 30), rng.uniform(0.8, 2.2)
    n = int(rng.uniform(8, 30) * length * height)
    x = rng.uniform(-length / 2, length / 2, n)
    z = height * np.sqrt(rng.uniform(0, 1, n))  # more returns near the top
    y = rng.normal(0, rng.uniform(0.02, 0.1), n)
    if rng.random() < 0.4:  # a corner
        bend = x > length / 4
        y[bend] += x[bend] - length / 4
        x[bend] = length / 4
    return np.column_stack([x, y, z])


def _pole(rng):
    height, radius = rng.uniform(4, 12), rng.uniform(0.08, 0.3)
    n = int(rng.uniform(8, 25) * height)
    theta = rng.uniform(0, 2 * np.pi, n)
    z = rng.uniform(0, height, n)
    pts = np.column_stack([radius * np.cos(theta), radius * np.sin(theta), z])
    if rng.random() < 0.5:  # a lamp arm at the top
        m = max(5, n // 6)
        arm = rng.uniform(0.8, 2.5)
        pts = np.vstack(
            [
                pts,
                np.column_stack(
                    [
                        rng.uniform(0, arm, m),
                        rng.normal(0, 0.05, m),
                        rng.normal(height, 0.05, m),
                    ]
                ),
            ]
        )
    return pts


def _tree(rng):
    crown_r = rng.uniform(1.5, 6)
    crown_h = crown_r * rng.uniform(0.8, 1.6)
    trunk = rng.uniform(1.5, 5)
    n = int(rng.uniform(8, 25) * crown_r**2 * np.pi)
    # points inside an ellipsoid, denser near its surface, more on the top
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    direction[:, 2] = np.abs(direction[:, 2]) * np.where(rng.random(n) < 0.75, 1, -1)
    depth = rng.uniform(0, 1, n) ** 0.4
    pts = direction * depth[:, None] * np.array([crown_r, crown_r, crown_h / 2])
    pts[:, 2] += trunk + crown_h / 2
    m = max(3, n // 40)
    stem = np.column_stack(
        [rng.normal(0, 0.1, m), rng.normal(0, 0.1, m), rng.uniform(0, trunk, m)]
    )
    return np.vstack([pts, stem])


_MAKERS = {
    "building": _building,
    "car": _car,
    "fence": _fence,
    "pole": _pole,
    "tree": _tree,
}


def make_urban_objects(n_per_class=40, *, noise=0.03, random_state=None):
    """Generate labelled aerial-LiDAR-like objects of five urban classes.

    Each object is sampled on the surfaces an airborne scanner sees: roofs
    and, more sparsely, walls of buildings; the body of a car with its
    bonnet and boot lower than the cabin; a thin vertical fence (sometimes
    with a corner); a pole, half of them with a lamp arm; a tree crown with
    a few trunk points. Sizes, densities and orientation (about z) are
    random, Gaussian noise is added, and each object is placed at a random
    position in a 1 km square. The classes are those of DALES Objects
    (building, car, fence, pole, tree), which makes this set a stand-in for
    real data in examples and in ``skpcd evaluate``.

    Parameters
    ----------
    n_per_class : int, default=40
        Objects generated per class.
    noise : float, default=0.03
        Standard deviation, in metres, of the Gaussian noise on every
        coordinate.
    random_state : int, RandomState instance or None, default=None
        Seed or generator, for reproducible output.

    Returns
    -------
    clouds : list of ndarray of shape (n_points_i, 3)
        The objects, float64, classes interleaved (building, car, fence,
        pole, tree, building, ...).
    labels : ndarray of str of shape (5 * n_per_class,)
        The class of each object.

    Examples
    --------
    >>> from skpcd.datasets import make_urban_objects
    >>> clouds, labels = make_urban_objects(n_per_class=2, random_state=0)
    >>> len(clouds), sorted(set(labels.tolist()))
    (10, ['building', 'car', 'fence', 'pole', 'tree'])
    """
    if int(n_per_class) != n_per_class or n_per_class < 1:
        raise ValueError(f"n_per_class must be a positive integer, got {n_per_class}")
    if not noise >= 0:
        raise ValueError(f"noise must be non-negative, got {noise}")
    rng = check_random_state(random_state)
    clouds, labels = [], []
    for _ in range(int(n_per_class)):
        for label in URBAN_CLASSES:
            pts = _rotate_z(_MAKERS[label](rng), rng.uniform(0, 2 * np.pi))
            pts = pts + rng.normal(0, noise, pts.shape) if noise else pts
            pts += np.array(
                [rng.uniform(0, 1000), rng.uniform(0, 1000), rng.uniform(0, 30)]
            )
            clouds.append(pts)
            labels.append(label)
    return clouds, np.array(labels)
