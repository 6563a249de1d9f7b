"""A review page: one self-contained HTML file to look at segments and label them.

:func:`write_review_page` writes one HTML file with a card per segment (a
top and a side view coloured by height, its size, the predicted class and
confidence), its script, style and pictures inside it: the page opens from
``file://`` with no server and makes no request (its Content-Security-Policy
forbids any). The user sets labels with the keyboard and saves a
``labels.csv`` of ``file,label`` rows, which ``skpcd fit`` reads as it is.
"""

import base64
import json
import math

import numpy as np

from skpcd.io._atomic import atomic_path
from skpcd.io._thumbnails import HEIGHT_PALETTE, view_data_uris

__all__ = ["review_cards", "write_review_page"]

# points of a segment kept for the page's 3-D view
VIEW_POINTS = 400


def _view_points(cloud, n_points=VIEW_POINTS):
    """At most ``n_points`` points of ``cloud`` (evenly spread over its
    order after a fixed shuffle), centred on its box and scaled by its
    largest half-extent to [-1, 1], as 3 bytes each in base64."""
    if len(cloud) == 0:
        return ""
    rng = np.random.default_rng(0)
    keep = rng.permutation(len(cloud))[:n_points]
    pts = cloud[np.sort(keep)]
    lo, hi = cloud.min(axis=0), cloud.max(axis=0)
    half = max(float(np.max(hi - lo)) / 2, 1e-9)
    unit = (pts - (lo + hi) / 2) / half
    codes = np.clip(np.round((unit + 1) * 127.5), 0, 255).astype(np.uint8)
    return base64.b64encode(codes.tobytes()).decode("ascii")


