"""The review page in a real browser (headless Chromium): it loads from
file:// with no request, shows a card per segment least confident first,
labels set with key presses end in the saved labels.csv, and it draws."""

import csv
import io
import time

import numpy as np
import pytest

from skpcd.datasets import make_street_objects
from skpcd.io._review import write_review_page

N_SEGMENTS = 12


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    """A review page of simulated street objects, with made-up predictions
    and scores and one label already given; returns its path and what went
    into it."""
    clouds, truth = make_street_objects(
        3,
        classes=["car", "person", "pole", "tree"],
        scanner="spinning",
        min_points=20,
        random_state=0,
    )
    names = [f"segment_{i:04d}.ply" for i in range(len(clouds))]
    scores = np.linspace(0.95, 0.3, len(clouds))
    predictions = list(truth)
    predictions[0] = "tree"  # a wrong answer
    path = tmp_path_factory.mktemp("review") / "review.html"
    write_review_page(
        path,
        clouds,
        names,
        predictions=predictions,
        scores=scores,
        score_kind="probability",
        labels={names[1]: "person"},
        classes=["car", "person", "pole", "tree"],
    )
    return {"path": path, "names": names, "scores": scores, "truth": truth}


@pytest.fixture(scope="module")
def loaded(browser, page):
    browser.get(page["path"].as_uri())
    return browser


def _press(driver, keys):
    from selenium.webdriver.common.action_chains import ActionChains

    actions = ActionChains(driver)
    for k in keys:
        actions.send_keys(k)
    actions.perform()


def _reset(driver, page):
    driver.get(page["path"].as_uri())


def test_page_makes_no_request(loaded, page):
    resources = loaded.execute_script(
        "return performance.getEntriesByType('resource').map(e => e.name)"
    )
    assert all(r.startswith(("data:", "blob:")) for r in resources), resources
    # the pictures are drawn, from the file itself
    sizes = loaded.execute_script(
        "const imgs = [...document.querySelectorAll('.card img')].slice(0, 4);"
        "return imgs.map(i => [i.complete, i.naturalWidth, i.src.slice(0, 22)])"
    )
    assert sizes == [[True, 96, "data:image/png;base64,"]] * 4
    # the page's policy forbids any request: a picture from the network is
    # refused by the browser, not fetched
    blocked = loaded.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "document.addEventListener('securitypolicyviolation',"
        "  e => done(e.violatedDirective), {once: true});"
        "const img = new Image(); img.src = 'http://127.0.0.1:9/x.png';"
        "document.body.appendChild(img);"
    )
    assert blocked.startswith("img-src")


def test_cards_least_confident_first_and_filter(loaded, page):
    _reset(loaded, page)
    files = loaded.execute_script(
        "return [...document.querySelectorAll('.card')].map(c => c.dataset.file)"
    )
    assert len(files) == N_SEGMENTS
    # scores fall with the index: the last segment is the least confident
    assert files == page["names"][::-1]
    text = loaded.execute_script(
        "return document.querySelector('.card[data-file=\"segment_0001.ply\"]')"
        ".innerText"
    )
    assert "label: person (from labels.csv)" in text
    from selenium.webdriver.support.ui import Select

    Select(loaded.find_element("id", "filter")).select_by_value("pole")
    shown = loaded.execute_script(
        "return [...document.querySelectorAll('.card:not(.hidden)')]"
        ".map(c => c.dataset.file)"
    )
    expected = [n for n, y in zip(page["names"], page["truth"]) if y == "pole"]
    assert sorted(shown) == sorted(expected)
    # the keys move through the cards shown only, and label them at once
    _press(loaded, ["j", "j"])
    current = loaded.execute_script(
        "return skpcdReview.cards[skpcdReview.current()].file"
    )
    assert current == shown[2]  # the first shown selected, then two on


