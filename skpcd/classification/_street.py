"""The street model: a pipeline robust to density, and the fitted one shipped."""

from pathlib import Path

import numpy as np
from sklearn.ensemble import RandomForestClassifier
from sklearn.pipeline import FeatureUnion, Pipeline

from skpcd.classification._reject import RejectUnknown
from skpcd.datasets import STREET_OBJECT_CLASSES
from skpcd.exceptions import IncompatibleModelError
from skpcd.features import PFHTransformer, ShapeFeatures, VerticalProfile
from skpcd.io import load_model
from skpcd.preprocessing import GridSampler

__all__ = [
    "STREET_MODEL_CLASSES",
    "STREET_MODEL_PATH",
    "STREET_VOXEL",
    "load_street_model",
    "make_street_pipeline",
]

#: The model file shipped inside the package (rebuilt by
#: ``benchmarks/build_street_model.py``).
STREET_MODEL_PATH = Path(__file__).with_name("street_model.skpcd")

# how close the shipped model's answers on its probe clouds must stay
_PROBE_TOLERANCE = 1e-6

#: The classes of the shipped street model: every object class of the street
#: simulator but ``fence`` (long fences are cut into pieces of any length by a
#: segmentation; they are left to the user's own labels).
STREET_MODEL_CLASSES = tuple(c for c in STREET_OBJECT_CLASSES if c != "fence")

#: The grid (m) each segment is sampled on before the street pipeline
#: describes it.
STREET_VOXEL = 0.2


def make_street_pipeline(
    *, voxel_size=STREET_VOXEL, unknown_threshold=None, random_state=0, n_jobs=None
):
    """Build the identification pipeline of the street model.

    The features of the default pipeline (:func:`make_default_pipeline`:
    shape features, vertical profile and mean PFH) after a
    :class:`~skpcd.preprocessing.GridSampler` that brings every segment to
    one spacing, and a random forest of 300 trees that can answer
    ``"unknown"``. A car 5 m from a 128-beam sensor and one 60 m from a
    16-beam sensor are described at the same density, as far as the
    sparser allows: this is what lets a model trained on simulated scans of
    some sensors carry to real scans of others (the sim-to-real benchmark,
    :ref:`own_scans`).

    Parameters
    ----------
    voxel_size : float, default=STREET_VOXEL
        Cell of the grid each segment is sampled on, metres.
    unknown_threshold : float or None, default=None
        Answer ``"unknown"`` where the best class probability is below it
        (:class:`~skpcd.classification.RejectUnknown`); None always answers
        a class. It can be changed after fitting with
        ``set_params(classifier__threshold=...)``.
    random_state : int, RandomState instance or None, default=0
        Seeds the forest.
    n_jobs : int, default=None
        Threads for sampling, the PFH and the forest; None means 1, -1 all
        cores.

    Returns
    -------
    pipeline : sklearn.pipeline.Pipeline
        An unfitted pipeline with the steps ``"sample"``, ``"features"``
        and ``"classifier"`` (the forest is
        ``classifier__estimator``).

    See Also
    --------
    load_street_model : This pipeline fitted on simulated streets.
    make_default_pipeline : The same features without the sampling.

    Examples
    --------
    >>> from skpcd.classification import make_street_pipeline
    >>> [name for name, _ in make_street_pipeline().steps]
    ['sample', 'features', 'classifier']
    """
    features = FeatureUnion(
        [
            ("shape", ShapeFeatures()),
            ("vertical", VerticalProfile()),
            ("pfh", PFHTransformer(n_neighbors=10, pooling="mean", n_jobs=n_jobs)),
        ]
    )
    forest = RandomForestClassifier(
        n_estimators=300, random_state=random_state, n_jobs=n_jobs
    )
    return Pipeline(
        [
            ("sample", GridSampler(voxel_size=voxel_size, n_jobs=n_jobs)),
            ("features", features),
            ("classifier", RejectUnknown(forest, threshold=unknown_threshold)),
        ]
    )


def load_street_model(*, unknown_threshold=None, return_info=False):
    """The street model shipped with skpcd, fitted on simulated streets only.

    A :func:`make_street_pipeline` fitted on objects of the street
    simulator (:func:`~skpcd.datasets.make_street_objects` with
    ``randomise=True``: spinning sensors of 16 to 128 beams and profilers,
    at the ranges, heights and speeds they are used) of the classes
    ``STREET_MODEL_CLASSES``: pole, lamp post, street light, traffic light,
    pedestrian signal, traffic sign, tree, car, bush, other street
    furniture and person. No real scan went into it, so it carries the
    project's licence; what it scores on real scans is in the user guide
    (:ref:`own_scans`). It is the model of ``skpcd identify`` and ``skpcd
    predict`` when no model is given.

    The file is loaded as any model file (:func:`skpcd.io.load_model`: no
    code from it runs), but across scikit-learn releases: instead of the
    versions, the model's answers on the probe clouds stored in the file
    are checked against those it gave when it was built.

    Parameters
    ----------
    unknown_threshold : float or None, default=None
        Answer ``"unknown"`` where the best class probability is below it;
        None always answers a class.
    return_info : bool, default=False
        Also return the file's metadata (version, training recipe, classes,
        versions of the libraries that built it).

    Returns
    -------
    model : sklearn.pipeline.Pipeline
        The fitted pipeline; it takes a list of clouds.
    info : dict
        Only with ``return_info=True``.

    Raises
    ------
    IncompatibleModelError
        If the model answers its probe clouds differently from when it was
        built (a scikit-learn or skpcd change): rebuild it with
        ``python benchmarks/build_street_model.py``.

    See Also
    --------
    SimulationAugmented : Add a few real labels of your own scans.

    Examples
    --------
    >>> from skpcd.classification import load_street_model
    >>> model = load_street_model()
    >>> "car" in model.classes_ and "person" in model.classes_
    True
    """
    if unknown_threshold is not None and not 0 <= unknown_threshold <= 1:
        raise ValueError(
            f"unknown_threshold must be a probability in [0, 1] or None, got "
            f"{unknown_threshold!r}"
        )
    model, info = load_model(STREET_MODEL_PATH, return_info=True, check_versions=False)
    probe = info["metadata"].get("probe", {})
    clouds = [np.asarray(c, dtype=np.float64) for c in probe.get("clouds", [])]
    expected = np.asarray(probe.get("proba", []), dtype=np.float64)
    answer = model.predict_proba(clouds) if clouds else np.empty((0, 0))
    if (
        not clouds
        or answer.shape != expected.shape
        or not np.allclose(answer, expected, rtol=0, atol=_PROBE_TOLERANCE)
    ):
        built = info["versions"]
        raise IncompatibleModelError(
            STREET_MODEL_PATH,
            "the street model answers its probe clouds differently from when it "
            f"was built (skpcd {built.get('skpcd')}, scikit-learn "
            f"{built.get('scikit-learn')}); rebuild it with python "
            "benchmarks/build_street_model.py",
        )
    model.set_params(classifier__threshold=unknown_threshold)
    return (model, info) if return_info else model
