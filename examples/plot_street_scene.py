"""
A simulated mobile street scan: segment it, identify the segments
=================================================================

Everything on this page runs on **simulated** data, not on a real scan:
:func:`skpcd.datasets.make_street_scene` lays out a street at random (road, kerbs,
pavements, facades with windows, trees, parked cars, street furniture, wires) and
scans it by ray casting, so the class and the object of every point are known. The
scanner is the mobile pattern of He et al. (2017), an Optech Lynx-like vehicle with
two profilers whose vertical scan planes stand at +-45 degrees to the driving
direction, here with a coarser angular step (0.2 degree) and 100 rotations per second
instead of the default 0.1 degree and 200, so that the page builds in well under a
minute.

The scan is cut into segments by :func:`skpcd.segmentation.segment_scene` (ground
removal with the ``"mobile"`` preset, then DBSCAN with automatic eps), and each
segment is identified by :func:`skpcd.classification.make_default_pipeline`, trained
on objects of :func:`skpcd.datasets.make_street_objects`: objects cut out of other
simulated streets by their true instance, with the occlusion, partial views and
density of the same scanner. Read more in :ref:`simulation`.
"""

import matplotlib.pyplot as plt
import numpy as np
from sklearn.metrics import adjusted_rand_score

from skpcd.classification import make_default_pipeline
from skpcd.datasets import (
    STREET_CLASSES,
    make_street_objects,
    make_street_scene,
)
from skpcd.preprocessing import grid_sample
from skpcd.segmentation import segment_scene

PATTERN = {"angular_step": 0.2, "rotation_rate": 100.0}
COLORS = {
    "ground": "#b0b0b0",
    "facade": "#aec7e8",
    "wire": "#000000",
    "pole": "#1f77b4",
    "lamp_post": "#ffbb78",
    "street_light": "#ff7f0e",
    "traffic_light": "#9467bd",
    "pedestrian_signal": "#c5b0d5",
    "traffic_sign": "#e377c2",
    "tree": "#2ca02c",
    "car": "#d62728",
    "bush": "#98df8a",
    "other": "#bcbd22",
    "fence": "#8c564b",
}
rng = np.random.default_rng(0)

scene = make_street_scene(80.0, scanner_params=PATTERN, random_state=11)
print(f"data: simulated mobile scan of an 80 m street, {len(scene.points)} points")
for name, count in zip(*np.unique(scene.labels, return_counts=True)):
    print(f"  {name:18s} {count:8d}")


def scatter(ax, points, labels, axes=(0, 1), size=0.3, n=200_000):
    """Points coloured by class, a random subset of at most ``n``."""
    pick = rng.choice(len(points), min(n, len(points)), replace=False)
    colors = [COLORS[c] for c in labels[pick]]
    ax.scatter(*points[pick][:, axes].T, c=colors, s=size, linewidths=0)
    ax.set_aspect("equal")


# %%
# The scene, coloured by class
# ----------------------------
# The vehicle drives the right lane (black line) towards +x. The ground under it is
# missing (the vehicle hides a cone below the scanners), objects cast shadows on what
# stands behind them, and points are found behind the windows (glass lets part of the
# beam through). Top view, then a side view of the left side of the street.
fig, (top, side) = plt.subplots(2, 1, figsize=(10, 7.5))
scatter(top, scene.points, scene.labels)
top.plot(*scene.trajectory[:, :2].T, "k-", lw=1)
top.set(xlabel="x (m)", ylabel="y (m)", title="simulated mobile scan, top view")
left = scene.points[:, 1] > 0
scatter(side, scene.points[left], scene.labels[left], axes=(0, 2))
side.set(xlabel="x (m)", ylabel="z (m)", title="left side of the street, side view")
handles = [
    plt.Line2D([], [], ls="", marker="o", color=COLORS[c], label=c)
    for c in STREET_CLASSES
    if c in set(scene.labels)
]
fig.legend(handles=handles, loc="lower center", ncol=7, fontsize=7)
fig.tight_layout(rect=(0, 0.06, 1, 1))

# %%
# Three scan patterns, one street
# -------------------------------
# The layout depends only on ``random_state``: the same 30 m street seen by the mobile
# profilers, by an airborne swath (DALES-like: five flight lines at 1300 m, about 40
# points per square metre) and by one sweep of a 32-beam spinning sensor on a small
# ground vehicle (its rings are visible on the road).
fig, axes = plt.subplots(1, 3, figsize=(12, 4.2), sharey=True)
for ax, pattern in zip(axes, ["mobile", "aerial", "ugv"]):
    params = PATTERN if pattern == "mobile" else None
    s = make_street_scene(30.0, scanner=pattern, scanner_params=params, random_state=5)
    scatter(ax, s.points, s.labels, size=0.3, n=60_000)
    ax.set(title=f"{pattern}: {len(s.points)} points", xlabel="x (m)", xlim=(-5, 35))
    if pattern == "ugv":
        ax.plot(*s.trajectory[0, :2], "k*", ms=10)
