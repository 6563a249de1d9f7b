"""Identification of segments from their descriptors."""

from skpcd.classification._default import make_default_pipeline
from skpcd.classification._two_step import TwoStepClassifier

__all__ = ["TwoStepClassifier", "make_default_pipeline"]
