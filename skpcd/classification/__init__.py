"""Identification of segments from their descriptors."""

from skpcd.classification._default import make_default_pipeline

__all__ = ["make_default_pipeline"]
