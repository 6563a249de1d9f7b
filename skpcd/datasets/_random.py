"""Small random point clouds for tests and doctests."""

import numpy as np
from sklearn.utils import check_random_state

__all__ = ["make_point_clouds"]


def make_point_clouds(
    n_clouds=10, *, n_points=(50, 500), n_columns=3, noise=0.01, random_state=None
):
    """Generate a ragged list of random surface-like point clouds.

    Each cloud samples a random smooth surface patch (a bent, stretched
    plane), so that normals and local descriptors are well defined, then
    rotates and translates it at random. Use it to feed estimators in tests,
    the role ``make_classification`` plays for tabular data.

    Parameters
    ----------
    n_clouds : int, default=10
        Number of clouds.
    n_points : int or tuple of (int, int), default=(50, 500)
        Points per cloud: a fixed number or an inclusive range drawn from.
    n_columns : int, default=3
        Columns per cloud. With 6 or more, columns 3-5 are the unit normals
        of the surface (the layout the descriptors read as given normals,
        see :class:`~skpcd.features.PFHTransformer`); the other columns
        beyond xyz hold uniform noise in [0, 1) (like an intensity).
    noise : float, default=0.01
        Standard deviation of the Gaussian noise added to the coordinates.
    random_state : int, RandomState instance or None, default=None
        Seed or generator, for reproducible output.

    Returns
    -------
    clouds : list of ndarray of shape (n_points_i, n_columns)
        The clouds, float64.

    Examples
    --------
    >>> from skpcd.datasets import make_point_clouds
    >>> clouds = make_point_clouds(3, n_points=(10, 20), random_state=0)
    >>> [c.shape[1] for c in clouds]
    [3, 3, 3]
    >>> import numpy as np
    >>> with_normals = make_point_clouds(2, n_columns=6, random_state=0)
    >>> bool(np.allclose(np.linalg.norm(with_normals[0][:, 3:6], axis=1), 1.0))
    True
    """
    rng = check_random_state(random_state)
    if n_clouds < 1:
        raise ValueError(f"n_clouds must be at least 1, got {n_clouds}")
    if n_columns < 3:
        raise ValueError(f"n_columns must be at least 3, got {n_columns}")
    lo, hi = (n_points, n_points) if np.isscalar(n_points) else n_points
    clouds = []
    for _ in range(n_clouds):
        n = int(rng.randint(lo, hi + 1))
        uv = rng.uniform(-1, 1, size=(n, 2)) * rng.uniform(0.5, 3, size=2)
        bend = rng.uniform(-0.5, 0.5, size=3)
        w = (
            bend[0] * uv[:, 0] ** 2
            + bend[1] * uv[:, 1] ** 2
            + bend[2] * uv[:, 0] * uv[:, 1]
        )
        pts = np.column_stack([uv, w]) + rng.normal(0, noise, size=(n, 3))
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        pts = pts @ q.T + rng.uniform(-10, 10, size=3)
        if n_columns >= 6:
            # the surface's normal (-dw/du, -dw/dv, 1), turned with the patch
            du = 2 * bend[0] * uv[:, 0] + bend[2] * uv[:, 1]
            dv = 2 * bend[1] * uv[:, 1] + bend[2] * uv[:, 0]
            normals = np.column_stack([-du, -dv, np.ones(n)]) @ q.T
            normals /= np.linalg.norm(normals, axis=1, keepdims=True)
            extra = rng.uniform(0, 1, size=(n, n_columns - 6))
            pts = np.hstack([pts, normals, extra])
        elif n_columns > 3:
            pts = np.hstack([pts, rng.uniform(0, 1, size=(n, n_columns - 3))])
        clouds.append(pts)
    return clouds