axes[0].set_ylabel("y (m)")
fig.tight_layout()

# %%
# Objects to learn from
# ---------------------
# :func:`~skpcd.datasets.make_street_objects` scans other streets furnished with the
# wanted classes and cuts each object out by its true instance (with the ground points
# at its foot, as a segmentation leaves them). Eight per class here; three of each,
# seen from the side along their widest horizontal direction (arms, plates, car
# lengths in the picture plane), coloured by height. Heights, arms, heads
# and plates vary within each class, so that classes overlap as real ones do: a lamp
# post is as tall as a traffic sign, a traffic light pole may carry a mast arm like a
# street light's arm.
clouds, labels = make_street_objects(8, scanner_params=PATTERN, random_state=0)
classes = list(dict.fromkeys(labels))
fig, axes = plt.subplots(3, len(classes), figsize=(14, 5.2))
for j, c in enumerate(classes):
    for i, k in enumerate(np.flatnonzero(labels == c)[:3]):
        ax = axes[i, j]
        xy = clouds[k][:, :2] - clouds[k][:, :2].mean(axis=0)
        widest = np.linalg.eigh(xy.T @ xy)[1][:, -1]
        z = clouds[k][:, 2] - clouds[k][:, 2].min()
        ax.scatter(xy @ widest, z, c=z, s=0.3, cmap="viridis", linewidths=0)
        ax.set_aspect("equal")
        ax.set_xlim(-4, 4)
        ax.set_ylim(-0.3, 13)
        ax.set_xticks([])
        ax.set_yticks([] if j else [0, 5, 10])
        if i == 0:
            ax.set_title(c.replace("_", " "), fontsize=8)
fig.suptitle("simulated objects of make_street_objects (side views, metres)")
fig.tight_layout()

# %%
# Segment the scan
# ----------------
# Ground removal (SMRF, mobile preset), then DBSCAN on the rest with eps estimated from
# the data; segments of fewer than 100 points are dropped. The adjusted Rand index
# compares the segments with the true objects over the non-ground points.
seg = segment_scene(scene.points, ground="mobile", min_cluster_size=100)
above = scene.labels != "ground"
ari = adjusted_rand_score(scene.instances[above], seg.labels[above])
print(f"{seg.n_segments} segments, eps {seg.eps:.2f} m, ARI {ari:.2f}")
members = [np.flatnonzero(seg.labels == s) for s in range(seg.n_segments)]
# the true class of a segment: the class of most of its points
truth = np.array(
    [max(set(scene.labels[m]), key=list(scene.labels[m]).count) for m in members],
    dtype=object,
)

# %%
# Identify the segments
# ---------------------
# The default pipeline (shape features, vertical profile and the mean PFH of the
# points, a random forest) is fitted on the simulated objects, both thinned to one
# point per 10 cm cell (:func:`~skpcd.preprocessing.grid_sample`), and predicts
# every segment. It knows the ten object classes only: segments of facades (walls,
# and rooms seen through windows) get one of those labels and are left out of the
# score.
model = make_default_pipeline().fit([grid_sample(c, 0.1) for c in clouds], labels)
predicted = model.predict([grid_sample(scene.points[m], 0.1) for m in members])
known = np.isin(truth, model.classes_)
accuracy = (predicted[known] == truth[known]).mean()
print(f"{known.sum()} segments of object classes, {accuracy:.0%} identified right")
for c in model.classes_:
    m = truth == c
    if m.any():
        print(f"  {c:18s} {int((predicted[m] == c).sum())} of {int(m.sum())}")

fig, (ax_t, ax_p) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
for ax, names, title in (
    (ax_t, truth, "segments of object classes, true class"),
    (ax_p, predicted, f"identified: {accuracy:.0%} right (crosses: wrong)"),
):
    for m, name, ok in zip(members, names, known):
        if ok:
            pts = scene.points[m[:: max(1, len(m) // 400)]]
            ax.scatter(*pts[:, :2].T, color=COLORS[name], s=1, linewidths=0)
    ax.set(title=title, ylabel="y (m)")
    ax.set_aspect("equal")
for m, ok, right in zip(members, known, predicted == truth):
    if ok and not right:
        ax_p.plot(*scene.points[m, :2].mean(axis=0), "kx", ms=8)
ax_p.set_xlabel("x (m)")
handles = [
    plt.Line2D([], [], ls="", marker="o", color=COLORS[c], label=c)
    for c in model.classes_
]
fig.legend(handles=handles, loc="lower center", ncol=5, fontsize=7)
fig.tight_layout(rect=(0, 0.08, 1, 1))
plt.show()
