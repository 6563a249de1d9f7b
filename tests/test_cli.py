import subprocess
import sys

import numpy as np
import pytest

from skpcd.cli import format_report, main
from skpcd.io import write_point_cloud


def test_info(tmp_path, capsys):
    path = tmp_path / "grid.ply"
    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(4.0), [1.0]), -1).reshape(-1, 3)
    write_point_cloud(path, 0.5 * g, fields={"intensity": np.arange(20.0)})
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "points    20" in out
    assert "fields    x y z intensity" in out
    assert "x         [0.0000, 2.0000]" in out
    assert "spacing   0.5000" in out


def test_info_bad_file_is_a_clean_error(tmp_path, capsys):
    path = tmp_path / "bad.xyz"
    path.write_text("1 2\n")
    assert main(["info", str(path)]) == 1
    err = capsys.readouterr().err
    assert "error" in err and str(path) in err and "Traceback" not in err


def test_evaluate_folder(tmp_path, capsys):
    from skpcd.datasets import make_urban_objects

    clouds, labels = make_urban_objects(n_per_class=6, random_state=1)
    rows = ["file,label"]
    for i, (c, y) in enumerate(zip(clouds, labels)):
        write_point_cloud(tmp_path / f"{i:03d}.xyz", c)
        rows.append(f"{i:03d}.xyz,{y}")
    (tmp_path / "labels.csv").write_text("\n".join(rows))
    assert main(["evaluate", str(tmp_path), "--folds", "3", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "30 segments, 5 classes" in out
    assert "precision" in out and "recall" in out
    assert "confusion matrix" in out
    for cls in ("building", "car", "fence", "pole", "tree"):
        assert cls in out


def test_evaluate_needs_enough_segments_per_class(tmp_path):
    for i in range(4):
        write_point_cloud(
            tmp_path / f"{i}.xyz", np.random.default_rng(i).normal(size=(20, 3))
        )
    (tmp_path / "labels.csv").write_text("0.xyz,a\n1.xyz,a\n2.xyz,b\n3.xyz,b\n")
    with pytest.raises(SystemExit, match="fewer than --folds 5"):
        main(["evaluate", str(tmp_path)])


def test_format_report_confusion_matrix():
    text = format_report(
        np.array(["a", "a", "b"]), np.array(["a", "b", "b"]), [1.0, 0.5]
    )
    assert "accuracy  0.7500 +/- 0.2500 over 2 folds" in text
    lines = text.splitlines()
    header = lines.index("confusion matrix (rows: true, columns: predicted)")
    assert lines[header + 2].split() == ["a", "1", "1"]
    assert lines[header + 3].split() == ["b", "0", "1"]


def test_console_entry_point_default_data_quiet_when_not_a_tty():
    proc = subprocess.run(
        [sys.executable, "-m", "skpcd", "evaluate", "--folds", "2"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "embedded synthetic urban objects" in proc.stdout
    assert "accuracy" in proc.stdout
    assert proc.stderr == ""  # no progress bar when not on a terminal
