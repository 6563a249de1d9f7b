"""Identification of segments from their descriptors."""

from skpcd.classification._case_based import (
    CaseBasedClassifier,
    case_similarity,
    make_case_based_pipeline,
)
from skpcd.classification._confidence import predict_with_confidence
from skpcd.classification._default import (
    PIPELINES,
    make_default_pipeline,
    make_named_pipeline,
)
from skpcd.classification._reject import RejectUnknown
from skpcd.classification._two_step import TwoStepClassifier

__all__ = [
    "PIPELINES",
    "CaseBasedClassifier",
    "RejectUnknown",
    "TwoStepClassifier",
    "case_similarity",
    "make_case_based_pipeline",
    "make_default_pipeline",
    "make_named_pipeline",
    "predict_with_confidence",
]
