"""
Load the DALES objects and look at them
=======================================

:func:`skpcd.datasets.load_dales_objects` reads the DALES objects (Singer and Asari,
2021; one file per object and a ``labels.csv``) with :func:`skpcd.io.read_segments`,
which reads any folder of labelled segments. The objects are not shipped with skpcd:
the function reads them from a folder you give, or from the one named by
``SKPCD_DALES_DIR``. With ``synthetic_if_missing=True``, as here, it returns the
synthetic objects of :func:`skpcd.datasets.make_urban_objects` when there is no such
folder, and ``folder`` is then None. Here we count the objects per class and draw
one object of each class; the output and the figure's title say which data came back.
"""

import matplotlib.pyplot as plt
import numpy as np

from skpcd.datasets import load_dales_objects

# The DALES objects where SKPCD_DALES_DIR names their folder, else synthetic objects
# of make_urban_objects (40 per class); ``objects.folder`` is None for the latter.
objects = load_dales_objects(synthetic_if_missing=True, n_per_class=40)
if objects.folder is not None:
    data = f"DALES objects ({len(objects.data)} real aerial objects)"
else:
    data = f"synthetic make_urban_objects ({len(objects.data)}; DALES unavailable)"
print(f"data: {data}")
clouds, labels = objects.data, objects.target

classes, counts = np.unique(labels, return_counts=True)
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
fig.suptitle(data)
plt.show()
