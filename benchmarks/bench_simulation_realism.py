"""How real do simulated scans look? Simulated aerial objects against DALES.

1. Aerial: streets of :func:`~skpcd.datasets.make_street_scene` scanned with
   the ``"aerial"`` pattern (its defaults: five flight lines at 1300 m, two
   channels looking 14 degrees forward and backward, about 40 pulses per m2),
   cut by true instance into the five DALES classes
   (facade -> building; pole, street_light, lamp_post and traffic_light ->
   pole, as DALES's poles are utility and light poles; car; fence; tree;
   the other classes are left out), objects
   of at least ``--min-points`` returns. Compared with the 399 real DALES
   objects (``load_dales_objects``) on point count, height (z extent) and
   point spacing (:func:`skpcd.preprocessing.point_spacing`, the median
   distance to the nearest neighbour), each as the 10th, 50th and 90th
   percentile per class, and the points per metre of height (which takes
   the height out of the point count); for poles, the fraction of the circumference seen
   (twelve 30-degree sectors around an axis fitted to the points of the
   shaft, 20 to 60 % of the height; the same estimator for both).
2. Mobile: bare poles of simulated streets (``"mobile"`` pattern, its
   defaults: two profilers at +-45 degrees, 200 Hz, 0.1 degree, 10 m/s):
   points per metre of shaft (2.2 to 3.2 m above the base, above parked
   cars) against the horizontal distance d from the trajectory, with the
   analytic count of the scan geometry, ``2 D / (dx d da)`` for a pole of
   diameter D, profile spacing ``dx = speed / rotation_rate`` and angular
   step ``da`` (each scanner's plane crosses the pole ``D / (dx sin 45)``
   times, each time with ``sin 45 / (d da)`` points per metre): the fitted
   exponent of count against range, and the ratio to the analytic count.

Run from the repository root (about 4 minutes)::

    python benchmarks/bench_simulation_realism.py
    python benchmarks/bench_simulation_realism.py --quick

The results go to ``benchmarks/results/simulation_realism.{json,txt}``.
"""

import argparse
import itertools
import json
import os
from pathlib import Path

import numpy as np

from skpcd.datasets import SCAN_PATTERNS, load_dales_objects, make_street_scene
from skpcd.preprocessing import point_spacing

HERE = Path(__file__).resolve().parent
DALES = Path(
    os.environ.get("SKPCD_DALES_DIR", HERE.parent.parent / "shared/data/dales_objects")
)
TO_DALES = {
    "facade": "building",
    "car": "car",
    "fence": "fence",
    "tree": "tree",
    "pole": "pole",
    "street_light": "pole",
    "lamp_post": "pole",
    "traffic_light": "pole",
}
CLASSES = ("building", "car", "fence", "pole", "tree")


def circumference_seen(points, center=None, n_sectors=12):
    """Fraction of 30-degree sectors around the shaft axis holding a point.

    The shaft is the band 20-60 % of the z extent; its axis is a least
    squares circle fit (Kasa) of the band's xy when that gives a radius
    between 3 and 50 cm, else the band's mean. None with fewer than 5
    points in the band.
    """
    z = points[:, 2]
    lo, hi = z.min() + 0.2 * np.ptp(z), z.min() + 0.6 * np.ptp(z)
    xy = points[(z >= lo) & (z <= hi), :2]
    if len(xy) < 5:
        return None
    if center is None:
        center = xy.mean(axis=0)
        a = np.column_stack([2 * xy, np.ones(len(xy))])
        sol, *_ = np.linalg.lstsq(a, (xy**2).sum(axis=1), rcond=None)
        r = np.sqrt(max(sol[2] + sol[0] ** 2 + sol[1] ** 2, 0.0))
        if 0.03 <= r <= 0.5 and np.linalg.norm(sol[:2] - center) < 0.5:
            center = sol[:2]
    v = xy - center
    sector = (np.arctan2(v[:, 1], v[:, 0]) % (2 * np.pi)) // (2 * np.pi / n_sectors)
    return len(np.unique(sector)) / n_sectors


