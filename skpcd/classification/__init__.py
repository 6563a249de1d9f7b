"""Identification of segments from their descriptors."""

from skpcd.classification._augmented import AUGMENT_SCANNERS, SimulationAugmented
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
from skpcd.classification._segments import identify_segments
from skpcd.classification._street import (
    STREET_MODEL_CLASSES,
    STREET_MODEL_PATH,
    STREET_VOXEL,
    load_street_model,
    make_street_pipeline,
)
from skpcd.classification._two_step import TwoStepClassifier

__all__ = [
    "AUGMENT_SCANNERS",
    "PIPELINES",
    "STREET_MODEL_CLASSES",
    "STREET_MODEL_PATH",
    "STREET_VOXEL",
    "CaseBasedClassifier",
    "RejectUnknown",
    "SimulationAugmented",
    "TwoStepClassifier",
    "case_similarity",
    "identify_segments",
    "load_street_model",
    "make_case_based_pipeline",
    "make_default_pipeline",
    "make_named_pipeline",
    "make_street_pipeline",
    "predict_with_confidence",
]
