"""Street objects as analytic primitives, one builder per class.

Every builder takes a random generator and returns ``(parts, params)``: the
object's :class:`~skpcd.datasets._street._primitives.Parts` in its own
frame (origin at its base on the ground, ``+x`` towards the road, ``+y``
along the street, ``z`` up; a car's ``+x`` is its length) and a dict of the
shape parameters drawn (what the ``frame`` of a scene reports). The ranges
follow street furniture as it stands in European and North American towns;
they overlap between classes as real ones do (a 4 m street light is as
tall as a lamp post, a sign board hangs on many light poles).
"""

import numpy as np

from skpcd.datasets._street._primitives import Parts, rot_y, rot_z

__all__ = ["BUILDERS", "OBJECT_CLASSES", "POLE_CLASSES"]

# the pole-like classes: a pole, and what it carries
POLE_CLASSES = (
    "pole",
    "lamp_post",
    "street_light",
    "traffic_light",
    "pedestrian_signal",
    "traffic_sign",
)
# classes of objects a scene is made of (ground, facade and wire besides)
OBJECT_CLASSES = (*POLE_CLASSES, "tree", "car", "bush", "other", "fence", "person")


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


def _pick(rng, options, p=None):
    return options[int(rng.choice(len(options), p=p))]


def _plate(parts, center, shape, width, height, thickness=0.025, yaw=0.0):
    """A sign plate facing +-y (its normal along y, turned by ``yaw``)."""
    c = np.asarray(center, float)
    rot = rot_z(yaw)
    t = thickness / 2
    if shape in ("round", "octagon"):
        n = rot @ np.array([0.0, t, 0.0])
        parts.cylinder(c - n, c + n, width / 2)
    elif shape == "diamond":
        s = width / np.sqrt(2)
        parts.box(c, (s / 2, t, s / 2), rot @ rot_y(np.pi / 4))
    elif shape in ("triangle", "triangle_down"):
        # an equilateral triangle as four strips of decreasing width
        n_strips, h = 4, width * np.sqrt(3) / 2
        for i in range(n_strips):
            frac = (i + 0.5) / n_strips
            w = width * (1 - frac)
            dz = -h / 2 + h * (i + 0.5) / n_strips
            if shape == "triangle_down":
                dz = -dz
            parts.box(c + rot @ np.array([0.0, 0.0, dz]), (w / 2, t, h / 8), rot)
    else:  # rectangle
        parts.box(c, (width / 2, t, height / 2), rot)


def _head_box(parts, center, width, depth, height, facing_x=False, backplate=False):
    """A signal head: a box facing the traffic (+-y) or the road (+x)."""
    if facing_x:
        half = (depth / 2, width / 2, height / 2)
    else:
        half = (width / 2, depth / 2, height / 2)
    parts.box(center, half)
    if backplate:
        grow = 0.12
        c = np.asarray(center, float)
        if facing_x:
            parts.box(
                c - [depth / 2 + 0.01, 0, 0],
                (0.01, width / 2 + grow, height / 2 + grow),
            )
        else:
            parts.box(
                c - [0, depth / 2 + 0.01, 0],
                (width / 2 + grow, 0.01, height / 2 + grow),
            )


def _attached_sign(rng, parts, post_r, z_lo, z_hi):
    """A sign board on the side of a light pole (He et al., 2017)."""
    shape = _pick(rng, ("rectangle", "round", "triangle", "rectangle"))
    w = _u(rng, 0.4, 0.8)
    h = _u(rng, 0.3, 0.7) if shape == "rectangle" else w
    z = _u(rng, z_lo, z_hi)
    side = _pick(rng, (-1.0, 1.0))
    _plate(parts, (0.0, side * (post_r + 0.05), z), shape, w, h)
    return {"shape": shape, "width": w, "z": z}


