"""Outputs that cannot be written are found before any work and named;
outputs never go where a next run would read them; library messages speak
the CLI's options; progress shows on a terminal only, and ``--quiet``
means the same for every command."""

import errno
import fcntl
import io
import os
import pty
import struct
import subprocess
import sys
import termios

import pytest

import skpcd.segmentation
from skpcd.cli import main
from skpcd.cli._common import cli_spelling
from skpcd.io._atomic import PARTIAL_MARK
from skpcd.utils._progress import progress, silenced, stage


def _segment(scene, out, *extra):
    return ["segment", str(scene), "-o", str(out), "--min-size", "30", *extra]


def _fit(tmp_path, labelled_folder):
    labelled_folder(tmp_path / "train", n_per_class=4)
    model = tmp_path / "m.skpcd"
    assert main(["fit", str(tmp_path / "train"), "-o", str(model), "--quiet"]) == 0
    return model


@pytest.fixture
def no_segmentation(monkeypatch):
    """Fail the test if the command starts segmenting."""
    calls = []

    def segment_scene(*args, **kwargs):
        calls.append(1)
        raise AssertionError("the work started")

    monkeypatch.setattr(skpcd.segmentation, "segment_scene", segment_scene)
    return calls


# --- 9. unwritable outputs: found first, named -----------------------------------


@pytest.fixture
def read_only(tmp_path):
    """A folder in which nothing can be created: chmod 555, or for root
    (whom chmod does not stop) the immutable attribute; skipped when
    neither holds."""
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    immutable = False
    if os.access(folder, os.W_OK):
        done = subprocess.run(["chattr", "+i", str(folder)], capture_output=True)
        immutable = done.returncode == 0
        if not immutable:
            folder.chmod(0o755)
            pytest.skip("cannot make a read-only folder here")
    yield folder
    if immutable:
        subprocess.run(["chattr", "-i", str(folder)], check=True)
    folder.chmod(0o755)


