"""The street: its cross-section, its ground, buildings and furniture.

The street runs along ``x`` from 0 to ``length``, centred on ``y = 0``;
``y > 0`` is the left side (for a vehicle driving towards ``+x``). The
cross-section from the centre line outwards: the carriageway (a cambered
road, two lanes), a parking lane on some sides, a kerb, a pavement rising
gently away from the road, a front garden on some sides, then the building
line; the whole street climbs with a constant longitudinal slope.

:class:`Street` holds those numbers, the exact ground height and the ground
primitives; :func:`furnish` places objects along its strips (the natural
mix of a town street, or as many objects of given classes as fit, for
:func:`~skpcd.datasets.make_street_objects`), and :func:`build_scene`
packs everything into a :class:`SceneArrays` with one instance id per object
and a frame (what each instance is).
"""

import itertools

import numpy as np

from skpcd.datasets._street._catalogue import BUILDERS, OBJECT_CLASSES
from skpcd.datasets._street._primitives import (
    Parts,
    SceneArrays,
    parts_aabb,
    rot_x,
    rot_y,
    rot_z,
)
from skpcd.datasets._street._scenery import building, wire

__all__ = ["STREET_CLASSES", "Street", "build_scene", "furnish"]

STREET_CLASSES = ("ground", "facade", "wire", *OBJECT_CLASSES)
CLASS_ID = {c: i for i, c in enumerate(STREET_CLASSES)}

_MARGIN = 30.0  # ground beyond the ends of the street, m

# where each class may stand: kerb strip, inner strip (by the buildings or the
# pavement's outer edge), front garden, parking lane
_STRIPS = {
    "pole": ("kerb", "kerb", "inner"),
    "lamp_post": ("kerb", "inner", "garden"),
    "street_light": ("kerb",),
    "traffic_light": ("kerb",),
    "pedestrian_signal": ("kerb",),
    "traffic_sign": ("kerb", "kerb", "inner"),
    "tree": ("kerb", "kerb", "garden"),
    "car": ("parking",),
    "bush": ("inner", "garden", "garden", "kerb"),
    "other": ("inner", "inner", "kerb", "garden"),
    "fence": ("edge",),
    "person": ("kerb", "inner", "inner"),
}


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


