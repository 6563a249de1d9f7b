"""
Train on scans labelled point by point, and score a scan point by point
=======================================================================

A survey whose points are already labelled (a classification painted in CloudCompare,
the ``classification`` of a LAS file) trains a model without cutting objects by hand:
:func:`skpcd.datasets.objects_from_labelled_scans` cuts each scan into segments as
``skpcd identify`` does and gives every segment the class of most of its points. Here
two labelled scans train a model, ``skpcd identify`` labels a third, and
``skpcd score-scan`` (:func:`skpcd.metrics.scan_scores`) scores the third point by
point against its own labels.

The three sweeps are **simulated** (:func:`skpcd.datasets.make_street_scene` with the
``"spinning"`` pattern and the beams of a Hesai Pandar64), so that the page builds
anywhere, and written as a user would have them: two LAZ files with class codes in
``classification`` and a Classification Lookup naming them, and one PLY exported from
CloudCompare with the codes in a scalar field. Everything is written in a new
temporary folder. Read more in :ref:`labelled-scan-training`.
"""

import tempfile
from pathlib import Path

import laspy
import matplotlib.pyplot as plt
import numpy as np
from sklearn.model_selection import GroupKFold, cross_val_score

import skpcd.cli
from skpcd.classification import make_street_pipeline
from skpcd.datasets import make_street_scene, objects_from_labelled_scans
from skpcd.io import (
    read_point_labels,
    read_predicted_labels,
    save_model,
    write_point_cloud,
)
from skpcd.metrics import scan_scores

folder = Path(tempfile.mkdtemp(prefix="skpcd_labelled_scans_"))

# %%
# Three labelled sweeps, as files
# -------------------------------
# The annotator's codes: ASPRS codes where ASPRS has the class, user codes from 64
# for the others, and 0 for the points left unlabelled (here every point farther than
# 40 m from the sensor). ``classes.csv`` is the class map: a ``code,name`` row per
# code, ``ignore`` for the points that must count neither in training nor in scoring.
CODES = {
    "ground": 2,
    "bush": 4,
    "tree": 5,
    "facade": 6,
    "wire": 14,
    "car": 64,
    "person": 65,
    "pole": 66,
    "lamp_post": 67,
    "street_light": 68,
    "traffic_light": 69,
    "pedestrian_signal": 70,
    "traffic_sign": 71,
    "fence": 72,
    "other": 73,
}
class_map = folder / "classes.csv"
class_map.write_text(
    "code,name\n0,ignore\n" + "".join(f"{c},{n}\n" for n, c in CODES.items())
)

scenes = []
for seed in (1, 2, 3):
    scene = make_street_scene(
        80.0,
        scanner="spinning",
        scanner_params={"sensor": "pandar64"},
        random_state=seed,
    )
    codes = np.array([CODES[c] for c in scene.labels], dtype=np.uint8)
    far = np.linalg.norm(scene.points[:, :2] - scene.trajectory[0, :2], axis=1) > 40
    codes[far] = 0
    scenes.append((scene, codes))
    print(f"street {seed}: {len(scene.points)} points, {far.sum()} left unlabelled")

# Two LAZ files, as a LAS tool writes them: codes in ``classification`` and a
# Classification Lookup VLR (names of at most 15 characters) naming them.
for i, (scene, codes) in enumerate(scenes[:2], 1):
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = np.floor(scene.points.min(axis=0))
    header.scales = [0.001, 0.001, 0.001]
    lookup = laspy.vlrs.known.ClassificationLookupVlr()
    lookup[0] = "unlabelled"
    for name, code in CODES.items():
        lookup[code] = name[:15]
    header.vlrs.append(lookup)
    las = laspy.LasData(header)
    las.x, las.y, las.z = scene.points.T
    las.classification = codes
    las.write(folder / f"street_{i}.laz")

# The third as CloudCompare exports a cloud with a painted scalar field: a PLY whose
# field ``scalar_Classification`` holds the codes as floats.
test_scene, test_codes = scenes[2]
write_point_cloud(
    folder / "street_3.ply",
    test_scene.points,
    fields={"scalar_Classification": test_codes.astype(np.float32)},
)

# The lookup names the codes of a LAZ file; the class map renames them and leaves
# the unlabelled points out.
for map_ in (None, class_map):
    scan = read_point_labels(folder / "street_1.laz", class_map=map_)
    names, counts = np.unique(scan.labels, return_counts=True)
    print(
        f"street_1.laz, class map {map_ and map_.name}:",
        ", ".join(f"{n} {c}" for n, c in zip(names, counts)),
    )