@pytest.mark.parametrize(
    "command, name",
    [("segment", "segs"), ("identify", "l.ply"), ("segment", "a-file/segs")],
)
def test_an_unwritable_output_is_refused_before_any_work(
    tmp_path, capsys, scene_file, no_segmentation, read_only, command, name
):
    # before: the whole segmentation ran, then "error: .../.skpcd-partial-..."
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    if name.startswith("a-file/"):  # a path under a file: fails for root too
        (tmp_path / "a-file").write_text("not a folder")
        out = tmp_path / name
    else:
        out = read_only / name
    assert main([command, str(scene), "-o", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{out}:" in err[0], err
    assert PARTIAL_MARK not in err[0]
    assert no_segmentation == []
    assert not out.exists()
    assert list(read_only.iterdir()) == []
    assert _leftovers(tmp_path) == []


def test_an_output_on_a_read_only_file_system_is_named(
    tmp_path, capsys, scene_file, monkeypatch
):
    # before: "error: .../ro/.skpcd-partial-2085-probe-segs: Read-only file
    # system": the probe failed, then its removal failed too (on a read-only
    # file system, unlinking a missing file is EROFS, not ENOENT)
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    ro = tmp_path / "ro"
    ro.mkdir()
    real_open, real_unlink = os.open, os.unlink

    def read_only(call):
        def refused(path, *args, **kwargs):
            if os.fspath(path).startswith(str(ro)):
                raise OSError(errno.EROFS, os.strerror(errno.EROFS), os.fspath(path))
            return call(path, *args, **kwargs)

        return refused

    monkeypatch.setattr(os, "open", read_only(real_open))
    monkeypatch.setattr(os, "unlink", read_only(real_unlink))
    out = ro / "segs"
    assert main(["segment", str(scene), "-o", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{out}: Read-only file system" in err[0], err
    assert PARTIAL_MARK not in err[0]


def _leftovers(folder):
    return [p.name for p in folder.iterdir() if p.name.startswith(".")]


def test_an_unwritable_predictions_file_is_refused_before_reading(
    tmp_path, capsys, labelled_folder, monkeypatch, read_only
):
    model = _fit(tmp_path, labelled_folder)
    out = read_only / "pred.csv"
    import skpcd.cli._model as model_cli

    monkeypatch.setattr(model_cli, "read_folder", lambda *a: pytest.fail("read"))
    status = main(["predict", str(model), str(tmp_path / "train"), "-o", str(out)])
    assert status == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{out}:" in err[0], err


def _full_disk(monkeypatch):
    """``os.write`` fails with ENOSPC for every temporary output of skpcd."""
    real = os.write

    def write(fd, data):
        with_name = os.readlink(f"/proc/self/fd/{fd}")
        if PARTIAL_MARK in with_name:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data)

    monkeypatch.setattr(os, "write", write)


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="needs /proc")
@pytest.mark.parametrize("command", ["segment", "identify"])
def test_a_full_disk_is_found_before_any_work_and_names_the_output(
    tmp_path, capsys, monkeypatch, scene_file, no_segmentation, command
):
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    out = tmp_path / ("segs" if command == "segment" else "labelled.ply")
    _full_disk(monkeypatch)
    assert main([command, str(scene), "-o", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"skpcd {command}: error: {out}: No space left on device; nothing was "
        "written in its place"
    ]
    assert no_segmentation == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.ply"]


def test_a_write_error_names_the_output_not_its_temporary(tmp_path, capsys):
    from skpcd.io._atomic import atomic_path

    out = tmp_path / "x.csv"
    with pytest.raises(OSError) as info, atomic_path(out) as tmp:
        raise OSError(errno.EIO, "Input/output error", str(tmp))
    assert info.value.filename == str(out)
    assert list(tmp_path.iterdir()) == []


# --- 10. outputs never go into the folder a next run reads -----------------------


def test_predict_refuses_to_write_into_the_folder_it_reads(
    tmp_path, capsys, labelled_folder, scene_file
):
    # before: accepted; the next predict of the folder read pred.csv as a
    # segment ("the header names the columns file, label, probability but
    # not x, y, z")
    model = _fit(tmp_path, labelled_folder)
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    segs = tmp_path / "segs"
    assert main(_segment(scene, segs, "--eps", "1.0", "--quiet")) == 0
    before = sorted(p.name for p in segs.iterdir())
    inside = ["predict", str(model), str(segs), "-o", str(segs / "pred.csv")]
    with pytest.raises(SystemExit, match=r"is inside .*segs, the folder of segments"):
        main(inside)
    assert sorted(p.name for p in segs.iterdir()) == before
    beside = ["predict", str(model), str(segs), "-o", str(tmp_path / "pred.csv")]
    assert main(beside) == 0
    assert main([*beside, "--overwrite"]) == 0  # the next predict still reads it
    out = capsys.readouterr().out
    assert out.count(f"predicted {len(before) - 2} segments") == 2


def test_an_output_the_folder_would_not_read_may_go_into_it(tmp_path, labelled_folder):
    # a model is not a point cloud: reading the folder never takes it
    labelled_folder(tmp_path / "train", n_per_class=2)
    out = tmp_path / "train" / "m.skpcd"
    assert main(["fit", str(tmp_path / "train"), "-o", str(out), "--quiet"]) == 0
    assert main(["fit", str(tmp_path / "train"), "-o", str(tmp_path / "m2.skpcd")]) == 0


# --- 8. library messages in the CLI's spelling -----------------------------------


def test_library_keywords_are_spelled_as_the_command_s_options():
    from skpcd.cli import build_parser

    args = build_parser().parse_args(["segment", "s.las", "-o", "out"])
    assert cli_spelling("a: exists; pass overwrite=True to replace it", args) == (
        "a: exists; pass --overwrite to replace it"
    )
    assert cli_spelling("With tile_size pass ground='mobile'", args) == (
        "With --tile-size pass --ground mobile"
    )
    assert cli_spelling("or set structures=False.", args) == "or set --no-structures."
    assert cli_spelling("The 'min_cluster_size' parameter of f must be", args) == (
        "The --min-size option must be"
    )
    # paths are left alone
    for path in ("/data/tile_size/x.las: bad", "out/eps=0.3/segs", "tile_size.las"):
        assert cli_spelling(path, args) == path
    # a keyword the command has no option for stays as the library says it
    predict = build_parser().parse_args(["predict", "m", "f", "-o", "p.csv"])
    assert cli_spelling("pass tile_size=3 or format='joblib'", predict) == (
        "pass tile_size=3 or format='joblib'"
    )


@pytest.mark.parametrize(
    "options, said",
    [
        (["--eps", "-1"], "The --eps option must be"),
        (["--min-size", "0"], "The --min-size option must be"),
        (
            ["--tile-size", "20", "--tile-buffer", "0.1", "--eps", "1"],
            "--tile-buffer 0.1 is too small for --eps 1",
        ),
    ],
)
def test_errors_of_segment_name_its_options(tmp_path, scene_file, options, said):
    # before: "The 'eps' parameter of segment_scene", "tile_buffer=0.1 ..."
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    args = ["segment", str(scene), "-o", str(tmp_path / "o"), "--no-structures"]
    with pytest.raises(SystemExit) as info:
        main([*args, "--quiet", *options])
    assert said in str(info.value.code)
    assert "=" not in str(info.value.code).split(":", 1)[1].split(" the ")[0]


# --- 7. progress on a terminal, --quiet alike everywhere ------------------------


def test_progress_draws_a_bar_with_its_eta_and_stages_their_time():
    stream = io.StringIO()
    assert list(progress(range(5), desc="writing", enabled=True, stream=stream)) == [
        0,
        1,
        2,
        3,
        4,
    ]
    drawn = stream.getvalue()
    assert "writing: 100%" in drawn and "5/5" in drawn and "<" in drawn  # ETA
    stream = io.StringIO()
    with stage("ground (csf)", enabled=True, stream=stream):
        pass
    assert "ground (csf): 00:00" in stream.getvalue()
    stream = io.StringIO()
    with silenced():
        list(progress(range(5), enabled=True, stream=stream))
        with stage("ground", enabled=True, stream=stream):
            pass
    assert stream.getvalue() == ""
    # not a terminal: nothing
    list(progress(range(5), stream=stream))
    assert stream.getvalue() == ""


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_library_loops_draw_only_for_the_command():
    from skpcd.utils._progress import reporting, steps

    stream = _Terminal()
    assert list(steps(range(3), "tiles (cloth)", stream=stream)) == [0, 1, 2]
    assert stream.getvalue() == ""  # a script calling the library sees nothing
    with reporting():
        for _ in steps(range(3), "tiles (cloth)", stream=stream):
            with stage("GroundFilter (csf)", stream=stream):  # not drawn inside
                pass
    drawn = stream.getvalue()
    assert "tiles (cloth):" in drawn and "0/3 [" in drawn  # a count, an ETA
    assert drawn.rstrip("\r").endswith(" ")  # erased when the loop ends
    assert "GroundFilter" not in drawn


def _on_a_terminal(argv, cwd):
    """``python -m skpcd argv`` with stderr on a pseudo-terminal of 100
    columns; returns (status, stdout, what the terminal showed)."""
    leader, follower = pty.openpty()
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 100, 0, 0))
    proc = subprocess.Popen(
        [sys.executable, "-m", "skpcd", *argv],
        stdout=subprocess.PIPE,
        stderr=follower,
        cwd=cwd,
    )
    os.close(follower)
    shown = b""
    while True:
        try:
            chunk = os.read(leader, 4096)
        except OSError:  # EIO: the command ended
            break
        if not chunk:
            break
        shown += chunk
    out = proc.stdout.read().decode()
    proc.wait(timeout=120)
    os.close(leader)
    return proc.returncode, out, shown.decode(errors="replace")


def test_segment_shows_its_stages_and_a_bar_on_a_terminal_only(tmp_path, scene_file):
    # before: nothing until the end
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    status, out, shown = _on_a_terminal(_segment(scene, tmp_path / "a"), tmp_path)
    assert status == 0, shown
    assert "reading scene.ply: 00:0" in shown
    assert (
        "GroundFilter (" in shown
        and "structures (facades, wires, trunks): 00:" in shown
    )
    assert "writing: 100%" in shown and "it/s]" in shown
    assert "written" in out
    quiet = _segment(scene, tmp_path / "b", "--quiet")
    status, out, shown = _on_a_terminal(quiet, tmp_path)
    assert (status, out, shown) == (0, "", "")
    piped = subprocess.run(
        [sys.executable, "-m", "skpcd", *_segment(scene, tmp_path / "c")],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "written" in piped.stdout
    assert "%" not in piped.stderr and "00:0" not in piped.stderr


def test_quiet_prints_nothing_in_every_command_that_writes(
    tmp_path, capfd, labelled_folder, scene_file
):
    # before: fit printed data/fit/model lines and predict its summary (and
    # a first version of --quiet let the C++ messages of CSF through)
    model = _fit(tmp_path, labelled_folder)
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    train = str(tmp_path / "train")
    runs = [
        ["fit", train, "-o", str(tmp_path / "m2.skpcd")],
        ["predict", str(model), train, "-o", str(tmp_path / "p.csv")],
        ["describe", train, "-o", str(tmp_path / "f.csv")],
        # the cloth simulation's C++ messages on descriptor 1 too
        _segment(scene, tmp_path / "segs", "--ground", "csf"),
        ["identify", str(scene), "--model", str(model), "-o", str(tmp_path / "l.ply")],
    ]
    capfd.readouterr()
    for argv in runs:
        assert main([*argv, "--quiet"]) == 0, argv
        assert capfd.readouterr() == ("", ""), argv
    # without --quiet each says what it wrote
    assert main(["predict", str(model), train, "-o", str(tmp_path / "q.csv")]) == 0
    assert "predicted" in capfd.readouterr().out
