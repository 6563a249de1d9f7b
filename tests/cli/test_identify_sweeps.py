"""``skpcd segment|identify --method range-image`` and streamed identification,
``skpcd identify SCENE [SCENE ...] -o FOLDER``: one output per scene, the
same as identifying each alone; every refusal before any work, in one line;
an interrupt or a bad scene in the middle leaves the scenes done before."""

import csv
import json
import shutil
import signal
import sys
import textwrap
from pathlib import Path

import laspy
import numpy as np
import pytest

from skpcd.cli import main
from skpcd.io import read_point_cloud, write_point_cloud
from skpcd.io._atomic import PARTIAL_MARK
from tests.cli._started import start_until

REAL_SWEEP = Path("/work/shared/data/real_labelled/scans/semantickitti_07_000964.laz")
FIELDS = ("segment", "class", "ground", "probability")
SWEEP = ["--method", "range-image", "--no-structures"]  # one box, one segment


def _sweep(x, rings=16, columns=1800):
    """A sweep of a 16-ring spinning sensor at the origin: a flat road 1.8 m
    below it and a 2 m wide box ``x`` m ahead; returns the points and the
    ring of each."""
    az = np.tile(np.linspace(-np.pi, np.pi, columns, endpoint=False), rings)
    el = np.repeat(np.radians(np.linspace(-15, 1, rings)), columns)
    ring = np.repeat(np.arange(rings), columns)
    ray = np.column_stack(
        [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]
    )
    t = np.where(ray[:, 2] < 0, -1.8 / np.minimum(ray[:, 2], -1e-9), np.inf)
    tb = x / np.maximum(ray[:, 0], 1e-9)
    box = ray * tb[:, None]
    on = (np.abs(box[:, 1]) < 1) & (box[:, 2] > -1.8) & (tb < t) & (ray[:, 0] > 0)
    t[on] = tb[on]
    seen = np.isfinite(t)
    return ray[seen] * t[seen, None], ring[seen]


def _write_sweep(path, x):
    """The sweep with its box ``x`` m ahead written to ``path``: a LAS 1.4
    file with a ``ring`` extra dimension and an intensity, or any other
    format with an intensity; returns the points."""
    points, ring = _sweep(x)
    intensity = np.arange(len(points)) % 60000
    if path.suffix == ".las":
        header = laspy.LasHeader(point_format=6, version="1.4")
        header.scales, header.offsets = [0.001] * 3, [0.0] * 3
        header.add_extra_dims([laspy.ExtraBytesParams("ring", np.uint8)])
        las = laspy.LasData(header)
        las.x, las.y, las.z = points.T
        las.ring, las.intensity = ring, intensity
        las.write(path)
    else:
        write_point_cloud(path, points, fields={"intensity": intensity})
    return points


@pytest.fixture
def sweeps(tmp_path):
    """Three sweeps in tmp_path/in: a.las, b.ply, c.las."""
    folder = tmp_path / "in"
    folder.mkdir()
    for name, x in (("a.las", 6.0), ("b.ply", 8.0), ("c.las", 10.0)):
        _write_sweep(folder / name, x)
    return [folder / n for n in ("a.las", "b.ply", "c.las")]


def _tree(folder):
    """Every file under ``folder`` with its bytes."""
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in sorted(Path(folder).rglob("*"))
        if p.is_file()
    }


def _same_output(a, b):
    """Two identify outputs hold the same points and per-point fields, and
    their legends are the same."""
    xyz_a, fa = read_point_cloud(a, fields="all")
    xyz_b, fb = read_point_cloud(b, fields="all")
    np.testing.assert_array_equal(xyz_a, xyz_b)
    assert sorted(fa) == sorted(fb)
    for name in fa:
        np.testing.assert_array_equal(fa[name], fb[name], err_msg=name)
    legend = Path(f"{a}.classes.csv").read_text()
    assert legend == Path(f"{b}.classes.csv").read_text()
    return fa


def _refused(argv, match):
    """``main(argv)`` ends with a one-line message matching ``match``
    (status 1 from the shell); returns it."""
    with pytest.raises(SystemExit, match=match) as caught:
        main(argv)
    message = caught.value.code
    assert isinstance(message, str) and message.startswith("skpcd ")
    assert "\n" not in message
    return message


# --- several scenes, a folder ------------------------------------------------