# %%
# Objects to train on
# -------------------
# No instance ids in these files: every object is a segment of skpcd's own
# segmentation, labelled by the majority of its labelled points. A segment is left
# out when its majority is ground, when all its points are unlabelled, when its
# majority class holds less than half of its labelled points (``min_purity=0.5``),
# or when it has fewer than 50 points. ``objects.scan`` says which scan each object
# came from: the groups of a cross-validation that never tests on a scan it trained
# on.
train = [folder / "street_1.laz", folder / "street_2.laz"]
objects = objects_from_labelled_scans(train, class_map=class_map, n_jobs=-1)
names, counts = np.unique(objects.labels, return_counts=True)
print(
    f"{len(objects.clouds)} objects:",
    ", ".join(f"{n} {c}" for n, c in zip(names, counts)),
)
print("left out:", objects.left_out)
print(f"purity: median {np.median(objects.purity):.2f}, min {objects.purity.min():.2f}")

accuracy = cross_val_score(
    make_street_pipeline(n_jobs=-1),
    objects.clouds,
    objects.labels,
    groups=objects.scan,
    cv=GroupKFold(n_splits=2),
)
print(f"trained on one scan, tested on the other: accuracy {np.round(accuracy, 2)}")

# %%
# Fit, then identify the third scan
# ---------------------------------
# The street pipeline (:func:`~skpcd.classification.make_street_pipeline`: every
# segment sampled on a 0.2 m grid first, which suits sweeps whose density falls with
# the range) is fitted on the objects of both scans and saved.
# ``skpcd fit street_1.laz street_2.laz --class-map classes.csv -o model.skpcd``
# cuts the same objects and fits the default pipeline on them. ``skpcd identify``
# cuts the third scan as the training scans were cut and labels every point; the
# calls of :func:`skpcd.cli.main` below are those of the command line.
model = make_street_pipeline(n_jobs=-1).fit(objects.clouds, objects.labels)
save_model(model, folder / "model.skpcd")
status = skpcd.cli.main(
    [
        "identify",
        str(folder / "street_3.ply"),
        "--model",
        str(folder / "model.skpcd"),
        "-o",
        str(folder / "identified.ply"),
    ]
)

# %%
# Score the third scan point by point
# -----------------------------------
# ``skpcd score-scan`` reads what ``identify`` wrote (points in no segment are
# ``unclassified``, ground points ``ground``) and the truth from the CloudCompare
# field, names both with the class map, and prints the IoU of every true class,
# their mean (mIoU), the overall accuracy and the confusion matrix.
status = skpcd.cli.main(
    [
        "score-scan",
        str(folder / "identified.ply"),
        "--truth",
        str(folder / "street_3.ply"),
        "--truth-from",
        "scalar_Classification",
        "--map",
        str(class_map),
        "-o",
        str(folder / "scores.json"),
    ]
)

# %%
# The same in Python, and what it looks like
# ------------------------------------------
# :func:`~skpcd.metrics.scan_scores` takes the two arrays of class names. The first
# figure gives the IoU of each class, the second the third scan from above,
# coloured by its labels and by the classes ``identify`` gave (dark grey: points in
# no segment).
#
# Two sweeps make a small training set: most of its objects are pieces of facade,
# and a class seen in a few objects only is often given another one. The classes
# that matter for a survey need tens of objects each, from as many scans as it
# takes; :func:`~skpcd.datasets.objects_from_labelled_scans` reads any number, and
# the cross-validation grouped by scan above says how a model carries to a scan it
# has not seen.
truth = read_point_labels(
    folder / "street_3.ply", "scalar_Classification", class_map=class_map
).labels
pred = read_predicted_labels(folder / "identified.ply")
scores = scan_scores(truth, pred)
print(f"mIoU {scores.miou:.3f}, accuracy {scores.accuracy:.3f}")

fig, ax = plt.subplots(figsize=(6, 3.5), layout="constrained")
order = sorted(scores.classes, key=scores.iou.get)
ax.barh(order, [scores.iou[c] for c in order], color="C0")
ax.axvline(scores.miou, color="k", ls="--", lw=1, label=f"mIoU {scores.miou:.2f}")
ax.set_xlim(0, 1)
ax.set_xlabel("IoU")
ax.legend(loc="lower right")
ax.set_title("third scan, per-point IoU of each class")

COLORS = {
    "ground": "0.8",
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
    "person": "#17becf",
    "unclassified": "0.5",
    "ignore": "0.93",
}
points = test_scene.points
fig, axes = plt.subplots(2, 1, figsize=(9, 7.5), layout="constrained", sharex=True)
for ax, labels, title in ((axes[0], truth, "labels"), (axes[1], pred, "identify")):
    for name, color in COLORS.items():
        sel = labels == name
        if sel.any():
            ax.scatter(
                *points[sel, :2].T, s=0.3, color=color, label=name, rasterized=True
            )
    ax.plot(*test_scene.trajectory[0, :2], "k*", ms=6)
    ax.set_aspect("equal")
    ax.set_xlim(-5, 85)
    ax.set_ylim(-20, 20)
    ax.set_ylabel("y (m)")
    ax.set_title(f"third scan, {title}")
    ax.legend(
        fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1), markerscale=8
    )
axes[1].set_xlabel("x (m)")
plt.show()
