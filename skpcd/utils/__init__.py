"""Utilities: input validation and helpers shared by the estimators."""

from skpcd.utils._validation import check_point_clouds

__all__ = ["check_point_clouds"]
