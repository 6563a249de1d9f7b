"""Objects placed on a synthetic terrain: a scene whose segmentation is
known, to score a segmentation on real objects."""

import numpy as np
from sklearn.utils import check_random_state

__all__ = ["make_scene", "terrain_height"]


def terrain_height(x, y, relief):
    """Gently rolling synthetic terrain (slopes up to about 10 %)."""
    return relief * np.sin(2 * np.pi * x / 70.0) * np.cos(2 * np.pi * y / 90.0) + (
        0.02 * x
    )


def make_scene(
    clouds,
    *,
    gap=2.0,
    ground_density=20.0,
    resample=1.0,
    noise=0.005,
    holes=3,
    relief=1.0,
    occlusion=0.8,
    random_state=None,
):
    """Place objects on a synthetic terrain: a scene with a known segmentation.

    The objects are laid out in rows, their bounding boxes ``gap`` apart,
    each resting on a rolling terrain (its lowest point on the surface).
    The terrain is sampled at random with ``ground_density`` points per
    square metre (2 cm of height noise), except in ``holes`` round gaps of
    2 to 5 m (water, occlusion) and, with probability ``occlusion``, under
    the objects. Isolated noise points are added above (80 %) and below
    (20 %) the terrain.

    Parameters
    ----------
    clouds : sequence of array-like of shape (n_points_i, 3+)
        The objects (for example real segments from
        :func:`~skpcd.io.read_segments`); only xyz is used.
    gap : float, default=2.0
        Space between the bounding boxes of neighbouring objects, in metres.
    ground_density : float, default=20.0
        Ground points per square metre.
    resample : float, default=1.0
        Object density relative to the input: below 1 a random subset of
        each object is kept (sparser, aerial-like); above 1 jittered copies
        (1 cm) of its points are added (denser, mobile-like).
    noise : float, default=0.005
        Noise points, as a fraction of the object and ground points.
    holes : int, default=3
        Round gaps in the ground.
    relief : float, default=1.0
        Amplitude of the terrain undulation, in metres (0: a plane sloping
        2 %).
    occlusion : float, default=0.8
        Fraction of the ground points under an object that are removed.
    random_state : int, RandomState instance or None, default=None
        Seed.

    Returns
    -------
    points : ndarray of shape (n_points, 3)
        The scene, in random order.
    truth : ndarray of shape (n_points,), dtype int64
        Index of the object of each point; -1 for ground, -2 for noise.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.datasets import make_scene
    >>> rng = np.random.default_rng(0)
    >>> objects = [rng.random((300, 3)) * [2, 2, 3] for _ in range(4)]
    >>> points, truth = make_scene(objects, random_state=0)
    >>> [int((truth == i).sum()) for i in (0, 1, 2, 3)]
    [300, 300, 300, 300]
    >>> bool((truth == -1).sum() > 500), bool((truth == -2).any())
    (True, True)
    """
    rng = check_random_state(random_state)
    objects = []
    for i, cloud in enumerate(clouds):
        xyz = np.asarray(cloud, dtype=np.float64)[:, :3]
        if xyz.ndim != 2 or len(xyz) == 0:
            raise ValueError(f"clouds[{i}] must be a non-empty (n_points, 3+) array")
        if resample < 1:
            keep = rng.random_sample(len(xyz)) < resample
            xyz = xyz[keep] if keep.any() else xyz[:1]
        elif resample > 1:
            extra = round((resample - 1) * len(xyz))
            pick = rng.randint(0, len(xyz), extra)
            xyz = np.vstack([xyz, xyz[pick] + rng.normal(0, 0.01, (extra, 3))])
        objects.append(xyz - xyz.min(axis=0))
    if not objects:
        raise ValueError("clouds is empty: at least one object is needed")
    extents = np.array([o.max(axis=0) for o in objects])
    width = np.sqrt(np.sum((extents[:, 0] + gap) * (extents[:, 1] + gap)))
    width = max(width, extents[:, 0].max() + gap)
    x = y = gap
    row = 0.0
    parts, truth = [], []
    for i, (obj, ext) in enumerate(zip(objects, extents)):
        if x + ext[0] > width + gap:
            x, y, row = gap, y + row + gap, 0.0
        placed = obj + np.array([x, y, 0.0])
        ground_z = terrain_height(placed[:, 0], placed[:, 1], relief)
        placed[:, 2] += np.max(ground_z - placed[:, 2])
        parts.append(placed)
        truth.append(np.full(len(placed), i, dtype=np.int64))
        x += ext[0] + gap
        row = max(row, ext[1])
    size = np.array([width + gap, y + row + gap])
    n_ground = rng.poisson(ground_density * size[0] * size[1])
    g = rng.random_sample((n_ground, 2)) * size
    for _ in range(holes):
        c, r = rng.random_sample(2) * size, rng.uniform(2.0, 5.0)
        g = g[np.hypot(*(g - c).T) > r]
    # ground under an object: the cells of 0.5 m holding object points
    cell = 0.5
    dims = np.floor(size / cell).astype(np.int64) + 1
    covered = np.zeros(dims, dtype=bool)
    for obj in parts:
        ij = np.floor(obj[:, :2] / cell).astype(np.int64)
        covered[ij[:, 0], ij[:, 1]] = True
    ij = np.floor(g / cell).astype(np.int64)
    under = covered[ij[:, 0], ij[:, 1]]
    g = g[~under | (rng.random_sample(len(g)) >= occlusion)]
    ground = np.column_stack(
        [g, terrain_height(g[:, 0], g[:, 1], relief) + rng.normal(0, 0.02, len(g))]
    )
    n_noise = round(noise * (len(ground) + sum(map(len, parts))))
    nxy = rng.random_sample((n_noise, 2)) * size
    above = rng.random_sample(n_noise) < 0.8
    dz = np.where(
        above, rng.uniform(1.0, 25.0, n_noise), -rng.uniform(0.5, 3.0, n_noise)
    )
    noise_pts = np.column_stack(
        [nxy, terrain_height(nxy[:, 0], nxy[:, 1], relief) + dz]
    )
    points = np.vstack([*parts, ground, noise_pts])
    truth = np.concatenate(
        [*truth, np.full(len(ground), -1), np.full(n_noise, -2)]
    ).astype(np.int64)
    order = rng.permutation(len(points))
    return points[order], truth[order]