def _stats(clouds):
    n = np.array([len(c) for c in clouds], float)
    h = np.array([np.ptp(c[:, 2]) for c in clouds])
    s = np.array([point_spacing(c) for c in clouds])
    return {
        "objects": len(clouds),
        "points": np.percentile(n, [10, 50, 90]).tolist(),
        "height": np.percentile(h, [10, 50, 90]).tolist(),
        "points_per_metre": np.percentile(
            n / np.maximum(h, 0.1), [10, 50, 90]
        ).tolist(),
        "spacing": np.nanpercentile(s, [10, 50, 90]).tolist(),
    }


def aerial(n_streets, length, min_points):
    objects = {c: [] for c in CLASSES}
    centres = []
    for seed in range(n_streets):
        scene = make_street_scene(length, scanner="aerial", random_state=seed)
        order = np.argsort(scene.instances, kind="stable")
        inst = scene.instances[order]
        bounds = np.searchsorted(inst, np.arange(len(scene.frame) + 1) - 0.5)
        for f in scene.frame:
            cls = TO_DALES.get(f["class"])
            pts = scene.points[order[bounds[f["id"]] : bounds[f["id"] + 1]]]
            if cls is None or len(pts) < min_points:
                continue
            objects[cls].append(pts)
            if cls == "pole":
                centres.append(np.asarray(f["position"][:2]))
    return objects, centres