def pole(rng):
    """A bare pole: steel, wooden utility or concrete, sometimes a crossarm."""
    kind = _pick(rng, ("steel", "wood", "concrete"), p=(0.45, 0.35, 0.2))
    if kind == "steel":
        h, r0 = _u(rng, 2.5, 7.0), _u(rng, 0.04, 0.09)
        r1 = r0 * _u(rng, 0.8, 1.0)
    elif kind == "wood":
        h, r0 = _u(rng, 7.0, 10.5), _u(rng, 0.11, 0.16)
        r1 = r0 * _u(rng, 0.7, 0.9)
    else:
        h, r0 = _u(rng, 6.0, 10.0), _u(rng, 0.12, 0.18)
        r1 = r0 * _u(rng, 0.55, 0.8)
    parts = Parts().cylinder((0, 0, 0), (0, 0, h), r0, r1)
    crossarm = kind == "wood" and rng.random() < 0.4
    if crossarm:
        w = _u(rng, 1.2, 2.0)
        parts.box((0.0, 0.0, h - 0.3), (0.05, w / 2, 0.05))
    return parts, {"kind": kind, "height": h, "radius": r0, "crossarm": crossarm}


def _lantern(rng, parts, z, style):
    if style == "globe":
        r = _u(rng, 0.18, 0.3)
        parts.ellipsoid((0, 0, z + r), r)
        return z + 2 * r
    if style == "lantern":
        w, h = _u(rng, 0.28, 0.45), _u(rng, 0.4, 0.65)
        parts.box((0, 0, z + h / 2), (w / 2, w / 2, h / 2))
        parts.cylinder((0, 0, z + h), (0, 0, z + h + 0.25 * w + 0.05), 0.75 * w, 0.05)
        return z + h + 0.25 * w
    if style == "cylinder":
        r, h = _u(rng, 0.12, 0.25), _u(rng, 0.35, 0.8)
        parts.cylinder((0, 0, z), (0, 0, z + h), r)
        return z + h
    # mushroom / top-hat: a wide flat cone
    r, h = _u(rng, 0.25, 0.45), _u(rng, 0.15, 0.35)
    parts.cylinder((0, 0, z), (0, 0, z + h), 0.06, r)
    return z + h


def lamp_post(rng):
    """A 3-5 m post with one lantern on top (or two on a short bracket)."""
    h = _u(rng, 3.0, 5.0)
    r = _u(rng, 0.045, 0.09)
    parts = Parts()
    plinth = rng.random() < 0.5
    if plinth:
        hb = _u(rng, 0.3, 0.9)
        parts.cylinder((0, 0, 0), (0, 0, hb), _u(rng, 0.12, 0.2), r * 1.3)
        parts.cylinder((0, 0, hb), (0, 0, h), r * 1.3, r)
    else:
        parts.cylinder((0, 0, 0), (0, 0, h), r, r * _u(rng, 0.8, 1.0))
    style = _pick(rng, ("globe", "lantern", "cylinder", "mushroom"))
    double = rng.random() < 0.2
    if double:
        arm = _u(rng, 0.3, 0.6)
        parts.cylinder((-arm, 0, h), (arm, 0, h), 0.03)
        for side in (-1, 1):
            sub = Parts()
            _lantern(rng, sub, 0.0, style)
            parts.extend(sub.placed(np.eye(3), (side * arm, 0, h - 0.05)))
        top = h + 0.6
    else:
        top = _lantern(rng, parts, h, style)
    params = {"height": top, "post_height": h, "lantern": style, "double": double}
    if rng.random() < 0.15:
        params["sign"] = _attached_sign(rng, parts, r, 1.8, min(2.6, h - 0.5))
    return parts, params


def _luminaire(rng, parts, end, style, yaw=0.0):
    e = np.asarray(end, float)
    rot = rot_z(yaw)
    if style == "flat":
        length, width, th = _u(rng, 0.5, 0.85), _u(rng, 0.22, 0.4), _u(rng, 0.08, 0.16)
        parts.box(
            e + rot @ [length / 2 - 0.1, 0, -th / 2],
            (length / 2, width / 2, th / 2),
            rot @ rot_y(_u(rng, -0.1, 0.1)),
        )
    elif style == "cobra":
        a, b, c = _u(rng, 0.3, 0.45), _u(rng, 0.14, 0.22), _u(rng, 0.09, 0.15)
        parts.ellipsoid(e + rot @ [a * 0.7, 0, -c * 0.6], (a, b, c), rot)
    else:  # hanging drum or bowl
        r, h = _u(rng, 0.2, 0.35), _u(rng, 0.2, 0.45)
        parts.cylinder(e, e - [0, 0, 0.15], 0.02)
        parts.cylinder(e - [0, 0, 0.15], e - [0, 0, 0.15 + h], r * 0.6, r)


