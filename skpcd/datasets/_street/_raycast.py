"""Ray casting against analytic primitives through a uniform grid (numba).

All the kernels of the scan simulation live in this one module (numba's
cache does not follow calls into other modules).

The scene is packed arrays (see :mod:`skpcd.datasets._street._primitives`):
``kind (m,)``, ``params (m, 24)``, ``hit (m,)`` and the axis-aligned bounding
box of each primitive ``aabb (m, 6)``. A 2-D grid of square cells over
``x, y`` lists, in CSR form, the primitives whose box overlaps each cell; a
ray walks through the cells it crosses (Amanatides and Woo, 1987), tests
the primitives of each cell once (a per-primitive mailbox holds the id of
the last ray that tested it) and stops as soon as its nearest hit lies in
the cell being left. The first hit along the ray is returned: what stands
behind it is never seen.

A primitive with hit probability ``p < 1`` (foliage, glass, mesh) is hit by
a ray that crosses it with probability ``p`` and otherwise let through. The
draw is a counter-based hash of the scan seed, the ray id and the primitive
id, so a scan does not depend on the order in which the primitives are
tested, on the chunking of the rays, or on threads.

A scan pattern is an integer code with a float parameter vector ``fp``, a
float table ``fa`` (one row per scanner, flight line, or the beams,
flattened) and a table ``ft`` of the cosines and sines of the pattern's scan
angles (so that no pulse computes a trigonometric function).
``pulse_ray`` turns a pulse number ``k`` into the origin, direction, time
and channel of its ray; ``simulate`` casts the pulses ``k0 .. k1 - 1`` and
writes the returns. Rays are never stored: a scan of any size runs in
chunks of constant memory.
"""

import math

import numpy as np
from numba import njit

CYLINDER, BOX, ELLIPSOID, WALL, PROFILE = 0, 1, 2, 3, 4
N_PARAMS = 32
MAX_PROFILE_VERTICES = (N_PARAMS - 4) // 2

# salts of the hash draws of one ray (the primitives use SALT_PRIM + id, the
# glass of walls SALT_GLASS + id); SALT_NOISE's hash gives the four normal
# numbers of the ray's jitter and range noise
SALT_DROP = 8
SALT_NOISE = 9
SALT_GLASS = 1 << 40
SALT_PRIM = 1 << 20

_C1 = np.uint64(0x9E3779B97F4A7C15)
_C2 = np.uint64(0xBF58476D1CE4E5B9)
_C3 = np.uint64(0x94D049BB133111EB)
_S11 = np.uint64(11)
_S27 = np.uint64(27)
_S30 = np.uint64(30)
_S31 = np.uint64(31)
_INV53 = 1.0 / 9007199254740992.0
_EPS = 1e-12


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def hash64(seed, k, salt):
    """A 64-bit hash of (seed, ray id, salt): the splitmix64 finaliser."""
    z = np.uint64(seed) + np.uint64(k) * _C1 + np.uint64(salt) * _C3
    z = (z ^ (z >> _S30)) * _C2
    z = (z ^ (z >> _S27)) * _C3
    return z ^ (z >> _S31)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def uniform(seed, k, salt):
    """A uniform number in [0, 1) from (seed, ray id, salt)."""
    return np.float64(hash64(seed, k, salt) >> _S11) * _INV53


# ---------------------------------------------------------------------------
# intersections: the smallest t in (tmin, tmax) where the ray meets the
# primitive's surface, or inf