def test_several_scenes_are_identified_as_each_alone(tmp_path, sweeps, capsys):
    out = tmp_path / "out"
    argv = ["identify", *map(str, sweeps), "-o", str(out), *SWEEP]
    assert main(argv) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 4
    for line, scene in zip(lines, sweeps):
        assert line.startswith(f"{scene.name}  ") and " points  " in line
        assert line.endswith(" s") and " segments  " in line
    assert lines[-1].startswith("identified 3 scenes in ")
    assert "sweeps per second" in lines[-1]
    written = sorted(p.name for p in out.iterdir())
    assert written == sorted(
        [s.name for s in sweeps] + [f"{s.name}.classes.csv" for s in sweeps]
    )
    for scene in sweeps:
        alone = tmp_path / "alone" / scene.name
        alone.parent.mkdir(exist_ok=True)
        argv = ["identify", str(scene), "-o", str(alone), *SWEEP, "--quiet"]
        assert main(argv) == 0
        fields = _same_output(out / scene.name, alone)
        assert set(FIELDS) <= set(fields)
        # the box is one segment, the road ground
        assert fields["segment"].max() == 0 and fields["ground"].mean() > 0.9
        if scene.suffix == ".las":  # every dimension of the scan kept
            _, source = read_point_cloud(scene, fields="all")
            np.testing.assert_array_equal(fields["ring"], source["ring"])
            np.testing.assert_array_equal(fields["intensity"], source["intensity"])
    capsys.readouterr()
    # --quiet: nothing on standard output
    argv = ["identify", *map(str, sweeps), "-o", str(out), *SWEEP]
    assert main([*argv, "--overwrite", "--quiet"]) == 0
    assert capsys.readouterr().out == ""


def test_a_folder_is_its_point_cloud_files_by_name(tmp_path, sweeps, capsys):
    folder = sweeps[0].parent
    (folder / ".hidden.ply").write_bytes(b"not read")
    (folder / "a.las.classes.csv").write_text("class,name\n")  # a legend
    (folder / "notes").mkdir()
    out = tmp_path / "made" / "out"  # created, with its parent
    assert main(["identify", str(folder), "-o", str(out), *SWEEP]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines[:-1]] == ["a.las", "b.ply", "c.las"]
    assert sorted(p.name for p in out.iterdir() if not p.name.endswith(".csv")) == [
        "a.las",
        "b.ply",
        "c.las",
    ]
    rows = list(csv.DictReader((out / "b.ply.classes.csv").open()))
    assert rows[0]["name"] == "(no segment)"


def test_an_empty_folder_is_refused(tmp_path):
    (tmp_path / "empty").mkdir()
    argv = ["identify", str(tmp_path / "empty"), "-o", str(tmp_path / "out")]
    _refused(argv, "holds no point-cloud file")
    assert not (tmp_path / "out").exists()


# --- range-image in segment and identify ----------------------------------------


def test_segment_range_image_writes_valid_metadata(tmp_path, sweeps, capsys):
    out = tmp_path / "segs"
    assert main(["segment", str(sweeps[0]), "-o", str(out), *SWEEP]) == 0
    printed = capsys.readouterr().out
    assert "segments  1 (range-image); " in printed and "nan" not in printed
    # strict JSON: no NaN
    text = (out / "segmentation.json").read_text()
    meta = json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in JSON"))
    assert meta["method"] == "range-image" and meta["eps"] is None
    assert meta["ground"] == "range-image" and meta["n_segments"] == 1
    assert main(["info", str(out)]) == 0
    assert "nan" not in capsys.readouterr().out


def test_segment_says_where_the_rays_start(tmp_path, capsys):
    # the sweep in a vehicle's frame (origin on the road, 1.8 m below the
    # sensor): said on stderr and in segmentation.json; in its sensor's
    # frame or with --sensor, nothing said, the choice in the JSON
    points = _sweep(8.0)[0]
    scenes = {}
    for name, shift in (("vehicle", 1.8), ("sensor", 0.0)):
        scenes[name] = tmp_path / f"{name}.ply"
        write_point_cloud(scenes[name], points + np.array([0.0, 0.0, shift]))
    runs = {
        "vehicle": (scenes["vehicle"], []),
        "sensor": (scenes["sensor"], []),
        "given": (scenes["vehicle"], ["--sensor", "0", "0", "1.8"]),
    }
    for name, (scene, extra) in runs.items():
        out = tmp_path / f"segs_{name}"
        assert main(["segment", str(scene), "-o", str(out), *SWEEP, *extra]) == 0
        err = capsys.readouterr().err
        meta = json.loads((out / "segmentation.json").read_text())
        assert ("the origin of the sweep is on the ground" in err) == (
            name == "vehicle"
        )
        assert meta["n_segments"] == 1
        if name == "vehicle":
            assert meta["sensor_from"] == "above the origin"
            np.testing.assert_allclose(meta["sensor"], [0, 0, 1.85], atol=0.06)
            assert "--sensor X Y Z" in err
        else:
            assert meta["sensor_from"] == ("origin" if name == "sensor" else "given")