class GroundHeight:
    """The exact height of the street's ground at ``(x, y)`` (vectorised).

    Parameters
    ----------
    street : Street
        The street whose cross-section it evaluates.
    """

    def __init__(self, street):
        self.slope = street.slope
        self.crown = street.crown
        self.edges = street.edges
        self.kerb_width = street.kerb_width
        self.kerb_height = street.kerb_height
        self.pavement = street.pavement
        self.cross_slope = street.cross_slope

    def __call__(self, x, y):
        """Ground height; ``x`` and ``y`` broadcast together."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        side = (y >= 0).astype(int)  # 0 right, 1 left
        edge = np.where(side == 1, self.edges[1], self.edges[0])
        pave = np.where(side == 1, self.pavement[1], self.pavement[0])
        d = np.abs(y)
        road = self.crown * (1 - d / edge)
        kerb_end = edge + self.kerb_width
        pave_z = self.kerb_height + self.cross_slope * np.clip(d - kerb_end, 0, pave)
        z = np.where(d < edge, road, np.where(d < kerb_end, self.kerb_height, pave_z))
        out = self.slope * x + z
        return out if out.ndim else float(out)


class Street:
    """The cross-section of a street, drawn at random, and its ground.

    Parameters
    ----------
    rng : numpy.random.RandomState
        The generator.
    length : float
        Length along ``x``, metres.
    slope : float or None
        Longitudinal slope (rise over run); None draws it in [-0.04, 0.04].
    """

    def __init__(self, rng, length, slope=None):
        self.length = float(length)
        self.slope = _u(rng, -0.04, 0.04) if slope is None else float(slope)
        self.carriageway = _u(rng, 6.0, 7.2)
        self.parking = [
            _u(rng, 2.0, 2.4) if rng.random() < 0.6 else 0.0 for _ in range(2)
        ]  # right, left
        half = self.carriageway / 2
        self.edges = (half + self.parking[0], half + self.parking[1])
        self.crown = 0.02 * min(self.edges)
        self.kerb_width = _u(rng, 0.15, 0.3)
        self.kerb_height = _u(rng, 0.08, 0.16)
        self.pavement = (_u(rng, 2.2, 5.0), _u(rng, 2.2, 5.0))
        self.cross_slope = 0.015
        self.garden = tuple(
            0.0 if rng.random() < 0.55 else _u(rng, 2.0, 6.0) for _ in range(2)
        )
        self.right_lane = -half / 2
        self.drive = (0.0, self.length)  # x range of a mobile survey
        self.ground_height = GroundHeight(self)
        self.top = 0.0
        self.extent = (0.0, 0.0, 0.0, 0.0)

    def line(self, side, what):
        """Distance from the centre line of a strip of a side (0 right, 1 left)."""
        kerb = self.edges[side] + self.kerb_width
        pave_out = kerb + self.pavement[side]
        return {
            "edge": self.edges[side],
            "kerb": kerb,
            "pavement": pave_out,
            "building": pave_out + self.garden[side],
        }[what]

    def ground_parts(self, far):
        """The terrain: one profile (road, kerb faces and tops, pavements, land).

        ``far`` is the distance from the centre line where the land ends, on
        the right and on the left.
        """
        pave_top = self.kerb_height + self.cross_slope * np.array(self.pavement)
        verts = []
        for side, sign in ((0, -1.0), (1, 1.0)):
            e = self.edges[side]
            k = self.line(side, "kerb")
            p = self.line(side, "pavement")
            half = [
                (sign * e, 0.0),
                (sign * e, self.kerb_height),
                (sign * k, self.kerb_height),
                (sign * p, pave_top[side]),
                (sign * far[side], pave_top[side]),
            ]
            verts.append(half if side else half[::-1])
        vertices = [*verts[0], (0.0, self.crown), *verts[1]]
        return Parts().profile(self.slope, (-_MARGIN, self.length + _MARGIN), vertices)


class _Strip:
    """Occupied intervals along x of one strip."""

    def __init__(self, lo, hi):
        self.lo, self.hi = lo, hi
        self.taken = []

    def free(self, a, b, gap=0.3):
        if a < self.lo or b > self.hi:
            return False
        return all(b + gap <= c or a - gap >= d for c, d in self.taken)

    def take(self, a, b):
        self.taken.append((a, b))


class _Plan:
    """Objects to build: (class, parts, params, position, rotation, yaw)."""

    def __init__(self, street, rng):
        self.street, self.rng = street, rng
        self.items = []
        L = street.length
        self.strips = {
            (side, s): _Strip(0.5, L - 0.5)
            for side in (0, 1)
            for s in ("kerb", "inner", "garden", "parking", "edge", "lane")
        }

    def _y(self, side, strip, depth):
        st, rng = self.street, self.rng
        sign = 1.0 if side == 1 else -1.0
        if strip == "kerb":
            d = st.line(side, "kerb") + _u(rng, 0.35, 0.7) + depth
        elif strip == "inner":
            d = st.line(side, "pavement") - _u(rng, 0.3, 0.6) - depth
        elif strip == "garden":
            g = st.garden[side]
            if g < 1.5:
                return None
            d = st.line(side, "pavement") + _u(rng, 0.6, g - 0.6)
        elif strip == "edge":
            if st.garden[side] <= 0:
                return None
            d = st.line(side, "pavement") + 0.15
        elif strip == "lane":  # driving in the middle of a lane
            d = st.carriageway / 4 + _u(rng, -0.25, 0.25)
        else:  # parking
            if st.parking[side] <= 0:
                return None
            d = st.edges[side] - st.parking[side] / 2 + _u(rng, -0.1, 0.15)
        return sign * d

    def place(self, cls, side, x=None, strip=None, tries=8, built=None):
        """Build an object of ``cls`` and put it on a side; False if no room."""
        rng = self.rng
        parts, params = built if built is not None else BUILDERS[cls](rng)
        lo, hi = parts_aabb(parts)
        strip = strip or _STRIPS[cls][int(rng.randint(len(_STRIPS[cls])))]
        depth = 0.0
        if cls == "car":
            along = (lo[0], hi[0])
            yaw = 0.0 if rng.random() < 0.5 else np.pi
        elif cls == "person":  # facing any way
            reach = float(np.abs(np.r_[lo[:2], hi[:2]]).max())
            along = (-reach, reach)
            yaw = _u(rng, -np.pi, np.pi)
        else:
            along = (lo[1], hi[1])
            yaw = -np.pi / 2 if side == 1 else np.pi / 2
            if cls in ("bush", "other", "fence"):
                # keep low objects clear of the kerb or the buildings
                depth = hi[0] if strip == "kerb" else -lo[0]
                depth = float(np.clip(depth, 0.0, 1.5))
        half = max(abs(along[0]), abs(along[1])) + 0.2
        if cls == "tree":
            half = max(half * 0.6, 1.0)  # crowns may touch
        for attempt in range(tries):
            y = self._y(side, strip, depth)
            if y is None:
                return False
            xx = x if (x is not None and attempt == 0) else None
            if xx is None:
                if x is not None:
                    xx = x + _u(rng, -3, 3)
                else:
                    xx = _u(rng, 0.5 + half, self.street.length - 0.5 - half)
            key = (side, strip)
            if self.strips[key].free(xx - half, xx + half):
                self.strips[key].take(xx - half, xx + half)
                lean = (
                    rng.normal(0, 0.008, 2)
                    if cls not in ("car", "fence", "person")
                    else (0, 0)
                )
                rot = rot_z(yaw) @ rot_x(lean[0]) @ rot_y(lean[1])
                z = float(self.street.ground_height(xx, y))
                self.items.append((cls, parts, params, (xx, y, z), rot, yaw))
                return True
        return False


def _natural(plan):
    """A town street: lights, tree rows, a crossing, signs, clutter, cars."""
    rng, st = plan.rng, plan.street
    L = st.length
    # a signalised crossing
    if rng.random() < 0.5:
        xc = _u(rng, 0.3, 0.7) * L
        plan.place("traffic_light", 0, xc - 3.0)
        plan.place("traffic_light", 1, xc + 3.0)
        plan.place("pedestrian_signal", 0, xc + 1.5)
        plan.place("pedestrian_signal", 1, xc - 1.5)
        for side in (0, 1):
            plan.strips[(side, "parking")].take(xc - 8, xc + 8)
    # lights
    light = "street_light" if rng.random() < 0.7 else "lamp_post"
    spacing = _u(rng, 22, 35) if light == "street_light" else _u(rng, 12, 20)
    arrangement = rng.choice(["one", "alternate", "both"])
    sides = [int(rng.randint(2))]
    for i, x in enumerate(np.arange(_u(rng, 2, spacing), L - 1, spacing)):
        if arrangement == "both":
            for side in (0, 1):
                plan.place(light, side, x)
        elif arrangement == "alternate":
            plan.place(light, i % 2, x)
        else:
            plan.place(light, sides[0], x)
    # tree rows
    if rng.random() < 0.6:
        row_sides = [0, 1] if rng.random() < 0.5 else [int(rng.randint(2))]
        gap = _u(rng, 7, 12)
        for side in row_sides:
            for x in np.arange(_u(rng, 2, gap), L - 2, gap):
                plan.place("tree", side, x + _u(rng, -0.5, 0.5), strip="kerb")
    # a line of utility poles with wires
    if rng.random() < 0.25:
        side = int(rng.randint(2))
        gap = _u(rng, 28, 40)
        for x in np.arange(_u(rng, 3, 10), L - 1, gap):
            built = _utility_pole(rng)
            plan.place("pole", side, x, strip="kerb", built=built)
    for side in (0, 1):
        for _ in range(rng.poisson(L / 20)):
            plan.place("traffic_sign", side)
        for _ in range(rng.poisson(L / 60)):
            plan.place("pole", side)
        for _ in range(rng.poisson(L / 10)):
            plan.place("other", side)
        for _ in range(rng.poisson(L / 40)):
            plan.place("bush", side, strip="inner")
        if st.garden[side] > 0:
            for _ in range(rng.poisson(L / 6)):
                plan.place("bush", side, strip="garden")
            for _ in range(rng.poisson(L / 25)):
                plan.place("tree", side, strip="garden")
            for _ in range(rng.poisson(L / 8)):
                plan.place("fence", side, strip="edge")
        if st.parking[side] > 0:
            _park(plan, side, 0.75)


def _park(plan, side, occupancy):
    """Cars parked one behind the other along a parking lane, with gaps."""
    rng = plan.rng
    x = _u(rng, 0.5, 4.0)
    while x < plan.street.length - 2.0:
        if rng.random() < occupancy:
            built = BUILDERS["car"](rng)
            length = built[1]["length"]
            plan.place("car", side, x + length / 2 + 0.2, tries=1, built=built)
            x += length + _u(rng, 0.6, 2.5)
        else:
            x += _u(rng, 4.0, 10.0)


def _utility_pole(rng):
    parts = Parts()
    h, r0 = _u(rng, 7.5, 10.5), _u(rng, 0.12, 0.16)
    parts.cylinder((0, 0, 0), (0, 0, h), r0, r0 * 0.75)
    w = _u(rng, 1.2, 2.0)
    parts.box((0.0, 0.0, h - 0.3), (0.05, w / 2, 0.05))
    return parts, {
        "kind": "wood",
        "height": h,
        "radius": r0,
        "crossarm": True,
        "crossarm_width": w,
    }


def _requested(plan, wanted, traffic=False):
    """As many objects of the wanted classes as fit (for make_street_objects);
    with ``traffic`` half the cars drive in the lanes."""
    rng, st = plan.rng, plan.street
    need = dict(wanted)
    for side in (0, 1):
        misses = 0
        while misses < 12 and any(v > 0 for v in need.values()):
            classes = [c for c, v in need.items() if v > 0]
            weights = np.array([need[c] for c in classes], float)
            cls = classes[int(rng.choice(len(classes), p=weights / weights.sum()))]
            strip = "lane" if cls == "car" and traffic and rng.random() < 0.5 else None
            if plan.place(cls, side, strip=strip, tries=4):
                need[cls] -= 1
                misses = 0
            else:
                misses += 1
    # background: parked cars that were not asked for
    for side in (0, 1):
        if st.parking[side] > 0 and "car" not in wanted:
            _park(plan, side, 0.5)


def furnish(street, rng, wanted=None, traffic=False, clear=None):
    """Objects of a street: the natural mix, or the ``wanted`` counts per class
    (with ``traffic``, half the cars in the lanes, none in the x ranges of
    ``clear``, ``{side: (x0, x1)}``, of a lane: where the scanner is)."""
    plan = _Plan(street, rng)
    for side, (x0, x1) in (clear or {}).items():
        plan.strips[(side, "lane")].take(x0, x1)
    if wanted is None:
        _natural(plan)
    else:
        _requested(plan, wanted, traffic)
    return plan


def _buildings(street, rng, side):
    """A row of buildings along one side: (parts, params, x centre, y, z, rot)."""
    sign = 1.0 if side == 1 else -1.0
    y = sign * street.line(side, "building")
    rot = np.eye(3) if side == 1 else rot_z(np.pi)
    out = []
    x = -_u(rng, 0, 10)
    while x < street.length + 10:
        width = _u(rng, 6.0, 22.0)
        xc = x + width / 2
        zs = street.ground_height(np.array([x, x + width]), y)
        parts, params = building(rng, width, base_depth=0.3)
        out.append((parts, params, (xc, y, float(np.min(zs))), rot))
        x += width
        if rng.random() < 0.3:
            x += _u(rng, 2.0, 8.0)  # an alley
    return out


def build_scene(street, plan, rng, *, buildings=True):
    """Pack the street: ground, buildings, planned objects, wires.

    Returns ``(scene, frame)``: the packed arrays (see
    :class:`SceneArrays`) and one dict per instance.
    """
    arrays = SceneArrays()
    frame = []
    far = [street.line(s, "building") + 20.0 for s in (0, 1)]
    arrays.add(street.ground_parts(far), -1, CLASS_ID["ground"])
    top = 0.0
    if buildings:
        for side in (0, 1):
            for parts, params, pos, rot in _buildings(street, rng, side):
                iid = len(frame)
                arrays.add(parts.placed(rot, pos), iid, CLASS_ID["facade"])
                frame.append(_entry(iid, "facade", pos, 0.0 if side else np.pi, params))
                top = max(top, pos[2] + params["height"])
    poles_by_side = {0: [], 1: []}
    for cls, parts, params, pos, rot, yaw in plan.items:
        iid = len(frame)
        placed = parts.placed(rot, pos)
        arrays.add(placed, iid, CLASS_ID[cls])
        _, hi = parts_aabb(placed)
        entry = _entry(iid, cls, pos, yaw, params)
        entry["height"] = float(hi[2] - pos[2])
        frame.append(entry)
        top = max(top, hi[2])
        if cls == "pole" and params.get("crossarm_width"):
            poles_by_side[int(pos[1] > 0)].append((pos, params, rot))
    # wires between consecutive utility poles, and span wires over the street
    for side, poles in poles_by_side.items():
        poles.sort(key=lambda p: p[0][0])
        for (pa, qa, ra), (pb, qb, rb) in itertools.pairwise(poles):
            span = pb[0] - pa[0]
            for off in (-0.45, 0.0, 0.45)[: int(rng.randint(1, 4))]:
                a = np.asarray(pa) + ra @ [
                    0.0,
                    off * qa["crossarm_width"],
                    qa["height"] - 0.25,
                ]
                b = np.asarray(pb) + rb @ [
                    0.0,
                    off * qb["crossarm_width"],
                    qb["height"] - 0.25,
                ]
                _add_wire(arrays, frame, a, b, _u(rng, 0.01, 0.03) * span)
    if buildings and rng.random() < 0.3:
        for _ in range(int(rng.randint(1, 4))):
            x = _u(rng, 5, street.length - 5)
            z0 = street.ground_height(x, 0.0) + _u(rng, 6.0, 8.0)
            a = (x, -street.line(0, "building") + 0.1, z0)
            b = (x + _u(rng, -1, 1), street.line(1, "building") - 0.1, z0)
            _add_wire(arrays, frame, a, b, _u(rng, 0.2, 0.5))
    scene = arrays.pack()
    street.top = float(max(top, scene["aabb"][:, 5].max()))
    street.extent = (
        -_MARGIN,
        -far[0],
        street.length + _MARGIN,
        far[1],
    )
    return scene, frame


def _add_wire(arrays, frame, a, b, sag):
    iid = len(frame)
    arrays.add(wire(a, b, sag), iid, CLASS_ID["wire"])
    mid = (np.asarray(a) + np.asarray(b)) / 2
    frame.append(
        _entry(
            iid,
            "wire",
            tuple(mid.tolist()),
            float(np.arctan2(b[1] - a[1], b[0] - a[0])),
            {
                "start": tuple(map(float, a)),
                "end": tuple(map(float, b)),
                "sag": float(sag),
            },
        )
    )


def _entry(iid, cls, pos, yaw, params):
    return {
        "id": int(iid),
        "class": cls,
        "position": tuple(float(v) for v in pos),
        "yaw": float(yaw),
        "height": float(params.get("height", 0.0)),
        "params": params,
    }
