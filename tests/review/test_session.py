"""A labelling session end to end: segment a simulated street, review it
with the shipped model in headless Chromium, correct five labels with key
presses, save labels.csv and fit a model on it.

With ``SKPCD_WRITE_SCREENSHOTS=1`` the page's screenshot is written to
``docs/_static/review.png`` (the user guide shows it)."""

import csv
import io
import os
import shutil
import time
from pathlib import Path

import numpy as np

from skpcd.cli import main
from skpcd.io import read_point_cloud, write_point_cloud

DOCS_SCREENSHOT = (
    Path(__file__).resolve().parents[2] / "docs" / "_static" / "review.png"
)


def _true_classes(folder, names, scene):
    """The class of most points of each segment file, from the simulator."""
    from scipy.spatial import cKDTree

    tree = cKDTree(scene.points)
    truth = {}
    for name in names:
        _, idx = tree.query(read_point_cloud(folder / name))
        values, counts = np.unique(scene.labels[idx], return_counts=True)
        truth[name] = str(values[np.argmax(counts)])
    return truth


def _wait_for(path, timeout=10):
    deadline = time.monotonic() + timeout
    while not path.is_file() and time.monotonic() < deadline:
        time.sleep(0.1)
    return path.is_file()


def test_label_session_on_a_simulated_street(tmp_path, browser, downloads):
    from PIL import Image
    from selenium.webdriver.common.action_chains import ActionChains

    from skpcd.datasets import make_street_scene

    scene = make_street_scene(30, scanner="spinning", random_state=3)
    scan = tmp_path / "street.las"
    write_point_cloud(scan, scene.points)
    segments = tmp_path / "segments"
    assert main(["segment", str(scan), "-o", str(segments), "--quiet"]) == 0
    page = tmp_path / "review.html"
    assert main(["review", str(segments), "-o", str(page), "--quiet"]) == 0

    browser.set_window_size(1200, 900)
    browser.get(page.as_uri())
    cards = browser.execute_script("return skpcdReview.cards.map(c => c.file)")
    names = sorted(p.name for p in segments.glob("segment_*.ply"))
    assert sorted(cards) == names
    scores = browser.execute_script("return skpcdReview.cards.map(c => c.score)")
    known = [s for s in scores if s is not None]
    assert known == sorted(known)  # least confident first

    # correct the five least confident answers: the true class of each,
    # with its number key where it has one, else typed as a new class
    truth = _true_classes(segments, cards[:5], scene)
    for i, name in enumerate(cards[:5]):
        assert browser.execute_script("return skpcdReview.current()") == i
        classes = browser.execute_script("return skpcdReview.classes")
        label = truth[name]
        actions = ActionChains(browser)
        if label in classes and classes.index(label) < 20:
            j = classes.index(label)
            key = str((j % 10 + 1) % 10)
            if j >= 10:
                actions.key_down("\ue008").send_keys(key).key_up("\ue008")
            else:
                actions.send_keys(key)
            actions.perform()
        else:  # n asks for the new class's name
            actions.send_keys("n").perform()
            alert = browser.switch_to.alert
            alert.send_keys(label)
            alert.accept()
    given = browser.execute_script("return [...skpcdReview.labels]")
    assert dict(given) == truth

    shot = np.asarray(
        Image.open(io.BytesIO(browser.get_screenshot_as_png())).convert("RGB")
    )
    assert len(np.unique(shot.reshape(-1, 3), axis=0)) > 50
    if os.environ.get("SKPCD_WRITE_SCREENSHOTS") == "1":
        DOCS_SCREENSHOT.parent.mkdir(exist_ok=True)
        DOCS_SCREENSHOT.write_bytes(browser.get_screenshot_as_png())

    ActionChains(browser).send_keys("s").perform()
    saved = downloads / "labels.csv"
    assert _wait_for(saved)
    shutil.move(saved, segments / "labels.csv")
    with open(segments / "labels.csv", newline="") as fh:
        rows = dict(list(csv.reader(fh))[1:])
    assert sorted(rows) == names  # every segment: the five and the predictions
    assert {n: rows[n] for n in truth} == truth

    model = tmp_path / "model.skpcd"
    assert main(["fit", str(segments), "-o", str(model), "--quiet"]) == 0
    from skpcd.io import load_model

    fitted = load_model(model)
    assert set(truth.values()) <= set(fitted.classes_)
