"""Utilities: input validation and helpers shared by the estimators."""

from skpcd.utils._parallel import batch_config
from skpcd.utils._validation import check_point_clouds

__all__ = ["batch_config", "check_point_clouds"]
