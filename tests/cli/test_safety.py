"""The CLI never loses data, mixes runs, leaves a partial output that looks
complete, or writes over one of its inputs; it ends every failure with one
clear line."""

import csv
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from skpcd.cli import build_parser, main
from skpcd.io import read_segments


def _leftovers(folder):
    """Hidden temporary outputs left in ``folder``."""
    return [p.name for p in folder.iterdir() if p.name.startswith(".")]


def _segment_args(scene, out, *extra):
    return ["segment", str(scene), "-o", str(out), "--min-size", "30", *extra]


# --- an output folder holds one run, whole ------------------------------------


def test_overwrite_replaces_the_whole_run(tmp_path, capsys, scene_file):
    # before: the 11 files of the second run were written over the 21 of the
    # first, and predict read 21 segments of both runs
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    out = tmp_path / "segs"
    args = _segment_args(scene, out, "--eps", "0.3", "--quiet")
    assert main([*args, "--min-size", "10"]) == 0  # 54 segments
    first = sorted(p.name for p in out.iterdir())
    assert main(_segment_args(scene, out, "--eps", "1.0", "--overwrite")) == 0
    n = int(capsys.readouterr().out.split("segments  ")[1].split()[0])
    second = sorted(p.name for p in out.iterdir())
    # the segments, segmentation.json and segments.csv
    assert len(first) > len(second) == n + 2
    rows = list(csv.DictReader((out / "segments.csv").open()))
    assert [r["file"] for r in rows] == second[:-2]
    clouds, _, _ = read_segments(out)
    assert len(clouds) == n
    assert _leftovers(tmp_path) == []


def test_overwrite_never_deletes_what_skpcd_did_not_write(tmp_path, scene_file):
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    out = tmp_path / "segs"
    assert main(_segment_args(scene, out, "--eps", "1.0", "--quiet")) == 0
    (out / "labels.csv").write_text("segment_0000.ply,car\n")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(SystemExit, match="not empty; pass --overwrite"):
        main(_segment_args(scene, out, "--eps", "0.3", "--quiet"))
    assert main(_segment_args(scene, out, "--eps", "0.3", "--overwrite")) == 1
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert _leftovers(tmp_path) == []


def test_segment_never_writes_over_its_scene(tmp_path, scene_file):
    # before: `segment dir/segment_0000.ply -o dir --overwrite` replaced the
    # 581,764-point scene by one of its segments
    scene = tmp_path / "segs" / "segment_0000.ply"
    scene.parent.mkdir()
    scene_file(scene)
    before = scene.read_bytes()
    for out in (scene.parent, tmp_path):
        with pytest.raises(SystemExit, match="inside the output folder"):
            main(_segment_args(scene, out, "--overwrite", "--quiet"))
    assert scene.read_bytes() == before


@pytest.mark.parametrize("command", ["fit", "describe"])
def test_no_command_writes_over_an_input_segment(tmp_path, command, labelled_folder):
    # before: `fit segs -o segs/obj_000.ply --overwrite` replaced a segment
    # by a pickle
    labelled_folder(tmp_path / "segs", n_per_class=1)
    name = "000.xyz" if command == "fit" else "labels.csv"
    target = tmp_path / "segs" / name
    before = target.read_bytes()
    args = [command, str(target.parent), "-o", str(target), "--overwrite", "--quiet"]
    with pytest.raises(SystemExit, match="is an input file"):
        main(args)
    assert target.read_bytes() == before


def test_predict_refuses_a_folder_of_an_interrupted_or_mixed_run(
    tmp_path, labelled_folder, scene_file
):
    # before: an interrupted segment left segment files without
    # segments.csv, and predict labelled them ("predicted 200 segments")
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    labelled_folder(tmp_path / "train", n_per_class=4)
    model = tmp_path / "m.joblib"
    assert main(["fit", str(tmp_path / "train"), "-o", str(model), "--quiet"]) == 0
    out = tmp_path / "segs"
    assert main(_segment_args(scene, out, "--eps", "1.0", "--quiet")) == 0
    pred = ["predict", str(model), str(out), "-o", str(tmp_path / "p.csv")]
    assert main(pred) == 0
    os.replace(out / "segment_0000.ply", out / "segment_0099.ply")
    assert main([*pred, "--overwrite"]) == 1  # 1 not listed, 1 missing
    (out / "segments.csv").unlink()
    assert main([*pred, "--overwrite"]) == 1  # no segments.csv
    with pytest.raises(Exception, match=r"no segments\.csv"):
        read_segments(out)


