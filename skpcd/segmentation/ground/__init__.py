"""Ground removal: the estimator, its filters (SMRF, CSF, the bases pass)
and their parameters for each kind of scan."""

from skpcd.segmentation.ground._filter import GroundFilter
from skpcd.segmentation.ground._presets import GROUND_PRESETS

__all__ = ["GROUND_PRESETS", "GroundFilter"]
