"""Basic shapes of Wang et al. (2023), Figure 4: planes, spheres, cylinders,
cones, corners and edges, sampled as noisy point clouds."""

from numbers import Integral, Real

import numpy as np
from sklearn.utils import check_random_state

__all__ = ["PRIMITIVES", "make_primitives"]

PRIMITIVES = ("plane", "sphere", "cylinder", "cone", "corner", "edge")


def _square(rng, n, size):
    return np.column_stack([rng.uniform(0, size, (n, 2)), np.zeros(n)])


def _plane(rng, n):
    return _square(rng, n, 1.0) * [rng.uniform(1, 5), rng.uniform(1, 5), 0.0]


def _sphere(rng, n):
    v = rng.normal(size=(n, 3))
    return rng.uniform(0.5, 3) * v / np.linalg.norm(v, axis=1, keepdims=True)


def _cylinder(rng, n):
    t = rng.uniform(0, 2 * np.pi, n)
    r = rng.uniform(0.2, 1.5)
    return np.column_stack([r * np.cos(t), r * np.sin(t), rng.uniform(0, 1, n)]) * [
        1,
        1,
        rng.uniform(1, 6),
    ]


def _cone(rng, n):
    radius, height = rng.uniform(0.5, 2), rng.uniform(1, 4)
    # uniform on the lateral surface: the radius of a slice grows linearly
    s = np.sqrt(rng.uniform(0, 1, n))
    t = rng.uniform(0, 2 * np.pi, n)
    return np.column_stack(
        [radius * s * np.cos(t), radius * s * np.sin(t), height * (1 - s)]
    )


def _corner(rng, n):
    """Three squares meeting at right angles at the origin, like a room's."""
    size = rng.uniform(1, 4)
    face = rng.integers(0, 3, n)
    pts = _square(rng, n, size)
    out = np.empty_like(pts)
    for f in range(3):
        m = face == f
        out[m] = np.roll(pts[m], f, axis=1)
    return out


def _edge(rng, n):
    """Two rectangles sharing a side, at a dihedral angle of 60-120 degrees."""
    size, length = rng.uniform(1, 4), rng.uniform(1, 5)
    angle = np.deg2rad(rng.uniform(60, 120))
    u = rng.uniform(0, size, n)
    along = rng.uniform(0, length, n)
    second = rng.random(n) < 0.5
    x = np.where(second, u * np.cos(angle), u)
    z = np.where(second, u * np.sin(angle), 0.0)
    return np.column_stack([x, along, z])


_MAKERS = {
    "plane": _plane,
    "sphere": _sphere,
    "cylinder": _cylinder,
    "cone": _cone,
    "corner": _corner,
    "edge": _edge,
}


def _rotation(rng):
    """A rotation drawn uniformly (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _range(value, name):
    lo, hi = (value, value) if np.isscalar(value) else value
    if not (0 <= lo <= hi):
        raise ValueError(f"{name} must be a number or a (low, high) pair, got {value}")
    return float(lo), float(hi)


def make_primitives(
    n_per_shape=20,
    *,
    shapes=PRIMITIVES,
    n_points=(400, 1500),
    noise=(0.0, 0.02),
    random_state=None,
):
    """Generate noisy point clouds of basic shapes, labelled by shape.

    The shapes of Wang et al. (2023), Figure 4: ``"plane"`` (a rectangle of
    1-5 m sides), ``"sphere"`` (radius 0.5-3 m), ``"cylinder"`` (lateral
    surface, radius 0.2-1.5 m, height 1-6 m), ``"cone"`` (lateral surface,
    base radius 0.5-2 m, height 1-4 m), ``"corner"`` (three perpendicular
    squares sharing a vertex) and ``"edge"`` (two rectangles sharing a side
    at 60-120 degrees). Each cloud is sampled uniformly on its surface with
    a random number of points, gets Gaussian noise of a random standard
    deviation, a uniformly random rotation and a random translation.

    Parameters
    ----------
    n_per_shape : int, default=20
        Clouds generated per shape.
    shapes : sequence of str, default=PRIMITIVES
        Which shapes, among :data:`PRIMITIVES`.
    n_points : int or tuple of (int, int), default=(400, 1500)
        Points per cloud, or an inclusive range to draw from.
    noise : float or tuple of (float, float), default=(0.0, 0.02)
        Standard deviation of the noise on every coordinate, in metres, or
        a range to draw it from per cloud (airborne and mobile LiDAR: 1-3 cm).
    random_state : int, RandomState instance or None, default=None
        Seed or generator, for reproducible output.

    Returns
    -------
    clouds : list of ndarray of shape (n_points_i, 3)
        The clouds, float64, shapes interleaved.
    labels : ndarray of str of shape (len(shapes) * n_per_shape,)
        The shape of each cloud.

    Examples
    --------
    >>> from skpcd.datasets import make_primitives
    >>> clouds, labels = make_primitives(1, n_points=200, random_state=0)
    >>> labels.tolist()
    ['plane', 'sphere', 'cylinder', 'cone', 'corner', 'edge']
    >>> clouds[0].shape
    (200, 3)
    """
    if not isinstance(n_per_shape, Integral) or n_per_shape < 1:
        raise ValueError(f"n_per_shape must be a positive integer, got {n_per_shape}")
    shapes = [shapes] if isinstance(shapes, str) else list(shapes)
    unknown = sorted(set(shapes) - set(PRIMITIVES))
    if unknown or not shapes:
        raise ValueError(f"unknown shapes {unknown}; choose among {PRIMITIVES}")
    n_lo, n_hi = _range(n_points, "n_points")
    if n_lo < 1 or not all(isinstance(v, (Integral, Real)) for v in (n_lo, n_hi)):
        raise ValueError(f"n_points must be at least 1, got {n_points}")
    s_lo, s_hi = _range(noise, "noise")
    rng = np.random.default_rng(check_random_state(random_state).randint(2**31))
    clouds, labels = [], []
    for _ in range(n_per_shape):
        for shape in shapes:
            n = int(rng.integers(int(n_lo), int(n_hi) + 1))
            pts = _MAKERS[shape](rng, n)
            pts = pts - pts.mean(axis=0)
            pts = pts + rng.normal(0, rng.uniform(s_lo, s_hi), pts.shape)
            pts = pts @ _rotation(rng).T + rng.uniform(-10, 10, 3)
            clouds.append(pts)
            labels.append(shape)
    return clouds, np.array(labels)