def test_key_presses_end_in_saved_csv(loaded, page, downloads):
    _reset(loaded, page)
    # cards: segment_0011 (a tree), segment_0010 (a pole), segment_0009...
    # 2 sets the second class (person) and moves on; a accepts the
    # prediction (pole) and moves on; k goes back; x clears a label
    _press(loaded, ["2", "a", "k", "k"])
    assert loaded.execute_script("return skpcdReview.current()") == 0
    assert loaded.execute_script(
        "return [...skpcdReview.labels].filter(([f]) => f.startsWith('segment_001'))"
    ) == [["segment_0011.ply", "person"], ["segment_0010.ply", "pole"]]
    _press(loaded, ["j", "x", "k", "a", "j", "j", "x"])
    _press(loaded, ["s"])
    csv_text = loaded.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "skpcdReview.lastBlob().text().then(done);"
    )
    rows = dict(list(csv.reader(io.StringIO(csv_text)))[1:])
    assert rows["segment_0011.ply"] == "tree"  # set to person, then accepted
    assert rows["segment_0001.ply"] == "person"  # from labels.csv
    assert rows["segment_0000.ply"] == "tree"  # an unlabelled prediction
    assert len(rows) == N_SEGMENTS
    saved = downloads / "labels.csv"
    deadline = time.monotonic() + 10
    while not saved.is_file() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert saved.read_text() == csv_text
    # unticking "save predictions" keeps only the labels given
    loaded.find_element("id", "accept").click()
    kept = loaded.execute_script("return skpcdReview.labelsCsv()")
    assert sorted(r.split(",")[0] for r in kept.split()[1:]) == [
        "segment_0001.ply",
        "segment_0011.ply",
    ]


def test_screenshot_is_not_blank(loaded, page):
    from PIL import Image

    _reset(loaded, page)
    shot = np.asarray(
        Image.open(io.BytesIO(loaded.get_screenshot_as_png())).convert("RGB")
    )
    assert shot.shape[0] > 300 and shot.shape[1] > 300
    colours = np.unique(shot.reshape(-1, 3), axis=0)
    assert len(colours) > 50
    # the views' height colours (viridis: more green than red) cover
    # part of the page
    r, g = (shot[..., i].astype(int) for i in range(2))
    coloured = (g > r + 30) & (g > 80)
    assert coloured.mean() > 0.002


def _canvas_pixels(driver):
    """The non-white pixels of the 3-D view's canvas."""
    return driver.execute_script(
        "const c = document.getElementById('view3d');"
        "const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
        "let n = 0, h = 0;"
        "for (let i = 0; i < d.length; i += 4) {"
        "  if (d[i] + d[i + 1] + d[i + 2] < 700) { n++; h = (h * 31 + i) % 1000003; }"
        "}"
        "return [n, h];"
    )


def test_3d_view_opens_turns_and_closes(loaded, page):
    from selenium.webdriver.common.action_chains import ActionChains

    _reset(loaded, page)
    _press(loaded, ["v"])
    assert loaded.execute_script("return skpcdReview.view3d()") == 0
    assert loaded.find_element("id", "viewer").is_displayed()
    drawn, before = _canvas_pixels(loaded)
    assert drawn > 200
    # keys do not label while it is open
    _press(loaded, ["1"])
    assert loaded.execute_script("return skpcdReview.labels.size") == 1
    canvas = loaded.find_element("id", "view3d")
    ActionChains(loaded).click_and_hold(canvas).move_by_offset(
        60, 20
    ).release().perform()
    assert _canvas_pixels(loaded)[1] != before  # turned
    _press(loaded, ["\ue00c"])  # Escape
    assert loaded.execute_script("return skpcdReview.view3d()") is None
    assert not loaded.find_element("id", "viewer").is_displayed()


def test_two_thousand_segments_draw_only_the_pictures_near_the_screen(
    browser, tmp_path
):
    # the user guide's promise for large folders: every card is there, the
    # pictures of cards far from the screen are drawn only when scrolled to,
    # and the page stays at a few kilobytes per segment
    rng = np.random.default_rng(0)
    clouds = [rng.normal(0, 1, (int(rng.integers(50, 400)), 3)) for _ in range(2000)]
    names = [f"segment_{i:04d}.ply" for i in range(len(clouds))]
    path = tmp_path / "review.html"
    write_review_page(path, clouds, names)
    assert path.stat().st_size < 2000 * 10_000
    browser.get(path.as_uri())
    count = "return document.querySelectorAll('.card').length"
    drawn = "return [...document.querySelectorAll('.card img')]" + (
        ".filter(i => i.getAttribute('src')).length"
    )
    deadline = time.time() + 10
    while browser.execute_script(count) < 2000 and time.time() < deadline:
        time.sleep(0.1)
    assert browser.execute_script(count) == 2000
    first = browser.execute_script(drawn)
    assert 0 < first < 2 * 400, first
    browser.execute_script("window.scrollTo(0, document.body.scrollHeight)")
    deadline = time.time() + 10
    while browser.execute_script(drawn) <= first and time.time() < deadline:
        time.sleep(0.1)
    assert first < browser.execute_script(drawn) < 2 * 2000
