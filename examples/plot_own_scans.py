"""
Identify the objects of a scan with no labels, then with a few
==============================================================

A new survey comes without labels. skpcd ships a street model
(:func:`skpcd.classification.load_street_model`) fitted on simulated streets only,
which ``skpcd identify`` and ``skpcd predict`` use when no model is given. Here it
labels the segments of one sweep of a car-mounted 64-beam spinning sensor; then
:class:`~skpcd.classification.SimulationAugmented` learns from three labelled
segments per class, completed by simulated objects of those classes.

The sweep is **simulated** (:func:`skpcd.datasets.make_street_scene` with the
``"spinning"`` pattern and the beams of a Hesai Pandar64, as in PandaSet), so that
the page builds anywhere and every point carries its truth. What the model scores
on real PandaSet and KITTI sweeps is in the user guide (:ref:`own_scans`).
"""

import matplotlib.pyplot as plt
import numpy as np

from skpcd.classification import (
    SimulationAugmented,
    load_street_model,
    make_street_pipeline,
    predict_with_confidence,
)
from skpcd.datasets import make_street_objects, make_street_scene
from skpcd.segmentation import segment_scene

scene = make_street_scene(
    60.0, scanner="spinning", scanner_params={"sensor": "pandar64"}, random_state=7
)
points = scene.points
print(f"one Pandar64 sweep of a 60 m street: {len(points)} points")

# %%
# Segment, then label every segment with the shipped model
# --------------------------------------------------------
# Facades and wires come out of the segmentation typed as such; the other segments
# go to the model. Each answer has a probability; the model can also say "unknown"
# below a probability (``load_street_model(unknown_threshold=0.5)``).
seg = segment_scene(points)
model, info = load_street_model(return_info=True)
print(f"street model {info['metadata']['model_version']}: {', '.join(model.classes_)}")
objects = np.flatnonzero(seg.kinds == "object")
clouds = [points[seg.labels == i] for i in objects]
keep = [len(c) >= 20 for c in clouds]
objects = objects[keep]
clouds = [c for c, k in zip(clouds, keep) if k]
pred, kind, confidence = predict_with_confidence(model, clouds)

# the true class of each segment: the class of most of its points
truth = []
for i in objects:
    names, counts = np.unique(scene.labels[seg.labels == i], return_counts=True)
    truth.append(names[np.argmax(counts)])
truth = np.array(truth)
known = np.isin(truth, model.classes_)
print(
    f"{len(clouds)} object segments, {known.sum()} mostly of a class the model knows "
    f"(the others are mostly ground or facade); right: "
    f"{(pred[known] == truth[known]).mean():.0%}"
)
for c in np.unique(truth[known]):
    m = truth == c
    names, counts = np.unique(pred[m], return_counts=True)
    called = ", ".join(f"{p} {n}" for p, n in zip(names, counts))
    print(f"  {c:18s} {m.sum():3d} segments, called {called}")

# %%
# The sweep, coloured by the answer
# ---------------------------------
# Top view; grey: ground, facades, wires and segments of fewer than 20 points. The
# pieces of wall that the segmentation leaves as objects (along the building lines)
# get a class too: what to do with them is the segmentation's business.
classes = list(model.classes_)
palette = plt.get_cmap("tab20")(np.arange(len(classes)))
fig, ax = plt.subplots(figsize=(9, 4.5), layout="constrained")
rest = np.ones(len(points), bool)
for i, p in zip(objects, pred):
    rest[seg.labels == i] = False
ax.scatter(*points[rest, :2].T, s=0.2, c="0.8", rasterized=True)
for j, c in enumerate(classes):
    sel = np.isin(seg.labels, objects[pred == c])
    if sel.any():
        ax.scatter(
            *points[sel, :2].T, s=1.5, color=palette[j], label=c, rasterized=True
        )
ax.plot(*scene.trajectory[0, :2], "k*", ms=3, label="sensor")
ax.set_aspect("equal")
ax.set_xlim(-5, 65)
ax.set_ylim(-20, 20)
ax.set_xlabel("x (m)")
ax.set_ylabel("y (m)")
ax.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1), markerscale=4)
ax.set_title("segments labelled by the shipped street model")

# %%
# A few labels of your own
# ------------------------
# Three labelled segments per class, here cut from other simulated sweeps (a user
# would label segments of the survey with ``skpcd segment`` and a ``labels.csv``).
# ``SimulationAugmented`` adds 20 simulated objects of each of these classes, here of
# spinning sensors (its default, ``scanner="auto"``, also tries profilers and keeps
# the kind whose simulated objects label your segments best), and counts each real
# segment five times; a model of the three segments per class alone is the
# comparison.
few, few_labels = make_street_objects(
    3,
    classes=["car", "person", "tree", "traffic_sign"],
    scanner="spinning",
    scanner_params={"sensor": "pandar64"},
    min_points=20,
    random_state=70,
)
augmented = SimulationAugmented(n_per_class=20, scanner="spinning", random_state=0)
augmented.fit(few, few_labels)
alone = make_street_pipeline().fit(few, few_labels)
test = np.isin(truth, augmented.classes_)
for name, m in (("3 per class + simulation", augmented), ("3 per class alone", alone)):
    right = (m.predict([clouds[i] for i in np.flatnonzero(test)]) == truth[test]).mean()
    print(f"{name:25s} right on {test.sum()} segments of those classes: {right:.0%}")
