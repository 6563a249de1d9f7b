"""
Cross-validate the default identification pipeline
==================================================

The default pipeline (:func:`skpcd.classification.make_default_pipeline`) describes
each segment with global shape features (:class:`skpcd.features.ShapeFeatures`) and
classifies it with a random forest. This is what ``skpcd evaluate`` runs; here we
cross-validate it on the DALES objects and draw the confusion matrix.
"""

import matplotlib.pyplot as plt
import numpy as np
from sklearn.metrics import ConfusionMatrixDisplay, classification_report
from sklearn.model_selection import StratifiedKFold, cross_val_predict

from skpcd.classification import make_default_pipeline
from skpcd.datasets import load_dales_objects

# The real DALES objects where SKPCD_DALES_DIR points to them, else synthetic stand-ins.
objects = load_dales_objects(synthetic_if_missing=True, n_per_class=40)
clouds, labels = objects.data, objects.target

cv = StratifiedKFold(n_splits=5, shuffle=True, random_state=0)
predicted = cross_val_predict(make_default_pipeline(n_jobs=2), clouds, labels, cv=cv)
print(f"accuracy: {np.mean(predicted == labels):.3f}")
print(classification_report(labels, predicted, digits=3))

# %%
# Where the errors are.
ConfusionMatrixDisplay.from_predictions(labels, predicted, cmap="Blues", colorbar=False)
plt.title("5-fold cross-validated predictions")
plt.tight_layout()
plt.show()
