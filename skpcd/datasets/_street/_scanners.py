"""Scan patterns: mobile profilers, an airborne swath, spinning multi-beam sensors.

``SCAN_PATTERNS`` holds the default numbers of each pattern;
:func:`plan_scan` turns a pattern, its overrides and a street into the
arrays of :mod:`skpcd.datasets._street._raycast`, and :func:`scan`
casts every pulse against the packed scene, in chunks of constant memory.
"""

import math
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy.special import ndtri

from skpcd.datasets._street._raycast import (
    AERIAL,
    BOX,
    CYLINDER,
    MOBILE,
    MOBILE_ROW,
    PROFILE,
    UGV,
    cast_rays,
    grid_cells,
    simulate,
)

__all__ = [
    "SCAN_PATTERNS",
    "SPINNING_SENSORS",
    "build_grid",
    "first_hits",
    "plan_scan",
    "randomise_pattern",
    "scan",
]

# HDL-32E vertical angles: 32 beams from -30.67 to +10.67 degrees, 1.33 apart
_HDL32_ELEVATIONS = tuple(np.round(np.linspace(-30.67, 10.67, 32), 4).tolist())


def _hdl64():
    """HDL-64E (KITTI): 32 beams 1/3 deg apart from +2 to -8.33 deg, 32 beams
    1/2 deg apart from -8.83 to -24.33 deg."""
    upper, lower = np.linspace(2.0, -8.33, 32), np.linspace(-8.83, -24.33, 32)
    return tuple(np.round(np.r_[upper, lower], 4).tolist())


def _pandar64():
    """Pandar64: 1 deg steps from -25 to -6 and from +2 to +15 (coarser
    at the ends), 1/6 deg in the band from -6 to +2 where the road is."""
    fine = np.linspace(-6.0, 2.0, 49)
    below = np.r_[-25.0, -19.0, -14.0, np.arange(-13.0, -6.0, 1.0)]
    above = np.r_[3.0, 4.0, 5.0, 11.0, 15.0]
    return tuple(np.round(np.sort(np.r_[below, fine, above])[::-1], 4).tolist())


#: Spinning multi-beam sensors of the ``"spinning"`` pattern: vertical angles
#: (degrees, one per beam), azimuth step at 10 Hz (degrees), range noise (m).
SPINNING_SENSORS = {
    "vlp16": {
        "elevations": tuple(np.linspace(15.0, -15.0, 16).tolist()),
        "azimuth_step": 0.2,
        "range_noise": 0.03,
    },
    "hdl32": {
        "elevations": _HDL32_ELEVATIONS[::-1],
        "azimuth_step": 0.16,
        "range_noise": 0.02,
    },
    "hdl64": {
        "elevations": _hdl64(),
        "azimuth_step": 0.18,
        "range_noise": 0.02,
    },
    "pandar64": {
        "elevations": _pandar64(),
        "azimuth_step": 0.2,
        "range_noise": 0.02,
    },
    # OS1-128-like: 128 beams evenly over 45 deg, 1024 columns
    "os128": {
        "elevations": tuple(np.round(np.linspace(22.5, -22.5, 128), 4).tolist()),
        "azimuth_step": 360.0 / 1024,
        "range_noise": 0.03,
    },
}