# --- interrupts and failures leave nothing that looks complete -----------------


def _interrupt_on_write(monkeypatch, after, how):
    """Make the ``after``-th segment file written interrupt the command."""
    import skpcd.io._segment_folder as folder

    calls = []
    original = folder.write_point_cloud

    def write(*args, **kwargs):
        calls.append(1)
        if len(calls) == after:
            if how == "SIGTERM":
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(1)
            raise KeyboardInterrupt
        return original(*args, **kwargs)

    monkeypatch.setattr(folder, "write_point_cloud", write)


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM"])
def test_an_interrupted_segment_leaves_no_output(
    tmp_path, capsys, monkeypatch, how, scene_file
):
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    out = tmp_path / "segs"
    _interrupt_on_write(monkeypatch, 4, how)
    status = main(_segment_args(scene, out, "--eps", "1.0", "--quiet"))
    assert status == (130 if how == "SIGINT" else 143)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no partial output left" in err[0]
    assert not out.exists() and _leftovers(tmp_path) == []


def test_an_interrupted_overwrite_keeps_the_previous_run(
    tmp_path, monkeypatch, scene_file
):
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    out = tmp_path / "segs"
    assert main(_segment_args(scene, out, "--eps", "1.0", "--quiet")) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    _interrupt_on_write(monkeypatch, 2, "SIGINT")
    args = _segment_args(scene, out, "--eps", "0.3", "--quiet", "--overwrite")
    assert main(args) == 130
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert _leftovers(tmp_path) == []


def test_ctrl_c_in_a_real_process_is_one_line(tmp_path, scene_file):
    """A real SIGINT from outside, while the segments are being written."""
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    out = tmp_path / "segs"
    script = textwrap.dedent(
        f"""
        import sys, time
        import skpcd.io._segment_folder as folder
        from skpcd.cli import main
        original = folder.write_point_cloud
        def slow(*a, **k):
            time.sleep(2.0)  # still writing when the signal comes, under any load
            return original(*a, **k)
        folder.write_point_cloud = slow
        sys.exit(main({_segment_args(scene, out, "--eps", "1.0", "--quiet")!r}))
        """
    )
    # as from a terminal: SIGINT at its default (a pytest-xdist worker ignores
    # it, and a child started from there would inherit that and run on)
    proc = subprocess.Popen(
        [sys.executable, "-c", script],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 120
    while not _leftovers(tmp_path) and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=60)[1]
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == [
        "skpcd segment: interrupted; no partial output left"
    ]
    assert not out.exists() and _leftovers(tmp_path) == []


def _run_with_file_size_limit(argv, limit):
    """``skpcd argv`` in a process that cannot write files larger than
    ``limit`` bytes (as on a full disk: writes fail with an OSError)."""
    script = textwrap.dedent(
        f"""
        import resource, signal, sys
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
        from skpcd.cli import main
        sys.exit(main({argv!r}))
        """
    )
    return subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
    )


def test_a_full_disk_is_one_line_and_leaves_nothing(
    tmp_path, labelled_folder, scene_file
):
    # before: a raw OSError traceback, and predict left a 0-byte CSV that
    # blocked the rerun
    scene = tmp_path / "scene.ply"
    scene_file(scene)
    labelled_folder(tmp_path / "train", n_per_class=4)
    model = tmp_path / "m.joblib"
    assert main(["fit", str(tmp_path / "train"), "-o", str(model), "--quiet"]) == 0
    out = tmp_path / "segs"
    proc = _run_with_file_size_limit(_segment_args(scene, out, "--quiet"), 4000)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.splitlines()) == 1
    assert "File too large" in proc.stderr
    assert not out.exists() and _leftovers(tmp_path) == []
    csv_out = tmp_path / "p.csv"
    argv = ["predict", str(model), str(tmp_path / "train"), "-o", str(csv_out)]
    proc = _run_with_file_size_limit(argv, 100)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert not csv_out.exists() and _leftovers(tmp_path) == []
    assert main(argv) == 0  # nothing blocks the rerun


# --- messages and rough edges -----------------------------------------------------


@pytest.mark.parametrize("command", ["evaluate", "fit", "predict", "describe", "score"])
def test_a_misspelled_folder_is_said_not_to_exist(tmp_path, command):
    # before: "has no labels.csv"
    model = tmp_path / "m.joblib"
    first = [str(model)] if command in ("predict", "score") else []
    out = (
        ["-o", str(tmp_path / "out.x")] if command not in ("evaluate", "score") else []
    )
    with pytest.raises(SystemExit, match="segmnts does not exist"):
        main([command, *first, str(tmp_path / "segmnts"), *out])