def street_light(rng):
    """A 6-12 m tapered pole with one or two arms and luminaire heads."""
    h = _u(rng, 6.0, 12.0)
    r0 = _u(rng, 0.075, 0.14)
    r1 = r0 * _u(rng, 0.45, 0.8)
    parts = Parts().cylinder((0, 0, 0), (0, 0, h), r0, r1)
    shape = _pick(rng, ("straight", "curved", "post_top"), p=(0.5, 0.35, 0.15))
    style = _pick(rng, ("flat", "cobra", "drum"), p=(0.45, 0.4, 0.15))
    n_arms = 1 if rng.random() < 0.7 else 2
    arm = _u(rng, 0.5, 3.0)
    rise = _u(rng, 0.0, 0.25)
    ra = _u(rng, 0.03, 0.055)
    for i in range(n_arms):
        yaw = 0.0 if i == 0 else np.pi + _u(rng, -0.1, 0.1)
        rot = rot_z(yaw)
        if shape == "post_top":
            parts.cylinder((0, 0, h), (0, 0, h + 0.3), r1, r1 * 0.8)
            end = np.array([0.0, 0.0, h + 0.3])
            if i == 0:
                sub = Parts()
                _lantern(rng, sub, 0.0, _pick(rng, ("cylinder", "mushroom", "globe")))
                parts.extend(sub.placed(np.eye(3), end))
            break
        if shape == "straight":
            a = np.array([0.0, 0.0, h - 0.25])
            end = a + rot @ [arm, 0, arm * rise]
            parts.cylinder(a, end, ra)
        else:  # a curved arm as three segments: up, bend, out
            a = np.array([0.0, 0.0, h - 0.1])
            b = a + rot @ [arm * 0.25, 0, 0.45]
            c = b + rot @ [arm * 0.35, 0, 0.12]
            end = c + rot @ [arm * 0.4, 0, -0.02]
            parts.cylinder(a, b, ra).cylinder(b, c, ra).cylinder(c, end, ra)
        _luminaire(rng, parts, end, style, yaw)
    params = {
        "height": h,
        "radius": r0,
        "arm_shape": shape,
        "arms": 0 if shape == "post_top" else n_arms,
        "arm_length": 0.0 if shape == "post_top" else arm,
        "luminaire": style,
    }
    if rng.random() < 0.25:
        params["sign"] = _attached_sign(rng, parts, r0, 2.0, 3.2)
    if rng.random() < 0.1:  # a banner
        zb = _u(rng, 4.0, min(6.5, h - 1.0))
        parts.box((-0.4, 0.0, zb), (0.35, 0.01, 0.7))
        params["banner"] = zb
    return parts, params


def traffic_light(rng):
    """A pole with signal heads; some with a mast arm over the road."""
    mast = rng.random() < 0.4
    r = _u(rng, 0.06, 0.11)
    h = _u(rng, 5.5, 7.5) if mast else _u(rng, 3.0, 4.5)
    parts = Parts().cylinder((0, 0, 0), (0, 0, h), r, r * _u(rng, 0.75, 1.0))
    w, d = _u(rng, 0.25, 0.35), _u(rng, 0.18, 0.3)
    hh = _u(rng, 0.75, 1.05)
    backplate = rng.random() < 0.4
    facing = _pick(rng, (-1.0, 1.0))
    n_pole = 1 if mast else int(rng.randint(1, 3))
    zs = []
    for i in range(n_pole):
        z = _u(rng, 2.3, 3.0) + i * (hh + 0.1)
        z = min(z, h - hh / 2 - 0.05)
        zs.append(z)
        _head_box(
            parts,
            (0.0, facing * (r + d / 2 + 0.05), z),
            w,
            d,
            hh,
            backplate=backplate,
        )
    params = {"height": h, "radius": r, "mast_arm": mast, "heads_on_pole": n_pole}
    if mast:
        arm = _u(rng, 3.0, 8.0)
        za = h - _u(rng, 0.3, 0.8)
        parts.cylinder((0, 0, za), (arm, 0, za + _u(rng, 0.0, 0.3)), r * 0.6, r * 0.35)
        n_arm = int(rng.randint(1, 4))
        for j in range(n_arm):
            x = arm * (0.45 + 0.5 * (j + 1) / (n_arm + 1))
            _head_box(parts, (x, 0.0, za - hh / 2 - 0.1), w, d, hh, backplate=backplate)
        if rng.random() < 0.4:  # a street-name board on the arm
            _plate(parts, (arm * 0.3, 0.0, za + 0.35), "rectangle", 1.2, 0.3)
        params.update(arm_length=arm, heads_on_arm=n_arm)
    if rng.random() < 0.6:  # push button
        parts.box((r + 0.06, 0, 1.1), (0.06, 0.06, 0.12))
    return parts, params


