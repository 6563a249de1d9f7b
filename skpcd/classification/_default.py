"""The default identification pipeline used by ``skpcd evaluate``."""

from sklearn.ensemble import RandomForestClassifier
from sklearn.pipeline import make_pipeline

from skpcd.features import ShapeFeatures

__all__ = ["make_default_pipeline"]


def make_default_pipeline(*, random_state=0, n_jobs=None):
    """Build the default segment-identification pipeline.

    Global shape features of each segment (:class:`~skpcd.features.ShapeFeatures`)
    followed by a random forest of 300 trees. It takes a list of clouds and
    predicts one label per cloud; it composes with
    :func:`~sklearn.model_selection.cross_val_score` and
    :class:`~sklearn.model_selection.GridSearchCV` like any scikit-learn
    pipeline (``randomforestclassifier__max_features``...).

    Parameters
    ----------
    random_state : int, RandomState instance or None, default=0
        Seeds the forest.
    n_jobs : int, default=None
        Threads for the forest; None means 1, -1 all cores.

    Returns
    -------
    pipeline : sklearn.pipeline.Pipeline
        An unfitted pipeline.

    Examples
    --------
    >>> from skpcd.classification import make_default_pipeline
    >>> from skpcd.datasets import make_urban_objects
    >>> clouds, labels = make_urban_objects(n_per_class=10, random_state=0)
    >>> model = make_default_pipeline().fit(clouds[:40], labels[:40])
    >>> model.predict(clouds[40:]).shape
    (10,)
    """
    return make_pipeline(
        ShapeFeatures(),
        RandomForestClassifier(
            n_estimators=300, random_state=random_state, n_jobs=n_jobs
        ),
    )
