"""``skpcd review`` without a browser: what the page holds (cards, labels
kept, predictions least confident first), that it names no outside
resource, the thumbnails, and the refusals."""

import io
import json
import re

import numpy as np
import pytest

from skpcd.cli import main
from skpcd.io import write_point_cloud
from skpcd.io._thumbnails import HEIGHT_PALETTE, encode_png, render_views


def _page_data(path):
    text = path.read_text(encoding="utf-8")
    match = re.search(
        r'<script type="application/json" id="review-data">(.*?)</script>',
        text,
        re.S,
    )
    return text, json.loads(match.group(1))


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    from skpcd.datasets import make_street_objects

    clouds, labels = make_street_objects(
        2,
        classes=["car", "person", "pole"],
        scanner="spinning",
        min_points=20,
        random_state=1,
    )
    root = tmp_path_factory.mktemp("segments")
    for i, c in enumerate(clouds):
        write_point_cloud(root / f"seg_{i}.xyz", c)
    return root, list(labels)


def test_page_holds_every_segment_and_keeps_labels(folder, tmp_path, capsys):
    root, truth = folder
    # a partial labels file, with a file that is not in the folder
    labels = tmp_path / "given.csv"
    labels.write_text("file,label\nseg_0.xyz,car\nseg_3.xyz,bicycle\ngone.xyz,tree\n")
    out = tmp_path / "review.html"
    argv = ["review", str(root), "--labels", str(labels), "-o", str(out)]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "gone.xyz" in captured.err
    assert f"{len(truth)} segments" in captured.out
    text, data = _page_data(out)
    cards = data["cards"]
    assert sorted(c["file"] for c in cards) == sorted(
        f"seg_{i}.xyz" for i in range(len(truth))
    )
    given = {c["file"]: c["label"] for c in cards if c["label"] is not None}
    assert given == {"seg_0.xyz": "car", "seg_3.xyz": "bicycle"}
    scores = [c["score"] for c in cards]
    assert scores == sorted(scores) and all(0 <= s <= 1 for s in scores)
    # the shipped model's classes on the number keys, the given ones after
    assert data["classes"][:2] == ["bush", "car"] and "bicycle" in data["classes"]
    # nothing from outside: every src and href is inline, and the policy
    # forbids requests
    assert not re.search(r'(src|href)\s*=\s*"(?!data:)', text)
    assert "default-src 'none'" in text
    assert all(c["top"].startswith("data:image/png;base64,") for c in cards)
    # the page refuses to be overwritten without --overwrite
    with pytest.raises(SystemExit, match="exists; pass --overwrite"):
        main(argv)


def test_without_a_model(folder, tmp_path):
    root, truth = folder
    out = tmp_path / "review.html"
    assert main(["review", str(root), "--no-model", "-o", str(out), "--quiet"]) == 0
    _, data = _page_data(out)
    assert [c["pred"] for c in data["cards"]] == [None] * len(truth)
    # file order when there is nothing to sort by
    assert [c["file"] for c in data["cards"]] == [
        f"seg_{i}.xyz" for i in range(len(truth))
    ]
    with pytest.raises(SystemExit, match="--model and --no-model"):
        main(["review", str(root), "--no-model", "--model", "m.skpcd", "-o", "x.html"])
    with pytest.raises(SystemExit, match="does not exist"):
        main(["review", str(tmp_path / "nowhere"), "-o", str(tmp_path / "y.html")])


def test_thumbnails_are_pngs_of_the_views():
    from PIL import Image

    z = np.linspace(0, 6, 600)
    pole = np.column_stack([0.05 * np.cos(z * 30), 0.05 * np.sin(z * 30), z])
    top, side = render_views(pole, size=64)
    # seen from above a pole is a dot; from the side, a line the image's height
    assert (top > 0).sum() < 20
    rows = np.flatnonzero((side > 0).any(axis=1))
    assert rows.min() <= 1 and rows.max() >= 62
    # low at the bottom (dark), high at the top (bright) of the side view
    column = side[:, np.flatnonzero((side > 0).any(axis=0))[0]]
    drawn = column[column > 0]
    assert drawn[0] > drawn[-1]
    image = Image.open(io.BytesIO(encode_png(side)))
    assert image.mode == "P" and image.size == (64, 64)
    np.testing.assert_array_equal(np.asarray(image), side)
    rgb = np.asarray(image.convert("RGB"))
    np.testing.assert_array_equal(rgb[side > 0], HEIGHT_PALETTE[side[side > 0]])
