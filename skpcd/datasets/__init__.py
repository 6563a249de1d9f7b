"""Datasets: synthetic generators and the embedded default objects."""

from skpcd.datasets._dales import DALES_ENV, load_dales_objects
from skpcd.datasets._labelled_scans import GROUND_CLASSES, objects_from_labelled_scans
from skpcd.datasets._object_scene import make_scene
from skpcd.datasets._primitives import PRIMITIVES, make_primitives
from skpcd.datasets._random import make_point_clouds
from skpcd.datasets._street import (
    SCAN_PATTERNS,
    SPINNING_SENSORS,
    STREET_CLASSES,
    STREET_OBJECT_CLASSES,
    make_street_objects,
    make_street_scene,
)
from skpcd.datasets._urban import URBAN_CLASSES, make_urban_objects

__all__ = [
    "DALES_ENV",
    "GROUND_CLASSES",
    "PRIMITIVES",
    "SCAN_PATTERNS",
    "SPINNING_SENSORS",
    "STREET_CLASSES",
    "STREET_OBJECT_CLASSES",
    "URBAN_CLASSES",
    "load_dales_objects",
    "make_point_clouds",
    "make_primitives",
    "make_scene",
    "make_street_objects",
    "make_street_scene",
    "make_urban_objects",
    "objects_from_labelled_scans",
]
