"""Encodings of local descriptors into one fixed-length vector per segment."""

from skpcd.encoding._bag import BagOfFeatures

__all__ = ["BagOfFeatures"]