SCAN_PATTERNS = {
    # Optech Lynx-like mobile mapping: two profilers on the vehicle roof whose
    # vertical rotation planes stand at +-45 degrees to the driving direction
    # (and so at right angles to each other), as in He et al. (2017).
    "mobile": {
        "speed": 10.0,  # m/s (36 km/h)
        "rotation_rate": 200.0,  # rotations per second, each scanner
        "angular_step": 0.1,  # degrees between pulses in the scan plane
        "height": 2.2,  # scanner centres above the road, m
        "plane_azimuths": (45.0, -45.0),  # scan planes from the heading, deg
        "mount_offsets": ((-0.5, 0.35, 0.0), (-0.5, -0.35, 0.0)),  # fwd, left, up
        "blind_angle": 40.0,  # half-angle of the cone below hidden by the car, deg
        "lane": None,  # y of the trajectory; None: middle of the right lane
        "min_range": 1.0,  # m
        "max_range": 100.0,  # m
        "range_noise": 0.008,  # m, standard deviation
        "beam_divergence": 1.5e-4,  # rad, standard deviation of the ray jitter
        "footprint": 0.0,  # m, added to the radius of cylinders (beam width)
        "max_returns": 1,  # echoes per pulse
        "return_separation": 1.0,  # m, least distance between two echoes
    },
    # Airborne swath (DALES-like: Riegl Q1560 at 1300 m): two channels,
    # each with straight parallel scan lines across track, one looking
    # forward and one backward (crossed scan lines), several overlapping
    # flight lines along the street flown in alternate directions.
    "aerial": {
        "altitude": 1300.0,  # m above the road at x = 0
        "speed": 72.0,  # m/s
        "density": 8.0,  # pulses per m2 at nadir, each flight line (all channels)
        "field_of_view": 58.0,  # full scan angle, deg
        # y of the flight lines, m: the street seen from 0 to 23 degrees off
        # nadir, from both sides
        "line_offsets": (-550.0, -250.0, 0.0, 250.0, 550.0),
        # forward look of each channel's scan plane, deg: a dual-channel
        # scanner's crossed scan lines see vertical objects from the front
        # and the back as well as from the side (HELIOS++ models the two
        # channels of the VQ-1560i, the Q1560's successor, at +-14 deg)
        "channel_tilts": (14.0, -14.0),
        "min_range": 10.0,
        "max_range": 3000.0,
        "range_noise": 0.02,
        "beam_divergence": 1.25e-4,
        # half the width of a 0.25 mrad beam at 1300 m: thin poles and wires
        # return from a partial footprint, so they look that much wider
        "footprint": 0.15,
        "max_returns": 4,
        "return_separation": 1.0,
    },
    # A spinning 32-beam sensor (HDL-32E-like vertical angles) on a small
    # ground vehicle, one full sweep.
    "ugv": {
        "height": 1.8,  # m above the road
        "position": None,  # (x, y); None: middle of the street, right lane
        "elevations": _HDL32_ELEVATIONS,  # deg
        "azimuth_step": 0.16,  # deg between firings (HDL-32E at 10 Hz)
        "rotation_rate": 10.0,  # Hz
        "min_range": 1.0,
        "max_range": 100.0,
        "range_noise": 0.02,
        "beam_divergence": 1.0e-3,
        "footprint": 0.0,
        "max_returns": 1,
        "return_separation": 1.0,
    },
    # One sweep of a spinning multi-beam sensor on a car's roof, as in
    # autonomous-driving data (KITTI, PandaSet): the beams of ``sensor`` (a
    # key of SPINNING_SENSORS) unless ``elevations`` / ``azimuth_step`` are
    # given; ``position`` None puts the car in the middle of the street, in
    # the right lane.
    "spinning": {
        "sensor": "hdl64",
        "height": 1.73,
        "position": None,
        "elevations": None,
        "azimuth_step": None,
        "rotation_rate": 10.0,
        "min_range": 2.0,
        "max_range": 120.0,
        "range_noise": None,
        "beam_divergence": 1.5e-3,
        "footprint": 0.0,
        "max_returns": 1,
        "return_separation": 1.0,
    },
}


def _scene_arrays(scene, grid):
    """The ``world`` of the casting kernels: the scene's primitive arrays
    and its grid in one tuple, in the order ``_raycast.cast`` unpacks them."""
    return (
        scene["kind"],
        scene["params"],
        scene["hit"],
        scene["aabb"],
        grid["glob"],
        grid["bounds"],
        grid["cell"],
        grid["nx"],
        grid["ny"],
        grid["start"],
        grid["items"],
        grid["boxes"],
        grid["zrange"],
        grid["coarse"],
        grid["ncx"],
        grid["czrange"],
        grid["ahead"],
    )