def pedestrian_signal(rng):
    """A post of about 3 m with one or two small signal boxes."""
    h = _u(rng, 2.6, 3.4)
    r = _u(rng, 0.045, 0.08)
    parts = Parts().cylinder((0, 0, 0), (0, 0, h), r)
    n = int(rng.randint(1, 3))
    w, d, hh = _u(rng, 0.22, 0.32), _u(rng, 0.15, 0.25), _u(rng, 0.45, 0.7)
    for i in range(n):
        yaw = 0.0 if i == 0 else np.pi  # both directions of the crossing
        c = rot_z(yaw) @ np.array([r + d / 2 + 0.03, 0.0, h - hh / 2 - 0.05])
        parts.box(c, (d / 2, w / 2, hh / 2), rot_z(yaw))
    button = rng.random() < 0.7
    if button:
        parts.box((0, r + 0.06, 1.1), (0.06, 0.06, 0.12))
    return parts, {"height": h, "radius": r, "boxes": n, "button": button}


def traffic_sign(rng):
    """A post with one to three plates of varied shape, size and height."""
    h = _u(rng, 2.0, 3.6)
    r = _u(rng, 0.025, 0.045)
    parts = Parts().cylinder((0, 0, 0), (0, 0, h), r)
    n = int(rng.choice([1, 1, 2, 2, 3]))
    yaw = _u(rng, -0.25, 0.25) + _pick(rng, (0.0, np.pi))
    z = h
    plates = []
    for _ in range(n):
        shape = _pick(
            rng,
            ("round", "triangle", "triangle_down", "rectangle", "diamond", "octagon"),
            p=(0.3, 0.2, 0.05, 0.3, 0.07, 0.08),
        )
        w = _u(rng, 0.45, 0.9) if shape != "rectangle" else _u(rng, 0.3, 1.2)
        hp = _u(rng, 0.2, 1.0) if shape == "rectangle" else w
        if shape.startswith("triangle"):
            hp = w * np.sqrt(3) / 2
        c = (0.0, 0.0, z - hp / 2) + rot_z(yaw) @ np.array([0.0, -(r + 0.03), 0.0])
        _plate(parts, c, shape, w, hp, yaw=yaw)
        plates.append({"shape": shape, "width": w, "height": hp})
        z -= hp + _u(rng, 0.02, 0.15)
    return parts, {"height": h, "radius": r, "plates": plates}


