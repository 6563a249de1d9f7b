"""Ground removal: the estimator, its filters (SMRF, CSF, the bases pass)
and their parameters for each kind of scan; or the ground a scan already
carries in its classification (:class:`ClassifiedGround`)."""

from skpcd.segmentation.ground._classified import FROM_FILE, ClassifiedGround
from skpcd.segmentation.ground._filter import GroundFilter
from skpcd.segmentation.ground._presets import GROUND_PRESETS

__all__ = ["FROM_FILE", "GROUND_PRESETS", "ClassifiedGround", "GroundFilter"]