def resolve_pattern(scanner, scanner_params=None, **overrides):
    """The pattern's numbers: defaults, then ``scanner_params``, then overrides.

    ``overrides`` with a None value are ignored.
    """
    if scanner not in SCAN_PATTERNS:
        raise ValueError(
            f"scanner must be one of {sorted(SCAN_PATTERNS)}, got {scanner!r}"
        )
    conf = dict(SCAN_PATTERNS[scanner])
    given = dict(scanner_params or {})
    given.update({k: v for k, v in overrides.items() if v is not None})
    for key, value in given.items():
        if key not in conf:
            raise ValueError(
                f"unknown parameter {key!r} of the {scanner!r} scan pattern; "
                f"known: {sorted(conf)}"
            )
        conf[key] = value
    if "sensor" in conf:
        if conf["sensor"] not in SPINNING_SENSORS:
            raise ValueError(
                f"sensor must be one of {sorted(SPINNING_SENSORS)}, "
                f"got {conf['sensor']!r}"
            )
        for key, value in SPINNING_SENSORS[conf["sensor"]].items():
            if conf[key] is None:
                conf[key] = value
    if not 1 <= int(conf["max_returns"]) <= 8:
        raise ValueError(f"max_returns must be 1 to 8, got {conf['max_returns']}")
    for key in (
        "min_range",
        "max_range",
        "range_noise",
        "beam_divergence",
        "footprint",
        "return_separation",
    ):
        if not float(conf[key]) >= 0:
            raise ValueError(f"{key} must be non-negative, got {conf[key]}")
    if not float(conf["max_range"]) > float(conf["min_range"]):
        raise ValueError("max_range must be larger than min_range")
    return conf


def randomise_pattern(scanner, street, rng, fixed=None):
    """The numbers of ``scanner`` drawn at random for one street.

    Domain randomisation: what a user's scanner and survey are cannot be
    known, so each simulated street draws them from the ranges of the
    sensors in use, and a model trained on the mix does not learn one
    setting. ``fixed`` (the ``scanner_params`` of the caller) are kept.

    - ``"spinning"``: a sensor of :data:`SPINNING_SENSORS` (16 to 128
      beams), 1.5 to 2.1 m above the road, anywhere along the street
      (objects from a few metres to over 60 m away), in either lane;
      azimuth step x0.8-1.5, range noise x0.5-2.
    - ``"mobile"``: 5 to 15 m/s, 100 to 250 rotations per second, 0.05
      to 0.2 degrees between pulses, one or both profilers, either lane,
      2.0 to 2.6 m above the road.
    - ``"ugv"``: as ``"spinning"`` with the 16 and 32 beam sensors at 0.5
      to 1.2 m.
    - ``"aerial"``: 4 to 16 pulses per m2, the flight lines shifted.

    Parameters
    ----------
    scanner : str
        A key of ``SCAN_PATTERNS``.
    street : Street
        The street (its length and lanes).
    rng : numpy.random.RandomState
        The generator.
    fixed : dict or None
        Numbers not to draw.

    Returns
    -------
    conf : dict
        The pattern's numbers, as :func:`resolve_pattern` returns them.
    """
    u = rng.uniform
    lane = street.right_lane * (1.0 if rng.random_sample() < 0.5 else -1.0)
    if scanner in ("spinning", "ugv"):
        names = sorted(SPINNING_SENSORS)
        if scanner == "ugv":
            names = ["hdl32", "vlp16"]
        sensor = names[int(rng.randint(len(names)))]
        spec = SPINNING_SENSORS[sensor]
        drawn = {
            "elevations": spec["elevations"],
            "azimuth_step": spec["azimuth_step"] * u(0.8, 1.5),
            "range_noise": spec["range_noise"] * u(0.5, 2.0),
            "height": u(1.5, 2.1) if scanner == "spinning" else u(0.5, 1.2),
            "position": (u(-0.2, 1.2) * street.length, lane),
        }
        if scanner == "spinning":
            drawn["sensor"] = sensor
    elif scanner == "mobile":
        one = rng.random_sample() < 0.3
        drawn = {
            "speed": u(5.0, 15.0),
            "rotation_rate": u(100.0, 250.0),
            "angular_step": u(0.05, 0.2),
            "height": u(2.0, 2.6),
            "lane": lane,
            "range_noise": u(0.004, 0.02),
        }
        if one:
            drawn["plane_azimuths"] = (45.0,) if rng.random_sample() < 0.5 else (-45.0,)
    else:
        drawn = {
            "density": u(4.0, 16.0),
            "line_offsets": tuple(
                np.asarray(SCAN_PATTERNS["aerial"]["line_offsets"]) + u(-100, 100)
            ),
        }
    drawn.update(fixed or {})
    return resolve_pattern(scanner, drawn)


