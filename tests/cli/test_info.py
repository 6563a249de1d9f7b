"""``skpcd info``: what ``pdal info`` and ``lasinfo`` show of a LAS/LAZ file
(on real files of the laspy test data, tests/data/las/README.md), a summary
of a folder of segments, ``--json``, and no scikit-learn loaded."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from skpcd.cli import main
from skpcd.io import write_labelled_scan, write_point_cloud

LAS = Path(__file__).resolve().parents[1] / "data" / "las"
AUTZEN = LAS / "autzen_trim.laz"


def _info(capsys, *args):
    assert main(["info", *map(str, args)]) == 0
    return capsys.readouterr().out


def test_las_header_crs_vlrs_and_histograms(capsys):
    out = _info(capsys, AUTZEN)
    assert "las       version 1.2, point format 3 (34 bytes a point, LAZ)" in out
    assert "scale     0.01 0.01 0.01" in out
    assert "offset    0 0 0" in out
    assert "crs       NAD_1983_HARN_Lambert_Conformal_Conic (" in out
    assert "vlr       LASF_Projection 34735: GeoTiff GeoKeyDirectoryTag" in out
    assert "vlr       liblas 2112: OGR variant of OpenGIS WKT SRS (593 bytes)" in out
    assert "classes   1 unclassified: 83893, 2 ground: 26107" in out
    assert "returns   1: 99257, 2: 9021, 3: 1623, 4: 99" in out


def test_crs_from_the_geokeys_says_so(capsys):
    out = _info(capsys, LAS / "autzen_geokeys.las")
    (line,) = [s for s in out.splitlines() if s.startswith("crs")]
    try:
        import pyproj  # noqa: F401
    except ImportError:
        assert "Oregon Lambert (ft)" in line and "EPSG:2994" in line
        assert "GeoKeys VLR; pyproj not installed" in line
    else:
        assert "EPSG:2994" in line and "pyproj" in line


def test_evlrs_extra_dimensions_and_lookup_names(tmp_path, capsys):
    source = LAS / "1_4_w_evlr.laz"
    out = tmp_path / "labelled.las"
    n = 1000
    write_labelled_scan(
        source,
        out,
        segment=np.arange(n) % 3 - 1,
        class_index=np.arange(n) % 3 - 1,
        class_names=["car", "tree"],
        score=np.full(n, 0.5),
        score_name="probability",
    )
    text = _info(capsys, out)
    assert "evlr      pylastest 42: just a test evlr (16 bytes)" in text
    assert "extra     segment int32 (segment id (-1: none))" in text
    assert "extra     probability float32" in text
    assert "extra     original_classification uint8" in text
    # the names of the file's Classification Lookup VLR
    assert "classes   1 unclassified: 334, 5 tree: 333, 64 car: 333" in text


def test_json(capsys):
    info = json.loads(_info(capsys, "--json", AUTZEN))
    assert info["points"] == 110000
    las = info["las"]
    assert (las["version"], las["point_format"], las["scales"]) == (
        "1.2",
        3,
        [0.01, 0.01, 0.01],
    )
    assert las["crs"]["wkt"].startswith('PROJCS["NAD_1983_HARN')
    assert [v["record_id"] for v in las["vlrs"]][:3] == [34735, 34736, 34737]
    assert las["classification"][1] == {"code": 2, "points": 26107, "name": "ground"}


def test_other_formats_have_no_las_section(tmp_path, capsys):
    path = tmp_path / "cloud.ply"
    write_point_cloud(path, np.eye(3))
    out = _info(capsys, path)
    assert "points    3" in out and "las " not in out and "crs" not in out


def test_segment_folder(tmp_path, capsys):
    # before: "unknown point-cloud extension ''"
    segs = tmp_path / "segs"
    argv = ["segment", AUTZEN, "-o", segs, "--format", "las", "--ground", "none"]
    assert main([*map(str, argv), "--eps", "4", "--min-size", "300", "--quiet"]) == 0
    capsys.readouterr()
    rows = list(csv.DictReader(open(segs / "segments.csv")))
    with open(segs / "pred.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["file", "label", "probability"])
        for k, row in enumerate(rows):
            writer.writerow([row["file"], "tree" if k else "building", "0.9"])
    out = _info(capsys, segs)
    n_points = sum(int(r["n_points"]) for r in rows)
    assert f"segments  {len(rows)} (" in out and f"), {n_points} points" in out
    assert f"files     {len(rows)} point-cloud files ({len(rows)} las)" in out
    assert "run       scene " in out and "ground none, dbscan eps 4.000" in out
    first = int(rows[0]["n_points"])
    assert f"classes   pred.csv: building 1 ({first} points)" in out
    info = json.loads(_info(capsys, "--json", segs))
    assert info["segments"] == len(rows) and info["complete"] is True
    # a segment file gone: said, not a crash
    (segs / rows[0]["file"]).unlink()
    assert "problem   does not hold the run" in _info(capsys, segs)


def test_plain_folder(tmp_path, capsys):
    for k in range(3):
        write_point_cloud(tmp_path / f"{k}.xyz", np.eye(3) + k)
    (tmp_path / "labels.csv").write_text("file,label\n0.xyz,a\n1.xyz,a\n2.xyz,b\n")
    out = _info(capsys, tmp_path)
    assert "files     3 point-cloud files (3 xyz)" in out
    assert "classes   labels.csv: a 2, b 1" in out
    assert "segments" not in out


# the command's own work, in a fresh interpreter (the CLI may run it in a
# child process, whose modules the parent does not see)
_LOADED = """
import json, sys
from argparse import Namespace
from skpcd.cli._info import run
run(Namespace(file=sys.argv[1], json=False))
print("LOADED " + json.dumps(sorted(sys.modules)), file=sys.stderr)
"""


def test_info_loads_no_scikit_learn():
    done = subprocess.run(
        [sys.executable, "-c", _LOADED, str(AUTZEN)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    (line,) = [s for s in done.stderr.splitlines() if s.startswith("LOADED ")]
    loaded = {m.split(".")[0] for m in json.loads(line.removeprefix("LOADED "))}
    assert "skpcd" in loaded and "numpy" in loaded  # the check is not vacuous
    assert not loaded & {"sklearn", "numba", "pynndescent"}