def mobile_poles(n_streets, length):
    """(distance, diameter, points per metre of shaft) of bare poles."""
    from skpcd.datasets._street._layout import Street, build_scene, furnish
    from skpcd.datasets._street._scanners import (
        build_grid,
        plan_scan,
        resolve_pattern,
        scan,
    )

    conf = resolve_pattern("mobile")
    rows = []
    for seed in range(n_streets):
        rng = np.random.RandomState(1000 + seed)
        street = Street(rng, length)
        street.drive = (-12.0, length + 12.0)
        plan = furnish(street, rng, wanted={"pole": 14})
        scene, frame = build_scene(street, plan, rng)
        poles = [f for f in frame if f["class"] == "pole"]
        boxes = []
        for f in poles:
            x, y, z = f["position"]
            boxes.append([x - 0.5, y - 0.5, z + 2.2, x + 0.5, y + 0.5, z + 3.2])
        xyz, prim, *_ = scan(
            plan_scan("mobile", conf, street),
            conf,
            scene,
            build_grid(scene),
            seed,
            interest=np.array(boxes),
        )
        inst = scene["instance"][prim]
        lane = street.right_lane
        for f in poles:
            x, y, z = f["position"]
            pts = xyz[inst == f["id"]]
            band = (pts[:, 2] >= z + 2.2) & (pts[:, 2] <= z + 3.2)
            # radius at the band, from the pole's primitive (a cone frustum)
            row = scene["params"][np.flatnonzero(scene["instance"] == f["id"])[0]]
            r0, r1, shaft = row[6], row[7], row[11]
            radius = r0 + (r1 - r0) * 2.7 / shaft
            rows.append((abs(y - lane), 2 * radius, band.sum() / 1.0))
    return np.array(rows), conf


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--streets", type=int, default=24)
    p.add_argument("--mobile-streets", type=int, default=6)
    p.add_argument("--length", type=float, default=100.0)
    p.add_argument("--min-points", type=int, default=30)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=str(HERE / "results" / "simulation_realism.json"))
    a = p.parse_args(argv)
    if a.quick:
        a.streets, a.mobile_streets = 3, 1

    real = load_dales_objects(DALES)
    dales = {c: [x for x, y in zip(real.data, real.target) if y == c] for c in CLASSES}
    sim, centres = aerial(a.streets, a.length, a.min_points)
    result = {"dales": {}, "simulated": {}}
    for c in CLASSES:
        result["dales"][c] = _stats(dales[c])
        if sim[c]:
            result["simulated"][c] = _stats(sim[c])
    circ = {
        "dales": [circumference_seen(x) for x in dales["pole"]],
        "simulated": [circumference_seen(x) for x in sim["pole"]],
        "simulated, true axis": [
            circumference_seen(x, c) for x, c in zip(sim["pole"], centres)
        ],
    }
    circ = {k: [v for v in vals if v is not None] for k, vals in circ.items()}
    result["pole_circumference"] = {
        k: {"poles": len(v), "percentiles": np.percentile(v, [10, 50, 90]).tolist()}
        for k, v in circ.items()
        if v
    }

    rows, conf = mobile_poles(a.mobile_streets, a.length)
    dx = conf["speed"] / conf["rotation_rate"]
    da = np.deg2rad(conf["angular_step"])
    d, diam, per_m = rows.T
    n_scanners = len(conf["plane_azimuths"])
    expected = n_scanners * diam / (dx * d * da)
    seen = per_m > 0
    slope = np.polyfit(np.log(d[seen]), np.log(per_m[seen] / diam[seen]), 1)[0]
    ratio = per_m[seen] / expected[seen]
    bins = [0, 3, 5, 7, 9, 12, 20]
    by_range = []
    for lo, hi in itertools.pairwise(bins):
        m = seen & (d >= lo) & (d < hi)
        if m.any():
            by_range.append(
                {
                    "range": [lo, hi],
                    "poles": int(m.sum()),
                    "points_per_m": float(np.median(per_m[m])),
                    "expected_per_m": float(np.median(expected[m])),
                }
            )
    result["mobile"] = {
        "poles": len(rows),
        "hidden_poles": int((~seen).sum()),
        "fitted_exponent": float(slope),
        "ratio_to_analytic": np.percentile(ratio, [10, 50, 90]).tolist(),
        "by_range": by_range,
    }

    def fmt(v, digits=2):
        return "/".join(f"{x:.{digits}f}" for x in v)

    aer = SCAN_PATTERNS["aerial"]
    text = [
        "Simulated aerial objects against the DALES objects (real aerial LiDAR)",
        f"simulated: {a.streets} streets of {a.length:g} m, make_street_scene("
        f"scanner='aerial'), {len(aer['line_offsets'])} flight lines at "
        f"{aer['altitude']:g} m, {aer['density']:g} pulses/m2 each, channels tilted "
        f"{'/'.join(f'{t:g}' for t in aer['channel_tilts'])} deg; objects of "
        f">= {a.min_points} returns, cut by true instance",
        "values: 10th/50th/90th percentile",
        "",
        f"{'class':9s} {'source':9s} {'objects':>7s} {'points':>16s} "
        f"{'height m':>16s} {'spacing m':>17s} {'points/m height':>16s}",
    ]
    for c in CLASSES:
        for src in ("dales", "simulated"):
            s = result[src].get(c)
            if s is None:
                continue
            text.append(
                f"{c:9s} {src:9s} {s['objects']:7d} {fmt(s['points'], 0):>16s} "
                f"{fmt(s['height'], 1):>16s} {fmt(s['spacing'], 3):>17s} "
                f"{fmt(s['points_per_metre'], 0):>16s}"
            )
    text += ["", "poles: fraction of the circumference seen (12 sectors of 30 deg)"]
    for k, v in result["pole_circumference"].items():
        text.append(f"  {k:22s} {v['poles']:4d} poles  {fmt(v['percentiles'])}")
    m = result["mobile"]
    text += [
        "",
        "Mobile pattern (defaults), bare poles: points per metre of shaft "
        "(2.2-3.2 m above the base) against the horizontal range d",
        f"  {m['poles']} poles ({m['hidden_poles']} hidden at that height), "
        f"fitted exponent of points/m against d: {m['fitted_exponent']:.2f} "
        "(the geometry gives -1)",
        "  ratio to the analytic count 2 D / (dx d da): "
        f"{fmt(m['ratio_to_analytic'])} (10/50/90 %)",
        f"  {'range m':>9s} {'poles':>5s} {'points/m':>9s} {'analytic':>9s}",
    ]
    for r in m["by_range"]:
        text.append(
            f"  {r['range'][0]:>4d}-{r['range'][1]:<4d} {r['poles']:5d} "
            f"{r['points_per_m']:9.0f} {r['expected_per_m']:9.0f}"
        )
    print("\n".join(text))
    if a.out and not a.quick:
        out = Path(a.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(result, indent=1) + "\n")
        out.with_suffix(".txt").write_text("\n".join(text) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