def _mobile(conf, street):
    lane = street.right_lane if conf["lane"] is None else float(conf["lane"])
    azim = np.atleast_1d(np.asarray(conf["plane_azimuths"], dtype=float))
    mounts = np.asarray(conf["mount_offsets"], dtype=float).reshape(-1, 3)
    if len(mounts) < len(azim):
        mounts = np.vstack([mounts, np.zeros((len(azim) - len(mounts), 3))])
    rate, speed = float(conf["rotation_rate"]), float(conf["speed"])
    n_per = round(360.0 / float(conf["angular_step"]))
    if not (rate > 0 and speed > 0 and n_per >= 8):
        raise ValueError("rotation_rate, speed and angular_step must be positive")
    x_start, x_end = street.drive
    duration = (x_end - x_start) / speed
    n_rot = max(1, math.ceil(duration * rate))
    fa = np.zeros(len(azim) * MOBILE_ROW)
    for s, (psi, mount) in enumerate(zip(azim, mounts)):
        # the scanners fire half a step apart, so their pulses do not coincide
        psi = np.deg2rad(psi)
        fa[s * MOBILE_ROW : (s + 1) * MOBILE_ROW] = [
            np.cos(psi),
            np.sin(psi),
            *mount,
            s * 0.5 / (n_per * rate),
        ]
    alpha = 2 * np.pi * np.arange(n_per) / n_per
    ft = np.column_stack([np.cos(alpha), np.sin(alpha)]).ravel()
    z0 = street.ground_height(0.0, lane) if np.isfinite(lane) else 0.0
    fp = np.array(
        [
            x_start,
            lane,
            float(z0),
            street.slope,
            float(conf["height"]),
            speed,
            rate,
            n_per,
            n_rot,
            len(azim),
            math.cos(np.deg2rad(conf["blind_angle"])),
        ]
    )
    x = x_start + speed * np.arange(n_rot) / rate
    trajectory = np.column_stack(
        [x, np.full(n_rot, lane), z0 + street.slope * x + conf["height"]]
    )
    return MOBILE, fp, fa, ft, len(azim) * n_per * n_rot, trajectory


def _aerial(conf, street):
    tilts = np.deg2rad(np.atleast_1d(np.asarray(conf["channel_tilts"], dtype=float)))
    if not (len(tilts) and (np.abs(tilts) < np.deg2rad(45.0)).all()):
        raise ValueError("channel_tilts must be 1 or more angles within +-45 deg")
    # the pulses are shared between the channels, each with square spacing
    spacing = 1.0 / math.sqrt(float(conf["density"]) / len(tilts))
    speed, alt = float(conf["speed"]), float(conf["altitude"])
    line_rate = speed / spacing
    step = spacing / alt
    half_fov = np.deg2rad(conf["field_of_view"]) / 2
    x0, y0, x1, y1 = street.extent
    top = street.top + 5.0
    rows, traj, tables, first, n_ft = [], [], [], 0, 0
    offsets = np.atleast_1d(np.asarray(conf["line_offsets"], dtype=float))
    passes = [(p, y, tilt) for p, y in enumerate(offsets) for tilt in tilts]
    for p, y_line, tilt in passes:
        heading = 1.0 if p % 2 == 0 else -1.0
        # scan angles whose rays can reach the street: its ground, and the
        # tops of its tallest objects seen from the line
        lo = min(math.atan2(y0 - y_line, alt), math.atan2(y0 - y_line, alt - top))
        hi = max(math.atan2(y1 - y_line, alt), math.atan2(y1 - y_line, alt - top))
        lo, hi = max(lo, -half_fov), min(hi, half_fov)
        if hi <= lo:
            continue
        n_per = math.ceil((hi - lo) / step) + 1
        # a tilted plane reaches the ground alt tan(tilt) / cos(beta) ahead of
        # the aircraft (behind for a negative tilt): the lines start and end
        # so that every scan angle covers the street, tops included (5 m)
        ahead = [
            heading * (alt - z) * math.tan(tilt) / math.cos(b)
            for b in (lo, hi, min(max(0.0, lo), hi))
            for z in (0.0, top)
        ]
        a_lo, a_hi = min(ahead) - 1.0, max(ahead) + 1.0
        xs = x0 - a_hi if heading > 0 else x1 - a_lo
        n_lines = math.ceil((x1 - x0 + a_hi - a_lo) / (speed / line_rate)) + 1
        rows.append([y_line, heading, xs, n_ft, tilt, n_per, n_lines, first, 600.0 * p])
        beta = lo + step * np.arange(n_per)
        tables.append(np.column_stack([np.sin(beta), np.cos(beta)]).ravel())
        n_ft += n_per
        lines = np.arange(n_lines) / line_rate
        traj.append(
            np.column_stack(
                [
                    xs + heading * speed * lines,
                    np.full(n_lines, y_line),
                    np.full(n_lines, alt),
                ]
            )
        )
        first += n_per * n_lines
    if not rows:
        raise ValueError("no flight line sees the street: check line_offsets")
    # flight lines one after the other, 10 min apart; the channels of a line
    # fly together
    fa = np.asarray(rows, dtype=float).ravel()
    fp = np.array([alt, speed, line_rate, 0.0, len(rows)])
    return AERIAL, fp, fa, np.concatenate(tables), first, np.vstack(traj)


