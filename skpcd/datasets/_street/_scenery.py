"""What stands along a simulated street besides its objects: buildings
(facades with windows, doors, balconies and setbacks) and overhead wires, as
analytic primitives in their own frames."""

import itertools

import numpy as np

from skpcd.datasets._street._catalogue import _pick, _u
from skpcd.datasets._street._primitives import Parts, rot_x

__all__ = ["building", "wire"]


def building(rng, width, base_depth=0.0):
    """A building in its own frame: facade line ``y = 0`` facing ``-y``.

    ``x`` runs along the street from ``-width / 2`` to ``width / 2``, ``y``
    into the building, ``z`` up from the lowest ground in front of it (the
    walls reach ``base_depth`` below, hidden by the ground where it rises).
    Facade segments with setbacks (recesses), window grids with reveals and
    glass, a ground floor with shop windows or doors, floor slabs and a
    back wall seen through the windows, side walls, balconies, and a flat
    or gabled roof.
    """
    floors = int(rng.choice([1, 2, 2, 3, 3, 4, 5, 6]))
    gf = _u(rng, 3.2, 4.5)
    fh = _u(rng, 2.8, 3.4)
    height = gf + (floors - 1) * fh
    depth = _u(rng, 8.0, 15.0)
    thick = _u(rng, 0.15, 0.35)  # wall thickness = window reveal depth
    glass = _u(rng, 0.15, 0.5)
    parts = Parts()
    # facade segments
    n_seg = int(rng.choice([1, 1, 2, 3]))
    cuts = (
        np.sort(rng.uniform(-width / 2 + 2, width / 2 - 2, n_seg - 1))
        if (width > 6 and n_seg > 1)
        else np.array([])
    )
    edges = np.concatenate([[-width / 2], cuts, [width / 2]])
    setbacks = [0.0 if rng.random() < 0.6 else _u(rng, 0.3, 1.5) for _ in edges[:-1]]
    period = _u(rng, 2.2, 3.5)
    win_w = _u(rng, 0.9, min(1.7, period - 0.5))
    win_h = _u(rng, 1.2, 1.8)
    sill = _u(rng, 0.8, 1.0)
    shop = rng.random() < 0.5
    zb = -base_depth
    for (xa, xb), sb in zip(itertools.pairwise(edges), setbacks):
        w = xb - xa
        xc = (xa + xb) / 2
        n_cols = max(0, int((w - 0.6) // period))
        first = -(n_cols * period) / 2 + (period - win_w) / 2
        # upper floors
        up_h = height - gf
        if up_h > 0:
            parts.wall(
                (xc, sb + thick / 2, gf + up_h / 2),
                (w / 2, thick / 2, up_h / 2),
                (first, period, win_w, n_cols, -up_h / 2 + sill, fh, win_h, floors - 1),
                glass=glass,
            )
        # ground floor: shop windows or windows and a door, from base_depth below
        g_h = gf + base_depth
        if shop:
            sp = _u(rng, 2.8, 4.5)
            sw = sp - _u(rng, 0.4, 0.8)
            nc = max(1, int((w - 0.4) // sp))
            win = (
                -(nc * sp) / 2 + (sp - sw) / 2,
                sp,
                sw,
                nc,
                -g_h / 2 + base_depth + _u(rng, 0.2, 0.6),
                10.0,
                gf - _u(rng, 0.8, 1.2) - 0.4,
                1,
            )
        else:
            win = (
                first,
                period,
                win_w,
                n_cols,
                -g_h / 2 + base_depth + sill,
                10.0,
                win_h,
                1,
            )
        parts.wall(
            (xc, sb + thick / 2, zb + g_h / 2),
            (w / 2, thick / 2, g_h / 2),
            win,
            glass=glass,
        )
        # balconies on some upper floors
        if floors > 2 and rng.random() < 0.25 and n_cols > 0:
            bd = _u(rng, 0.9, 1.5)
            for f in range(1, floors):
                z = gf + (f - 1) * fh
                parts.box((xc, sb - bd / 2, z), (w * 0.35, bd / 2, 0.08))
                parts.box(
                    (xc, sb - bd + 0.02, z + 0.5), (w * 0.35, 0.02, 0.45), hit=0.6
                )
    # returns of the recesses, between segments of different setback
    for x, s0, s1 in zip(cuts, setbacks[:-1], setbacks[1:]):
        if abs(s0 - s1) > 0.01:
            lo, hi = min(s0, s1), max(s0, s1)
            parts.box(
                (x, (lo + hi) / 2, (zb + height) / 2),
                (0.1, (hi - lo) / 2, (height - zb) / 2),
            )
    back = max(setbacks) + thick
    room = _u(rng, 3.0, 6.0)
    # what the windows show: floor slabs, and the back of the rooms
    parts.box(
        (0, back + room + (depth - back - room) / 2, (zb + height) / 2),
        (width / 2, max(depth - back - room, 0.3) / 2, (height - zb) / 2),
    )
    for f in range(floors):
        z = gf + (f - 1) * fh if f else 0.0
        parts.box((0, back + room / 2, z - 0.1), (width / 2 - 0.1, room / 2, 0.1))
    # side walls (visible in the gaps between buildings and from above)
    for sx in (-1, 1):
        parts.box(
            (sx * (width / 2 - 0.15), depth / 2, (zb + height) / 2),
            (0.15, depth / 2, (height - zb) / 2),
        )
    roof = _pick(rng, ("flat", "gabled"), p=(0.6, 0.4))
    top = height
    if roof == "flat":
        parts.box((0, depth / 2, height + 0.15), (width / 2, depth / 2, 0.15))
        parts.box((0, 0.15, height + 0.5), (width / 2, 0.15, 0.2))  # parapet
        top = height + 0.7
    else:
        pitch = _u(rng, 0.45, 0.8)
        half = depth / 2 / np.cos(pitch)
        rise = depth / 2 * np.tan(pitch)
        for sy in (-1, 1):
            c = (0, depth / 2 + sy * depth / 4, height + rise / 2)
            parts.box(c, (width / 2 + 0.2, half / 2 + 0.15, 0.12), rot_x(-sy * pitch))
        # gable ends
        for sx in (-1, 1):
            parts.box(
                (sx * (width / 2 - 0.15), depth / 2, height + rise / 3),
                (0.15, depth / 4, rise / 3),
            )
        top = height + rise
    return parts, {
        "width": width,
        "depth": depth,
        "height": top,
        "floors": floors,
        "roof": roof,
        "shop_front": shop,
        "setbacks": [float(s) for s in setbacks],
        "window_period": period,
    }


def wire(a, b, sag, radius=0.02, n_segments=8):
    """A hanging wire from a to b (a parabola of ``sag`` metres), as segments.

    The radius is the wire's *effective* one: real beams are several
    centimetres wide and return from wires thinner than that.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    s = np.linspace(0, 1, n_segments + 1)
    pts = a + s[:, None] * (b - a)
    pts[:, 2] -= 4 * sag * s * (1 - s)
    parts = Parts()
    for p, q in itertools.pairwise(pts):
        parts.cylinder(p, q, radius)
    return parts
