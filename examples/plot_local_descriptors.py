"""
Local descriptors of one object per class
=========================================

:class:`skpcd.features.FPFHTransformer` gives one 33-bin histogram per point. Averaged
over an object, the histogram already tells flat roofs from the scattered surfaces of
trees. Here: one object per class, the mean histograms side by side, and its points
coloured by the dominant bin.

The objects are DALES objects where ``SKPCD_DALES_DIR`` names their folder, and
synthetic objects of :func:`skpcd.datasets.make_urban_objects` otherwise; the
example prints, and the figures' titles say, which.
"""

import matplotlib.pyplot as plt
import numpy as np

from skpcd.datasets import load_dales_objects
from skpcd.features import FPFHTransformer, PFHTransformer

# The DALES objects where SKPCD_DALES_DIR names their folder, else synthetic objects
# of make_urban_objects (10 per class); ``objects.folder`` is None for the latter.
objects = load_dales_objects(synthetic_if_missing=True, n_per_class=10)
if objects.folder is not None:
    data = f"DALES objects ({len(objects.data)} real aerial objects)"
else:
    data = f"synthetic make_urban_objects ({len(objects.data)}; DALES unavailable)"
print(f"data: {data}")
clouds, labels = objects.data, objects.target

classes = sorted(set(labels.tolist()))
picked = [next(c for c, y in zip(clouds, labels) if y == k) for k in classes]
fpfh = FPFHTransformer(n_neighbors=15, pooling="mean").fit_transform(picked)
pfh = PFHTransformer(n_neighbors=15, pooling="mean").fit_transform(picked)

fig, axes = plt.subplots(2, 1, figsize=(10, 6), constrained_layout=True)
width = 0.8 / len(classes)
for i, name in enumerate(classes):
    axes[0].bar(np.arange(33) + i * width, fpfh[i], width, label=name)
    axes[1].plot(pfh[i], label=name)
for x in (11, 22):
    axes[0].axvline(x - 0.1, color="k", lw=0.5)
axes[0].set_title("mean FPFH (f1 | f2 | f3, 11 bins each)")
axes[1].set_title("mean PFH (125 bins, f1 fastest)")
axes[0].legend(ncol=len(classes))
axes[1].set_xlabel("bin")
fig.suptitle(f"one object per class: {data}")
plt.show()

# %%
# The points of each object, coloured by the FPFH bin of f2 (11-21) with the
# largest value: flat parts and edges separate.
per_point = FPFHTransformer(n_neighbors=15, undefined="zero").fit_transform(picked)
fig = plt.figure(figsize=(12, 3.2))
for i, (name, cloud, h) in enumerate(zip(classes, picked, per_point)):
    ax = fig.add_subplot(1, len(classes), i + 1, projection="3d")
    xyz = cloud - cloud.mean(axis=0)
    ax.scatter(*xyz.T, c=h[:, 11:22].argmax(axis=1), s=1, cmap="tab10", vmin=0, vmax=10)
    ax.set_title(name)
    ax.set_axis_off()
    ax.set_box_aspect(np.ptp(xyz, axis=0) + 1e-9)
fig.suptitle(data)
plt.show()
