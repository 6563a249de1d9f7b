"""Analytic shapes of a street scene, and their packing into arrays.

An object is built as :class:`Parts` in its own frame (origin at its base on
the ground, ``+x`` towards the road, ``z`` up), placed in the street with a
rotation and a shift, and added to a :class:`SceneArrays`, which packs every
primitive into the arrays the ray-casting kernels read: ``kind``,
``params (m, 24)``, ``hit`` (hit probability), ``instance``, ``class_id``
and the bounding box ``aabb (m, 6)``.

Parameter rows (see :mod:`skpcd.datasets._street._raycast`):

- cylinder (a capped cone frustum): ``p0 (3), p1 (3), r0, r1, axis (3),
  length``;
- box and ellipsoid: ``centre (3), half extents or semi-axes (3), axes (9)``
  where ``axes[3 * j + i]`` is world component j of local axis i;
- wall (a box with window openings): the box's 15 numbers, then the window
  grid ``x_first, x_period, width, n_columns, z_first, z_period, height,
  n_rows, glass_hit_probability``;
- profile (the terrain): ``slope, x0, x1, n_vertices`` and the ``(y, z)``
  vertices of the cross-section.
"""

import numpy as np

from skpcd.datasets._street._raycast import (
    BOX,
    CYLINDER,
    ELLIPSOID,
    MAX_PROFILE_VERTICES,
    N_PARAMS,
    PROFILE,
    WALL,
)

__all__ = ["Parts", "SceneArrays", "parts_aabb", "rot_x", "rot_y", "rot_z"]