def _ugv(conf, street):
    if conf["position"] is None:
        x, y = street.length / 2, street.right_lane
    else:
        x, y = map(float, conf["position"])
    z = street.ground_height(x, y) + float(conf["height"])
    n_az = round(360.0 / float(conf["azimuth_step"]))
    fp = np.array([x, y, float(z), n_az, float(conf["rotation_rate"])])
    el = np.deg2rad(np.asarray(conf["elevations"], dtype=float))
    fa = np.column_stack([np.cos(el), np.sin(el)]).ravel()
    az = 2 * np.pi * np.arange(n_az) / n_az
    ft = np.column_stack([np.cos(az), np.sin(az)]).ravel()
    return UGV, fp, fa, ft, n_az * len(el), np.array([[x, y, float(z)]])


# standard normal quantiles at (i + 0.5) / 65536: 16 bits of a hash index them
_GAUSS = ndtri((np.arange(1 << 16) + 0.5) / (1 << 16))

_PLANNERS = {"mobile": _mobile, "aerial": _aerial, "ugv": _ugv, "spinning": _ugv}


def plan_scan(scanner, conf, street):
    """Kernel arrays of a pattern over a street.

    ``street`` has ``length``, ``slope``, ``right_lane``, ``drive`` (x range
    of a mobile survey), ``extent`` (x0, y0, x1, y1 of the scene), ``top``
    (highest z) and ``ground_height(x, y)``.
    Returns a dict with ``code, fp, fa, ft, n_pulses, trajectory``.
    """
    code, fp, fa, ft, n, traj = _PLANNERS[scanner](conf, street)
    return {
        "code": code,
        "fp": np.ascontiguousarray(fp, dtype=np.float64),
        "fa": np.ascontiguousarray(fa, dtype=np.float64),
        "ft": np.ascontiguousarray(ft, dtype=np.float64),
        "n_pulses": int(n),
        "trajectory": np.ascontiguousarray(traj, dtype=np.float64),
    }


# correlation length of foliage and fence mesh (leaf clumps, twigs, mesh
# cells), m: a footprint of radius R covers about pi R^2 / GRAIN^2 independent
# patches of such a surface
GRAIN = 0.1


