"""
Load the DALES objects and look at them
=======================================

:func:`skpcd.datasets.load_dales_objects` reads the DALES objects (one file per object
and a ``labels.csv``) with :func:`skpcd.io.read_segments`, which reads any folder of
labelled segments. Here we count them per class and draw one object of each class.
"""

import matplotlib.pyplot as plt
import numpy as np

from skpcd.datasets import load_dales_objects

# The real DALES objects where SKPCD_DALES_DIR points to them, else synthetic stand-ins.
objects = load_dales_objects(synthetic_if_missing=True, n_per_class=40)
clouds, labels = objects.data, objects.target

classes, counts = np.unique(labels, return_counts=True)
print(objects.source)
for c, n in zip(classes, counts):
    sizes = [len(x) for x, y in zip(clouds, labels) if y == c]
    print(f"{c:>10}: {n} objects, median {int(np.median(sizes))} points")

# %%
# One object per class, coloured by height.
fig = plt.figure(figsize=(12, 3.2))
for i, c in enumerate(classes):
    cloud = next(x for x, y in zip(clouds, labels) if y == c)
    cloud = cloud - cloud.mean(axis=0)
    ax = fig.add_subplot(1, len(classes), i + 1, projection="3d")
    ax.scatter(*cloud.T, c=cloud[:, 2], s=1, cmap="viridis")
    ax.set_title(c)
    ax.set_axis_off()
    ax.set_box_aspect(np.ptp(cloud, axis=0) + 1e-9)
fig.suptitle(objects.source)
plt.show()