def test_range_image_reads_the_rings_of_the_file(tmp_path, sweeps):
    from skpcd.segmentation import segment_scene

    scene = sweeps[0]  # a LAS file with a ring field
    out = tmp_path / "alone.ply"
    assert main(["identify", str(scene), "-o", str(out), *SWEEP, "--quiet"]) == 0
    _, fields = read_point_cloud(out, fields=["segment", "ground"])
    want = segment_scene(str(scene), method="range-image", structures=False)
    np.testing.assert_array_equal(fields["segment"], want.labels)
    np.testing.assert_array_equal(fields["ground"].astype(bool), want.ground)


def test_range_image_with_another_ground(tmp_path, sweeps, capsys):
    out = tmp_path / "segs"
    argv = ["segment", str(sweeps[1]), "-o", str(out), *SWEEP, "--ground", "none"]
    assert main([*argv, "--min-size", "10"]) == 0
    assert "0 ground" in capsys.readouterr().out
    meta = json.loads((out / "segmentation.json").read_text())
    assert meta["eps"] is None and meta["n_ground"] == 0


@pytest.mark.parametrize("command", ["segment", "identify", "identify several"])
def test_range_image_is_refused_with_tile_size(tmp_path, sweeps, command):
    scenes = [str(s) for s in (sweeps if command.endswith("several") else sweeps[:1])]
    out = tmp_path / ("out" if command == "segment" else "out.ply")
    argv = [command.split()[0], *scenes, "-o", str(out), *SWEEP, "--tile-size", "20"]
    before = _tree(tmp_path)
    message = _refused(argv, "--method range-image")
    assert "--tile-size" in message
    assert _tree(tmp_path) == before


# --- refusals, before any work ------------------------------------------------------


@pytest.fixture
def unread_model(tmp_path):
    """A --model that is never read: the refusals come first."""
    model = tmp_path / "model.skpcd"
    model.write_bytes(b"never read: the outputs are refused first")
    return model


def test_the_output_folder_may_not_hold_inputs(tmp_path, sweeps, unread_model):
    folder = sweeps[0].parent
    before = _tree(tmp_path)
    scenes = list(map(str, sweeps))
    argv = ["identify", *scenes, "--model", str(unread_model), *SWEEP, "--overwrite"]
    for out in (folder, folder / ".." / "in"):
        message = _refused([*argv, "-o", str(out)], "holds input scenes")
        assert str(out) in message
    assert _tree(tmp_path) == before


def test_two_scenes_of_one_name_are_refused(tmp_path, sweeps, unread_model):
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(sweeps[1], other / sweeps[1].name)
    before = _tree(tmp_path)
    out = tmp_path / "out"
    for scenes in (
        [sweeps[0], sweeps[1], other / sweeps[1].name],
        [sweeps[0].parent, other],  # two folders holding b.ply
        [sweeps[0], sweeps[0]],
    ):
        argv = ["identify", *map(str, scenes), "-o", str(out)]
        message = _refused(
            [*argv, "--model", str(unread_model)], "two scenes are named"
        )
        assert sweeps[0].name in message or sweeps[1].name in message
    assert _tree(tmp_path) == before and not out.exists()


def test_existing_outputs_need_overwrite(tmp_path, sweeps, unread_model, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "b.ply.classes.csv").write_text("an earlier legend")
    before = _tree(tmp_path)
    argv = ["identify", *map(str, sweeps), "-o", str(out), *SWEEP]
    message = _refused([*argv, "--model", str(unread_model)], "exist; pass --overwrite")
    assert "b.ply.classes.csv" in message
    assert _tree(tmp_path) == before
    assert main([*argv, "--overwrite", "--quiet"]) == 0
    assert (out / "b.ply.classes.csv").read_text().startswith("class,")


@pytest.mark.parametrize(
    "case",
    ["inventory", "output is a file", "missing scene", "kitti bin"],
)
def test_other_refusals(tmp_path, sweeps, unread_model, case):
    argv = ["identify", *map(str, sweeps), "--model", str(unread_model)]
    out = tmp_path / "out"
    if case == "inventory":
        argv += ["--inventory", str(tmp_path / "objects.csv")]
        match = "--inventory takes one scene"
    elif case == "output is a file":
        out = tmp_path / "out.ply"
        out.write_text("a file")
        match = "is a file; with several scenes -o names a folder"
    elif case == "missing scene":
        argv.insert(2, str(tmp_path / "missing.ply"))
    else:
        np.zeros((10, 4), np.float32).tofile(tmp_path / "in" / "000000.bin")
        argv.insert(2, str(tmp_path / "in" / "000000.bin"))
        match = "000000.bin: a KITTI .bin scan holds"
    before = _tree(tmp_path)
    if case == "missing scene":
        assert main([*argv, "-o", str(out)]) == 1
    else:
        _refused([*argv, "-o", str(out)], match)
    assert _tree(tmp_path) == before and not (tmp_path / "out").is_dir()


