"""
An inventory of street furniture, on a map
==========================================

``skpcd identify scan.laz -o labelled.laz --inventory objects.gpkg`` writes one
point per object found: its class and confidence, the position of its base on the
ground under it, its height and footprint (width, length and heading of the
smallest rectangle around it), and for poles, lamp posts, lights and signs the lean
of the shaft and the height of what the pole carries. Here the same steps run from
Python on a **simulated** mobile scan of a 60 m street
(:func:`skpcd.datasets.make_street_scene`, at a sixteenth of the pattern's density
so that the page builds in seconds): segment it, identify each segment with the
street model shipped with skpcd, measure each object and write the inventory as
GeoJSON. The map shows the ground, each object's footprint and base, coloured by
its class, and the true objects of the simulator. Read more in the user guide
(:ref:`review`).
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Polygon

from skpcd.classification import identify_segments, load_street_model
from skpcd.datasets import make_street_scene
from skpcd.io._inventory import write_inventory
from skpcd.segmentation import segment_scene
from skpcd.segmentation._inventory import (
    GroundHeight,
    object_inventory,
    segment_geometry,
)
from skpcd.segmentation._members import segment_members

PATTERN = {"angular_step": 0.4, "rotation_rate": 50.0}
scene = make_street_scene(60.0, scanner_params=PATTERN, random_state=4)
points = scene.points
print(f"data: simulated mobile scan of a 60 m street, {len(points)} points")

result = segment_scene(points, random_state=0)
segments = [points[idx] for idx in segment_members(result.labels, result.n_segments)]
kinds = result.kinds
print(f"{result.n_segments} segments, {int(result.ground.sum())} ground points")

# %%
# Identify each segment (facades and wires keep their type) and measure it.
model = load_street_model()
pred, kind, score, _ = identify_segments(
    model, ((s, {}) for s in segments), kinds=kinds
)
geometries = [segment_geometry(s, pole=True) for s in segments]
ground = GroundHeight().fit(points[result.ground])
inventory = object_inventory(geometries, pred, score, ground=ground)

out = Path(tempfile.mkdtemp()) / "objects.geojson"
write_inventory(out, inventory)
print(f"written {out.name}: {len(inventory['id'])} objects")
header = (
    f"{'class':>18} {'x':>7} {'y':>7} {'z':>6} {'height':>6} {'lean':>5} {'carried':>7}"
)
print(header)
# the poles the model is sure of (the others are in the file too)
for i in np.flatnonzero(~np.isnan(inventory["lean"]) & (inventory["confidence"] > 0.6)):
    print(
        f"{inventory['class'][i]:>18} {inventory['x'][i]:7.2f} {inventory['y'][i]:7.2f}"
        f" {inventory['z'][i]:6.2f} {inventory['height'][i]:6.2f}"
        f" {inventory['lean'][i]:5.1f} {inventory['carried_height'][i]:7.2f}"
    )

# %%
# The map: ground points in grey, each object's footprint (the rectangle of width
# and length along its heading) and base, coloured by class; crosses mark the
# objects the simulator placed.
classes = sorted(set(inventory["class"]))
colours = dict(zip(classes, plt.cm.tab20(np.linspace(0, 1, max(len(classes), 2)))))
fig, ax = plt.subplots(figsize=(12, 6))
g = points[result.ground][::40]
ax.scatter(g[:, 0], g[:, 1], s=0.2, c="0.8", rasterized=True)
for i in range(len(inventory["id"])):
    c = inventory["class"][i]
    heading = np.radians(inventory["heading"][i])
    along = np.array([np.sin(heading), np.cos(heading)])  # clockwise from north
    across = np.array([-along[1], along[0]])
    centre = geometries[i]["centre"]
    half_l, half_w = inventory["length"][i] / 2, inventory["width"][i] / 2
    corners = [
        centre + sl * half_l * along + sw * half_w * across
        for sl, sw in ((-1, -1), (1, -1), (1, 1), (-1, 1))
    ]
    ax.add_patch(Polygon(corners, fill=False, ec=colours[c], lw=1))
    ax.plot(inventory["x"][i], inventory["y"][i], "o", ms=4, color=colours[c])
truth = [o for o in scene.frame if o["class"] not in ("facade", "wire")]
ax.plot(
    [o["position"][0] for o in truth],
    [o["position"][1] for o in truth],
    "k+",
    ms=6,
    label="simulated objects",
)
for c in classes:
    ax.plot([], [], "o", color=colours[c], label=c)
ax.set_aspect("equal")
ax.set_xlim(-5.0, 65.0)
ax.set_xlabel("x (m, east)")
ax.set_ylabel("y (m, north)")
ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
ax.set_title("Inventory of a simulated street: bases and footprints by class")
fig.tight_layout()
plt.show()