def rot_x(a):
    """Rotation matrix about x by ``a`` radians."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a):
    """Rotation matrix about y by ``a`` radians."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a):
    """Rotation matrix about z by ``a`` radians."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


_EYE = np.eye(3)


class Parts:
    """The primitives of one object, in the object's frame.

    Each primitive is kept as ``(kind, geometry, hit)``: a cylinder's
    geometry is ``(p0, p1, r0, r1)``, a box's or an ellipsoid's
    ``(centre, half, rotation)`` and a wall's ``(centre, half, rotation,
    windows)``.
    """

    def __init__(self):
        self.items = []

    def __len__(self):
        return len(self.items)

    def cylinder(self, p0, p1, r0, r1=None, hit=1.0):
        """A capped cylinder (``r1=None``) or cone frustum from p0 to p1."""
        p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
        r1 = r0 if r1 is None else r1
        if np.linalg.norm(p1 - p0) > 1e-9 and max(r0, r1) > 0:
            self.items.append((CYLINDER, (p0, p1, float(r0), float(r1)), hit))
        return self

    def box(self, center, half, rotation=None, hit=1.0):
        """An oriented box: centre, half extents, rotation (local to world)."""
        rot = _EYE if rotation is None else np.asarray(rotation, float)
        geo = (np.asarray(center, float), np.abs(np.asarray(half, float)), rot)
        self.items.append((BOX, geo, hit))
        return self

    def ellipsoid(self, center, radii, rotation=None, hit=1.0):
        """An ellipsoid (a sphere with equal radii)."""
        rot = _EYE if rotation is None else np.asarray(rotation, float)
        radii = np.broadcast_to(np.asarray(radii, float), (3,)).copy()
        self.items.append((ELLIPSOID, (np.asarray(center, float), radii, rot), hit))
        return self

    def wall(self, center, half, windows, rotation=None, glass=0.3):
        """A wall with a grid of window openings; its front is local ``-y``.

        ``windows`` is ``(x_first, x_period, width, n_columns, z_first,
        z_period, height, n_rows)`` in the wall's local coordinates (x along
        the wall from its centre, z up from its centre).
        """
        rot = _EYE if rotation is None else np.asarray(rotation, float)
        win = np.array([*windows, glass], dtype=float)
        geo = (np.asarray(center, float), np.abs(np.asarray(half, float)), rot, win)
        self.items.append((WALL, geo, 1.0))
        return self

    def profile(self, slope, x_range, vertices):
        """Terrain: a polyline of ``(y, z)`` vertices extruded along x.

        Heights are at ``x = 0`` and rise by ``slope`` per metre of x; the
        surface spans ``x_range``. Vertical segments are allowed (kerbs).
        """
        v = np.asarray(vertices, dtype=float).reshape(-1, 2)
        if len(v) > MAX_PROFILE_VERTICES:
            raise ValueError(f"at most {MAX_PROFILE_VERTICES} profile vertices")
        geo = (float(slope), tuple(map(float, x_range)), v)
        self.items.append((PROFILE, geo, 1.0))
        return self

    def extend(self, other):
        """Add the primitives of another :class:`Parts`."""
        self.items.extend(other.items)
        return self

    def placed(self, rotation, shift):
        """A copy rotated by ``rotation`` (3 x 3) about the origin, then shifted."""
        rot = np.asarray(rotation, float)
        shift = np.asarray(shift, float)
        out = Parts()
        for kind, geo, hit in self.items:
            if kind == PROFILE:
                raise ValueError("a terrain profile is built in place")
            if kind == CYLINDER:
                p0, p1, r0, r1 = geo
                new = (rot @ p0 + shift, rot @ p1 + shift, r0, r1)
            else:
                new = (rot @ geo[0] + shift, geo[1], rot @ geo[2], *geo[3:])
            out.items.append((kind, new, hit))
        return out


def _row(kind, geo):
    row = np.zeros(N_PARAMS)
    if kind == PROFILE:
        slope, (x0, x1), v = geo
        row[:4] = [slope, x0, x1, len(v)]
        row[4 : 4 + 2 * len(v)] = v.ravel()
    elif kind == CYLINDER:
        p0, p1, r0, r1 = geo
        axis = p1 - p0
        length = np.linalg.norm(axis)
        row[:12] = [*p0, *p1, r0, r1, *(axis / length), length]
    else:
        row[0:3] = geo[0]
        row[3:6] = geo[1]
        row[6:15] = geo[2].ravel()
        if kind == WALL:
            row[15:24] = geo[3]
    return row


def _aabb(kind, row):
    if kind == PROFILE:
        slope, x0, x1, n = row[0], row[1], row[2], int(row[3])
        v = row[4 : 4 + 2 * n].reshape(n, 2)
        dz = sorted([slope * x0, slope * x1])
        return np.array(
            [
                x0,
                v[:, 0].min(),
                v[:, 1].min() + dz[0],
                x1,
                v[:, 0].max(),
                v[:, 1].max() + dz[1],
            ]
        )
    if kind == CYLINDER:
        p0, p1, r0, r1, axis = row[0:3], row[3:6], row[6], row[7], row[8:11]
        ext = np.sqrt(np.clip(1.0 - axis**2, 0.0, 1.0))
        lo = np.minimum(p0 - r0 * ext, p1 - r1 * ext)
        hi = np.maximum(p0 + r0 * ext, p1 + r1 * ext)
        return np.concatenate([lo, hi])
    center, half, rot = row[0:3], row[3:6], row[6:15].reshape(3, 3)
    if kind == ELLIPSOID:
        ext = np.sqrt(((rot * half) ** 2).sum(axis=1))
    else:
        ext = np.abs(rot) @ half
    return np.concatenate([center - ext, center + ext])


class SceneArrays:
    """Primitives of a whole scene, packed for the kernels.

    Add objects with :meth:`add`, then :meth:`pack`.
    """

    def __init__(self):
        self.kind, self.rows, self.hit, self.instance, self.class_id = (
            [],
            [],
            [],
            [],
            [],
        )

    def __len__(self):
        return len(self.kind)

    def add(self, parts, instance, class_id):
        """Add the (already placed) primitives of one object."""
        for kind, geo, hit in parts.items:
            self.kind.append(kind)
            self.rows.append(_row(kind, geo))
            self.hit.append(hit)
            self.instance.append(instance)
            self.class_id.append(class_id)

    def pack(self):
        """The arrays: dict of ``kind, params, hit, instance, class_id, aabb``."""
        kind = np.asarray(self.kind, dtype=np.int64)
        params = np.ascontiguousarray(np.vstack(self.rows), dtype=np.float64)
        aabb = np.vstack([_aabb(k, r) for k, r in zip(kind, params)])
        return {
            "kind": kind,
            "params": params,
            "hit": np.asarray(self.hit, dtype=np.float64),
            "instance": np.asarray(self.instance, dtype=np.int64),
            "class_id": np.asarray(self.class_id, dtype=np.int64),
            "aabb": np.ascontiguousarray(aabb),
        }


def parts_aabb(parts):
    """Bounding box ``(lo (3,), hi (3,))`` of some :class:`Parts`."""
    boxes = np.vstack([_aabb(k, _row(k, g)) for k, g, _ in parts.items])
    return boxes[:, :3].min(axis=0), boxes[:, 3:].max(axis=0)