def test_a_stray_file_is_skipped_on_request_and_reported(tmp_path, labelled_folder):
    # before: one notes.txt in the folder aborted predict
    script = textwrap.dedent(
        """
        import sys
        from skpcd.cli import main
        sys.exit(main(sys.argv[1:]))
        """
    )
    folder = tmp_path / "segs"
    labelled_folder(folder, n_per_class=2)
    model = tmp_path / "m.joblib"
    assert main(["fit", str(folder), "-o", str(model), "--quiet"]) == 0
    (folder / "notes.txt").write_text("measured on a rainy day\n")
    out = tmp_path / "p.csv"
    argv = ["predict", str(model), str(folder), "-o", str(out)]
    proc = subprocess.run(
        [sys.executable, "-c", script, *argv], capture_output=True, text=True
    )
    assert proc.returncode == 1 and "notes.txt" in proc.stderr
    proc = subprocess.run(
        [sys.executable, "-c", script, *argv, "--skip-unreadable"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr
    warning = [line for line in proc.stderr.splitlines() if "notes.txt" in line]
    assert len(warning) == 1 and warning[0].startswith("skpcd: warning: ")
    assert "warnings.warn" not in proc.stderr  # no Python source line
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 10 and "notes.txt" not in {r["file"] for r in rows}


def test_commands_use_every_core_by_default():
    parser = build_parser()
    for argv in (
        ["evaluate"],
        ["fit", "f", "-o", "m"],
        ["describe", "f", "-o", "d.npz"],
        ["segment", "s.ply", "-o", "o"],
        ["identify", "s.ply", "--model", "m", "-o", "o.ply"],
    ):
        assert parser.parse_args(argv).n_jobs == -1


def test_score_prints_accuracy_and_confusion_matrix(tmp_path, capsys, labelled_folder):
    train, test = tmp_path / "train", tmp_path / "test"
    labelled_folder(train, n_per_class=6, random_state=1)
    labels = labelled_folder(test, n_per_class=3, random_state=2)
    model = tmp_path / "m.joblib"
    assert main(["fit", str(train), "-o", str(model), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["score", str(model), str(test), "--quiet"]) == 0
    out = capsys.readouterr().out
    accuracy = float(out.split("accuracy  ")[1].split()[0])
    assert f"on {len(labels)} segments" in out and 0.6 <= accuracy <= 1.0
    lines = out.splitlines()
    header = lines.index("confusion matrix (rows: true, columns: predicted)")
    rows = [line.split() for line in lines[header + 2 : header + 7]]
    assert sorted(r[0] for r in rows) == sorted(set(labels))
    assert sum(int(v) for r in rows for v in r[1:]) == len(labels)
    diagonal = sum(int(r[1 + i]) for i, r in enumerate(rows))
    assert diagonal / len(labels) == pytest.approx(accuracy, abs=1e-4)
    assert "precision" in out and "recall" in out


class _Payload:
    """A pickle that would create a file when unpickled."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_pickled_models_load_only_with_trust_pickle(tmp_path, capsys, labelled_folder):
    # before: a pickle's __reduce__ ran (its file was created) although
    # predict then rejected the model
    import joblib

    from skpcd.io import load_model, save_model

    folder = tmp_path / "segs"
    labelled_folder(folder, n_per_class=1)
    skops_model = tmp_path / "m.skpcd"
    assert main(["fit", str(folder), "-o", str(skops_model), "--quiet"]) == 0
    pickled = tmp_path / "m.joblib"
    save_model(load_model(skops_model), pickled, format="joblib")
    evil = tmp_path / "evil.joblib"
    joblib.dump(_Payload(str(tmp_path / "pwned")), evil)
    out = tmp_path / "p.csv"
    for model in (pickled, evil):
        argv = ["predict", str(model), str(folder), "-o", str(out), "--quiet"]
        capsys.readouterr()
        assert main(argv) == 1
        assert "--trust-pickle" in capsys.readouterr().err
        assert not out.exists() and not (tmp_path / "pwned").exists()
    argv = ["predict", str(pickled), str(folder), "-o", str(out), "--trust-pickle"]
    assert main(argv) == 0 and out.is_file()
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["predict", "--help"])
    assert "DANGER" in " ".join(capsys.readouterr().out.split())