def tree(rng):
    """A trunk, branches and a crown of foliage clusters (partly transparent)."""
    kind = _pick(
        rng, ("broadleaf", "columnar", "conifer", "young"), p=(0.55, 0.15, 0.12, 0.18)
    )
    if kind == "broadleaf":
        height = _u(rng, 6.0, 16.0)
        crown_r = float(np.clip(height * _u(rng, 0.22, 0.38), 1.5, 5.0))
        base = _u(rng, 2.0, 3.5)
    elif kind == "columnar":
        height = _u(rng, 6.0, 14.0)
        crown_r, base = _u(rng, 0.8, 1.6), _u(rng, 1.5, 2.5)
    elif kind == "conifer":
        height = _u(rng, 5.0, 14.0)
        crown_r, base = _u(rng, 1.2, 2.8), _u(rng, 0.4, 1.5)
    else:
        height = _u(rng, 3.5, 6.0)
        crown_r, base = _u(rng, 0.6, 1.4), _u(rng, 1.8, 2.3)
    crown_h = height - base
    trunk_r = 0.03 + height * _u(rng, 0.01, 0.02)
    leaf_off = kind != "conifer" and rng.random() < 0.15
    p_hit = _u(rng, 0.06, 0.12) if leaf_off else _u(rng, 0.35, 0.7)
    lean = rng.normal(0, 0.03, 2)
    top = np.array([lean[0] * height, lean[1] * height, base + 0.45 * crown_h])
    parts = Parts().cylinder((0, 0, 0), top, trunk_r, trunk_r * 0.55)
    center = np.array([top[0] * 1.5, top[1] * 1.5, base + crown_h / 2])
    n_branch = int(rng.randint(3, 7)) + (5 if leaf_off else 0)
    for _ in range(n_branch):
        a = _u(rng, 0, 2 * np.pi)
        z0 = _u(rng, base, base + 0.4 * crown_h)
        start = np.array([top[0] * z0 / top[2], top[1] * z0 / top[2], z0])
        reach = _u(rng, 0.5, 0.85) * crown_r
        out = np.array([np.cos(a), np.sin(a), 0.0]) * reach
        end = center + out + [0.0, 0.0, _u(rng, -0.1, 0.4) * crown_h]
        parts.cylinder(start, end, trunk_r * _u(rng, 0.25, 0.45), trunk_r * 0.1)
    n_cl = int(np.clip(12 + 4.0 * crown_r * crown_h, 12, 160))
    if kind == "conifer":
        z = base + crown_h * rng.uniform(0, 1, n_cl) ** 1.3
        rad = crown_r * (height - z) / crown_h * np.sqrt(rng.uniform(0.2, 1, n_cl))
        ang = rng.uniform(0, 2 * np.pi, n_cl)
        cen = np.column_stack([rad * np.cos(ang), rad * np.sin(ang), z])
        cen[:, :2] += center[:2]
    else:
        v = rng.normal(size=(n_cl, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        v[:, 2] = np.where(v[:, 2] < -0.6, -v[:, 2] * 0.5, v[:, 2])  # few below
        depth = rng.uniform(0.3, 1.0, n_cl) ** 0.35
        cen = center + v * depth[:, None] * [
            crown_r * 0.8,
            crown_r * 0.8,
            crown_h * 0.4,
        ]
    size = np.clip(0.3 + 0.12 * crown_r, 0.35, 0.9)
    radii = size * rng.uniform(0.6, 1.3, (n_cl, 1)) * [1.0, 1.0, 0.75]
    for c, rr in zip(cen, radii):
        parts.ellipsoid(
            c, rr * rng.uniform(0.8, 1.2, 3), rot_z(_u(rng, 0, np.pi)), hit=p_hit
        )
    return parts, {
        "kind": kind,
        "height": height,
        "crown_radius": crown_r,
        "crown_base": base,
        "trunk_radius": trunk_r,
        "leaf_off": leaf_off,
        "foliage_hit_probability": p_hit,
        "clusters": n_cl,
    }


# the kinds of car: the ranges of their length, width, body height and cabin
# height (m; a van's body is its cabin, and it has none above), their ground
# clearance (m), the cabin's length and its shift from the middle, as
# fractions of the length
_CARS = {
    "sedan": (4.3, 5.0, 1.72, 1.88, 0.55, 0.7, 0.42, 0.52, 0.16, 0.48, -0.04),
    "hatchback": (3.6, 4.2, 1.62, 1.78, 0.55, 0.7, 0.45, 0.55, 0.15, 0.56, -0.1),
    "suv": (4.4, 4.9, 1.82, 2.0, 0.75, 0.9, 0.5, 0.62, 0.22, 0.6, -0.08),
    "van": (4.8, 5.8, 1.9, 2.05, 1.55, 2.0, 0.0, 0.0, 0.2, 0.0, 0.0),
}


def car(rng):
    """A parked car: body, cabin with glass, roof, wheels (``+x`` its length)."""
    kind = _pick(rng, ("sedan", "hatchback", "suv", "van"), p=(0.4, 0.3, 0.2, 0.1))
    l0, l1, w0, w1, b0, b1, c0, c1, clear, cab_len, shift = _CARS[kind]
    L, W, body = _u(rng, l0, l1), _u(rng, w0, w1), _u(rng, b0, b1)
    cabin = _u(rng, c0, c1) if c1 > 0 else 0.0
    glass = _u(rng, 0.35, 0.65)
    parts = Parts()
    zb = clear + body / 2
    if kind == "van":
        bonnet = _u(rng, 0.5, 0.8)
        parts.box((-bonnet / 2, 0, zb), ((L - bonnet) / 2, W / 2, body / 2))
        parts.box((L / 2 - bonnet / 2, 0, clear + 0.4), (bonnet / 2, W / 2 - 0.05, 0.4))
        # windscreen
        parts.box(
            (L / 2 - bonnet - 0.02, 0, clear + 0.8 + (body - 0.8) / 2),
            (0.03, W / 2 - 0.08, (body - 0.8) / 2),
            hit=glass,
        )
    else:
        parts.box((0, 0, zb), (L / 2, W / 2, body / 2))
        cl = L * cab_len
        cx = L * shift
        z0 = clear + body
        # side windows (glass) and a seat row inside, roof on top
        parts.box(
            (cx, 0, z0 + cabin / 2), (cl / 2, W / 2 - 0.08, cabin / 2 - 0.03), hit=glass
        )
        parts.box((cx, 0, z0 + cabin - 0.03), (cl / 2 - 0.05, W / 2 - 0.1, 0.03))
        parts.box((cx, 0, z0 + 0.2), (0.2, W / 2 - 0.2, 0.2))
        # sloped windscreen and rear window
        for sgn, ang in ((1, _u(rng, 0.9, 1.1)), (-1, _u(rng, 0.6, 1.0))):
            run = cabin / np.tan(ang)
            c = (cx + sgn * (cl / 2 + run / 2), 0.0, z0 + cabin / 2)
            tilt = rot_y(-sgn * (np.pi / 2 - ang))
            parts.box(c, (0.02, W / 2 - 0.1, cabin / 2 / np.sin(ang)), tilt, hit=glass)
    r = _u(rng, 0.3, 0.36) if kind != "van" else _u(rng, 0.33, 0.38)
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (L / 2 - 0.8), sy * (W / 2 - 0.13)
            parts.cylinder((x, y - 0.11, r), (x, y + 0.11, r), r)
    height = clear + body + cabin
    return parts, {"kind": kind, "length": L, "width": W, "height": height}


def bush(rng):
    """A round bush of a few dense clusters, or a hedge along the street."""
    hedge = rng.random() < 0.35
    p_hit = _u(rng, 0.5, 0.85)
    parts = Parts()
    if hedge:
        length, height, width = _u(rng, 2.0, 7.0), _u(rng, 0.6, 1.8), _u(rng, 0.5, 1.2)
        n = max(3, int(length / 0.7))
        for i in range(n):
            y = -length / 2 + length * (i + 0.5) / n
            parts.ellipsoid(
                (rng.normal(0, 0.05), y, height * 0.55),
                (
                    width / 2 * _u(rng, 0.9, 1.1),
                    0.55 * length / n * 1.6,
                    height * 0.5 * _u(rng, 0.9, 1.1),
                ),
                hit=p_hit,
            )
        return parts, {"kind": "hedge", "length": length, "height": height}
    height = _u(rng, 0.5, 2.0)
    spread = _u(rng, 0.4, 1.4)
    n = int(rng.randint(4, 12))
    for _ in range(n):
        r = _u(rng, 0.25, 0.6) * max(spread, 0.5)
        a, d = _u(rng, 0, 2 * np.pi), _u(rng, 0, spread * 0.6)
        z = float(
            np.clip(_u(rng, 0.4, 0.8) * height, r * 0.7, max(height - r * 0.6, r * 0.7))
        )
        parts.ellipsoid((d * np.cos(a), d * np.sin(a), z), (r, r, r * 0.8), hit=p_hit)
    return parts, {"kind": "round", "height": height, "spread": spread}


def other(rng):
    """Street clutter: bin, bench, bollards, cabinet, column, rack, planter,
    meter, and road works: cones, barriers, drums."""
    kind = _pick(
        rng,
        (
            "bin",
            "bench",
            "bollards",
            "cabinet",
            "column",
            "bike_rack",
            "planter",
            "meter",
            "cone",
            "barrier",
            "drum",
        ),
        p=(0.14, 0.1, 0.12, 0.1, 0.04, 0.07, 0.07, 0.06, 0.12, 0.12, 0.06),
    )
    parts = Parts()
    if kind == "bin":
        if rng.random() < 0.5:
            r, h = _u(rng, 0.22, 0.35), _u(rng, 0.8, 1.1)
            parts.cylinder((0, 0, 0), (0, 0, h), r * 0.9, r)
        else:  # on a post
            h = _u(rng, 0.9, 1.2)
            parts.cylinder((0, 0, 0), (0, 0, h), 0.04)
            parts.cylinder((0.2, 0, h - 0.65), (0.2, 0, h), 0.18)
    elif kind == "bench":
        length, h = _u(rng, 1.4, 2.2), 0.45
        parts.box((0, 0, h), (0.22, length / 2, 0.03))
        parts.box((-0.22, 0, h + 0.3), (0.03, length / 2, 0.18))
        for y in (-length / 2 + 0.15, length / 2 - 0.15):
            parts.box((0, y, h / 2), (0.2, 0.03, h / 2))
        h += 0.48
    elif kind == "bollards":
        n = int(rng.randint(1, 5))
        r, h, gap = _u(rng, 0.05, 0.12), _u(rng, 0.6, 1.1), _u(rng, 1.2, 1.8)
        for i in range(n):
            y = (i - (n - 1) / 2) * gap
            parts.cylinder((0, y, 0), (0, y, h), r)
    elif kind == "cabinet":
        w, d, h = _u(rng, 0.5, 1.3), _u(rng, 0.3, 0.5), _u(rng, 0.9, 1.6)
        parts.box((0, 0, h / 2), (d / 2, w / 2, h / 2))
    elif kind == "column":  # advertising column
        r, h = _u(rng, 0.5, 0.7), _u(rng, 2.5, 3.5)
        parts.cylinder((0, 0, 0), (0, 0, h), r)
        parts.cylinder((0, 0, h), (0, 0, h + 0.35), r + 0.08, 0.1)
        h += 0.35
    elif kind == "bike_rack":
        n, h = int(rng.randint(3, 7)), _u(rng, 0.7, 0.9)
        for i in range(n):
            y = (i - (n - 1) / 2) * 0.7
            a, b = (-0.35, y, 0), (0.35, y, 0)
            parts.cylinder(a, (-0.35, y, h), 0.025).cylinder(b, (0.35, y, h), 0.025)
            parts.cylinder((-0.35, y, h), (0.35, y, h), 0.025)
    elif kind == "planter":
        w, h = _u(rng, 0.6, 1.5), _u(rng, 0.4, 0.8)
        parts.box((0, 0, h / 2), (w / 2, w / 2, h / 2))
        parts.ellipsoid((0, 0, h + 0.25), (w * 0.45, w * 0.45, 0.35), hit=0.7)
        h += 0.6
    elif kind == "meter":  # parking meter or ticket machine
        h = _u(rng, 1.2, 1.7)
        parts.cylinder((0, 0, 0), (0, 0, h - 0.4), 0.05)
        parts.box((0, 0, h - 0.2), (0.15, 0.2, 0.2))
    elif kind == "cone":  # traffic cone or delineator post on a square base
        h, r = _u(rng, 0.45, 1.1), _u(rng, 0.12, 0.2)
        base = r + _u(rng, 0.03, 0.08)
        parts.box((0, 0, 0.02), (base, base, 0.02))
        parts.cylinder((0, 0, 0.04), (0, 0, h), r, _u(rng, 0.02, 0.05))
    elif kind == "barrier":
        length = _u(rng, 1.0, 2.5)
        if rng.random() < 0.5:  # a concrete or plastic road barrier
            h, w = _u(rng, 0.6, 1.0), _u(rng, 0.4, 0.7)
            parts.box((0, 0, h * 0.3), (w / 2, length / 2, h * 0.3))
            parts.box((0, 0, h * 0.8), (w / 4, length / 2, h * 0.2))
        else:  # a construction barrier: a board on two A-frame legs
            h = _u(rng, 0.9, 1.3)
            parts.box((0, 0, h - 0.15), (0.02, length / 2, 0.15))
            for y in (-length / 2 + 0.1, length / 2 - 0.1):
                for dx in (-0.25, 0.25):
                    parts.cylinder((dx, y, 0), (0, y, h), 0.025)
    else:  # a traffic drum or barrel
        h, r = _u(rng, 0.9, 1.1), _u(rng, 0.25, 0.32)
        parts.cylinder((0, 0, 0), (0, 0, h), r, r * 0.9)
    return parts, {"kind": kind, "height": h}


def fence(rng):
    """A front-garden fence along the street: posts and a panel."""
    length = _u(rng, 3.0, 20.0)
    kind = _pick(rng, ("mesh", "railing", "panel"), p=(0.35, 0.3, 0.35))
    h = _u(rng, 0.8, 2.4) if kind != "railing" else _u(rng, 0.8, 1.4)
    p_hit = {"mesh": _u(rng, 0.25, 0.5), "railing": _u(rng, 0.3, 0.5), "panel": 1.0}
    parts = Parts()
    n_posts = max(2, int(length / 2.2) + 1)
    for i in range(n_posts):
        y = -length / 2 + length * i / (n_posts - 1)
        parts.cylinder((0, y, 0), (0, y, h + 0.05), 0.04)
    parts.box((0, 0, h / 2 + 0.05), (0.02, length / 2, h / 2), hit=p_hit[kind])
    if kind == "railing":
        parts.box((0, 0, h), (0.025, length / 2, 0.025))
    return parts, {"kind": kind, "length": length, "height": h + 0.05}


def person(rng):
    """A pedestrian standing or walking: legs, torso, arms, head; some
    children, some with a bag or a pushchair (``+x`` the way they face)."""
    h = _u(rng, 1.55, 1.95) if rng.random() < 0.85 else _u(rng, 1.0, 1.5)
    s = h / 1.75  # body proportions scale with the height
    hip, shoulder = 0.53 * h, 0.82 * h
    half_w = _u(rng, 0.17, 0.23) * s  # half the shoulder width
    depth = _u(rng, 0.1, 0.16) * s  # half the torso's depth
    stride = _u(rng, 0.0, 0.35) * s  # 0: standing, feet together
    parts = Parts()
    for side, ahead in ((-1.0, 1.0), (1.0, -1.0)):
        y = side * 0.09 * s
        parts.cylinder((ahead * stride / 2, y, 0.05), (0.0, y, hip), 0.06 * s, 0.08 * s)
        swing = -ahead * stride * 0.6
        parts.cylinder(
            (0.0, side * (half_w + 0.03), shoulder),
            (swing, side * (half_w + 0.06), hip - 0.05 * h),
            0.045 * s,
        )
    # torso and coat: an ellipsoid from the hips to the shoulders
    parts.ellipsoid(
        (0.0, 0.0, (hip + shoulder) / 2 + 0.02 * h),
        (depth, half_w, (shoulder - hip) / 2 + 0.06 * h),
    )
    parts.ellipsoid((0.0, 0.0, h - 0.11 * s), (0.09 * s, 0.08 * s, 0.115 * s))
    extra = _pick(
        rng, ("none", "bag", "backpack", "pushchair"), p=(0.6, 0.15, 0.15, 0.1)
    )
    if extra == "bag":
        side = _pick(rng, (-1.0, 1.0))
        parts.box((0.0, side * (half_w + 0.1), hip - 0.05), (0.15, 0.05, 0.15))
    elif extra == "backpack":
        parts.box((-depth - 0.08, 0.0, shoulder - 0.22), (0.09, 0.15, 0.2))
    elif extra == "pushchair":
        parts.box((0.75, 0.0, 0.55), (0.3, 0.25, 0.25))
        parts.cylinder((0.45, -0.22, 0.9), (0.45, 0.22, 0.9), 0.02)
    return parts, {"height": h, "stride": stride, "extra": extra}


BUILDERS = {
    "pole": pole,
    "lamp_post": lamp_post,
    "street_light": street_light,
    "traffic_light": traffic_light,
    "pedestrian_signal": pedestrian_signal,
    "traffic_sign": traffic_sign,
    "tree": tree,
    "car": car,
    "bush": bush,
    "other": other,
    "fence": fence,
    "person": person,
}
