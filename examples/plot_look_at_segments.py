"""
Read a folder of segments and look at them
==========================================

:func:`skpcd.io.read_segments` reads one file per object and its labels. Here we read
the DALES objects, count them per class, and draw one object of each class.
"""

import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from skpcd.datasets import make_urban_objects
from skpcd.io import read_segments

folder = Path(os.environ.get("SKPCD_DALES_DIR", "../../shared/data/dales_objects"))
if (folder / "labels.csv").is_file():
    clouds, labels, names = read_segments(folder, folder / "labels.csv")
    source = "DALES objects"
else:  # no real data here: the embedded synthetic objects
    clouds, labels = make_urban_objects(n_per_class=40, random_state=0)
    source = "synthetic urban objects"

classes, counts = np.unique(labels, return_counts=True)
print(source)
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
fig.suptitle(source)
plt.show()