# --- a bad scene, an interrupt -------------------------------------------------------


def test_a_bad_scene_stops_there_and_the_outputs_before_it_stay(tmp_path, sweeps):
    bad = sweeps[0].parent / "b.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nend_header\n")
    out = tmp_path / "out"
    message = _refused(
        ["identify", *map(str, sweeps), "-o", str(out), *SWEEP, "--quiet"], "b.ply"
    )
    assert message.startswith("skpcd identify: error: ")
    assert "the 1 scenes before it are written in" in message
    assert sorted(p.name for p in out.iterdir()) == ["a.las", "a.las.classes.csv"]


def test_a_bad_first_scene_leaves_no_output_folder(tmp_path, sweeps):
    bad = sweeps[0].parent / "0.ply"  # first by name
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nend_header\n")
    out = tmp_path / "new" / "out"
    _refused(["identify", str(bad.parent), "-o", str(out), *SWEEP, "--quiet"], "0.ply")
    assert not (tmp_path / "new").exists()


def test_an_interrupt_leaves_the_scenes_done(tmp_path, sweeps, monkeypatch):
    import skpcd.io

    original, calls = skpcd.io.write_labelled_scan, []

    def interrupted_second(*args, **kwargs):
        calls.append(1)
        original(*args, **kwargs)  # the temporary file written, then Ctrl-C
        if len(calls) == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr(skpcd.io, "write_labelled_scan", interrupted_second)
    out = tmp_path / "out"
    argv = ["identify", *map(str, sweeps), "-o", str(out), *SWEEP, "--quiet"]
    assert main(argv) == 130
    assert sorted(p.name for p in out.iterdir()) == ["a.las", "a.las.classes.csv"]


# The command as ``python -m skpcd`` runs it, the second scene's writing made
# long (argv: MARKER ARGS...).
_SCRIPT = textwrap.dedent(
    """
    import sys, time
    import skpcd.io

    marker, argv = sys.argv[1], sys.argv[2:]
    original, calls = skpcd.io.write_labelled_scan, []

    def slow_second(*args, **kwargs):
        calls.append(1)
        original(*args, **kwargs)
        if len(calls) == 2:
            open(marker, "w").close()
            time.sleep(60)

    skpcd.io.write_labelled_scan = slow_second
    sys.argv = ["skpcd", *argv]
    from skpcd.cli import main
    sys.exit(main())
    """
)


@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_leaves_the_scenes_done_and_nothing_partial(tmp_path, sweeps, how):
    marker, out = tmp_path / "began", tmp_path / "out"
    argv = ["identify", *map(str, sweeps), "-o", str(out), *SWEEP, "--quiet"]
    proc = start_until(
        [sys.executable, "-c", _SCRIPT, str(marker), *argv],
        marker,
        {"TMPDIR": str(tmp_path)},
        "the second scene was never written",
    )
    proc.send_signal(how)
    err = proc.communicate(timeout=60)[1].strip().splitlines()
    assert proc.returncode == (130 if how == signal.SIGINT else 143), err
    assert "no partial output left" in err[-1]
    assert sorted(p.name for p in out.iterdir()) == ["a.las", "a.las.classes.csv"]
    left = [p.name for p in tmp_path.rglob("*") if PARTIAL_MARK in p.name]
    assert left == [] and not list(tmp_path.glob("skpcd-*"))


# --- a real sweep -------------------------------------------------------------------


@pytest.mark.skipif(not REAL_SWEEP.exists(), reason="the real sweeps are not here")
def test_a_real_sweep_streamed_and_alone(tmp_path, capsys):
    copy = tmp_path / "in" / "copy.laz"
    copy.parent.mkdir()
    shutil.copy(REAL_SWEEP, copy)
    out = tmp_path / "out"
    argv = ["identify", str(REAL_SWEEP), str(copy), "-o", str(out), *SWEEP]
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"{REAL_SWEEP.name}  120485 points  ")
    alone = tmp_path / "alone.laz"
    assert main(["identify", str(REAL_SWEEP), "-o", str(alone), *SWEEP]) == 0
    fields = _same_output(out / REAL_SWEEP.name, alone)
    _same_output(out / "copy.laz", alone)
    _, source = read_point_cloud(REAL_SWEEP, fields="all")
    assert set(source) <= set(fields)  # every dimension kept
    assert fields["segment"].max() >= 10  # cars, poles, trunks...
    assert 0.3 < fields["ground"].mean() < 0.9