def apply_footprint(scene, footprint, porous=None):
    """The scene as a beam of footprint radius ``footprint`` sees it.

    - Cylinders get ``footprint`` added to their radius: a beam of finite
      width returns from a pole or a wire as soon as its footprint touches
      it, at the range of the pole, so the pole looks wider by the
      footprint's radius.
    - Boxes thinner than the footprint across a near-horizontal axis (fence
      panels and mesh, sign plates, railing bars) get it added across that
      axis, for the same reason.
    - ``porous`` primitives (foliage, mesh: a mask) of hit probability p for
      a thin ray return an echo from a wide footprint with probability
      ``1 - (1 - p) ** n``, ``n = pi footprint**2 / GRAIN**2`` patches: a
      footprint of 0.15 m covers seven leaf clumps or mesh cells, and meets
      at least one with probability 0.95 for p = 0.35. The beam goes on
      behind them for later echoes.

    Returns the scene itself for ``footprint=0``.
    """
    if not footprint > 0:
        return scene
    out = dict(scene)
    kind = scene["kind"]
    params = out["params"] = scene["params"].copy()
    aabb = out["aabb"] = scene["aabb"].copy()
    cyl = kind == CYLINDER
    params[cyl, 6:8] += footprint
    aabb[cyl, :3] -= footprint
    aabb[cyl, 3:] += footprint
    box = np.flatnonzero(kind == BOX)
    half = params[box, 3:6]
    rot = params[box, 6:15].reshape(-1, 3, 3)  # rot[:, j, i]: world j of axis i
    thin = (half < footprint) & (np.abs(rot[:, 2, :]) < 0.5)
    grow = np.where(thin, footprint, 0.0)
    params[box, 3:6] += grow
    ext = np.einsum("bji,bi->bj", np.abs(rot), grow)
    aabb[box, :3] -= ext
    aabb[box, 3:] += ext
    if porous is not None and np.any(porous):
        n = np.pi * footprint**2 / GRAIN**2
        hit = out["hit"] = scene["hit"].copy()
        p = np.clip(hit[porous], 0.0, 1.0)
        # stays below 1, so that the beam goes on behind for later echoes
        hit[porous] = np.minimum(1.0 - (1.0 - p) ** max(n, 1.0), 0.999)
    return out


