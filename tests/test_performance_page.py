"""The Performance page shows figures of the result files, and only those.

``docs/_performance.py`` writes the page's tables from ``benchmarks/results/*.json``
when the docs are built. These tests run it on the committed result files and check
every figure against the file it names, and that a missing or malformed file stops it.
"""

import importlib.util
import json
import math
import re
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def _load_generator():
    spec = importlib.util.spec_from_file_location(
        "skpcd_docs_performance", ROOT / "docs" / "_performance.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


perf = _load_generator()


def _numbers(value):
    """Every number of a parsed JSON document (booleans are not numbers)."""
    if isinstance(value, dict):
        for item in value.values():
            yield from _numbers(item)
    elif isinstance(value, list):
        for item in value:
            yield from _numbers(item)
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield float(value)


def _check_number(cell, numbers, where):
    # a fraction in per cent, bytes in MiB, or the value itself: nothing else
    assert cell.scale in (1.0, 100.0, perf.MIB), f"{where}: scale {cell.scale}"
    for value in cell.values:
        assert value in numbers, f"{where}: {value} is not a number of the file"
    if cell.op == "ratio":
        figure = cell.values[0] / cell.values[1]
    elif cell.op == "mean":
        figure = sum(cell.values) / len(cell.values) * cell.scale
    else:
        figure = cell.values[0] * cell.scale
    shown = float(str(cell).replace(" ", ""))
    assert math.isclose(shown, round(figure, cell.digits), abs_tol=1e-9), where


def _check_text(cell, raw, where):
    # names and settings are copied from the file: any part with a digit is in it
    for token in re.split(r"[\s(),]+", str(cell)):
        if re.search(r"\d", token):
            assert token in raw, f"{where}: {token!r} is not in the file"


@pytest.mark.parametrize("key", sorted(perf.TABLES))
def test_every_figure_comes_from_its_file(key):
    source = perf.TABLES[key].source
    raw = (RESULTS / source).read_text()
    numbers = set(_numbers(json.loads(raw)))
    header, rows, where = perf.table(key)
    assert rows, f"{key}: no rows"
    for i, row in enumerate(rows):
        assert len(row) == len(header), f"{key} row {i}: {len(row)} cells"
        for j, cell in enumerate(row):
            at = f"{key} row {i} column {header[j]!r} ({source})"
            if isinstance(cell, perf.Number):
                _check_number(cell, numbers, at)
            else:
                assert isinstance(cell, perf.Text), f"{at}: {cell!r} is neither"
                for number in getattr(cell, "numbers", ()):
                    _check_number(number, numbers, at)
                if not hasattr(cell, "numbers"):
                    _check_text(cell, raw, at)
    # the commit, machine and date are the file's, or said to be missing
    for field in ("commit", "machine", "date"):
        value = where[field]
        if value != perf.NOT_RECORDED:
            _check_text(
                perf.Text(
                    value.replace("before ", "")
                    .replace("after ", "")
                    .replace("rerun ", "")
                    .replace(" to ", " ")
                ),
                raw,
                f"{key} {field}",
            )


@pytest.mark.parametrize("key", sorted(perf.TABLES))
def test_render_names_the_file(key):
    lines = perf.render(key)
    assert f"From ``benchmarks/results/{perf.TABLES[key].source}``" in "\n".join(lines)
    assert ".. list-table::" in lines


def test_the_page_places_every_table_once():
    page = (ROOT / "docs" / "performance.rst").read_text()
    placed = re.findall(r"^\.\. performance-table:: (\S+)$", page, flags=re.M)
    assert sorted(placed) == sorted(perf.TABLES)


def test_a_file_that_records_no_commit_says_so(tmp_path):
    (tmp_path / "threads.json").write_text(
        json.dumps({"stages": {"search": {"1": {"best": 2.0}, "2": {"best": 1.0}}}})
    )
    _, rows, where = perf.table("threads", tmp_path)
    assert where == dict.fromkeys(("commit", "machine", "date"), perf.NOT_RECORDED)
    assert [str(c) for c in rows[0]] == ["search", "2.00", "1.00", "2.00"]


def test_a_missing_file_fails_loudly(tmp_path):
    with pytest.raises(perf.ResultsError, match=r"threads\.json: no such result file"):
        perf.render("threads", tmp_path)


def test_a_malformed_file_fails_loudly(tmp_path):
    (tmp_path / "threads.json").write_text('{"stages": ')
    with pytest.raises(perf.ResultsError, match=r"threads\.json: not JSON"):
        perf.render("threads", tmp_path)


def test_a_missing_key_names_the_file_and_the_key(tmp_path):
    shutil.copy(RESULTS / "descriptors.json", tmp_path)
    data = json.loads((tmp_path / "descriptors.json").read_text())
    del data["ratios"][3]["cpu_ratio"]
    (tmp_path / "descriptors.json").write_text(json.dumps(data))
    with pytest.raises(
        perf.ResultsError,
        match=r"descriptors\.json: no \['ratios'\]\[3\]\['cpu_ratio'\]",
    ):
        perf.render("descriptor_speedups", tmp_path)


def test_scene_labels_leave_out_the_classes_a_source_does_not_score():
    data = json.loads((RESULTS / "scene_labels.json").read_text())
    header, rows, _ = perf.table("scene_labels")
    expected = [
        (source, model)
        for source, block in data["sources"].items()
        for model in block["models"]
    ]
    assert len(rows) == len(expected)
    for row, (source, model) in zip(rows, expected):
        block = data["sources"][source]
        scores = block["models"][model]["scores"]
        assert row[1] == model
        for c in perf.SCENE_CLASSES:
            cell = row[header.index(f"{c} IoU %")]
            if c in block["classes"]:
                assert cell.values == (scores["iou"][c],), (source, model, c)
            else:
                assert cell == "", (source, model, c)
        # the mIoU shown is the mean over the classes scored, and only those
        iou = [scores["iou"][c] for c in block["classes"]]
        assert row[header.index("mIoU %")].values == (scores["miou"],)
        assert math.isclose(scores["miou"], sum(iou) / len(iou))


def test_scene_labels_blank_a_class_the_source_lacks(tmp_path):
    scores = {"miou": 0.5, "iou": {"ground": 0.9, "car": 0.1}}
    row = {
        "scores": scores,
        "manmade_union": {"miou": 0.4},
        "time": {"wall_s_median": 7},
    }
    (tmp_path / "scene_labels.json").write_text(
        json.dumps(
            {
                "sources": {
                    "nuscenes": {
                        "sensor": "HDL-32E",
                        "classes": ["ground", "car"],
                        "models": {"shipped": row},
                    }
                }
            }
        )
    )
    header, rows, _ = perf.table("scene_labels", tmp_path)
    shown = dict(zip(header, map(str, rows[0])))
    assert shown["source (sensor)"] == "nuscenes (HDL-32E)"
    assert (shown["mIoU %"], shown["ground IoU %"], shown["car IoU %"]) == (
        "50.0",
        "90.0",
        "10.0",
    )
    assert shown["building IoU %"] == shown["manmade IoU %"] == ""
    assert shown["identify, s per scan"] == "7.0"
