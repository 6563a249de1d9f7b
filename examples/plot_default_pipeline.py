"""
Cross-validate the default identification pipeline
==================================================

The default pipeline (:func:`skpcd.classification.make_default_pipeline`) describes
each segment with global shape features (:class:`skpcd.features.ShapeFeatures`), its
vertical structure (:class:`skpcd.features.VerticalProfile`) and its PFH averaged over
its points (:class:`skpcd.features.PFHTransformer`), and classifies it with a random
forest of 300 trees. This is what ``skpcd evaluate`` runs;
here we cross-validate it (one 5-fold cross-validation) and draw the confusion matrix.

It runs on the DALES objects where ``SKPCD_DALES_DIR`` names their folder, and on the
200 synthetic objects of :func:`skpcd.datasets.make_urban_objects` (the data of
``skpcd evaluate`` without a folder) otherwise; it prints, and the figure's title
says, which. The user guide's 98.9 % (:ref:`street_default`) is the mean over 5 folds
repeated twice on the DALES objects.
"""

import matplotlib.pyplot as plt
import numpy as np
from sklearn.metrics import ConfusionMatrixDisplay, classification_report
from sklearn.model_selection import StratifiedKFold, cross_val_predict

from skpcd.classification import make_default_pipeline
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

cv = StratifiedKFold(n_splits=5, shuffle=True, random_state=0)
predicted = cross_val_predict(make_default_pipeline(n_jobs=2), clouds, labels, cv=cv)
print(f"accuracy: {np.mean(predicted == labels):.3f}")
print(classification_report(labels, predicted, digits=3))

# %%
# Where the errors are.
ConfusionMatrixDisplay.from_predictions(labels, predicted, cmap="Blues", colorbar=False)
plt.title(f"5-fold cross-validated predictions\n{data}")
plt.tight_layout()
plt.show()