def build_grid(scene, cell=1.0, global_cells=400, coarse=3):
    """Uniform grid over the scene's primitives: a dict of kernel arrays.

    The terrain profile and primitives covering more than ``global_cells``
    cells are not listed in the cells: every ray tests them first. Blocks of
    ``2**coarse`` cells a side carry the z range of their items.
    """
    aabb = scene["aabb"]
    lo, hi = aabb[:, :3].min(axis=0) - 0.01, aabb[:, 3:].max(axis=0) + 0.01
    nx = max(1, math.ceil((hi[0] - lo[0]) / cell))
    ny = max(1, math.ceil((hi[1] - lo[1]) / cell))
    bounds = np.array(
        [lo[0], lo[1], lo[2], lo[0] + nx * cell, lo[1] + ny * cell, hi[2]]
    )
    area = np.prod(aabb[:, 3:5] - aabb[:, 0:2] + cell, axis=1) / cell**2
    is_global = (area > global_cells) | (scene["kind"] == PROFILE)
    start, items, boxes, zrange = grid_cells(
        aabb, ~is_global, bounds[0], bounds[1], float(cell), nx, ny
    )
    # z range of blocks of 2**coarse x 2**coarse cells
    block = 1 << coarse
    ncx, ncy = -(-nx // block), -(-ny // block)
    pad = np.full((ncy * block, ncx * block, 2), [np.inf, -np.inf])
    pad[:ny, :nx] = zrange.reshape(ny, nx, 2)
    blocks = pad.reshape(ncy, block, ncx, block, 2)
    czrange = np.empty((ncy * ncx, 2))
    czrange[:, 0] = blocks[..., 0].min(axis=(1, 3)).ravel()
    czrange[:, 1] = blocks[..., 1].max(axis=(1, 3)).ravel()
    # z range of all blocks ahead, per quadrant of direction (x+ y+, x+ y-,
    # x- y+, x- y-): running minima and maxima from the far corner
    lo = czrange[:, 0].reshape(ncy, ncx)
    hi = czrange[:, 1].reshape(ncy, ncx)
    ahead = np.empty((4, ncy * ncx, 2))
    for q, (fx, fy) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
        for k, (z, acc) in enumerate(((lo, np.minimum), (hi, np.maximum))):
            a = z[::fy, ::fx]
            a = acc.accumulate(acc.accumulate(a[::-1, ::-1], axis=0), axis=1)
            ahead[q, :, k] = a[::-1, ::-1][::fy, ::fx].ravel()
    return {
        "glob": np.flatnonzero(is_global).astype(np.int64),
        "bounds": bounds,
        "cell": float(cell),
        "nx": nx,
        "ny": ny,
        "start": start,
        "items": items,
        "boxes": boxes,
        "zrange": zrange,
        "coarse": int(coarse),
        "ncx": int(ncx),
        "czrange": czrange,
        "ahead": np.ascontiguousarray(ahead),
    }


class _Buffers:
    """Output arrays of one thread, reused from chunk to chunk.

    ``out`` holds, for ``n`` returns, their ``xyz, primitive, range, time,
    channel, return number`` in the order :func:`simulate` writes them.
    """

    def __init__(self, n, n_prims):
        self.out = (
            np.empty((n, 3)),
            np.empty(n, dtype=np.int64),
            np.empty(n),
            np.empty(n),
            np.empty(n, dtype=np.int64),
            np.empty(n, dtype=np.int64),
        )
        self.mailbox = np.full(n_prims, -1, dtype=np.int64)


def _chunks(plan, conf, scene, grid, seed, drop, interest, spans, chunk):
    """Cast the pulses of the ``(k0, k1)`` spans one after the other."""
    buf = _Buffers(chunk * int(conf["max_returns"]), len(scene["kind"]))
    pattern = (plan["code"], plan["fp"], plan["fa"], plan["ft"])
    beam = (
        float(conf["min_range"]),
        float(conf["max_range"]),
        float(conf["range_noise"]),
        float(conf["beam_divergence"]),
        float(drop),
        int(conf["max_returns"]),
        float(conf["return_separation"]),
    )
    world = _scene_arrays(scene, grid)
    out = []
    for k0, k1 in spans:
        m = simulate(
            pattern, beam, _GAUSS, k0, k1, seed, world, buf.mailbox, interest, buf.out
        )
        out.append(tuple(a[:m].copy() for a in buf.out))
    return out


def scan(
    plan,
    conf,
    scene,
    grid,
    seed,
    *,
    drop=0.0,
    interest=None,
    chunk=1 << 18,
    n_jobs=None,
):
    """Cast every pulse: ``xyz, primitive, range, time, channel, return``.

    ``interest``: boxes ``(m, 6)``; rays meeting none of them are not cast.

    Chunks of pulses run on ``n_jobs`` threads (the kernel releases the
    GIL), each thread with its own output buffers; the output does not
    depend on the chunking or the threads.
    """
    n = plan["n_pulses"]
    spans = [(k, min(k + chunk, n)) for k in range(0, n, chunk)] or [(0, 0)]
    workers = 1 if n_jobs is None else int(n_jobs)
    if workers < 0:
        workers = max(1, (os.cpu_count() or 1) + 1 + workers)
    workers = max(1, min(workers, len(spans)))
    # contiguous runs of chunks per thread keep the output in pulse order
    runs = [list(r) for r in np.array_split(np.arange(len(spans)), workers)]
    if interest is None:
        interest = np.empty((0, 6))
    interest = np.ascontiguousarray(interest, dtype=np.float64)
    args = (plan, conf, scene, grid, seed, drop, interest)
    if workers > 1:
        with ThreadPoolExecutor(workers) as pool:
            futures = [
                pool.submit(_chunks, *args, [spans[i] for i in r], chunk) for r in runs
            ]
            parts = [p for f in futures for p in f.result()]
    else:
        parts = _chunks(*args, spans, chunk)
    return tuple(np.concatenate(a) for a in zip(*parts))


def first_hits(scene, origins, directions, *, tmin=0.0, tmax=np.inf, seed=0, grid=None):
    """First primitive hit by each ray, and its distance (for tests and tools).

    ``origins`` and ``directions`` are ``(n, 3)``; directions are
    normalised here. Returns ``(primitive, t)``: -1 and inf for a miss.
    """
    origins = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(d / np.linalg.norm(d, axis=1, keepdims=True))
    grid = build_grid(scene) if grid is None else grid
    prim = np.empty(len(origins), dtype=np.int64)
    t = np.empty(len(origins))
    cast_rays(
        origins,
        d,
        float(tmin),
        float(min(tmax, 1e30)),
        int(seed),
        _scene_arrays(scene, grid),
        np.full(len(scene["kind"]), -1, dtype=np.int64),
        prim,
        t,
    )
    return prim, t
