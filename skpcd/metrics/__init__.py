"""Measures of a labelling: per-point scores of a labelled scan."""

from skpcd.metrics._scan_scores import format_scan_scores, scan_scores

__all__ = ["format_scan_scores", "scan_scores"]
