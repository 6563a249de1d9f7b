"""
Cut a scene into objects: ground removal and DBSCAN with automatic eps
=======================================================================

A scan comes as one cloud, not as objects. :func:`skpcd.segment_scene` removes the
ground with :class:`~skpcd.segmentation.GroundFilter` (by default the cloth simulation
filter; the facade, wire and trunk steps find nothing to do in these scenes of separate
objects, see :ref:`structures`) and clusters the rest with
:class:`~skpcd.segmentation.AutoEpsDBSCAN`, whose radius comes from the curve of the
mean k-th nearest-neighbour distance (Wang et al., 2019): a multiple (``eps_scale``,
2.5 by default) of the distance at the curve's knee.

To see how well it works we need a scene whose objects we know:
:func:`~skpcd.datasets.make_scene` places segmented objects on a synthetic terrain,
with gaps between them, holes in the ground and noise points. The objects are DALES
objects where ``SKPCD_DALES_DIR`` names their folder, and synthetic objects of
:func:`skpcd.datasets.make_urban_objects` otherwise; the output and the figures'
titles say which.
"""

import matplotlib.pyplot as plt
import numpy as np
from sklearn.metrics import adjusted_rand_score

from skpcd.datasets import load_dales_objects, make_scene
from skpcd.segmentation import AutoEpsDBSCAN, plot_eps_curve, segment_scene

# The DALES objects where SKPCD_DALES_DIR names their folder, else synthetic objects
# of make_urban_objects (40 per class); ``objects.folder`` is None for the latter.
objects = load_dales_objects(synthetic_if_missing=True, n_per_class=40)
if objects.folder is not None:
    data = f"DALES objects ({len(objects.data)} real aerial objects)"
else:
    data = f"synthetic make_urban_objects ({len(objects.data)}; DALES unavailable)"
print(f"data: {data}")
clouds, labels = objects.data, objects.target

rng = np.random.default_rng(0)
pick = np.concatenate(
    [
        rng.choice(np.flatnonzero(labels == c), 5, replace=False)
        for c in np.unique(labels)
    ]
)
points, truth = make_scene([clouds[i] for i in pick], gap=3.0, random_state=0)
print(f"{len(pick)} of them in a scene of {len(points)} points")

# %%
# Segment the scene
# -----------------
# First with the default radius estimated from the data, then with the knee distance
# itself as the radius (``eps_scale=1``). The knee distance measures the spacing of
# the points on the surfaces; the sparser parts of real objects (pole arms, fence
# gaps, thin canopy) are wider apart, and at that radius they break off. The default,
# 2.5 times the knee distance (chosen by cross-validation on scenes of DALES objects,
# see :ref:`segmentation`), bridges them and stays below the 3 m gaps between
# objects. The adjusted Rand index compares the segments with the objects over the
# object points (the lowest of which the ground filter takes as ground).
auto = segment_scene(points, min_cluster_size=30)
scale = AutoEpsDBSCAN().eps_scale
knee = segment_scene(points, eps=auto.eps / scale, min_cluster_size=30)

scored = truth >= 0
for name, seg in (("automatic eps", auto), ("knee distance", knee)):
    ari = adjusted_rand_score(truth[scored], seg.labels[scored])
    print(
        f"{name:>14}: eps {seg.eps:.2f} m, {seg.n_segments} segments, "
        f"{int(seg.ground.sum())} ground points, ARI {ari:.3f}"
    )

# %%
# The segments, in colour
# -----------------------
# Ground in light grey, points in no segment (noise, fragments smaller than 30 points)
# in black.


def draw(ax, seg, title):
    n = max(seg.n_segments, 1)
    colours = plt.get_cmap("turbo")(np.random.default_rng(1).permutation(n) / n)
    step = max(1, len(points) // 60_000)
    p, lab, g = points[::step], seg.labels[::step], seg.ground[::step]
    ax.scatter(*p[g, :2].T, s=0.2, color="0.85")
    none = (lab < 0) & ~g
    ax.scatter(*p[none, :2].T, s=0.5, color="k")
    ax.scatter(*p[lab >= 0, :2].T, s=1.0, color=colours[lab[lab >= 0]])
    ax.set_title(title)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")


fig, axes = plt.subplots(1, 2, figsize=(11, 5.5), sharey=True)
draw(axes[0], knee, f"knee distance = {knee.eps:.2f} m: {knee.n_segments} segments")
draw(axes[1], auto, f"automatic eps = {auto.eps:.2f} m: {auto.n_segments} segments")
axes[0].set_ylabel("y (m)")
fig.suptitle(f"a scene of {len(pick)} of the {data}")
fig.tight_layout()
plt.show()

# %%
# The distance curve behind the automatic eps
# -------------------------------------------
# The mean distance to the k-th nearest neighbour grows with k; the knee distance is
# the fitted curve's value at its knee and eps (dashed) is ``eps_scale`` times that. It
# measures how far apart the points of a surface are, so it follows the sampling
# density of the scan.
db = AutoEpsDBSCAN(random_state=0).fit(points[~auto.ground])
ax = plot_eps_curve(db)
ax.set_title(f"the scene's non-ground points: {data}", fontsize="medium")
plt.tight_layout()
plt.show()
