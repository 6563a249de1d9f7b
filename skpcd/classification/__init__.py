"""Identification of segments from their descriptors."""

from skpcd.classification._case_based import (
    CaseBasedClassifier,
    case_similarity,
    make_case_based_pipeline,
)
from skpcd.classification._default import make_default_pipeline
from skpcd.classification._two_step import TwoStepClassifier

__all__ = [
    "CaseBasedClassifier",
    "TwoStepClassifier",
    "case_similarity",
    "make_case_based_pipeline",
    "make_default_pipeline",
]