@njit(cache=True, nogil=True, _nrt=False)
def hit_cylinder(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Capped cone frustum ``i``: from ``p[0:3]`` (radius ``p[6]``) to ``p[3:6]``.

    ``p = params[i]``: radius ``p[7]`` at the far end, ``p[8:11]`` the unit
    axis and ``p[11]`` the length.
    """
    ax, ay, az, length = params[i, 8], params[i, 9], params[i, 10], params[i, 11]
    r0, r1 = params[i, 6], params[i, 7]
    wx, wy, wz = ox - params[i, 0], oy - params[i, 1], oz - params[i, 2]
    da = dx * ax + dy * ay + dz * az
    wa = wx * ax + wy * ay + wz * az
    dpx, dpy, dpz = dx - da * ax, dy - da * ay, dz - da * az
    wpx, wpy, wpz = wx - wa * ax, wy - wa * ay, wz - wa * az
    k = (r1 - r0) / length
    rr = r0 + k * wa
    a = dpx * dpx + dpy * dpy + dpz * dpz - k * k * da * da
    b = 2.0 * (wpx * dpx + wpy * dpy + wpz * dpz - k * rr * da)
    c = wpx * wpx + wpy * wpy + wpz * wpz - rr * rr
    best = np.inf
    if abs(a) > _EPS:
        disc = b * b - 4.0 * a * c
        if disc >= 0.0:
            sq = math.sqrt(disc)
            t1 = (-b - sq) / (2.0 * a)
            t2 = (-b + sq) / (2.0 * a)
            if t1 > t2:
                t1, t2 = t2, t1
            if tmin < t1 < tmax:
                h = wa + t1 * da
                if 0.0 <= h <= length:
                    best = t1
            if best == np.inf and tmin < t2 < tmax:
                h = wa + t2 * da
                if 0.0 <= h <= length:
                    best = t2
    if abs(da) > _EPS:
        t = -wa / da
        if tmin < t < tmax and t < best:
            qx, qy, qz = wpx + t * dpx, wpy + t * dpy, wpz + t * dpz
            if qx * qx + qy * qy + qz * qz <= r0 * r0:
                best = t
        t = (length - wa) / da
        if tmin < t < tmax and t < best:
            qx, qy, qz = wpx + t * dpx, wpy + t * dpy, wpz + t * dpz
            if qx * qx + qy * qy + qz * qz <= r1 * r1:
                best = t
    return best


@njit(cache=True, nogil=True, _nrt=False)
def to_local(params, i, ox, oy, oz, dx, dy, dz):
    """Ray in the frame of a box or ellipsoid: centre p[0:3], axes p[6:15].

    ``p[6 + 3 * j + i]`` is component j (world) of local axis i.
    """
    rx, ry, rz = ox - params[i, 0], oy - params[i, 1], oz - params[i, 2]
    lox = params[i, 6] * rx + params[i, 9] * ry + params[i, 12] * rz
    loy = params[i, 7] * rx + params[i, 10] * ry + params[i, 13] * rz
    loz = params[i, 8] * rx + params[i, 11] * ry + params[i, 14] * rz
    ldx = params[i, 6] * dx + params[i, 9] * dy + params[i, 12] * dz
    ldy = params[i, 7] * dx + params[i, 10] * dy + params[i, 13] * dz
    ldz = params[i, 8] * dx + params[i, 11] * dy + params[i, 14] * dz
    return lox, loy, loz, ldx, ldy, ldz


@njit(cache=True, nogil=True, _nrt=False)
def _slab(lo, ld, h, tn, tf, axis, side, this):
    """One axis of the slab test; keeps the entry axis and face side."""
    if abs(ld) < _EPS:
        if lo < -h or lo > h:
            return np.inf, -np.inf, axis, side
        return tn, tf, axis, side
    inv = 1.0 / ld
    t1 = (-h - lo) * inv
    t2 = (h - lo) * inv
    s = -1
    if t1 > t2:
        t1, t2 = t2, t1
        s = 1
    if t1 > tn:
        tn = t1
        axis = this
        side = s
    if t2 < tf:
        tf = t2
    return tn, tf, axis, side


@njit(cache=True, nogil=True, _nrt=False)
def box_span(params, i, lox, loy, loz, ldx, ldy, ldz):
    """Entry and exit of a ray in local box coordinates, with the entry face."""
    tn, tf, axis, side = -np.inf, np.inf, -1, 0
    tn, tf, axis, side = _slab(lox, ldx, params[i, 3], tn, tf, axis, side, 0)
    tn, tf, axis, side = _slab(loy, ldy, params[i, 4], tn, tf, axis, side, 1)
    tn, tf, axis, side = _slab(loz, ldz, params[i, 5], tn, tf, axis, side, 2)
    return tn, tf, axis, side


@njit(cache=True, nogil=True, _nrt=False)
def hit_box(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Oriented box: centre p[0:3], half extents p[3:6], axes p[6:15]."""
    lox, loy, loz, ldx, ldy, ldz = to_local(params, i, ox, oy, oz, dx, dy, dz)
    tn, tf, _, _ = box_span(params, i, lox, loy, loz, ldx, ldy, ldz)
    if tn > tf:
        return np.inf
    if tmin < tn < tmax:
        return tn
    if tn <= tmin < tf < tmax:  # ray starting inside
        return tf
    return np.inf


@njit(cache=True, nogil=True, _nrt=False)
def hit_ellipsoid(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Ellipsoid: centre p[0:3], semi-axes p[3:6], axes p[6:15]."""
    lox, loy, loz, ldx, ldy, ldz = to_local(params, i, ox, oy, oz, dx, dy, dz)
    lox, loy, loz = lox / params[i, 3], loy / params[i, 4], loz / params[i, 5]
    ldx, ldy, ldz = ldx / params[i, 3], ldy / params[i, 4], ldz / params[i, 5]
    a = ldx * ldx + ldy * ldy + ldz * ldz
    b = 2.0 * (lox * ldx + loy * ldy + loz * ldz)
    c = lox * lox + loy * loy + loz * loz - 1.0
    disc = b * b - 4.0 * a * c
    if disc < 0.0:
        return np.inf
    sq = math.sqrt(disc)
    t1 = (-b - sq) / (2.0 * a)
    if tmin < t1 < tmax:
        return t1
    t2 = (-b + sq) / (2.0 * a)
    if tmin < t2 < tmax:
        return t2
    return np.inf


@njit(cache=True, nogil=True, _nrt=False)
def hit_wall(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax, seed, ray):
    """A box with a grid of window openings through it (a facade).

    The box is ``hit_box``'s; its front face is the local ``-y`` face and
    its thickness the depth of the window reveals. With ``p = params[i]``,
    windows: columns of width ``p[17]`` from local x ``p[15]`` every
    ``p[16]`` (``p[18]`` columns), rows of height ``p[21]`` from local z
    ``p[19]`` every ``p[20]`` (``p[22]`` rows). A ray entering the front
    face in an opening hits a reveal if it leaves the opening before the
    back face, else the glass in the back face with probability ``p[23]``;
    otherwise it passes into the building.
    """
    lox, loy, loz, ldx, ldy, ldz = to_local(params, i, ox, oy, oz, dx, dy, dz)
    tn, tf, axis, side = box_span(params, i, lox, loy, loz, ldx, ldy, ldz)
    if tn > tf or tn >= tmax or tf <= tmin:
        return np.inf
    if tn <= tmin:
        return tf if tf < tmax else np.inf
    if axis != 1 or side != -1:
        return tn
    x0, x_period, width, n_cols = (
        params[i, 15],
        params[i, 16],
        params[i, 17],
        params[i, 18],
    )
    z0, z_period, height, n_rows = (
        params[i, 19],
        params[i, 20],
        params[i, 21],
        params[i, 22],
    )
    x = lox + tn * ldx - x0
    col = math.floor(x / x_period)
    if not (0 <= col < n_cols and x - col * x_period < width):
        return tn
    z = loz + tn * ldz - z0
    row = math.floor(z / z_period)
    if not (0 <= row < n_rows and z - row * z_period < height):
        return tn
    xa = x0 + col * x_period
    za = z0 + row * z_period
    t_back = (params[i, 4] - loy) / ldy
    t_side = np.inf
    if ldx > _EPS:
        t_side = (xa + width - lox) / ldx
    elif ldx < -_EPS:
        t_side = (xa - lox) / ldx
    if ldz > _EPS:
        t_side = min(t_side, (za + height - loz) / ldz)
    elif ldz < -_EPS:
        t_side = min(t_side, (za - loz) / ldz)
    if t_side < t_back:  # a reveal
        return t_side if t_side < tmax else np.inf
    if t_back < tmax and uniform(seed, ray, SALT_GLASS + i) < params[i, 23]:
        return t_back  # the glass
    return np.inf


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def hit_profile(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Terrain: a cross-section polyline in (y, z) extruded along x on a slope.

    ``p = params[i]``: slope ``p[0]``, x range ``p[1], p[2]``, ``p[3]``
    vertices ``(y, z)`` from ``p[4]`` on (heights at x = 0; vertical
    segments are kerb faces). In ``(y, z - slope * x)`` the surface is the
    polyline and the ray a 2-D line, so each segment is a 2-D crossing.
    """
    slope = params[i, 0]
    w = oz - slope * ox
    dw = dz - slope * dx
    best = tmax
    # which side of the ray's 2-D line each vertex lies on: a segment is
    # crossed where the side changes (no division for the others)
    n = int(params[i, 3])
    ay, az = params[i, 4], params[i, 5]
    sa = dy * (az - w) - dw * (ay - oy)
    for v in range(1, n):
        by, bz = params[i, 4 + 2 * v], params[i, 5 + 2 * v]
        sb = dy * (bz - w) - dw * (by - oy)
        if (sa <= 0.0) != (sb <= 0.0):
            ey, ez = by - ay, bz - az
            den = dy * ez - dw * ey
            if abs(den) > _EPS:
                t = ((ay - oy) * ez - (az - w) * ey) / den
                if tmin < t < best:
                    x = ox + t * dx
                    if params[i, 1] <= x <= params[i, 2]:
                        best = t
        ay, az, sa = by, bz, sb
    return best if best < tmax else np.inf


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def intersect(kind, params, i, ox, oy, oz, dx, dy, dz, tmin, tmax, seed, ray):
    """Dispatch on the primitive kind."""
    if kind == PROFILE:
        return hit_profile(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax)
    if kind == CYLINDER:
        return hit_cylinder(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax)
    if kind == BOX:
        return hit_box(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax)
    if kind == ELLIPSOID:
        return hit_ellipsoid(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax)
    return hit_wall(params, i, ox, oy, oz, dx, dy, dz, tmin, tmax, seed, ray)


# ---------------------------------------------------------------------------
# the grid


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _cell_span(aabb, i, x0, y0, cell, nx, ny):
    """The first and last cells (x, then y) that box ``i`` overlaps."""
    ix0 = min(max(int((aabb[i, 0] - x0) / cell), 0), nx - 1)
    ix1 = min(max(int((aabb[i, 3] - x0) / cell), 0), nx - 1)
    iy0 = min(max(int((aabb[i, 1] - y0) / cell), 0), ny - 1)
    iy1 = min(max(int((aabb[i, 4] - y0) / cell), 0), ny - 1)
    return ix0, ix1, iy0, iy1


@njit(cache=True, nogil=True)
def grid_cells(aabb, in_grid, x0, y0, cell, nx, ny):
    """CSR lists of the primitives whose bounding box overlaps each cell.

    Only primitives with ``in_grid`` are listed. Returns ``start (nx * ny +
    1,)``, ``items`` (primitive ids), ``boxes`` (a copy of the bounding box
    of each listed item, in list order, so that a ray reads them in
    sequence) and ``zrange (nx * ny, 2)``, the lowest and highest z of the
    cell's items.
    """
    m = aabb.shape[0]
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    fill = start[:-1]
    items = np.empty(0, dtype=np.int64)
    boxes = np.empty((0, 6))
    zrange = np.empty((nx * ny, 2))
    zrange[:, 0] = np.inf
    zrange[:, 1] = -np.inf
    # the same walk over the cells of each box twice: to count the items of
    # each cell, then to place them
    for place in (False, True):
        if place:
            for c in range(nx * ny):
                start[c + 1] += start[c]
            fill = start[:-1].copy()
            items = np.empty(start[-1], dtype=np.int64)
            boxes = np.empty((start[-1], 6))
        for i in range(m):
            if not in_grid[i]:
                continue
            ix0, ix1, iy0, iy1 = _cell_span(aabb, i, x0, y0, cell, nx, ny)
            for iy in range(iy0, iy1 + 1):
                for ix in range(ix0, ix1 + 1):
                    c = iy * nx + ix
                    if not place:
                        start[c + 1] += 1
                        continue
                    items[fill[c]] = i
                    boxes[fill[c]] = aabb[i]
                    fill[c] += 1
                    zrange[c, 0] = min(zrange[c, 0], aabb[i, 2])
                    zrange[c, 1] = max(zrange[c, 1], aabb[i, 5])
    return start, items, boxes, zrange


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _clip(o, d, lo, hi, t0, t1):
    if abs(d) < _EPS:
        if o < lo or o > hi:
            return np.inf, -np.inf
        return t0, t1
    ta = (lo - o) / d
    tb = (hi - o) / d
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _axis_span(lo, hi, o, inv, t0, t1):
    """``[t0, t1]`` cut to where the ray (inverse direction ``inv``) is in [lo, hi]."""
    ta = (lo - o) * inv
    tb = (hi - o) * inv
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _aabb_span(boxes, j, ox, oy, oz, ix, iy, iz, t0, t1):
    """``[t0, t1]`` cut to where the ray is in box j (empty if ``t0 > t1``)."""
    t0, t1 = _axis_span(boxes[j, 0], boxes[j, 3], ox, ix, t0, t1)
    t0, t1 = _axis_span(boxes[j, 1], boxes[j, 4], oy, iy, t0, t1)
    return _axis_span(boxes[j, 2], boxes[j, 5], oz, iz, t0, t1)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _box_overlap(boxes, j, ox, oy, oz, ix, iy, iz, t0, t1):
    """Does the ray (inverse direction ix, iy, iz) meet box j within [t0, t1]?"""
    t0, t1 = _aabb_span(boxes, j, ox, oy, oz, ix, iy, iz, t0, t1)
    return t0 <= t1


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _box_exit(boxes, j, ox, oy, oz, ix, iy, iz, t0, t1):
    """Where the ray leaves box j within [t0, t1], or -1 if it misses it."""
    t0, t1 = _aabb_span(boxes, j, ox, oy, oz, ix, iy, iz, t0, t1)
    return t1 if t0 <= t1 else -1.0


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _try(kind, params, hit, i, ox, oy, oz, dx, dy, dz, tmin, best, seed, ray):
    """Distance to primitive i if the ray is stopped by it before ``best``."""
    t = intersect(kind[i], params, i, ox, oy, oz, dx, dy, dz, tmin, best, seed, ray)
    if t < best:
        h = hit[i]
        if h < 1.0 and uniform(seed, ray, SALT_PRIM + i) >= h:
            return np.inf
    return t


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _axis_enter(o, d, t, lo, cell, n):
    """One axis of the grid walk at distance t: cell, step, next crossing, its step."""
    c = min(max(int((o + t * d - lo) / cell), 0), n - 1)
    if d > _EPS:
        return c, 1, (lo + (c + 1) * cell - o) / d, cell / d
    if d < -_EPS:
        return c, -1, (lo + c * cell - o) / d, -cell / d
    return c, 0, np.inf, np.inf


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _enter(ox, oy, dx, dy, t, x0, y0, cell, nx, ny):
    """Grid walk state at distance t: cell, steps, next crossings, their steps."""
    cx, sx, nxt_x, dtx = _axis_enter(ox, dx, t, x0, cell, nx)
    cy, sy, nxt_y, dty = _axis_enter(oy, dy, t, y0, cell, ny)
    return cx, cy, sx, sy, nxt_x, nxt_y, dtx, dty


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def cast(ox, oy, oz, dx, dy, dz, tmin, tmax, world, mailbox, ray, seed):
    """First primitive the ray meets in (tmin, tmax): ``(index, t)``, or (-1, inf).

    ``world`` is the tuple of the scene's arrays and its grid, in the
    order of the unpacking below (``_scanners._scene_arrays`` builds it).
    The primitives ``glob`` (the ground profile and other large ones, met
    by most rays) are tested first, which bounds the walk through the grid.
    ``bounds`` is ``(x0, y0, z0, x1, y1, z1)`` of the grid (z: of all the
    primitives); ``mailbox[i] == ray`` marks primitives already tested.
    Blocks of ``2**coarse`` x ``2**coarse`` cells (``ncx`` along x) have
    the z range of their items in ``czrange``: a ray passing above or below
    it crosses the block in one step (rays to the sky walk few cells).
    """
    kind, params, hit, aabb, glob, bounds, cell, nx, ny = world[:9]
    start, items, boxes, zrange, coarse, ncx, czrange, ahead = world[9:]
    # inverse directions for the box tests (a huge number for a zero component)
    ix = 1.0 / dx if abs(dx) > _EPS else 1e300 * (1.0 if dx >= 0 else -1.0)
    iy = 1.0 / dy if abs(dy) > _EPS else 1e300 * (1.0 if dy >= 0 else -1.0)
    iz = 1.0 / dz if abs(dz) > _EPS else 1e300 * (1.0 if dz >= 0 else -1.0)
    best = tmax
    best_i = -1
    for g in range(glob.shape[0]):
        i = glob[g]
        if kind[i] == PROFILE or _box_overlap(
            aabb, i, ox, oy, oz, ix, iy, iz, tmin, best
        ):
            t = _try(
                kind, params, hit, i, ox, oy, oz, dx, dy, dz, tmin, best, seed, ray
            )
            if t < best:
                best = t
                best_i = i
    t0, t1 = _clip(ox, dx, bounds[0], bounds[3], tmin, best)
    t0, t1 = _clip(oy, dy, bounds[1], bounds[4], t0, t1)
    t0, t1 = _clip(oz, dz, bounds[2], bounds[5], t0, t1)
    if t0 > t1:
        return best_i, best
    x0, y0 = bounds[0], bounds[1]
    cx, cy, sx, sy, nxt_x, nxt_y, dtx, dty = _enter(
        ox, oy, dx, dy, t0, x0, y0, cell, nx, ny
    )
    span = cell * (1 << coarse)
    t_enter = t0
    last = -1
    while True:
        # a coarse cell whose items the ray passes above or below is crossed
        # in one step
        cc = (cy >> coarse) * ncx + (cx >> coarse)
        if cc != last:
            last = cc
            t_out = min(t1, best)
            if dx > _EPS:
                t_out = min(t_out, (x0 + ((cx >> coarse) + 1) * span - ox) / dx)
            elif dx < -_EPS:
                t_out = min(t_out, (x0 + (cx >> coarse) * span - ox) / dx)
            if dy > _EPS:
                t_out = min(t_out, (y0 + ((cy >> coarse) + 1) * span - oy) / dy)
            elif dy < -_EPS:
                t_out = min(t_out, (y0 + (cy >> coarse) * span - oy) / dy)
            za = oz + t_enter * dz
            # above everything ahead and rising, or below and falling: done
            q = (2 if dx < 0.0 else 0) + (1 if dy < 0.0 else 0)
            if (dz >= 0.0 and za > ahead[q, cc, 1]) or (
                dz <= 0.0 and za < ahead[q, cc, 0]
            ):
                break
            zb = oz + t_out * dz
            if max(za, zb) < czrange[cc, 0] or min(za, zb) > czrange[cc, 1]:
                if t_out >= min(t1, best):
                    break
                t_next = t_out + 1e-7
                px = ox + t_next * dx
                py = oy + t_next * dy
                if not (x0 <= px < x0 + nx * cell and y0 <= py < y0 + ny * cell):
                    break
                jx, jy, sx, sy, nxt_x, nxt_y, dtx, dty = _enter(
                    ox, oy, dx, dy, t_next, x0, y0, cell, nx, ny
                )
                if (jy >> coarse) * ncx + (jx >> coarse) != cc:
                    cx, cy, t_enter = jx, jy, t_out
                    continue
                # rounding kept the ray in the same coarse cell: walk it
                cx, cy = jx, jy
        c = cy * nx + cx
        t_exit = min(nxt_x, nxt_y)
        # the ray's heights in the cell, against those of the cell's items
        za = oz + t_enter * dz
        zb = oz + min(t_exit, best) * dz
        if max(za, zb) >= zrange[c, 0] and min(za, zb) <= zrange[c, 1]:
            for j in range(start[c], start[c + 1]):
                i = items[j]
                if mailbox[i] == ray:
                    continue
                mailbox[i] = ray
                if not _box_overlap(boxes, j, ox, oy, oz, ix, iy, iz, tmin, best):
                    continue
                t = _try(
                    kind, params, hit, i, ox, oy, oz, dx, dy, dz, tmin, best, seed, ray
                )
                if t < best:
                    best = t
                    best_i = i
        if best <= t_exit or t_exit >= t1:
            break
        t_enter = t_exit
        if nxt_x < nxt_y:
            cx += sx
            if cx < 0 or cx >= nx:
                break
            nxt_x += dtx
        else:
            cy += sy
            if cy < 0 or cy >= ny:
                break
            nxt_y += dty
    return best_i, best


# ---------------------------------------------------------------------------
# scan patterns and the scan loop

MOBILE, AERIAL, UGV = 0, 1, 2

# fp of MOBILE: x_start, y_lane, z_lane_at_x0, slope, height, speed, rate,
#   n_per_rotation, n_rotations, n_scanners, cos_blind
# fa of MOBILE, one row of MOBILE_ROW per scanner: cos and sin of the azimuth
#   of the scan plane from the heading, mount offsets (forward, left, up),
#   time offset
# ft of MOBILE: cos, sin of the angle of pulse j in the rotation (n_per x 2)
MOBILE_ROW = 6
# fp of AERIAL: altitude, speed, line_rate, (unused), n_passes
# fa of AERIAL, one row of AERIAL_ROW per pass (a channel of a flight line):
#   y of the line, heading (+1, -1), x at the first line, first row of ft,
#   forward tilt of the scan plane (rad), pulses per line, number of lines,
#   first pulse of the pass, time offset
# ft of AERIAL: sin, cos of the scan angles of every pass, one after another
AERIAL_ROW = 9
# fp of UGV: x, y, z, n_azimuths, rate
# fa of UGV: cos, sin of the beam elevations (n_beams x 2)
# ft of UGV: cos, sin of the azimuths (n_azimuths x 2)


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def pulse_ray(code, fp, fa, ft, k):
    """``(ok, ox, oy, oz, dx, dy, dz, time, channel)`` of pulse ``k``."""
    if code == MOBILE:
        n_per = int(fp[7])
        per_scanner = n_per * int(fp[8])
        s = k // per_scanner
        rem = k - s * per_scanner
        r = rem // n_per
        j = rem - r * n_per
        row = s * MOBILE_ROW
        ca, sa = ft[2 * j], ft[2 * j + 1]
        if -sa > fp[10]:  # inside the cone hidden by the vehicle
            return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0
        time = (r + j / n_per) / fp[6] + fa[row + 5]
        slope = fp[3]
        norm = math.sqrt(1.0 + slope * slope)
        fx, fz = 1.0 / norm, slope / norm  # forward (pitched with the road)
        ux, uz = -slope / norm, 1.0 / norm  # up
        x = fp[0] + fp[5] * time
        ox = x + fa[row + 2] * fx + fa[row + 4] * ux
        oy = fp[1] + fa[row + 3]
        oz = fp[2] + slope * x + fp[4] + fa[row + 2] * fz + fa[row + 4] * uz
        cpsi, spsi = fa[row], fa[row + 1]
        # in-plane horizontal direction h = cos(psi) forward + sin(psi) left
        dx = ca * cpsi * fx + sa * ux
        dy = ca * spsi
        dz = ca * cpsi * fz + sa * uz
        return True, ox, oy, oz, dx, dy, dz, time, s
    if code == AERIAL:
        n_pass = int(fp[4])
        p = 0
        for q in range(n_pass):
            if k >= fa[q * AERIAL_ROW + 7]:
                p = q
        row = p * AERIAL_ROW
        rem = k - int(fa[row + 7])
        n_per = int(fa[row + 5])
        line = rem // n_per
        j = rem - line * n_per
        heading = fa[row + 1]
        t_line = line / fp[2]
        sb, cb = ft[2 * (int(fa[row + 3]) + j)], ft[2 * (int(fa[row + 3]) + j) + 1]
        ox = fa[row + 2] + heading * fp[1] * t_line
        oy = fa[row + 0]
        oz = fp[0]
        tilt = fa[row + 4]
        ct = math.cos(tilt)
        dx = heading * math.sin(tilt)
        return True, ox, oy, oz, dx, sb * ct, -cb * ct, t_line + fa[row + 8], p
    # UGV
    nb = fa.shape[0] // 2
    f = k // nb
    b = k - f * nb
    ce, se = fa[2 * b], fa[2 * b + 1]
    time = f / (fp[3] * fp[4])
    return True, fp[0], fp[1], fp[2], ce * ft[2 * f], ce * ft[2 * f + 1], se, time, b


@njit(cache=True, nogil=True, _nrt=False, inline="always")
def _gauss(gauss, h, shift):
    """A standard normal number: 16 bits of a hash index a table of quantiles."""
    return gauss[(h >> np.uint64(shift)) & np.uint64(0xFFFF)]


# Speed: the kernels allocate nothing and are compiled with _nrt=False, so
# that no reference counting of the array arguments happens on each call
# (a third of the time otherwise); the walk (cast) and the small helpers are
# inlined into the loop (another third), the intersections are not (they
# would multiply the compile time by five for a few per cent).
@njit(cache=True, nogil=True, _nrt=False)
def simulate(pattern, beam, gauss, k0, k1, seed, world, mailbox, interest, out):
    """Cast pulses ``k0 .. k1 - 1``; returns the number of returns written.

    ``pattern`` is ``(code, fp, fa, ft)`` (see :func:`pulse_ray`), ``beam``
    ``(min_range, max_range, noise, divergence, drop, max_returns,
    separation)``, ``world`` the scene and its grid (see :func:`cast`) and
    ``out`` the arrays ``(xyz, prim, range, time, channel, return)`` the
    returns are written to.
    Each ray's direction is jittered by ``divergence`` (standard deviation,
    radians, per axis), its first hit within ``[min_range, max_range]`` kept
    with probability ``1 - drop`` and its range perturbed by Gaussian
    ``noise`` (metres) along the ray. ``gauss`` holds the standard normal
    quantiles at ``(i + 0.5) / 65536``; one 64-bit hash per pulse gives the
    four normal numbers of its jitter and noise. Up to ``max_returns``
    echoes per pulse (at most 8): after a hit on a primitive of hit
    probability below 1 the beam goes on from ``separation`` metres behind
    it; ``out_return`` is the echo's number along the beam, from 1.

    A non-empty ``interest`` (boxes ``(m, 6)``) skips the rays that meet
    none of these boxes within range and ends the others where they leave
    the last box they cross: exact for whatever lies inside the boxes (the
    objects :func:`~skpcd.datasets.make_street_objects` keeps).
    """
    code, fp, fa, ft = pattern
    min_range, max_range, noise, divergence, drop, max_returns, separation = beam
    out_xyz, out_prim, out_range, out_time, out_channel, out_return = out
    hit = world[2]
    n = 0
    n_interest = interest.shape[0]
    for k in range(k0, k1):
        ok, ox, oy, oz, dx, dy, dz, time, channel = pulse_ray(code, fp, fa, ft, k)
        if not ok:
            continue
        h = hash64(seed, k, SALT_NOISE)
        if divergence > 0.0:
            dx += divergence * _gauss(gauss, h, 0)
            dy += divergence * _gauss(gauss, h, 16)
            dz += divergence * _gauss(gauss, h, 32)
            norm = math.sqrt(dx * dx + dy * dy + dz * dz)
            dx, dy, dz = dx / norm, dy / norm, dz / norm
        t_end = max_range
        if n_interest:
            # the far end of the wanted boxes the ray crosses: no return
            # beyond it is kept, so the walk stops there
            ix = 1.0 / dx if abs(dx) > _EPS else 1e300
            iy = 1.0 / dy if abs(dy) > _EPS else 1e300
            iz = 1.0 / dz if abs(dz) > _EPS else 1e300
            first = 0
            while first < n_interest and (
                _box_exit(interest, first, ox, oy, oz, ix, iy, iz, min_range, max_range)
                < 0.0
            ):
                first += 1
            if first == n_interest:
                continue
            t_end = -1.0
            for b in range(first, n_interest):
                t_end = max(
                    t_end,
                    _box_exit(
                        interest, b, ox, oy, oz, ix, iy, iz, min_range, max_range
                    ),
                )
            if t_end < 0.0:
                continue
        # the echoes of the pulse: behind a partly transparent primitive
        # (foliage, glass, mesh) the beam goes on and may return again
        t_from = min_range
        ray_id = k
        for r in range(max_returns):
            i, t = cast(
                ox, oy, oz, dx, dy, dz, t_from, t_end, world, mailbox, ray_id, seed
            )
            if i < 0:
                break
            if drop <= 0.0 or uniform(seed, k, SALT_DROP + 16 * r) >= drop:
                if noise > 0.0:
                    if r == 0:
                        g = _gauss(gauss, h, 48)
                    else:
                        g = _gauss(gauss, hash64(seed, k, SALT_NOISE + 16 * r), 0)
                    tr = t + noise * g
                else:
                    tr = t
                out_xyz[n, 0] = ox + tr * dx
                out_xyz[n, 1] = oy + tr * dy
                out_xyz[n, 2] = oz + tr * dz
                out_prim[n] = i
                out_range[n] = tr
                out_time[n] = time
                out_channel[n] = channel
                out_return[n] = r + 1
                n += 1
            if hit[i] >= 1.0:
                break
            t_from = t + separation
            # ids of later echoes: negative, never a pulse number nor -1
            ray_id = -(k * 8 + r + 1) - 2
    return n


@njit(cache=True, nogil=True, _nrt=False)
def cast_rays(origins, directions, tmin, tmax, seed, world, mailbox, out_prim, out_t):
    """First hit of each given ray (unit directions): primitive and distance.

    ``world`` is the scene and its grid (see :func:`cast`). Ray ``r`` has
    id ``r`` for the hit-probability draws; ``out_prim`` is -1 and ``out_t``
    inf where nothing is hit within ``(tmin, tmax)``.
    """
    for r in range(origins.shape[0]):
        o, d = origins[r], directions[r]
        i, t = cast(
            o[0], o[1], o[2], d[0], d[1], d[2], tmin, tmax, world, mailbox, r, seed
        )
        out_prim[r] = i
        out_t[r] = t if i >= 0 else np.inf