# The page. __TITLE__ and __DATA__ are replaced (the data is JSON whose "</"
# are escaped, so that it cannot end its <script> element).
_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="default-src 'none'; \
img-src data: blob:; style-src 'unsafe-inline'; script-src 'unsafe-inline'">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>__TITLE__</title>
<style>
body{font:14px system-ui,sans-serif;margin:0;background:#f4f4f4;color:#222}
header{position:sticky;top:0;z-index:2;background:#fff;border-bottom:1px solid #ccc;
padding:6px 12px}
header h1{font-size:16px;margin:0 12px 0 0;display:inline}
#keys{font-size:12px;color:#555;margin-top:4px}
#classes span{display:inline-block;margin:2px 6px 2px 0;padding:1px 6px;
border:1px solid #bbb;border-radius:3px;background:#fafafa}
#classes b{color:#06c}
#grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(230px,1fr));
gap:8px;padding:10px}
.card{background:#fff;border:2px solid #ddd;border-radius:4px;padding:6px;
min-height:180px;cursor:pointer}
.card.current{border-color:#06c;box-shadow:0 0 0 2px #9cf}
.card.set{background:#eefbe9}
.card.hidden{display:none}
.views{display:flex;gap:4px;height:96px}
.views img{width:96px;height:96px;background:#fff;border:1px solid #eee;
image-rendering:pixelated}
.name{font-weight:600;font-size:12px;word-break:break-all}
.info{font-size:12px;color:#444}
.pred{font-size:12px}
.low{color:#b00}
.label{font-size:13px;margin-top:2px}
.label b{color:#070}
button,select{font:inherit}
#status{margin-left:12px}
#viewer{position:fixed;inset:0;z-index:5;background:rgba(0,0,0,.45);display:none;
align-items:center;justify-content:center}
#viewer.open{display:flex}
#viewer div{background:#fff;padding:8px;border-radius:4px;text-align:center}
#viewer canvas{background:#fff;cursor:grab;display:block}
</style>
</head>
<body>
<header>
<h1>__TITLE__</h1>
<label>Show <select id="filter"></select></label>
<button id="save" type="button">Save labels.csv</button>
<label><input id="accept" type="checkbox" checked> save predictions of
unlabelled segments as their labels</label>
<span id="status"></span>
<div id="classes"></div>
<div id="keys">Keys: <b>1</b>-<b>9</b>, <b>0</b> (with <b>Shift</b>: the
eleventh to twentieth) set the class shown;
<b>a</b> or <b>Enter</b> accept the prediction; <b>n</b> a new class;
<b>x</b> clear; <b>v</b> a 3-D view; <b>j</b>/<b>&rarr;</b>/<b>&darr;</b> next,
<b>k</b>/<b>&larr;</b>/<b>&uarr;</b> previous; <b>s</b> save.</div>
</header>
<div id="grid"></div>
<div id="viewer"><div><canvas id="view3d" width="480" height="480"></canvas>
<span id="view3d-name"></span> &mdash; drag to turn; <b>v</b> or <b>Esc</b> closes</div>
</div>
<script type="application/json" id="review-data">__DATA__</script>
<script>
"use strict";
(function () {
  const data = JSON.parse(document.getElementById("review-data").textContent);
  const cards = data.cards;
  const labels = new Map();
  const setByUser = new Set();
  const classes = data.classes.slice();
  const byFile = new Map(cards.map(function (c) { return [c.file, c]; }));
  for (const c of cards) { if (c.label !== null) labels.set(c.file, c.label); }
  const grid = document.getElementById("grid");
  const filter = document.getElementById("filter");
  const status = document.getElementById("status");
  const accept = document.getElementById("accept");
  if (!data.has_predictions) { accept.checked = false; accept.disabled = true; }
  const elements = [];
  let current = -1;
  let lastCsv = null;
  let lastBlob = null;

  function fmt(v, d) { return v === null ? "-" : v.toFixed(d); }
  function classKey(i) {
    if (i >= 20) return "";
    return (i >= 10 ? "\u21e7" : "") + String((i % 10 + 1) % 10);
  }

  function showClasses() {
    const box = document.getElementById("classes");
    box.textContent = "";
    classes.forEach(function (c, i) {
      const s = document.createElement("span");
      const k = classKey(i);
      if (k) { const b = document.createElement("b"); b.textContent = k + " ";
        s.appendChild(b); }
      s.appendChild(document.createTextNode(c));
      box.appendChild(s);
    });
    const keep = filter.value;
    filter.textContent = "";
    for (const [v, t] of [["*", "all segments"], ["?", "unlabelled"],
                          ["!", "labelled here"]].concat(
                          classes.map(function (c) { return [c, c]; }))) {
      const o = document.createElement("option");
      o.value = v; o.textContent = t; filter.appendChild(o);
    }
    filter.value = keep || "*";
  }

  function fillViews(el, c) {
    const imgs = el.querySelectorAll("img");
    imgs[0].src = c.top; imgs[1].src = c.side;
  }

  const observer = ("IntersectionObserver" in window) ?
    new IntersectionObserver(function (entries) {
      for (const e of entries) {
        if (e.isIntersecting) {
          const i = Number(e.target.dataset.index);
          fillViews(e.target, cards[i]);
          observer.unobserve(e.target);
        }
      }
    }, {rootMargin: "800px"}) : null;

  function updateCard(i) {
    const c = cards[i], el = elements[i];
    const lab = el.querySelector(".label");
    const l = labels.get(c.file);
    lab.textContent = "label: ";
    const b = document.createElement("b");
    b.textContent = l === undefined ? "(none)" : l;
    lab.appendChild(b);
    if (l !== undefined && !setByUser.has(c.file) && l === c.label) {
      lab.appendChild(document.createTextNode(" (from labels.csv)"));
    }
    el.classList.toggle("set", setByUser.has(c.file));
  }

  function build() {
    const frag = document.createDocumentFragment();
    cards.forEach(function (c, i) {
      const el = document.createElement("div");
      el.className = "card";
      el.dataset.index = String(i);
      el.dataset.file = c.file;
      const views = document.createElement("div");
      views.className = "views";
      for (const t of ["top", "side"]) {
        const img = document.createElement("img");
        img.alt = t + " view of " + c.file; img.title = t + " view";
        views.appendChild(img);
      }
      const name = document.createElement("div");
      name.className = "name"; name.textContent = c.file;
      const info = document.createElement("div");
      info.className = "info";
      info.textContent = c.n_points + " points; " + fmt(c.size[0], 2) + " x " +
        fmt(c.size[1], 2) + " m, height " + fmt(c.size[2], 2) + " m";
      const pred = document.createElement("div");
      pred.className = "pred";
      if (c.pred !== null) {
        pred.textContent = "predicted: " + c.pred + (c.score === null ? "" :
          " (" + data.score_kind + " " + c.score.toFixed(2) + ")");
        if (c.score !== null && c.score < 0.5) pred.classList.add("low");
      }
      const lab = document.createElement("div");
      lab.className = "label";
      el.append(views, name, info, pred, lab);
      el.addEventListener("click", function () { select(i, false); });
      elements.push(el);
      frag.appendChild(el);
      if (observer) observer.observe(el); else fillViews(el, c);
      updateCard(i);
    });
    grid.appendChild(frag);
  }

  function visible(i) {
    const f = filter.value, c = cards[i], l = labels.get(c.file);
    if (f === "*") return true;
    if (f === "?") return l === undefined;
    if (f === "!") return setByUser.has(c.file);
    return l === f || (l === undefined && c.pred === f);
  }

  function applyFilter() {
    cards.forEach(function (c, i) {
      elements[i].classList.toggle("hidden", !visible(i));
    });
    if (current >= 0 && !visible(current)) move(1);
    showStatus();
  }

  function showStatus() {
    let shown = 0;
    for (const el of elements) if (!el.classList.contains("hidden")) shown++;
    status.textContent = shown + " of " + cards.length + " shown; " +
      labels.size + " labelled, " + setByUser.size + " here";
  }

  function select(i, scroll) {
    if (current >= 0) elements[current].classList.remove("current");
    current = i;
    if (i < 0) return;
    elements[i].classList.add("current");
    if (scroll !== false) elements[i].scrollIntoView({block: "nearest"});
  }

  function move(step) {
    let i = current < 0 ? (step > 0 ? -1 : cards.length) : current;
    for (i += step; i >= 0 && i < cards.length; i += step) {
      if (visible(i)) { select(i); return true; }
    }
    return false;
  }

  function setLabel(i, label) {
    const file = cards[i].file;
    if (label === null) { labels.delete(file); setByUser.delete(file); }
    else {
      label = String(label).trim();
      if (!label) return;
      if (!classes.includes(label)) { classes.push(label); showClasses(); }
      labels.set(file, label); setByUser.add(file);
    }
    updateCard(i);
    showStatus();
  }

  function csvField(v) {
    return /[",\\r\\n]/.test(v) ? '"' + v.replace(/"/g, '""') + '"' : v;
  }

  function labelsCsv() {
    const rows = ["file,label"];
    for (const c of data.order) {
      let l = labels.get(c);
      if (l === undefined && accept.checked && byFile.get(c).pred !== null) {
        l = byFile.get(c).pred;
      }
      if (l !== undefined) rows.push(csvField(c) + "," + csvField(l));
    }
    return rows.join("\\n") + "\\n";
  }

  function save() {
    lastCsv = labelsCsv();
    lastBlob = new Blob([lastCsv], {type: "text/csv"});
    const a = document.createElement("a");
    a.href = URL.createObjectURL(lastBlob);
    a.download = "labels.csv";
    document.body.appendChild(a);
    a.click();
    a.remove();
    const missing = data.order.length - (lastCsv.split("\\n").length - 2);
    status.textContent = "saved labels.csv (" + (lastCsv.split("\\n").length - 2) +
      " rows" + (missing ? "; " + missing + " segments without a label: " +
      "skpcd fit needs every segment labelled" : "") + ")";
  }

  // a light 3-D view: the segment's points (at most a few hundred, stored
  // as bytes in its box) turned with the mouse, drawn on a canvas
  const viewer = document.getElementById("viewer");
  const canvas = document.getElementById("view3d");
  const ctx = canvas.getContext("2d");
  const ramp = data.palette;
  let shown3d = null, yaw = 0.6, pitch = 0.35;

  function decode(b64) {
    const raw = atob(b64), out = new Float32Array(raw.length);
    for (let i = 0; i < raw.length; i++) out[i] = raw.charCodeAt(i) / 127.5 - 1;
    return out;
  }

  function draw3d() {
    const p = shown3d.points, n = p.length / 3;
    const cy = Math.cos(yaw), sy = Math.sin(yaw);
    const cp = Math.cos(pitch), sp = Math.sin(pitch);
    const items = [];
    for (let i = 0; i < n; i++) {
      const x = p[3 * i], y = p[3 * i + 1], z = p[3 * i + 2];
      const u = cy * x - sy * y, w = sy * x + cy * y;
      items.push([u, cp * z - sp * w, sp * z + cp * w, z]);
    }
    items.sort(function (a, b) { return b[2] - a[2]; });
    ctx.fillStyle = "#fff";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    const half = canvas.width / 2, scale = half * 0.55;
    for (const it of items) {
      const t = (it[3] - shown3d.zlo) / Math.max(shown3d.zhi - shown3d.zlo, 1e-9);
      const c = ramp[1 + Math.round(t * 254)];
      ctx.fillStyle = "rgb(" + c[0] + "," + c[1] + "," + c[2] + ")";
      ctx.fillRect(half + it[0] * scale - 2, half - it[1] * scale - 2, 4, 4);
    }
  }

  function open3d(i) {
    const points = decode(cards[i].points);
    let zlo = Infinity, zhi = -Infinity;
    for (let j = 2; j < points.length; j += 3) {
      zlo = Math.min(zlo, points[j]); zhi = Math.max(zhi, points[j]);
    }
    shown3d = {index: i, points: points, zlo: zlo, zhi: zhi};
    document.getElementById("view3d-name").textContent = cards[i].file;
    viewer.classList.add("open");
    draw3d();
  }

  function close3d() { viewer.classList.remove("open"); shown3d = null; }

  let drag = null;
  canvas.addEventListener("mousedown", function (e) {
    drag = [e.clientX, e.clientY];
  });
  window.addEventListener("mouseup", function () { drag = null; });
  window.addEventListener("mousemove", function (e) {
    if (!drag || !shown3d) return;
    yaw += (e.clientX - drag[0]) * 0.01;
    pitch = Math.max(-1.5, Math.min(1.5, pitch + (e.clientY - drag[1]) * 0.01));
    drag = [e.clientX, e.clientY];
    draw3d();
  });
  viewer.addEventListener("click", function (e) {
    if (e.target === viewer) close3d();
  });

  document.addEventListener("keydown", function (e) {
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    if (shown3d) {
      if (e.key === "v" || e.key === "Escape") { close3d(); e.preventDefault(); }
      return;
    }
    if (e.target.tagName === "SELECT" || e.target.tagName === "INPUT") return;
    const k = e.key;
    if (k === "j" || k === "ArrowDown" || k === "ArrowRight") { move(1); }
    else if (k === "k" || k === "ArrowUp" || k === "ArrowLeft") { move(-1); }
    else if (k === "s") { save(); }
    else if (current < 0) { return; }
    else if (/^Digit[0-9]$/.test(e.code)) {
      const d = Number(e.code.slice(5));
      const j = (d === 0 ? 9 : d - 1) + (e.shiftKey ? 10 : 0);
      if (j >= classes.length) return;
      setLabel(current, classes[j]); move(1);
    } else if (k === "a" || k === "Enter") {
      if (cards[current].pred === null) return;
      setLabel(current, cards[current].pred); move(1);
    } else if (k === "x" || k === "Backspace" || k === "Delete") {
      setLabel(current, null);
    } else if (k === "v") {
      open3d(current);
    } else if (k === "n") {
      const name = window.prompt("New class name");
      if (name) { setLabel(current, name); move(1); }
    } else { return; }
    e.preventDefault();
  });
  // back to the cards after a choice, so that the keys label them again
  filter.addEventListener("change", function () { applyFilter(); filter.blur(); });
  accept.addEventListener("change", function () { accept.blur(); });
  document.getElementById("save").addEventListener("click", save);

  showClasses();
  build();
  if (cards.length) select(0, false);
  showStatus();
  window.skpcdReview = {
    cards: cards,
    classes: classes,
    labels: labels,
    select: select,
    setLabel: function (file, label) {
      if (!byFile.has(file)) throw new Error("no card " + file);
      setLabel(cards.indexOf(byFile.get(file)), label);
    },
    labelsCsv: labelsCsv,
    save: save,
    lastCsv: function () { return lastCsv; },
    lastBlob: function () { return lastBlob; },
    current: function () { return current; },
    view3d: function () { return shown3d ? shown3d.index : null; }
  };
})();
</script>
</body>
</html>
"""


def _number(value, digits):
    """A finite float rounded for JSON, or None."""
    value = float(value)
    return round(value, digits) if math.isfinite(value) else None


def _html_text(text):
    return str(text).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def review_cards(
    clouds, names, *, predictions=None, scores=None, labels=None, thumbnail_size=96
):
    """The cards of a review page, least confident first.

    Parameters
    ----------
    clouds : sequence of ndarray of shape (n_points_i, 3)
        The segments.
    names : sequence of str
        The file name of each segment, as ``labels.csv`` names it.
    predictions : sequence of str, default=None
        The predicted class of each segment.
    scores : sequence of float, default=None
        The confidence of each prediction (NaN: none).
    labels : dict of str to str, default=None
        Labels already given (from a ``labels.csv``), by file name.
    thumbnail_size : int, default=96
        Width and height of each view in pixels.

    Returns
    -------
    cards : list of dict
        One per segment with ``file``, ``n_points``, ``size`` (extent along
        x, y, z in metres), ``pred``, ``score``, ``label`` (None where
        absent), the ``top`` and ``side`` views as PNG data URIs and
        ``points``, at most ``VIEW_POINTS`` of its points for the page's 3-D
        view (3 bytes each, in its box, base64); sorted
        by increasing score (segments without a score last), then in the
        given order.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.io._review import review_cards
    >>> rng = np.random.default_rng(0)
    >>> clouds = [rng.random((20, 3)), rng.random((30, 3))]
    >>> cards = review_cards(clouds, ["a.ply", "b.ply"], predictions=["car", "tree"],
    ...                      scores=[0.9, 0.4], labels={"a.ply": "car"})
    >>> [(c["file"], c["pred"], c["label"]) for c in cards]
    [('b.ply', 'tree', None), ('a.ply', 'car', 'car')]
    """
    labels = labels or {}
    cards = []
    for i, (cloud, name) in enumerate(zip(clouds, names)):
        cloud = np.asarray(cloud, dtype=float)
        size = np.ptp(cloud, axis=0) if len(cloud) else np.zeros(3)
        top, side = view_data_uris(cloud, thumbnail_size)
        score = None if scores is None else _number(scores[i], 3)
        cards.append(
            {
                "file": str(name),
                "n_points": len(cloud),
                "size": [_number(v, 3) for v in size],
                "pred": None if predictions is None else str(predictions[i]),
                "score": score,
                "label": labels.get(str(name)),
                "top": top,
                "side": side,
                "points": _view_points(cloud),
            }
        )
    order = sorted(
        range(len(cards)),
        key=lambda i: (cards[i]["score"] is None, cards[i]["score"] or 0.0, i),
    )
    return [cards[i] for i in order]


def write_review_page(
    path,
    clouds,
    names,
    *,
    predictions=None,
    scores=None,
    score_kind=None,
    labels=None,
    classes=None,
    title="skpcd review",
    thumbnail_size=96,
    overwrite=False,
):
    """Write a review page of segments: one self-contained HTML file.

    Each segment gets a card with a top and a side view coloured by height,
    its point count, extent and height, and (when given) its predicted
    class and confidence; the cards come least confident first and can be
    filtered by class. The user moves between cards and labels them with
    the keyboard (number keys for the classes, ``a`` to accept the
    prediction, ``j``/``k`` or the arrows to move, ``v`` for a 3-D view of
    a few hundred of its points turned with the mouse) and saves a
    ``labels.csv`` of ``file,label`` rows that ``skpcd fit`` reads as it
    is. Every script, style and picture is inside the file; its
    Content-Security-Policy forbids any request, so it opens from
    ``file://`` and works offline.

    Read more in the :ref:`User Guide <review>`.

    Parameters
    ----------
    path : str or path-like
        The HTML file to write (through a temporary file renamed when
        whole).
    clouds : sequence of ndarray of shape (n_points_i, 3)
        The segments.
    names : sequence of str
        The file name of each segment, relative to its folder (as
        ``labels.csv`` names it).
    predictions : sequence of str, default=None
        The predicted class of each segment; None shows none.
    scores : sequence of float, default=None
        The confidence of each prediction (NaN: none).
    score_kind : str, default=None
        What the scores are (``"probability"`` or ``"similarity"``).
    labels : dict of str to str, default=None
        Labels already given, by file name: shown, and saved again unless
        the user changes them.
    classes : sequence of str, default=None
        The classes offered on the number keys, in order (the model's);
        the classes of ``labels`` and ``predictions`` not in it follow.
    title : str, default="skpcd review"
        The page's title.
    thumbnail_size : int, default=96
        Width and height of each view in pixels.
    overwrite : bool, default=False
        Replace an existing file.

    Returns
    -------
    n_cards : int
        Number of segments on the page.

    Raises
    ------
    ValueError
        If ``names`` and ``clouds`` (or ``predictions``, ``scores``) differ
        in length.
    FileExistsError
        If ``path`` exists and ``overwrite`` is False.
    """
    names = [str(n) for n in names]
    for what, values in (("predictions", predictions), ("scores", scores)):
        if values is not None and len(values) != len(names):
            raise ValueError(
                f"{what} has {len(values)} entries for {len(names)} segments"
            )
    if len(clouds) != len(names):
        raise ValueError(f"{len(clouds)} clouds for {len(names)} names")
    labels = {str(k): str(v) for k, v in (labels or {}).items()}
    cards = review_cards(
        clouds,
        names,
        predictions=predictions,
        scores=scores,
        labels=labels,
        thumbnail_size=thumbnail_size,
    )
    offered = [str(c) for c in (classes if classes is not None else [])]
    seen = set(offered)
    extra = {str(p) for p in (predictions if predictions is not None else [])}
    extra |= {labels[n] for n in names if n in labels}
    offered += sorted(extra - seen)
    data = {
        "cards": cards,
        "classes": offered,
        "order": names,
        "has_predictions": predictions is not None,
        "score_kind": score_kind or "score",
        "palette": HEIGHT_PALETTE.tolist(),
    }
    text = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    page = _PAGE.replace("__TITLE__", _html_text(title)).replace("__DATA__", text)
    with atomic_path(path, overwrite=overwrite) as tmp:
        tmp.write_text(page, encoding="utf-8")
    return len(cards)
